"""The geometry of ``axdf fit`` (axdf_cli/tools/fit.py): a closed muscle surface → an AxDf
axis and section outlines, and the measures of how well the muscle model reproduces it.

1. **Axis** (:func:`medial_axis`): the muscle's medial curve. Surface samples are cut into
   slabs along their principal direction and the slabs' centroids give a first curve; then,
   tol.FIT_AXIS_ROUNDS times, every sample takes its nearest point on the current curve
   (extended straight past its ends), so the slabs lie perpendicular to the curve, and the
   curve is fitted again through their centroids. Its ends are the muscle's tips, where the
   surface's poles sit. The curve is the model's own: a clamped quadratic B-spline of 5
   control points, fitted by least squares with its end points fixed.
2. **Outlines** (:func:`plane_targets`): the surface is cut by planes perpendicular to the
   axis, in the rotation-minimizing frame (R, S) the model places sections in; each cut is
   read by rays from the axis (the farthest crossing, so a cut of several loops keeps its
   outer boundary), resampled at equal arc length, and turned so that point j follows the
   previous plane's point j (control points in phase along the muscle, no twisted net).
3. **Rows** (:class:`RowFit`): the rest surface is linear in the sections' in-plane control
   points, so they are solved by least squares through the surface's own bases (along: the
   clamped quadratic over poles and sections; around: the closed quadratic over 8) so that
   the evaluated surface passes through the outlines, not its control polygon. Sections sit
   at the Greville abscissae of the along basis, where the surface at parameter u lies at
   axis parameter u (linear precision), so an outline cut at t is the surface's row at t.
4. **Refinement**: tol.FIT_REFINE_ROUNDS rounds of closest points both ways (the surface's
   samples to the mesh, the mesh's samples to the surface's nearest sample), solved the same
   way: the cut outlines' rays miss what they cannot see from the axis.

Everything is batched numpy (a loop per plane or round, none per vertex) and deterministic.
"""
from __future__ import annotations

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.geometry.winding import inside
from axdf_cli.model import bspline
from axdf_cli.model.muscle import OCT

N_AXIS = 5  # axis control points (the paper's)


# ----------------------------------------------------------------------------- the axis


def curve_points(ctrl: np.ndarray, t: np.ndarray, deriv: int = 0) -> np.ndarray:
    """The clamped quadratic B-spline of control points ``ctrl`` (n, 3) at parameters t."""
    return bspline.basis_matrix(bspline.clamped_knots(len(ctrl), 2), 2, t, deriv) @ ctrl


def fit_curve(points: np.ndarray, ends: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Control points (N_AXIS, 3) of the clamped quadratic B-spline from ``ends`` through
    ``points`` (K, 3) in order, by least squares at their chord-length parameters."""
    pts = np.concatenate([ends[0][None], points, ends[1][None]])
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    u = chord / max(chord[-1], 1e-300)
    B = bspline.basis_matrix(bspline.clamped_knots(N_AXIS, 2), 2, u)
    rhs = pts - np.outer(B[:, 0], ends[0]) - np.outer(B[:, -1], ends[1])
    inner, *_ = np.linalg.lstsq(B[:, 1:-1], rhs, rcond=None)
    return np.concatenate([ends[0][None], inner, ends[1][None]])


def _arc_positions(ctrl: np.ndarray, samples: np.ndarray):
    """Every sample's arc position along the curve extended straight past both ends (metres
    from its start; negative before it), and the dense extended polyline (D, 3) with its arc
    positions (D,)."""
    from scipy.spatial import cKDTree

    t = np.linspace(0.0, 1.0, tol.FIT_AXIS_DENSE)
    x = curve_points(ctrl, t)
    seg = np.linalg.norm(np.diff(x, axis=0), axis=1)
    arc = np.concatenate([[0.0], np.cumsum(seg)])
    length = arc[-1]
    t0 = _unit(curve_points(ctrl, np.array([0.0]), 1)[0])
    t1 = _unit(curve_points(ctrl, np.array([1.0]), 1)[0])
    ext = np.linspace(0.0, length, tol.FIT_AXIS_DENSE // 2)[1:]
    poly = np.concatenate([x[0] - ext[::-1, None] * t0, x, x[-1] + ext[:, None] * t1])
    parc = np.concatenate([-ext[::-1], arc, length + ext])
    _, idx = cKDTree(poly).query(samples)
    return parc[idx], poly, parc


def medial_axis(samples: np.ndarray) -> np.ndarray:
    """The medial curve's control points (N_AXIS, 3) of a muscle's surface samples (S, 3)."""
    mean = samples.mean(axis=0)
    _, _, vt = np.linalg.svd(samples - mean, full_matrices=False)
    d = vt[0]
    proj = (samples - mean) @ d
    ctrl = fit_curve(np.array([mean + a * d for a in np.linspace(proj.min(), proj.max(), 5)[1:-1]]),
                     (mean + proj.min() * d, mean + proj.max() * d))
    for _ in range(tol.FIT_AXIS_ROUNDS):
        a, _, _ = _arc_positions(ctrl, samples)
        lo, hi = float(a.min()), float(a.max())
        nb = tol.FIT_AXIS_SLABS
        edges = np.linspace(lo, hi, nb + 1)
        which = np.clip(np.searchsorted(edges, a, side="right") - 1, 0, nb - 1)
        count = np.bincount(which, minlength=nb)
        sums = np.stack([np.bincount(which, samples[:, c], minlength=nb) for c in range(3)], axis=1)
        keep = count > 0
        cent = sums[keep] / count[keep, None]
        # the tips: the centroid of the samples within the last slab's share, carried along
        # the curve's direction to the extreme sample
        tip = (hi - lo) * tol.FIT_TIP_SHARE
        ends = []
        for sel, extreme in ((a <= lo + tip, lo), (a >= hi - tip, hi)):
            c = samples[sel].mean(axis=0)
            ac = a[sel].mean()
            direction = _unit(cent[-1] - cent[0])
            ends.append(c + (extreme - ac) * direction)
        ctrl = fit_curve(cent[1:-1] if len(cent) > 4 else cent, (ends[0], ends[1]))
    return ctrl


# ----------------------------------------------------------------------------- outlines


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-300)


def _ray_outline(seg2: np.ndarray, k: int) -> np.ndarray:
    """The farthest crossing of each of ``k`` rays from the origin with 2-D segments (n, 2, 2):
    (k,) radii, NaN where a ray meets none."""
    phi = np.arange(k) * (2.0 * np.pi / k)
    d = np.stack([np.cos(phi), np.sin(phi)], axis=1)  # (k, 2)
    p = seg2[:, 0]
    e = seg2[:, 1] - seg2[:, 0]
    cross = lambda a, b: a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]  # noqa: E731
    den = cross(d[:, None], e[None])  # (k, n)
    ok = np.abs(den) > 1e-300
    den = np.where(ok, den, 1.0)
    rho = cross(p[None], e[None]) / den
    lam = cross(p[None], d[:, None]) / den
    hit = ok & (lam >= 0.0) & (lam <= 1.0) & (rho > 0.0)
    r = np.where(hit, rho, -np.inf).max(axis=1)
    return np.where(np.isfinite(r), r, np.nan)


def _fill_periodic(r: np.ndarray) -> np.ndarray:
    """NaN entries of a periodic profile (k,) interpolated from their neighbours."""
    good = np.isfinite(r)
    if good.all() or not good.any():
        return r
    k = len(r)
    idx = np.arange(k)
    gi = idx[good]
    return np.interp(idx, np.concatenate([gi - k, gi, gi + k]), np.tile(r[good], 3))


def _resample_closed(pts: np.ndarray, n: int, shift: np.ndarray) -> np.ndarray:
    """Closed polygon (k, 2) resampled at ``n`` equal arc steps starting at arc fraction shift
    (each of S shifts) → (S, n, 2)."""
    loop = np.concatenate([pts, pts[:1]])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(loop, axis=0), axis=1))])
    total = max(arc[-1], 1e-300)
    s = ((shift[:, None] + np.arange(n)[None] / n) % 1.0) * total
    return np.stack([np.interp(s, arc, loop[:, c]) for c in range(2)], axis=-1)


def plane_targets(mesh, c: np.ndarray, r: np.ndarray, s: np.ndarray, around: int):
    """The surface's cuts by the planes through c (M, 3) spanned by r and s (M, 3), as 3-D
    targets (M, around, 3) in phase from plane to plane, and which planes cut it (M,) bool."""
    from trimesh.intersections import mesh_plane

    normal = np.cross(r, s)
    rays = tol.FIT_RAYS
    shifts = np.linspace(-0.5 / OCT, 0.5 / OCT, tol.FIT_PHASE_STEPS)
    out = np.zeros((len(c), around, 3))
    ok = np.zeros(len(c), dtype=bool)
    prev = None
    for i in range(len(c)):
        seg = mesh_plane(mesh, normal[i], c[i])
        if len(seg) == 0:
            continue
        rel = seg - c[i]
        seg2 = np.stack([rel @ r[i], rel @ s[i]], axis=-1)
        rad = _fill_periodic(_ray_outline(seg2, rays))
        if not np.isfinite(rad).any():
            continue
        phi = np.arange(rays) * (2.0 * np.pi / rays)
        poly = np.stack([rad * np.cos(phi), rad * np.sin(phi)], axis=1)
        cand = _resample_closed(poly, around, shifts if prev is not None else np.zeros(1))
        if prev is not None:  # point j follows the previous plane's point j
            best = int(np.argmin(((cand - prev[None]) ** 2).sum(axis=(1, 2))))
            pick = cand[best]
        else:
            pick = cand[0]
        prev = pick
        out[i] = c[i] + pick[:, :1] * r[i] + pick[:, 1:] * s[i]
        ok[i] = True
    return out, ok


# ----------------------------------------------------------------------------- the rows


class RowFit:
    """Least squares of N sections' in-plane control points (2 unknowns each) so that the
    rest surface passes through targets. The surface at along parameter u and around
    parameter v is sum_k Bu_k(u) sum_l Bv_l(v) P_kl over the rows [pole0, sections, pole1],
    P_kl = c_k + x_kl r_k + y_kl s_k; it is linear in (x, y).

    c, r, s: (N, 3) each, the sections' axis points and plane axes; poles: (2, 3); ``around``:
    control points per section (the file format's 8; more only to measure what they would buy,
    docs/FIT.md)."""

    def __init__(self, c: np.ndarray, r: np.ndarray, s: np.ndarray, poles: np.ndarray, around: int = OCT):
        self.c, self.r, self.s, self.poles = c, r, s, poles
        self.n = len(c)
        self.k = around
        self.knots = bspline.clamped_knots(self.n + 2, 2)

    def bases(self, u: np.ndarray, v: np.ndarray):
        """Along (P, N+2) and around (P, k) bases at the points' parameters (P,) each."""
        return (bspline.basis_matrix(self.knots, 2, u), bspline.periodic_quadratic_basis(self.k, v % 1.0))

    def design(self, u: np.ndarray, v: np.ndarray):
        """(A (3P, 2 N k), fixed (P, 3)): the surface at (u, v) is A @ [x, y] + fixed. A is
        dense while it takes at most tol.FIT_DENSE_DESIGN_BYTES, else a sparse CSR matrix of
        the same entries (each point sees 3 rows along and 3 control points around: 18 of its
        2 N k columns), so that many sections cost memory and time in proportion to N."""
        bu, bv = self.bases(u, v)
        inner = bu[:, 1:-1]
        fixed = np.outer(bu[:, 0], self.poles[0]) + np.outer(bu[:, -1], self.poles[1]) + \
            (inner * bv.sum(axis=1, keepdims=True)) @ self.c
        if 3 * len(u) * 2 * self.n * self.k * 8 > tol.FIT_DENSE_DESIGN_BYTES:
            return self._sparse_design(inner, bv), fixed
        w = (inner[:, :, None] * bv[:, None, :]).reshape(len(u), -1)  # (P, N*k)
        ax = w[:, :, None] * np.repeat(self.r, self.k, axis=0)[None]  # (P, N*k, 3)
        ay = w[:, :, None] * np.repeat(self.s, self.k, axis=0)[None]
        a = np.concatenate([ax, ay], axis=1).transpose(0, 2, 1).reshape(3 * len(u), -1)
        return a, fixed

    def _sparse_design(self, inner: np.ndarray, bv: np.ndarray):
        """The design matrix of :meth:`design` as CSR from the bases along (P, N) and around
        (P, k), each with at most 3 non-zeros a row (quadratic B-splines)."""
        from scipy import sparse

        P, n, k = len(inner), self.n, self.k
        ja = np.argpartition(-np.abs(inner), min(2, n - 1), axis=1)[:, :min(3, n)]  # (P, 3) rows along
        jb = np.argpartition(-np.abs(bv), min(2, k - 1), axis=1)[:, :min(3, k)]  # (P, 3) points around
        p = np.arange(P)[:, None, None]
        # W[p, j k + l] = inner[p, j] bv[p, l] over the non-zeros: (P, 3, 3)
        w = inner[p[:, :, 0], ja][:, :, None] * bv[p[:, :, 0], jb][:, None, :]
        col = ja[:, :, None] * k + jb[:, None, :]
        sec = np.broadcast_to(ja[:, :, None], col.shape)
        rows, cols, vals = [], [], []
        for c in range(3):  # A[3p + c, q] = W[p, q] r[q's section, c]; the y half with s
            for half, axes in ((0, self.r), (n * k, self.s)):
                rows.append(np.broadcast_to(3 * p + c, col.shape).ravel())
                cols.append((col + half).ravel())
                vals.append((w * axes[sec, c]).ravel())
        return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                 shape=(3 * P, 2 * n * k))

    def evaluate(self, xy: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Surface points (P, 3) for in-plane coordinates xy (N, k, 2)."""
        a, fixed = self.design(u, v)
        sol = np.concatenate([xy[..., 0].ravel(), xy[..., 1].ravel()])
        return (a @ sol).reshape(-1, 3) + fixed

    def solve(self, blocks: list) -> np.ndarray:
        """Least squares over blocks [(u, v, targets (P, 3), weight, normals (P, 3) or None)]
        (with normals, only the offsets along them count: point to plane), with a little
        smoothing of each control point along the muscle (tol.FIT_SMOOTH) and round each
        section (tol.FIT_SMOOTH_AROUND): in-plane coordinates (N, k, 2)."""
        ata = 0.0
        atb = 0.0
        for u, v, target, weight, normals in blocks:
            a, fixed = self.design(u, v)
            b = (target - fixed).ravel()
            dense = isinstance(a, np.ndarray)
            if normals is not None:
                b = np.einsum("pc,pc->p", normals, target - fixed)
                if dense:
                    a = np.einsum("pc,pck->pk", normals, a.reshape(len(u), 3, -1))
                else:  # row p: sum_c n[p, c] A[3p + c]
                    from scipy import sparse

                    pick = sparse.csr_matrix((normals.ravel(), (np.repeat(np.arange(len(u)), 3), np.arange(3 * len(u)))),
                                             shape=(len(u), 3 * len(u)))
                    a = pick @ a
            wt = weight / max(len(u), 1)
            ata = ata + wt * (a.T @ a if dense else (a.T @ a).toarray())
            atb = atb + wt * (a.T @ b)
        q = self.n * self.k
        scale = float(np.trace(ata)) / (2 * q)
        if self.n >= 3:
            d = np.zeros((self.n - 2, self.n))
            for k in range(self.n - 2):
                d[k, k:k + 3] = (1.0, -2.0, 1.0)
            lap = np.kron(d.T @ d, np.eye(self.k))
            ata = ata + tol.FIT_SMOOTH * scale * np.kron(np.eye(2), lap)
        # and around each section (second differences round the loop), the more the less the
        # data sees the section (near a pole the surface is mostly the pole's), so that such a
        # row stays a smooth loop instead of crumpling
        seen = np.diag(ata).reshape(2, self.n, self.k).mean(axis=(0, 2))
        weight = scale * tol.FIT_SMOOTH_AROUND * seen.max() / np.maximum(seen, 1e-12 * seen.max())
        ring = np.eye(self.k) * -2.0 + np.roll(np.eye(self.k), 1, axis=1) + np.roll(np.eye(self.k), -1, axis=1)
        ata = ata + np.kron(np.diag(np.tile(weight, 2)), ring.T @ ring)
        ata = ata + 1e-9 * scale * np.eye(2 * q)
        sol = np.linalg.solve(ata, atb)
        return np.stack([sol[:q], sol[q:]], axis=1).reshape(self.n, self.k, 2)


def greville(n_sections: int) -> np.ndarray:
    """The section parameters (N,): the interior Greville abscissae of the clamped quadratic
    along basis over N + 2 rows (the surface at u lies at axis parameter u there)."""
    k = bspline.clamped_knots(n_sections + 2, 2)
    return 0.5 * (k[1:-2] + k[2:-1])[1:-1]


def fit_rows(mesh, rows: RowFit, frames, samples: np.ndarray, normals: np.ndarray, bound=None) -> np.ndarray:
    """In-plane control points (N, 8, 2) of the sections of ``rows`` fitted to ``mesh``:
    cut outlines first, then closest-point refinement. ``frames(t)`` → (c, r, s) (M, 3)
    each, the rest axis' frame at parameters t; ``samples`` (S, 3) the mesh's surface and
    ``normals`` (S, 3) its normals there. ``bound``: a field the surface is kept
    tol.FIT_BOUND_MARGIN inside (:func:`_bounded`): ``value(points (P, 3))`` → (P,) metres,
    positive inside, and ``inward(points)`` → (P, 3) the direction it grows in
    (:class:`~axdf_cli.geometry.partition.MeshField`)."""
    import igl
    from scipy.spatial import cKDTree

    n = rows.n
    m = tol.FIT_PLANES_PER_SECTION * n + 2 * tol.FIT_PLANES_PER_SECTION
    u = (np.arange(m) + 0.5) / m
    c, r, s = frames(u)
    around = tol.FIT_AROUND
    targets, ok = plane_targets(mesh, c, r, s, around)
    uu = np.repeat(u[ok], around)
    vv = np.tile(np.arange(around) / around, int(ok.sum()))
    xy = rows.solve([(uu, vv, targets[ok].reshape(-1, 3), 1.0, None)])
    V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    fn = np.asarray(mesh.face_normals, dtype=np.float64)
    gu = np.repeat((np.arange(2 * m) + 0.5) / (2 * m), 2 * around)
    gv = np.tile(np.arange(2 * around) / (2 * around), 2 * m)
    def data(xy):
        g = rows.evaluate(xy, gu, gv)
        _, face, near = igl.point_mesh_squared_distance(g, V, F)
        _, idx = cKDTree(g).query(samples)
        pw = tol.FIT_POINT_WEIGHT
        return [(gu, gv, near, 1.0, fn[face]), (gu[idx], gv[idx], samples, 1.0, normals),
                (gu, gv, near, pw, None), (gu[idx], gv[idx], samples, pw, None)]

    for _ in range(tol.FIT_REFINE_ROUNDS):
        xy = rows.solve(data(xy))
    if bound is not None:
        xy = _bounded(rows, xy, data, bound, gu, gv)
    return xy


def _bounded(rows: RowFit, xy: np.ndarray, data, bound, gu: np.ndarray, gv: np.ndarray) -> np.ndarray:
    """The fit ``xy`` kept inside a territory: tol.FIT_BOUND_ROUNDS rounds in which each dense
    sample (gu, gv) less than tol.FIT_BOUND_MARGIN inside (``bound``'s value) is held on the
    plane that margin inside, across the field's inward direction, with tol.FIT_BOUND_WEIGHT a
    data point's weight; held samples stay held (the active set only grows), and the data's
    closest points are found again each round."""
    held_u, held_v, held_t, held_n = [], [], [], []
    for _ in range(tol.FIT_BOUND_ROUNDS):
        g = rows.evaluate(xy, gu, gv)
        val = bound.value(g)
        bad = np.flatnonzero(val < tol.FIT_BOUND_MARGIN)
        if len(bad) == 0:
            break
        n_in = bound.inward(g[bad])
        held_u.append(gu[bad])
        held_v.append(gv[bad])
        held_t.append(g[bad] + (tol.FIT_BOUND_MARGIN - val[bad])[:, None] * n_in)
        held_n.append(n_in)
        hu = np.concatenate(held_u)
        w = tol.FIT_BOUND_WEIGHT * len(hu) / len(gu)
        xy = rows.solve(data(xy) + [(hu, np.concatenate(held_v), np.concatenate(held_t), w, np.concatenate(held_n))])
    return xy


# ----------------------------------------------------------------------------- measures


def measure(mesh_v: np.ndarray, mesh_f: np.ndarray, fit_v: np.ndarray, fit_f: np.ndarray, seed: int = 0) -> dict:
    """How well a fitted surface reproduces a mesh (both closed, metres): the volumetric
    overlap (IoU of the winding-number insides, :func:`~axdf_cli.geometry.winding.inside` signed:
    as the shipped reports were made; on a grid of at most tol.FIT_IOU_SPACING, finer for a
    muscle too thin for tol.FIT_IOU_MIN_CELLS such cells: tol.FIT_IOU_SMALL_CELLS across its
    box's thinnest side), the surface distance both ways (mean, median, mm) and the volume
    ratio fitted / mesh."""
    import igl
    import trimesh

    a = trimesh.Trimesh(mesh_v, mesh_f, process=False)
    b = trimesh.Trimesh(fit_v, fit_f, process=False)
    lo = np.minimum(a.bounds[0], b.bounds[0])
    hi = np.maximum(a.bounds[1], b.bounds[1])
    h = tol.FIT_IOU_SPACING
    if float((hi - lo).min()) < tol.FIT_IOU_MIN_CELLS * h:  # a small muscle: a grid of its own size
        h = float((hi - lo).min()) / tol.FIT_IOU_SMALL_CELLS
    h = max(h, float(np.prod(hi - lo) / tol.FIT_IOU_MAX_POINTS) ** (1.0 / 3.0))
    axes = [np.arange(lo[k] + 0.5 * h, hi[k], h) for k in range(3)]
    q = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    ia, ib = inside(mesh_v, mesh_f, q, signed=True), inside(fit_v, fit_f, q, signed=True)
    iou = float((ia & ib).sum() / max((ia | ib).sum(), 1))
    pa, _ = trimesh.sample.sample_surface(a, tol.FIT_MEASURE_SAMPLES, seed=seed)
    pb, _ = trimesh.sample.sample_surface(b, tol.FIT_MEASURE_SAMPLES, seed=seed)
    da = np.sqrt(igl.point_mesh_squared_distance(pa, np.asarray(fit_v, np.float64), np.asarray(fit_f, np.int64))[0])
    db = np.sqrt(igl.point_mesh_squared_distance(pb, np.asarray(mesh_v, np.float64), np.asarray(mesh_f, np.int64))[0])
    d = np.concatenate([da, db]) * 1000.0
    return {"iou": iou, "distance_mean_mm": float(d.mean()), "distance_median_mm": float(np.median(d)),
            "distance_max_mm": float(d.max()), "volume_ratio": float(b.volume / a.volume), "grid_mm": 1000.0 * h}
