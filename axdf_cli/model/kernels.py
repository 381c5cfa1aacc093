"""The surface kernels shared by the batch pass and the contact stage, and what is written.

A muscle's surface is the grid A + s W of a fixed part A and a volume-scaled part W, both
tessellated from their control nets. :func:`volume_cubic` gives the mesh volume's cubic
V(s) = c0 + c1 s + c2 s^2 + c3 s^3 over the grid's quads (:func:`quad_volume_terms` per quad),
:func:`solve_scale` the s with V(s) = V0 (``exact``), :func:`ring_vertices` and
:func:`pole_normals` the final grid's vertices and outward normals. The run's compiled pass
over every muscle at once (:mod:`axdf_cli.model.batch_surface`) does the same steps with the
same operations, laid out for vector instructions. :func:`written` makes what the sinks write
of a result (float32, non-finite frames to the rest shape, bounds).

Compiled once and cached (numba ``cache=True``); no ``fastmath`` (but for the bounds' minima
and maxima, over finite numbers only), so the same inputs give the same bytes.
"""
from __future__ import annotations

import numpy as np

try:
    from numba import njit
except ImportError as e:  # a dependency: make setup installs it
    raise ImportError(f"axdf needs numba for its surface kernel ({e}); run `make setup` or "
                      "`pip install numba`") from None


def sparse_rows(basis: np.ndarray, width: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A dense basis matrix (R, n) whose rows have at most ``width`` non-zeros → column
    indices (R, width) int64 and weights (R, width) float64 (zero-padded)."""
    rows = basis.shape[0]
    idx = np.zeros((rows, width), dtype=np.int64)
    w = np.zeros((rows, width))
    for r in range(rows):
        nz = np.nonzero(basis[r])[0]
        if len(nz) > width:
            raise ValueError(f"basis row {r} has {len(nz)} non-zeros, more than {width}")
        idx[r, :len(nz)] = nz
        w[r, :len(nz)] = basis[r, nz]
    return idx, w


@njit(cache=True, inline="always")
def quad_volume_terms(ax, wx, ay, wy, ad, wd):
    """One quad's four contributions (times 6) to the volume cubic of the grid a + s w: the
    triple product x . (y x d) with x = ax + s wx, y = ay + s wy, d = ad + s wd (each a tuple of
    3 floats), by powers of s (P = ay x ad, Q = wy x wd, R = wy x ad + ay x wd). Shared by
    :func:`volume_cubic` and the batch pass, so both add the same terms in the same order."""
    ax0, ax1, ax2 = ax
    wx0, wx1, wx2 = wx
    ay0, ay1, ay2 = ay
    wy0, wy1, wy2 = wy
    ad0, ad1, ad2 = ad
    wd0, wd1, wd2 = wd
    p0 = ay1 * ad2 - ay2 * ad1
    p1 = ay2 * ad0 - ay0 * ad2
    p2 = ay0 * ad1 - ay1 * ad0
    q0 = wy1 * wd2 - wy2 * wd1
    q1 = wy2 * wd0 - wy0 * wd2
    q2 = wy0 * wd1 - wy1 * wd0
    r0 = (wy1 * ad2 - wy2 * ad1) + (ay1 * wd2 - ay2 * wd1)
    r1 = (wy2 * ad0 - wy0 * ad2) + (ay2 * wd0 - ay0 * wd2)
    r2 = (wy0 * ad1 - wy1 * ad0) + (ay0 * wd1 - ay1 * wd0)
    return (ax0 * p0 + ax1 * p1 + ax2 * p2,
            (wx0 * p0 + wx1 * p1 + wx2 * p2) + (ax0 * r0 + ax1 * r1 + ax2 * r2),
            (ax0 * q0 + ax1 * q1 + ax2 * q2) + (wx0 * r0 + wx1 * r1 + wx2 * r2),
            wx0 * q0 + wx1 * q1 + wx2 * q2)


@njit(cache=True)
def volume_cubic(ga, gw):
    """Coefficients (c0, c1, c2, c3) of the mesh volume V(s) of the grid ga + s gw.
    Each quad's two triangles give p01 . (p10 x (p00 - p11)) / 6, a trilinear form in
    (p01, p10, p00 - p11), each affine in s."""
    nu = ga.shape[0]
    na = ga.shape[1]
    c0 = 0.0
    c1 = 0.0
    c2 = 0.0
    c3 = 0.0
    for u in range(nu - 1):
        for a in range(na):
            a1 = a + 1 if a + 1 < na else 0
            ax0 = ga[u, a1, 0]
            ax1 = ga[u, a1, 1]
            ax2 = ga[u, a1, 2]
            wx0 = gw[u, a1, 0]
            wx1 = gw[u, a1, 1]
            wx2 = gw[u, a1, 2]
            ay0 = ga[u + 1, a, 0]
            ay1 = ga[u + 1, a, 1]
            ay2 = ga[u + 1, a, 2]
            wy0 = gw[u + 1, a, 0]
            wy1 = gw[u + 1, a, 1]
            wy2 = gw[u + 1, a, 2]
            ad0 = ga[u, a, 0] - ga[u + 1, a1, 0]
            ad1 = ga[u, a, 1] - ga[u + 1, a1, 1]
            ad2 = ga[u, a, 2] - ga[u + 1, a1, 2]
            wd0 = gw[u, a, 0] - gw[u + 1, a1, 0]
            wd1 = gw[u, a, 1] - gw[u + 1, a1, 1]
            wd2 = gw[u, a, 2] - gw[u + 1, a1, 2]
            t0, t1, t2, t3 = quad_volume_terms((ax0, ax1, ax2), (wx0, wx1, wx2), (ay0, ay1, ay2), (wy0, wy1, wy2),
                                               (ad0, ad1, ad2), (wd0, wd1, wd2))
            c0 += t0
            c1 += t1
            c2 += t2
            c3 += t3
    return c0 / 6.0, c1 / 6.0, c2 / 6.0, c3 / 6.0


@njit(cache=True)
def solve_scale(c0, c1, c2, c3, v0, s0, iters, rtol):
    """The root s of V(s) = v0 by safeguarded Newton from the paper's
    scale s0 (V is a cubic: quadratic convergence). Returns (s, no_solution); s0 when none."""
    s = s0
    for _ in range(iters):
        fv = ((c3 * s + c2) * s + c1) * s + c0 - v0
        df = (3.0 * c3 * s + 2.0 * c2) * s + c1
        step = fv / df if df > 0.0 else 0.0
        s_new = s - step if s - step > 0.0 else 0.5 * s
        done = abs(s_new - s) <= rtol * abs(s)
        s = s_new
        if done:
            break
    fv = ((c3 * s + c2) * s + c1) * s + c0 - v0
    if not (abs(fv) <= 1e-6 * abs(v0)) or not np.isfinite(s):
        return s0, True
    return s, False


@njit(cache=True)
def ring_vertices(ga, out_v, out_n, f):
    """The final grid's vertices (poles collapsed) and the rings' normals."""
    nu = ga.shape[0]
    na = ga.shape[1]
    last = 1 + (nu - 2) * na
    for c in range(3):
        out_v[f, 0, c] = ga[0, 0, c]
        out_v[f, last, c] = ga[nu - 1, 0, c]
    for u in range(1, nu - 1):
        for a in range(na):
            vi = 1 + (u - 1) * na + a
            an = a + 1 if a + 1 < na else 0
            ap = a - 1 if a > 0 else na - 1
            sv0 = ga[u, an, 0] - ga[u, ap, 0]
            sv1 = ga[u, an, 1] - ga[u, ap, 1]
            sv2 = ga[u, an, 2] - ga[u, ap, 2]
            su0 = ga[u + 1, a, 0] - ga[u - 1, a, 0]
            su1 = ga[u + 1, a, 1] - ga[u - 1, a, 1]
            su2 = ga[u + 1, a, 2] - ga[u - 1, a, 2]
            n0 = sv1 * su2 - sv2 * su1
            n1 = sv2 * su0 - sv0 * su2
            n2 = sv0 * su1 - sv1 * su0
            ln = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-300)
            for c in range(3):
                out_v[f, vi, c] = ga[u, a, c]
            out_n[f, vi, 0] = n0 / ln
            out_n[f, vi, 1] = n1 / ln
            out_n[f, vi, 2] = n2 / ln


@njit(cache=True)
def pole_normals(ga, end0, end1, out_n, f):
    """Pole normals, the fan's area-weighted normal; the axis direction where the
    fan folds."""
    nu = ga.shape[0]
    na = ga.shape[1]
    last = 1 + (nu - 2) * na
    for side in range(2):
        row = 0 if side == 0 else nu - 1
        ring = 1 if side == 0 else nu - 2
        vi = 0 if side == 0 else last
        sign = 1.0 if side == 0 else -1.0
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        for a in range(na):
            an = a + 1 if a + 1 < na else 0
            x0 = ga[ring, an, 0] - ga[row, 0, 0]
            x1 = ga[ring, an, 1] - ga[row, 0, 1]
            x2 = ga[ring, an, 2] - ga[row, 0, 2]
            y0 = ga[ring, a, 0] - ga[row, 0, 0]
            y1 = ga[ring, a, 1] - ga[row, 0, 1]
            y2 = ga[ring, a, 2] - ga[row, 0, 2]
            f0 += x1 * y2 - x2 * y1
            f1 += x2 * y0 - x0 * y2
            f2 += x0 * y1 - x1 * y0
        ln = max(np.sqrt(f0 * f0 + f1 * f1 + f2 * f2), 1e-300)
        f0 = sign * f0 / ln
        f1 = sign * f1 / ln
        f2 = sign * f2 / ln
        e0 = end0[f, 0] if side == 0 else end1[f, 0]
        e1 = end0[f, 1] if side == 0 else end1[f, 1]
        e2 = end0[f, 2] if side == 0 else end1[f, 2]
        if f0 * e0 + f1 * e1 + f2 * e2 <= 0.5:
            le = max(np.sqrt(e0 * e0 + e1 * e1 + e2 * e2), 1e-300)
            f0 = e0 / le
            f1 = e1 / le
            f2 = e2 / le
        out_n[f, vi, 0] = f0
        out_n[f, vi, 1] = f1
        out_n[f, vi, 2] = f2


@njit(cache=True, error_model="numpy")
def written(vertices, normals, rest_v, rest_n, out_v, out_n, bounds, bad):
    """What is written of a muscle's frames: vertices, normals (F, V, 3) float64 → out_v, out_n
    (F, V, 3) float32 (rounded as numpy's ``astype``), a frame with any non-finite float32
    value replaced by the rest shape rest_v, rest_n (V, 3) float32 (its flag set in bad (F,));
    bounds (F, 2, 3) each frame's smallest and largest written coordinates."""
    nf, nv = vertices.shape[0], vertices.shape[1]
    flat_v = vertices.reshape(nf, -1)
    flat_n = normals.reshape(nf, -1)
    o_v = out_v.reshape(nf, -1)
    o_n = out_n.reshape(nf, -1)
    n3 = _U(3 * nv)
    for f in range(nf):
        ok = True
        for i in range(n3):  # (x - x is 0 for a finite x, NaN otherwise; an and of flags: vector code)
            x = np.float32(flat_v[f, i])
            y = np.float32(flat_n[f, i])
            o_v[f, i] = x
            o_n[f, i] = y
            ok = ok & ((x - x) == 0.0) & ((y - y) == 0.0)
        bad[f] = not ok
        if not ok:
            out_v[f] = rest_v
            out_n[f] = rest_n
        _bounds(out_v[f], bounds[f])


@njit(cache=True, error_model="numpy", fastmath={"nnan", "nsz"})
def _bounds(v, out):
    """Smallest and largest of each coordinate of finite points v (V, 3) into out (2, 3)
    (no NaN here, so the compiler may take the minima in any order: vector code)."""
    lo0 = v[0, 0]
    lo1 = v[0, 1]
    lo2 = v[0, 2]
    hi0 = lo0
    hi1 = lo1
    hi2 = lo2
    for i in range(_U(1), _U(v.shape[0])):
        lo0 = min(lo0, v[i, 0])
        lo1 = min(lo1, v[i, 1])
        lo2 = min(lo2, v[i, 2])
        hi0 = max(hi0, v[i, 0])
        hi1 = max(hi1, v[i, 1])
        hi2 = max(hi2, v[i, 2])
    out[0, 0] = lo0
    out[0, 1] = lo1
    out[0, 2] = lo2
    out[1, 0] = hi0
    out[1, 1] = hi1
    out[1, 2] = hi2


_U = np.uint64  # loop indices the compiler can vectorize over (no negative-index wraparound)
