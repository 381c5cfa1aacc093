"""Contact: muscles push each other out of the way, bones push muscles (issue 18, parts 3-4).

Pure, batch-first functions over all muscles of one frame (the pipeline's FRAME-scope stage
calls :func:`resolve_frame` for every frame of a chunk). Nothing is carried from one frame to
the next: the result is a function of the frame's no-contact meshes and bone poses only, so
``--jobs``, ``--resume`` and any ``--frames`` subset give the same bytes.

Geometry (every muscle is a tessellated tube: a (U, A) grid whose first and last rows
collapse to the poles):

- **Bones** collide through a signed distance field per bone, sampled once per run on a
  bone-local grid (:func:`bone_field`; libigl's ``signed_distance`` with the fast winding
  number sign of Barill et al. 2018, so a bone mesh that is not closed still has an inside:
  the points whose generalized winding number (Jacobson et al. 2013) exceeds 1/2),
  trilinear between grid points. Bones never give way.
- **Muscles** are queried in axis space: a point x is compared with muscle j at the closest
  point c of j's centre polyline (the rings' centroids between the two poles): its radial
  distance rho from c, perpendicular to the polyline, against j's surface radius R in that
  direction (the ray from c cut with the two neighbouring rings, projected into the plane
  perpendicular to the polyline, linear between them). Inside when rho < R. Where c is a
  pole, x lies past j's end cap (the cone closing the mesh): outside.

Response (tol.CONTACT_ITERATIONS Jacobi passes, every muscle against every other's previous pass):

1. at 12 evenly spaced points of every ring (:func:`_ring_modes`), the push the point asks
   for (:func:`_point_push`): out of a neighbour j it lies within the margin of, along the line
   from j's axis to the centre of its own ring, by its share of the distance to leave j's
   section (a circle of radius R + margin; :func:`pair_shares`: a deeper muscle gives way
   more), faded out where the point and its ring's centre both lie near j's axis (two
   muscles on one line of action have no side to push to: pushing them piles them up; a ring
   that crosses j off its axis is pushed out even where its points pass near that axis); out
   of a bone by (margin - d) times the field's gradient (not normalized: it shortens deep
   inside where the field's sides meet and its direction turns); and, where the
   point's ring is thin against j (tol.CONTACT_THIN; not near i's ends, :data:`END_FADE`), j's
   section at the point's angle pulled in past it by j's share (a thin muscle inside a thick
   one: none of the thick one's points is inside the thin one, so its own samples never ask it
   to give way; the gracilis' origin in the adductor brevis, a tendon in a belly); and at
   each pole (the end cap's tip), the bones' push by the same rule, as a whole: a model's
   attachment point often lies a few mm inside its bone's mesh (gait2392's soleus origin
   6.7 mm inside the tibia, the tensor fasciae latae's insertion 6.3 mm), and so did the
   mesh's tip; the path, and so the length, stays the model's; a neighbour a pole lies in
   gives way to it, as to a thin muscle (the pole itself does not move out of muscles);
   each of the three asked for tol.CONTACT_RELAX times over (over-relaxation: step 2's
   low-pass spreads a local push, and step 3 gives some of it back, so a pass delivers only
   part of what its samples ask for at the deepest points), a pole's own push once;
2. per ring, the pushes' low-pass around the ring: the ring's shift, tilt of one side and
   flattening (the first two Fourier modes, the least-squares fit of those modes to the
   evenly spaced pushes), linear between sampled rings and smoothed along the muscle: the
   muscles' pushes with the poles (attachments) fixed, the bones' pushes with free ends (the
   rings next to an attachment keep their own push out of the bone, the pole its own);
   each point moves by its ring's modes, soft-capped at
   tol.CONTACT_MAX_STEP a pass. So the surface stays as smooth as the muscle (no point is
   moved alone: no dents, no wrapping under a bone), with 5 x 3 unknowns per ring;
3. the volume is solved exactly again: every point moves along its no-contact radial offset
   by sigma, the root of the mesh volume's cubic V(sigma) = V (the no-contact volume), as in
   :func:`axdf_cli.model.kernels.surface_stage`.

Every step is a continuous function of the frame's meshes (soft fades and caps, no switching,
a fixed number of passes), so surfaces do not pop from frame to frame. A muscle nothing
touches is returned unchanged, bit for bit. Keeping the volume exactly, the overlap a pass
clears is partly pressed into the next layer: a fixed few passes (tol.CONTACT_ITERATIONS; two,
over-relaxed, leave 0.30% of the packed walk's vertices inside another muscle and 0.07% inside
a bone without pops, README, Contact), not a solve to convergence.
"""
from __future__ import annotations

import functools
import hashlib
import io
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import AxdfError
from axdf_cli.fileio import atomic
from axdf_cli.model import kernels
from axdf_cli.model.muscle import ContactSpec
from axdf_cli.workers import THREADS_VAR

try:
    from numba import njit, prange
except ImportError as e:  # a dependency: make setup installs it
    raise ImportError(f"axdf needs numba ({e}); run `make setup` or `pip install numba`") from None


# ----------------------------------------------------------------------------- settings


def pair_shares(yields: np.ndarray) -> np.ndarray:
    """Share of an overlap that muscle i takes against j: (M, M), share[i, j] + share[j, i] = 1.

    0.5 for equal yields, growing by tol.CONTACT_SHARE_PER_LAYER per layer of difference up
    to tol.CONTACT_SHARE_MAX (a deep muscle gives way to a superficial one)."""
    d = yields[:, None] - yields[None, :]
    return np.clip(0.5 + tol.CONTACT_SHARE_PER_LAYER * d, 1.0 - tol.CONTACT_SHARE_MAX, tol.CONTACT_SHARE_MAX)


def pair_mask(names: list[str], specs: list[ContactSpec]) -> np.ndarray:
    """Which pairs collide: (M, M) bool, symmetric, False on the diagonal, within a group and
    where either muscle ignores the other."""
    m = len(names)
    ok = ~np.eye(m, dtype=bool)
    for i, s in enumerate(specs):
        for j in range(m):
            if i != j and ((s.group and s.group == specs[j].group) or names[j] in s.ignore
                           or names[i] in specs[j].ignore):
                ok[i, j] = ok[j, i] = False
    return ok


# ----------------------------------------------------------------------------- bones


@dataclass(frozen=True)
class BoneField:
    """A bone's signed distance field on a regular bone-local grid (negative inside).

    origin (3,) the grid's first point, h the spacing (m), values (nx, ny, nz) float64."""

    bone: int
    origin: np.ndarray
    h: float
    values: np.ndarray


def bone_field(bone: int, vertices: np.ndarray, faces: np.ndarray, clip: np.ndarray | None = None,
               h: float = tol.CONTACT_SDF_STEP, pad: float = tol.CONTACT_SDF_PAD) -> BoneField | None:
    """The signed distance field of a bone mesh (bone-local vertices (V, 3), faces (T, 3)) on a
    grid of spacing ``h`` over its bounds grown by ``pad``, cut to the box ``clip`` (2, 3)
    where muscles can reach (None where that leaves nothing). Computed once per mesh, box and
    process (cached by their bytes)."""
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    lo = v.min(axis=0) - pad
    hi = v.max(axis=0) + pad
    if clip is not None:
        # the box in whole tol.CONTACT_CLIP_STEP: small edits to the muscles keep the same field (cache)
        q = tol.CONTACT_CLIP_STEP
        lo = np.maximum(lo, np.floor(clip[0] / q) * q)
        hi = np.minimum(hi, np.ceil(clip[1] / q) * q)
        if np.any(hi <= lo):
            return None
    lo = np.floor(lo / h) * h  # on a grid fixed in the bone: the same field for any box
    box = np.concatenate([lo, hi])
    key = hashlib.sha256(v.tobytes() + f.tobytes() + np.array([h, *box]).tobytes()
                         + _igl_version().encode()).hexdigest()
    origin, values = _field_cached(key, v.tobytes(), f.tobytes(), v.shape[0], f.shape[0], h, box.tobytes())
    return BoneField(bone, origin, h, values)


CACHE_VERSION = 1  # part of the cache key: bump when the field's computation changes


@functools.lru_cache(maxsize=1)
def _igl_version() -> str:
    """libigl's installed version, part of a field's cache key: a field computed by another
    release (its distances or its winding-number sign may differ) is computed again, not read
    back (the cache outlives installs, as numba's does: axdf_cli/__init__.py)."""
    from importlib import metadata

    try:
        return "libigl " + metadata.version("libigl")
    except metadata.PackageNotFoundError:
        return "libigl ?"


def cache_dir() -> Path:
    """Where computed bone fields are kept between runs: $XDG_CACHE_HOME/axdf/sdf (default
    ~/.cache/axdf/sdf). Only ever a speed-up: a missing or unwritable cache computes again."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "axdf" / "sdf"


@functools.lru_cache(maxsize=64)
def _field_cached(key, vb, fb, nv, nt, h, boxb):
    path = cache_dir() / f"{key}-v{CACHE_VERSION}.npz"
    try:
        with np.load(path) as z:
            return z["origin"], np.ascontiguousarray(z["values"])
    except (OSError, KeyError, ValueError):
        pass
    origin, values = _compute_field(vb, fb, nv, nt, h, boxb)
    try:
        buf = io.BytesIO()
        np.savez(buf, origin=origin, values=values)
        atomic.ensure_dir(path.parent)
        atomic.write_bytes(path, buf.getvalue())
    except (OSError, AxdfError):
        pass  # the cache is only a speed-up
    return origin, values


def _compute_field(vb, fb, nv, nt, h, boxb):
    try:
        import igl
    except ImportError as e:
        from axdf_cli.errors import EnvironmentProblem

        raise EnvironmentProblem(f"contact needs libigl for the bones' distance fields ({e})",
                                 "pip install libigl (make setup installs it), or run with --no-contact") from None
    v = np.frombuffer(vb, dtype=np.float64).reshape(nv, 3)
    f = np.frombuffer(fb, dtype=np.int64).reshape(nt, 3)
    box = np.frombuffer(boxb, dtype=np.float64)
    lo = box[:3]
    n = np.ceil((box[3:] - lo) / h).astype(np.int64) + 1
    axes = [lo[i] + h * np.arange(n[i]) for i in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    sd = igl.signed_distance(pts, v, f, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]
    return lo, np.ascontiguousarray(np.asarray(sd, dtype=np.float64).reshape(tuple(n)))


@dataclass(frozen=True)
class BoneFields:
    """Every bone field of a skeleton, packed for the compiled kernels."""

    bones: np.ndarray  # (K,) bone index of each field
    origin: np.ndarray  # (K, 3)
    h: np.ndarray  # (K,)
    dims: np.ndarray  # (K, 3) int64
    offset: np.ndarray  # (K + 1,) start of each field in ``values``
    values: np.ndarray  # (sum of grid sizes,) float64

    @staticmethod
    def pack(fields: list[BoneField]) -> "BoneFields":
        dims = np.array([f.values.shape for f in fields], dtype=np.int64).reshape(-1, 3)
        sizes = np.prod(dims, axis=1) if len(fields) else np.zeros(0, np.int64)
        return BoneFields(np.array([f.bone for f in fields], dtype=np.int64),
                          np.array([f.origin for f in fields], dtype=np.float64).reshape(-1, 3),
                          np.array([f.h for f in fields], dtype=np.float64), dims,
                          np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64),
                          np.concatenate([f.values.ravel() for f in fields]) if fields else np.zeros(0))


@njit(cache=True, inline="always")
def _field_at(values, off, dims, origin, h, x0, x1, x2):
    """Trilinear signed distance at a bone-local point; (distance, inside the grid)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    fx = (x0 - origin[0]) / h
    fy = (x1 - origin[1]) / h
    fz = (x2 - origin[2]) / h
    if not (fx >= 0.0 and fy >= 0.0 and fz >= 0.0 and fx <= nx - 1 and fy <= ny - 1 and fz <= nz - 1):
        return 1e30, False
    ix = min(int(fx), nx - 2)
    iy = min(int(fy), ny - 2)
    iz = min(int(fz), nz - 2)
    tx = fx - ix
    ty = fy - iy
    tz = fz - iz
    b = off + (ix * ny + iy) * nz + iz
    sy = nz
    sx = ny * nz
    c00 = values[b] * (1 - tz) + values[b + 1] * tz
    c01 = values[b + sy] * (1 - tz) + values[b + sy + 1] * tz
    c10 = values[b + sx] * (1 - tz) + values[b + sx + 1] * tz
    c11 = values[b + sx + sy] * (1 - tz) + values[b + sx + sy + 1] * tz
    c0 = c00 * (1 - ty) + c01 * ty
    c1 = c10 * (1 - ty) + c11 * ty
    return c0 * (1 - tx) + c1 * tx, True


@njit(cache=True, inline="always")
def _local_field(x, m, fv, off, dims, origin, h):
    """World point x taken into a bone's frame by m (4, 4; world to bone-local) and the
    field's trilinear value there: (distance, inside the grid, the bone-local point)."""
    y0 = m[0, 0] * x[0] + m[0, 1] * x[1] + m[0, 2] * x[2] + m[0, 3]
    y1 = m[1, 0] * x[0] + m[1, 1] * x[1] + m[1, 2] * x[2] + m[1, 3]
    y2 = m[2, 0] * x[0] + m[2, 1] * x[1] + m[2, 2] * x[2] + m[2, 3]
    d, ok = _field_at(fv, off, dims, origin, h, y0, y1, y2)
    return d, ok, y0, y1, y2


@njit(cache=True, inline="always")
def _bone_query(x, inv, fb, fo, fh, fd, foff, fv, fsel, f0, f1, grad_below, g_out):
    """Smallest signed distance of world point x over the bone fields fsel[f0:f1] (inv: (B, 4,
    4) world to bone-local) and, where it is below ``grad_below``, in g_out[:3] its world
    gradient by central differences of the trilinear field over one grid step (continuous,
    unlike the trilinear's own gradient); 1e30 where no field covers x."""
    best = 1e30
    kb = -1
    l0 = 0.0
    l1 = 0.0
    l2 = 0.0
    for kk in range(f0, f1):
        k = fsel[kk]
        d, ok, y0, y1, y2 = _local_field(x, inv[fb[k]], fv, foff[k], fd[k], fo[k], fh[k])
        if ok and d < best:
            best = d
            kb = k
            l0 = y0
            l1 = y1
            l2 = y2
    if kb < 0 or not best < grad_below:
        return best
    h = fh[kb]
    for c in range(3):
        e0 = h if c == 0 else 0.0
        e1 = h if c == 1 else 0.0
        e2 = h if c == 2 else 0.0
        dp, okp = _field_at(fv, foff[kb], fd[kb], fo[kb], h, l0 + e0, l1 + e1, l2 + e2)
        dm, okm = _field_at(fv, foff[kb], fd[kb], fo[kb], h, l0 - e0, l1 - e1, l2 - e2)
        if not okp:
            dp = best
        if not okm:
            dm = best
        g_out[3 + c] = (dp - dm) / (2.0 * h)
    m = inv[fb[kb]]
    # world gradient = R g, R = the transpose of inv's rotation
    for c in range(3):
        g_out[c] = m[0, c] * g_out[3] + m[1, c] * g_out[4] + m[2, c] * g_out[5]
    return best


# ----------------------------------------------------------------------------- muscles


@njit(cache=True)
def _centres(grid, off, nu, na, cen, coff):
    """Ring centroids of every muscle (pole rows: the pole) in cen[:, :3], in cen[:, 3] each
    ring's largest distance from its centroid, and in cen[:, 4:8] of every SEG_GROUP-th ring
    the bounding sphere (centre, radius) of the centres from it to SEG_GROUP rings on, in
    cen[:, 8] the largest of those rings' radii, and in cen[:, 9] each ring's end fade (0 at
    the poles, 1 from :data:`END_FADE` of the rings on; cen: (rings, :data:`CEN_COLUMNS`))."""
    for m in range(nu.shape[0]):
        _centres_one(m, grid, off, nu, na, cen, coff)


@njit(cache=True)
def _centres_one(m, grid, off, nu, na, cen, coff):
    """:func:`_centres` for muscle m."""
    U = nu[m]
    A = na[m]
    for u in range(U):
        for c in range(3):
            s = 0.0
            for a in range(A):
                s += grid[off[m] + u * A + a, c]
            cen[coff[m] + u, c] = s / A
        r = 0.0
        for a in range(A):
            k = off[m] + u * A + a
            q = ((grid[k, 0] - cen[coff[m] + u, 0]) ** 2 + (grid[k, 1] - cen[coff[m] + u, 1]) ** 2
                 + (grid[k, 2] - cen[coff[m] + u, 2]) ** 2)
            if q > r:
                r = q
        cen[coff[m] + u, 3] = np.sqrt(r)
        cen[coff[m] + u, 9] = _smoothstep(min(u, U - 1 - u) / (END_FADE * (U - 1)))
    # each ring's plane normal (Newell's, over its polygon), along the centre line
    for u in range(U):
        r = coff[m] + u
        n0 = 0.0
        n1 = 0.0
        n2 = 0.0
        for a in range(A):
            p = off[m] + u * A + a
            q = off[m] + u * A + (a + 1) % A
            n0 += (grid[p, 1] - grid[q, 1]) * (grid[p, 2] + grid[q, 2])
            n1 += (grid[p, 2] - grid[q, 2]) * (grid[p, 0] + grid[q, 0])
            n2 += (grid[p, 0] - grid[q, 0]) * (grid[p, 1] + grid[q, 1])
        nl = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        ra = coff[m] + max(u - 1, 0)
        rb = coff[m] + min(u + 1, U - 1)
        d0 = cen[rb, 0] - cen[ra, 0]
        d1 = cen[rb, 1] - cen[ra, 1]
        d2 = cen[rb, 2] - cen[ra, 2]
        if nl <= 1e-12 * cen[r, 3] * cen[r, 3] or nl == 0.0:
            n0, n1, n2, nl = 0.0, 0.0, 0.0, 1.0  # a pole, or no area: the centre line's own
        elif n0 * d0 + n1 * d1 + n2 * d2 < 0.0:
            nl = -nl
        cen[r, 10] = n0 / nl
        cen[r, 11] = n1 / nl
        cen[r, 12] = n2 / nl
    # bounding spheres of the centre segments in groups of SEG_GROUP (cen[first, 4:8])
    for g in range((U - 2) // SEG_GROUP + 1):
        r0 = coff[m] + g * SEG_GROUP
        r1 = coff[m] + min(g * SEG_GROUP + SEG_GROUP, U - 1)
        for c in range(3):
            cen[r0, 4 + c] = 0.5 * (cen[r0, c] + cen[r1, c])
        r = 0.0
        for k in range(r0, r1 + 1):
            q = (cen[k, 0] - cen[r0, 4]) ** 2 + (cen[k, 1] - cen[r0, 5]) ** 2 + (cen[k, 2] - cen[r0, 6]) ** 2
            if q > r:
                r = q
        cen[r0, 7] = np.sqrt(r)
        big = 0.0
        for k in range(r0, r1 + 1):
            if cen[k, 3] > big:
                big = cen[k, 3]
        cen[r0, 8] = big


@njit(cache=True, parallel=True)
def _centres_and_boxes(grid, off, nu, na, cen, coff, box):
    """:func:`_centres` and :func:`_boxes`, muscle by muscle on numba's threads (the same values)."""
    for m in prange(nu.shape[0]):
        _centres_one(m, grid, off, nu, na, cen, coff)
        _box_one(m, grid, off, box)


@njit(cache=True)
def _centres_and_boxes_serial(grid, off, nu, na, cen, coff, box):
    """:func:`_centres_and_boxes` on this thread alone (:func:`use_threads`)."""
    for m in range(nu.shape[0]):
        _centres_one(m, grid, off, nu, na, cen, coff)
        _box_one(m, grid, off, box)


@njit(cache=True, inline="always")
def _ring_radius(grid, base, A, cx0, cx1, cx2, a0, a1, a2, b0, b1, b2):
    """Radius of a ring (A points from ``base``) along (a0, a1, a2) from the centre (cx0, cx1,
    cx2), in the plane of that direction and (b0, b1, b2): the ray cut with the ring's polygon
    projected into that plane (0 when it misses)."""
    best = 0.0
    px0 = 0.0
    py0 = 0.0
    for k in range(A + 1):
        i = base + (k % A)
        dx = grid[i, 0] - cx0
        dy = grid[i, 1] - cx1
        dz = grid[i, 2] - cx2
        px = dx * a0 + dy * a1 + dz * a2
        py = dx * b0 + dy * b1 + dz * b2
        if k > 0 and ((py0 <= 0.0 < py) or (py <= 0.0 < py0)):
            xh = px0 + (px - px0) * py0 / (py0 - py)
            if xh > best:
                best = xh
        px0 = px
        py0 = py
    return best


@njit(cache=True, inline="always")
def _centre_tangent(cen, coff_j, U, u):
    """Unit axis direction of a muscle at ring u: the ring's plane normal (cen[:, 10:13]); at
    the poles and rings with no area, the centre polyline's tangent (central difference;
    one-sided at the poles)."""
    r = coff_j + u
    if cen[r, 10] != 0.0 or cen[r, 11] != 0.0 or cen[r, 12] != 0.0:
        return cen[r, 10], cen[r, 11], cen[r, 12]
    a = coff_j + max(u - 1, 0)
    b = coff_j + min(u + 1, U - 1)
    d0 = cen[b, 0] - cen[a, 0]
    d1 = cen[b, 1] - cen[a, 1]
    d2 = cen[b, 2] - cen[a, 2]
    dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dl == 0.0:
        return 0.0, 0.0, 0.0
    return d0 / dl, d1 / dl, d2 / dl


#: Rings within this share of a muscle's length from an end make a thick neighbour give way less
#: (none at the poles): an attachment ring holds its place (:func:`_point_push`).
END_FADE = 0.1
#: Columns of the ring table :func:`_centres` fills.
CEN_COLUMNS = 13
#: Centre segments per bounding sphere in :func:`_muscle_query`'s search.
SEG_GROUP = 4
#: The trilinear field's largest slope (:func:`_measure`).
SQRT3 = float(np.sqrt(3.0))


@njit(cache=True, inline="always")
def _scan_segments(x, cen, coff_j, U, u0, u1, best, bu, bl):
    """The nearest of centre segments u0..u1-1 to x if nearer than ``best`` (squared distance):
    (best, segment, parameter), the parameter clamped to [0, 1]: beyond the first or last
    segment's end, the nearest point is the pole (the end cap's apex, :func:`_muscle_query`)."""
    for u in range(u0, u1):
        a0 = cen[coff_j + u, 0]
        a1 = cen[coff_j + u, 1]
        a2 = cen[coff_j + u, 2]
        d0 = cen[coff_j + u + 1, 0] - a0
        d1 = cen[coff_j + u + 1, 1] - a1
        d2 = cen[coff_j + u + 1, 2] - a2
        ll = d0 * d0 + d1 * d1 + d2 * d2
        lam = 0.0
        if ll > 0.0:
            lam = ((x[0] - a0) * d0 + (x[1] - a1) * d1 + (x[2] - a2) * d2) / ll
        lam = min(max(lam, 0.0), 1.0)
        e0 = x[0] - (a0 + lam * d0)
        e1 = x[1] - (a1 + lam * d1)
        e2 = x[2] - (a2 + lam * d2)
        q = e0 * e0 + e1 * e1 + e2 * e2
        if q < best:
            best = q
            bu = u
            bl = lam
    return best, bu, bl


@njit(cache=True, inline="always")
def _muscle_query(x, grid, off_j, U, A, cen, coff_j, reach, out):
    """:func:`_query_in` over all of muscle j's segment groups."""
    return _query_in(x, grid, off_j, U, A, cen, coff_j, reach, out, _ALL_GROUPS, 0, -1)


#: Length of :func:`_query_in`'s output (rho, R, axis point, radial direction, segment, parameter).
QUERY_SIZE = 10
#: No group list: :func:`_query_in` scans every group.
_ALL_GROUPS = np.zeros((1, 1), np.int64)


@njit(cache=True, inline="always")
def _query_in(x, grid, off_j, U, A, cen, coff_j, reach, out, gl, row, cnt):
    """Axis-space query of point x against muscle j. out (:data:`QUERY_SIZE`) = [rho, R, cx,
    cy, cz, rx, ry, rz, segment, parameter]: radial distance, surface radius, axis point, unit
    radial direction, and the axis point's centre segment and its parameter there. Returns False when x
    lies beyond j's ends, or when rho exceeds the two rings' largest radius (cen[:, 3]) plus
    ``reach`` (then rho > R + reach: the rings' radii are not read).
    Beyond an end: where the nearest point of the whole centre polyline (poles included) is a
    pole, x lies past the plane through the pole across the end segment, outside the end cap
    (the cone from the pole to ring 1 or U - 2 that closes the mesh), whose radius is 0 at the
    pole: False. (Scanned without the end segments' clamped ends, the nearest point was ring
    1's centre, and x read against an endless continuation of ring 1: inside wherever it lay
    within ring 1's radius of the axis line.)
    The nearest centre segment: the groups of :data:`SEG_GROUP` segments are scanned nearest
    bounding sphere first (cen[:, 4:8]), the others only where their sphere may hold a nearer
    point (the same segment as a scan of all, in fewer steps).
    Farther than the two rings' largest radius plus ``reach`` from the nearest centre point:
    False (every point of the tube lies within the larger of its two rings' radii of the
    segment between their centres). So where no group's bounding sphere comes within its
    largest ring radius (cen[first, 8]) plus ``reach`` of x, no segment is scanned.
    Only the groups gl[row, :cnt] are scanned (all where cnt < 0): those that may hold the
    nearest segment of any point near x (:func:`_ring_groups`), so the answer is the same."""
    ng = (U - 2) // SEG_GROUP + 1 if cnt < 0 else cnt
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        r = coff_j + g * SEG_GROUP
        lim = cen[r, 7] + cen[r, 8] + reach
        if (x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2 <= lim * lim:
            break
    else:
        return False  # no centre segment within its rings' radius plus reach
    gb = 0
    lb_best = 1e300
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        r = coff_j + g * SEG_GROUP
        e = np.sqrt((x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2) - cen[r, 7]
        if e < lb_best:
            lb_best = e
            gb = g
    best, bu, bl = _scan_segments(x, cen, coff_j, U, gb * SEG_GROUP, min(gb * SEG_GROUP + SEG_GROUP, U - 1),
                                  1e300, -1, 0.0)
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        if g == gb:
            continue
        r = coff_j + g * SEG_GROUP
        e = np.sqrt((x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2) - cen[r, 7]
        if e > 0.0 and e * e >= best:
            continue
        best, bu, bl = _scan_segments(x, cen, coff_j, U, g * SEG_GROUP, min(g * SEG_GROUP + SEG_GROUP, U - 1),
                                      best, bu, bl)
    if bu < 0:
        return False
    if best > (max(cen[coff_j + bu, 3], cen[coff_j + bu + 1, 3]) + reach) ** 2:
        return False  # farther from the centre line than its rings' largest radius: outside
    # the segment whose ring planes hold x between them, from the nearest one, and x's place
    # between them: a packed section whose centre leaves the line of action stands oblique to
    # the line of the centres, and the nearest centre is not in x's section
    sa = 0.0
    sb = 0.0
    ta0 = ta1 = ta2 = tb0 = tb1 = tb2 = 0.0
    settled = False
    for _ in range(U):
        ta0, ta1, ta2 = _centre_tangent(cen, coff_j, U, bu)
        tb0, tb1, tb2 = _centre_tangent(cen, coff_j, U, bu + 1)
        p0 = coff_j + bu
        sa = (x[0] - cen[p0, 0]) * ta0 + (x[1] - cen[p0, 1]) * ta1 + (x[2] - cen[p0, 2]) * ta2
        sb = (x[0] - cen[p0 + 1, 0]) * tb0 + (x[1] - cen[p0 + 1, 1]) * tb1 + (x[2] - cen[p0 + 1, 2]) * tb2
        if sa < 0.0 and bu > 0:
            bu -= 1
        elif sb > 0.0 and bu < U - 2:
            bu += 1
        else:
            settled = True
            break
    if not settled:
        # where ring planes cross (a squeezed section), the walk may go back and forth and
        # stop after U steps, one segment past the one it read: the directions of this one
        ta0, ta1, ta2 = _centre_tangent(cen, coff_j, U, bu)
        tb0, tb1, tb2 = _centre_tangent(cen, coff_j, U, bu + 1)
    if sa < 0.0:
        bl = 0.0
    elif sb > 0.0:
        bl = 1.0
    else:
        bl = sa / (sa - sb) if sa - sb > 0.0 else 0.5
    if (bu == 0 and bl <= 0.0) or (bu == U - 2 and bl >= 1.0):
        return False  # beyond an end: outside the end cap
    p0 = coff_j + bu
    p1 = p0 + 1
    cx0 = (1.0 - bl) * cen[p0, 0] + bl * cen[p1, 0]
    cx1 = (1.0 - bl) * cen[p0, 1] + bl * cen[p1, 1]
    cx2 = (1.0 - bl) * cen[p0, 2] + bl * cen[p1, 2]
    # the axis direction blends the two rings' directions (read above) along the segment: the
    # same at a shared ring from either segment, so the query is continuous where it changes
    t0 = (1.0 - bl) * ta0 + bl * tb0
    t1 = (1.0 - bl) * ta1 + bl * tb1
    t2 = (1.0 - bl) * ta2 + bl * tb2
    tl = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if tl == 0.0:
        return False
    t0 /= tl
    t1 /= tl
    t2 /= tl
    dt = (x[0] - cx0) * t0 + (x[1] - cx1) * t1 + (x[2] - cx2) * t2
    r0 = x[0] - cx0 - dt * t0
    r1 = x[1] - cx1 - dt * t1
    r2 = x[2] - cx2 - dt * t2
    rho = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if rho > max(cen[p0, 3], cen[p1, 3]) + reach:
        return False  # R <= the rings' largest radius (projected across the axis, no longer)
    if rho < 1e-12:
        # on the axis: any perpendicular
        r0 = t1 - t2
        r1 = t2 - t0
        r2 = t0 - t1
        rl = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if rl < 1e-12:
            r0 = -t1
            r1 = t0
            r2 = 0.0
            rl = np.sqrt(r0 * r0 + r1 * r1)
    else:
        rl = rho
    r0 /= rl
    r1 /= rl
    r2 /= rl
    b0 = t1 * r2 - t2 * r1
    b1 = t2 * r0 - t0 * r2
    b2 = t0 * r1 - t1 * r0
    ra = _ring_radius(grid, off_j + bu * A, A, cen[p0, 0], cen[p0, 1], cen[p0, 2], r0, r1, r2, b0, b1, b2)
    rb = _ring_radius(grid, off_j + (bu + 1) * A, A, cen[p1, 0], cen[p1, 1], cen[p1, 2], r0, r1, r2, b0, b1, b2)
    out[0] = rho
    out[1] = (1.0 - bl) * ra + bl * rb
    out[2] = cx0
    out[3] = cx1
    out[4] = cx2
    out[5] = r0
    out[6] = r1
    out[7] = r2
    out[8] = bu
    out[9] = bl
    return True


@njit(cache=True)
def _boxes(grid, off, box):
    """Every muscle's bounding box (M, 6): lo, hi."""
    for m in range(off.shape[0] - 1):
        _box_one(m, grid, off, box)


@njit(cache=True)
def _box_one(m, grid, off, box):
    """:func:`_boxes` for muscle m."""
    for c in range(3):
        box[m, c] = 1e300
        box[m, 3 + c] = -1e300
    for k in range(off[m], off[m + 1]):
        for c in range(3):
            v = grid[k, c]
            if v < box[m, c]:
                box[m, c] = v
            if v > box[m, 3 + c]:
                box[m, 3 + c] = v


@njit(cache=True, inline="always")
def _may_meet(x, j, box, margin):
    """Whether point x lies in muscle j's box grown by ``margin`` (before :func:`_muscle_query`)."""
    return not (x[0] < box[j, 0] - margin or x[1] < box[j, 1] - margin or x[2] < box[j, 2] - margin
                or x[0] > box[j, 3] + margin or x[1] > box[j, 4] + margin or x[2] > box[j, 5] + margin)


@njit(cache=True, inline="always")
def _smoothstep(x):
    """0 below 0, 1 above 1, 3x^2 - 2x^3 between: a continuous switch with continuous slope."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


#: The modes of a ring's displacement around its angle theta (module doc, step 2): the
#: section's shift (1), its shift and tilt of one side (cos, sin theta), its flattening (cos,
#: sin 2 theta).
NMODES = 5


@njit(cache=True)
def _modes(theta, b):
    b[0] = 1.0
    b[1] = np.cos(theta)
    b[2] = np.sin(theta)
    b[3] = np.cos(2.0 * theta)
    b[4] = np.sin(2.0 * theta)


@njit(cache=True, inline="always")
def _section_angle(grid, off_j, A, cen, coff_j, U, bu, bl, r0, r1, r2):
    """The angle, in muscle j's column angle (2 pi a / A for column a), of the unit direction
    (r0, r1, r2) perpendicular to j's centre line at parameter bl of segment bu: measured from
    the direction to column 0 towards column A / 4, both blended between the segment's two
    rings. NaN where those are degenerate (both rings at a pole)."""
    ka = off_j + bu * A
    kb = off_j + (bu + 1) * A
    ca = coff_j + bu
    cb = ca + 1
    qa = A // 4
    x0 = (1.0 - bl) * (grid[ka, 0] - cen[ca, 0]) + bl * (grid[kb, 0] - cen[cb, 0])
    x1 = (1.0 - bl) * (grid[ka, 1] - cen[ca, 1]) + bl * (grid[kb, 1] - cen[cb, 1])
    x2 = (1.0 - bl) * (grid[ka, 2] - cen[ca, 2]) + bl * (grid[kb, 2] - cen[cb, 2])
    y0 = (1.0 - bl) * (grid[ka + qa, 0] - cen[ca, 0]) + bl * (grid[kb + qa, 0] - cen[cb, 0])
    y1 = (1.0 - bl) * (grid[ka + qa, 1] - cen[ca, 1]) + bl * (grid[kb + qa, 1] - cen[cb, 1])
    y2 = (1.0 - bl) * (grid[ka + qa, 2] - cen[ca, 2]) + bl * (grid[kb + qa, 2] - cen[cb, 2])
    # e1 along column 0, e2: column A / 4 made perpendicular to it
    xl = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if xl < 1e-9:
        return np.nan
    x0 /= xl
    x1 /= xl
    x2 /= xl
    d = y0 * x0 + y1 * x1 + y2 * x2
    y0 -= d * x0
    y1 -= d * x1
    y2 -= d * x2
    yl = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    if yl < 1e-9:
        return np.nan
    return np.arctan2((r0 * y0 + r1 * y1 + r2 * y2) / yl, r0 * x0 + r1 * x1 + r2 * x2)


@njit(cache=True, inline="always")
def _within(x, j, jj, grid, off, nu, na, cen, coff, box, margin, q, gl, gn):
    """Whether point x lies within ``margin`` of neighbour j's surface (j = actm[jj], its
    segment groups gl[jj, :gn[jj]]: :func:`_ring_lists`), with j's query in q
    (:func:`_query_in`)."""
    if not _may_meet(x, j, box, margin):
        return False
    if not _query_in(x, grid, off[j], nu[j], na[j], cen, coff[j], margin, q, gl, jj, gn[jj]):
        return False
    return q[0] < q[1] + margin and q[1] > 0.0


@njit(cache=True, inline="always")
def _give_way(amt, gain, j, grid, off, nu, na, cen, coff, q, g, rec):
    """Record that muscle j's section at the point of query q (:func:`_query_in`) is pulled in
    by ``amt`` (m) at the point's angle, asked for ``gain`` times over (tol.CONTACT_RELAX):
    for each of j's two rings there, a record in rec (count in rec[0, 0]): the row, the modes
    of the pull (the Fourier sums of one sample, weighted by its length and the ring's share of
    the segment, times ``gain``), and that weight (:func:`_add_reactions` takes their weighted
    mean). g: scratch (NMODES)."""
    th = _section_angle(grid, off[j], na[j], cen, coff[j], nu[j], int(q[8]), q[9], q[5], q[6], q[7])
    if not (amt > 0.0 and th == th):
        return
    bu = int(q[8])
    _modes(th, g)
    for e in range(2):
        wr = amt * ((1.0 - q[9]) if e == 0 else q[9])
        if wr <= 0.0:
            continue
        n = int(rec[0, 0])
        rec[0, 0] += 1.0
        if n + 1 >= rec.shape[0]:
            continue  # no room: counted, and the pass is run again with more
        rec[n + 1, 0] = coff[j] + bu + e
        for r in range(NMODES):
            br = (1.0 if r == 0 else 2.0) * g[r]
            for c in range(3):
                rec[n + 1, 1 + r * 3 + c] = gain * wr * br * amt * q[5 + c]
        rec[n + 1, 1 + 3 * NMODES] = wr


@njit(cache=True, inline="always")
def _point_push(x, ci, i, grid, off, nu, na, cen, coff, box, actm, nmm, share, inv, fb, fo, fh, fd, foff, fv,
                actb, nbb, gl, gn, prm, q, g, p, rec):
    """The pushes that point x of muscle i (its ring's centre ci) asks for, against the bone
    fields actb[:nbb] and the neighbours actm[:nmm] (:func:`_ring_lists`): in p[4:7], out of
    every bone field by (margin_b - d) along the field's gradient where d < margin_b; in
    p[:3], out of every neighbour j it lies within the margin of, by i's share of the distance to leave j's
    section (a circle of j's radius + margin about j's axis point) along the line from j's axis
    to ci (plus a little of x's radial direction from j's axis, faded out for points nearer j's
    axis than deep1 of j's radius, none below deep0), the push faded out likewise where both x
    and ci lie near j's axis (ci's distance read as tol.CONTACT_DEEP_FADE_CENTRES of itself: two
    muscles on one line of action have no side to push to, and pushing them anyway piles them
    up; a ring that crosses j off its axis has one); p[3]: the signed
    distance to the nearest bone (1e30: none near). Kept apart, the two are smoothed along the
    muscle with different ends (:func:`_ring_modes`). Where x's ring is thin against j (its
    radius under thin1 of j's, fully under thin0, times the ring's end fade ci[9]), j gives way
    too: for each of j's two rings at x, a record in rec (count in rec[0, 0]): the row,
    the modes of a push of j's section at x's angle inwards past x by j's share (the Fourier
    sums of one sample, weighted by the push's length and the ring's share of the segment),
    and that weight (:func:`_add_reactions` takes their weighted mean). Returns how many
    neighbours pushed.
    Each of the three is asked for relax_m, relax_b, relax_r times over (tol.CONTACT_RELAX).
    prm: (margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b,
    relax_r), a tuple: the call stays
    under 30 arguments, which Python would otherwise pass as *args, and numba then packs a
    tuple of every array on each call (several times the query's own cost)."""
    margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b, relax_r = prm
    p[0] = 0.0
    p[1] = 0.0
    p[2] = 0.0
    p[3] = 1e30
    p[4] = 0.0
    p[5] = 0.0
    p[6] = 0.0
    if nbb > 0:
        d = _bone_query(x, inv, fb, fo, fh, fd, foff, fv, actb, 0, nbb, margin_b, g)
        p[3] = d
        if d < margin_b:
            # along the gradient as it is, not normalized: length 1 near the surface, shorter
            # where the field's sides meet deep inside, so the push fades where its direction
            # turns (normalized, it flipped there between frames: pops)
            for c in range(3):
                p[4 + c] = relax_b * (margin_b - d) * g[c]
    nm = 0
    for jj in range(nmm):
        j = actm[jj]
        if not _within(x, j, jj, grid, off, nu, na, cen, coff, box, margin_m, q, gl, gn):
            continue
        rho = q[0]
        rr = q[1] + margin_m
        fade = _smoothstep((rho / q[1] - deep0) / (deep1 - deep0))  # x near j's axis
        e0 = ci[0] - q[2]
        e1 = ci[1] - q[3]
        e2 = ci[2] - q[4]
        sep = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2) / q[1]  # x's ring centre from j's axis, in j's radii
        if fade <= 0.0 and tol.CONTACT_DEEP_FADE_CENTRES * sep <= deep0:
            continue
        # a thin muscle inside a thick one: the thick one gives way too, its section at x's
        # angle pulled in past x by its share (react: per ring of j, the modes' sums weighted
        # by the push's length, and those lengths: a weighted mean, continuous as samples come
        # and go)
        thin = (1.0 - _smoothstep((ci[3] / q[1] - thin0) / (thin1 - thin0))) * ci[9]
        if thin > 0.0 and fade > 0.0:
            # (g: free again once the bones' push is taken)
            _give_way(thin * fade * share[j, i] * (rr - rho), relax_r, j, grid, off, nu, na, cen, coff, q, g, rec)
        # the push: along the line from j's axis to x's ring centre, plus a little of x's radial
        # direction, which turns fast near j's axis (so that part fades there); faded out
        # where the two axes (nearly) meet, whose direction from one to the other turns fast as
        # they move, and where both x and its ring centre lie near j's axis (one line of
        # action: no side to push to), not where a ring crosses j off its axis
        bl = radial_blend * q[1] * fade
        fade = (_smoothstep((max(rho / q[1], tol.CONTACT_DEEP_FADE_CENTRES * sep) - deep0) / (deep1 - deep0))
                * _smoothstep((sep - sep0) / (sep1 - sep0)))
        if fade <= 0.0:
            continue
        e0 += bl * q[5]
        e1 += bl * q[6]
        e2 += bl * q[7]
        el = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if el < 1e-12:
            e0 = q[5]
            e1 = q[6]
            e2 = q[7]
        else:
            e0 /= el
            e1 /= el
            e2 /= el
        # leave the circle of radius rr about the axis point along e: x + s e
        b = rho * (q[5] * e0 + q[6] * e1 + q[7] * e2)
        s = -b + np.sqrt(max(b * b + rr * rr - rho * rho, 0.0))
        w = relax_m * fade * share[i, j] * s
        p[0] += w * e0
        p[1] += w * e1
        p[2] += w * e2
        nm += 1
    return nm


@njit(cache=True, parallel=True)
def _ring_modes(grid, off, nu, na, cen, coff, box, nbr_off, nbr, share, inv, fb, fo, fh, fd, foff, fv, fl_off, fl,
                margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b, relax_r,
                cstep, rstep, poles, coef, coefb, touched, buried, work):
    """One Jacobi pass (module doc, steps 1-2), every muscle from the same state: the pushes at
    ``ns`` = A / ``cstep`` evenly spaced points of every ``rstep``-th ring (and the last inner
    ring), and per such ring their low-pass around the ring, the least-squares fit of the
    :data:`NMODES` modes, which for evenly spaced samples are the discrete Fourier coefficients
    (the modes are orthogonal there): C_0 = mean p, C_k = (2 / ns) sum p b_k, the muscles'
    pushes into coef and the bones' into coefb (smoothed with different ends). coef (rings,
    NMODES, 3); rings between sampled ones: linear between theirs; poles: the bones' push alone,
    mode 0 alone (and the neighbours they lie in give way; ``poles`` False: 0). touched (M,):
    set where a sample was pushed; buried (M,): the share of samples inside a bone. work:
    scratch arrays (:func:`_work`), one set per muscle, and each muscle's thick neighbours'
    giving way recorded in its own rows of them (:func:`_add_reactions` adds them up in
    muscle order): the muscles are independent within a pass and run on numba's threads
    (:func:`_ring_modes_one`), the same bytes for any number of threads
    (:func:`_ring_modes_serial`: the same on this thread alone)."""
    prm = (margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b, relax_r)
    for i in prange(nu.shape[0]):
        _ring_modes_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, share, inv, fb, fo, fh, fd, foff, fv,
                        fl_off, fl, prm, cstep, rstep, poles, coef, coefb, touched, buried, work)


@njit(cache=True)
def _ring_modes_serial(grid, off, nu, na, cen, coff, box, nbr_off, nbr, share, inv, fb, fo, fh, fd, foff, fv, fl_off,
                       fl, margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b,
                       relax_r, cstep, rstep, poles, coef, coefb, touched, buried, work):
    """:func:`_ring_modes` on this thread alone (:func:`use_threads`)."""
    prm = (margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b, relax_r)
    for i in range(nu.shape[0]):
        _ring_modes_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, share, inv, fb, fo, fh, fd, foff, fv,
                        fl_off, fl, prm, cstep, rstep, poles, coef, coefb, touched, buried, work)


@njit(cache=True, _nrt=False)
def _ring_modes_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, share, inv, fb, fo, fh, fd, foff, fv, fl_off,
                    fl, prm, cstep, rstep, poles, coef, coefb, touched, buried, work):
    """:func:`_ring_modes` for muscle i, with its own scratch arrays (row i of each of
    work's). Compiled without numba's reference counting (it allocates nothing): the helpers
    inlined into its loops otherwise count references to each array they are handed, twice
    per call (measured: more than the queries' own arithmetic)."""
    q, g, p, b, actb, actm, gl, gn, rec, tab = (work[0][i], work[1][i], work[2][i], work[3][i], work[4][i], work[5][i],
                                                work[6][i], work[7][i], work[8][i], work[9][i])
    rec[0, 0] = 0.0
    tab_a = -1  # the resolution tab holds the modes of (its columns' angles)
    margin_m = prm[0]
    margin_b = prm[1]
    U = nu[i]
    A = na[i]
    ns = A // cstep
    last = -1
    nb = 0
    nsamp = 0
    u = 1
    while u <= U - 2:
        ci = cen[coff[i] + u]
        r0 = coff[i] + u
        nbb, nmm = _ring_lists(ci, i, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, nbr_off, nbr, box, margin_b,
                               margin_m, actb, actm, cen, coff, nu, gl, gn)
        for r in range(NMODES):
            for c in range(3):
                coef[r0, r, c] = 0.0
                coefb[r0, r, c] = 0.0
        if nbb == 0 and nmm == 0:
            nsamp += ns  # nothing near: no push (the sums below would add zeros)
            ns_loop = 0
        else:
            ns_loop = ns
        if ns_loop > 0 and tab_a != A:
            for a in range(A):  # the modes at each column of this resolution
                _modes(2.0 * np.pi * a / A, b)
                for r in range(NMODES):
                    tab[a, r] = b[r]
            tab_a = A
        for si in range(ns_loop):
            a = si * A // ns
            k = off[i] + u * A + a
            _point_push(grid[k], ci, i, grid, off, nu, na, cen, coff, box, actm, nmm, share, inv, fb, fo, fh,
                        fd, foff, fv, actb, nbb, gl, gn, prm, q, g, p, rec)
            nsamp += 1
            if p[3] < 0.0:
                nb += 1
            if p[0] != 0.0 or p[1] != 0.0 or p[2] != 0.0 or p[4] != 0.0 or p[5] != 0.0 or p[6] != 0.0:
                touched[i] = True
            for r in range(NMODES):
                w = (1.0 if r == 0 else 2.0) / ns
                for c in range(3):
                    coef[r0, r, c] += w * tab[a, r] * p[c]
                    coefb[r0, r, c] += w * tab[a, r] * p[4 + c]
        # rings between the previous sampled ring and this one: linear
        if last > 0:
            for v in range(last + 1, u):
                t = (v - last) / (u - last)
                for r in range(NMODES):
                    for c in range(3):
                        coef[coff[i] + v, r, c] = (1.0 - t) * coef[coff[i] + last, r, c] + t * coef[r0, r, c]
                        coefb[coff[i] + v, r, c] = (1.0 - t) * coefb[coff[i] + last, r, c] + t * coefb[r0, r, c]
        last = u
        if u == U - 2:
            break
        u = min(u + rstep, U - 2)
    # the poles (the tips of the end caps, on the attachments): pushed as a whole (mode 0 only,
    # so the pole's A grid copies stay one point) out of the bones they lie in, by the same
    # rule as a ring's samples: the mesh's tip leaves the bone where the model's attachment
    # point lies inside its mesh (the path, and so the length, stays the model's). Not out of
    # muscles: where attachments crowd (the adductors' origins by the pubis) a pole pushed
    # near a neighbour's axis turned between frames (a 2.4x step on the walk)
    for v in (0, U - 1):
        r0 = coff[i] + v
        for r in range(NMODES):
            for c in range(3):
                coef[r0, r, c] = 0.0
                coefb[r0, r, c] = 0.0
        if not poles:
            continue
        ci = cen[r0]
        nbb, nmm = _ring_lists(ci, i, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, nbr_off, nbr, box, margin_b,
                               margin_m, actb, actm, cen, coff, nu, gl, gn)
        x = grid[off[i] + v * A]
        if nbb > 0:
            # asked for once (relax_b 1): the pole moves by its own push, which no low-pass
            # spreads, so over-relaxed it would overshoot the bone's surface
            prm1 = (prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8], prm[9], 1.0, prm[11])
            _point_push(x, ci, i, grid, off, nu, na, cen, coff, box, actm, 0, share, inv, fb, fo, fh, fd, foff, fv,
                        actb, nbb, gl, gn, prm1, q, g, p, rec)
            for c in range(3):
                coefb[r0, 0, c] = p[4 + c]
            if p[4] != 0.0 or p[5] != 0.0 or p[6] != 0.0:
                touched[i] = True
        # a pole inside a neighbour: the neighbour gives way (the pole is an attachment, as
        # thin as can be), pulled in past it by its share, faded near its axis as a push is
        for jj in range(nmm):
            j = actm[jj]
            if not _within(x, j, jj, grid, off, nu, na, cen, coff, box, margin_m, q, gl, gn):
                continue
            rr = q[1] + margin_m
            fade = _smoothstep((q[0] / q[1] - prm[2]) / (prm[3] - prm[2]))  # (prm[2:4]: deep0, deep1)
            _give_way(fade * share[j, i] * (rr - q[0]), prm[11], j, grid, off, nu, na, cen, coff, q, g, rec)
    buried[i] = nb / max(nsamp, 1)


@njit(cache=True)
def _add_reactions(rec, react, coef, nu, coff, touched, floor):
    """The thick muscles' giving way (the records :func:`_point_push` left in each muscle's
    rec: rec[i, 0, 0] of them, from row 1: the row, the modes' sums, the weight) added up
    muscle by muscle, in order, into react, then into their rings' modes (the poles stay);
    react is cleared for the next pass."""
    for i in range(rec.shape[0]):
        for n in range(int(rec[i, 0, 0])):
            row = int(rec[i, n + 1, 0])
            for k in range(3 * NMODES):
                react[row, k] -= rec[i, n + 1, 1 + k]
            react[row, 3 * NMODES] += rec[i, n + 1, 1 + 3 * NMODES]
    for m in range(nu.shape[0]):
        for u in range(1, nu[m] - 1):
            row = coff[m] + u
            w = react[row, 3 * NMODES]
            if w <= 0.0:
                continue
            touched[m] = True
            # the pushes' mean weighted by their lengths (times the share of each that falls
            # on this ring), all of it once that weight reaches `floor`: continuous as
            # samples come and go, and as one passes from this ring's segment to the next
            w = max(w, floor)
            for r in range(NMODES):
                for c in range(3):
                    coef[row, r, c] += react[row, r * 3 + c] / (w * NMODES)
    react[:, :] = 0.0


@njit(cache=True)
def _smooth_rings(coef, nu, coff, passes, free_ends, tmp):
    """``passes`` rounds of [1 2 1]/4 smoothing of the modes along each muscle (the poles keep
    their own: 0 for the muscles' pushes, the attachments hold; ``free_ends``: the end rings
    are smoothed as if the pole moved with them, so they keep their own push)."""
    for i in range(nu.shape[0]):
        U = nu[i]
        o = coff[i]
        for _ in range(passes):
            for u in range(1, U - 1):
                lo = o + u - 1
                hi = o + u + 1
                if free_ends:
                    lo = max(lo, o + 1)
                    hi = min(hi, o + U - 2)
                for r in range(NMODES):
                    for c in range(3):
                        tmp[u, r, c] = 0.25 * coef[lo, r, c] + 0.5 * coef[o + u, r, c] + 0.25 * coef[hi, r, c]
            for u in range(1, U - 1):
                for r in range(NMODES):
                    for c in range(3):
                        coef[o + u, r, c] = tmp[u, r, c]


@njit(cache=True, parallel=True)
def _apply_and_solve(grid, rad, coef, off, nu, na, coff, active, target, max_step, ga, sigma):
    """Move every ring of an active muscle by its modes (the displacement's length soft-capped
    at max_step: max_step tanh(|D| / max_step)), then solve the volume exactly again (module
    doc, step 3): grid <- grid + D + sigma rad with V = target (rad: the no-contact shape's
    offsets from its ring centres, so the section grows about its centre). Muscle by muscle
    on numba's threads (:func:`_apply_one`; :func:`_apply_and_solve_serial` on this thread
    alone); ga: (M, U, A, 3) scratch."""
    for m in prange(nu.shape[0]):
        if active[m]:
            _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga[m], sigma)


@njit(cache=True)
def _apply_and_solve_serial(grid, rad, coef, off, nu, na, coff, active, target, max_step, ga, sigma):
    """:func:`_apply_and_solve` on this thread alone (:func:`use_threads`)."""
    for m in range(nu.shape[0]):
        if active[m]:
            _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga[m], sigma)


@njit(cache=True)
def _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga, sigma):
    """:func:`_apply_and_solve` for muscle m (ga: its (U, A, 3) scratch)."""
    b = np.empty(NMODES)
    U = nu[m]
    A = na[m]
    o = off[m]
    for a in range(A):
        _modes(2.0 * np.pi * a / A, b)
        for u in range(U):
            k = o + u * A + a
            d0 = 0.0
            d1 = 0.0
            d2 = 0.0
            for r in range(NMODES):
                d0 += b[r] * coef[coff[m] + u, r, 0]
                d1 += b[r] * coef[coff[m] + u, r, 1]
                d2 += b[r] * coef[coff[m] + u, r, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            f = 1.0 if dl < 1e-12 else max_step * np.tanh(dl / max_step) / dl
            grid[k, 0] += f * d0
            grid[k, 1] += f * d1
            grid[k, 2] += f * d2
            for c in range(3):
                ga[u, a, c] = grid[k, c]
    c0, c1, c2, c3 = kernels.volume_cubic(ga[:U, :A], rad[o:o + U * A].reshape(U, A, 3))
    s = _solve_offset(c0, c1, c2, c3, target[m])
    sigma[m] += s
    for k in range(o, o + U * A):
        for c in range(3):
            grid[k, c] += s * rad[k, c]


@njit(cache=True)
def _solve_offset(c0, c1, c2, c3, v0):
    """The root sigma nearest 0 of the cubic c0 + c1 s + c2 s^2 + c3 s^3 = v0 (the volume along
    the free points' radial offsets, increasing near 0): Newton from 0, safeguarded by
    bisection on a bracket grown from 0. 0 when there is none (the volume is then kept as is)."""
    f0 = c0 - v0
    if f0 == 0.0:
        return 0.0
    step = 0.05 if f0 < 0.0 else -0.05
    lo = 0.0
    hi = step
    fhi = ((c3 * hi + c2) * hi + c1) * hi + c0 - v0
    n = 0
    while fhi * f0 > 0.0 and n < 60:
        lo = hi
        hi *= 2.0
        fhi = ((c3 * hi + c2) * hi + c1) * hi + c0 - v0
        n += 1
    if fhi * f0 > 0.0:
        return 0.0
    a = min(lo, hi)
    b = max(lo, hi)
    fa = ((c3 * a + c2) * a + c1) * a + c0 - v0
    s = 0.5 * (a + b)
    for _ in range(100):
        fs = ((c3 * s + c2) * s + c1) * s + c0 - v0
        if abs(fs) <= tol.VOLUME_SOLVE_RTOL * abs(v0):
            break
        if (fs < 0.0) == (fa < 0.0):
            a = s
            fa = fs
        else:
            b = s
        df = (3.0 * c3 * s + 2.0 * c2) * s + c1
        sn = s - fs / df if df != 0.0 else 0.5 * (a + b)
        s = sn if a < sn < b else 0.5 * (a + b)
    return s


@njit(cache=True)
def _ring_lists(ci, i, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, nbr_off, nbr, box, reach_b, reach_m, actb, actm,
                cen, coff, nu, gl, gn):
    """What a ring of muscle i (centre ci[:3], every point within ri = ci[3] of it) may meet:
    into actb the bone fields of fl[fl_off[i]:fl_off[i + 1]] but those whose grid it misses or
    whose value at the centre exceeds sqrt(3) ri + reach_b (the trilinear field changes by at
    most sqrt(3) per metre: its grid values are exact distances, so each axis' difference
    quotient is at most 1), into actm the neighbours nbr[nbr_off[i]:nbr_off[i + 1]] whose box,
    grown by reach_m, its sphere meets, and, of those, whose centre line it may come within
    their radius of, with into gl, gn the segment groups to scan for each
    (:func:`_ring_groups`). Returns (how many fields, how many neighbours): testing only those
    gives the same answers as testing all."""
    ri = ci[3]
    nb = 0
    for kk in range(fl_off[i], fl_off[i + 1]):
        k = fl[kk]
        d, ok, y0, y1, y2 = _local_field(ci, inv[fb[k]], fv, foff[k], fd[k], fo[k], fh[k])
        if ok:
            if d > SQRT3 * ri + reach_b:
                continue
        else:
            # outside the grid: skip when the ring's sphere misses the grid's box (no point
            # outside a field's grid is inside or near its bone)
            e = 0.0
            yy = (y0, y1, y2)
            for c in range(3):
                lo = fo[k, c]
                hi = fo[k, c] + fh[k] * (fd[k, c] - 1)
                if yy[c] < lo:
                    e += (lo - yy[c]) ** 2
                elif yy[c] > hi:
                    e += (yy[c] - hi) ** 2
            if e > ri * ri:
                continue
        actb[nb] = k
        nb += 1
    nmm = 0
    for jj in range(nbr_off[i], nbr_off[i + 1]):
        j = nbr[jj]
        if _may_meet(ci, j, box, ri + reach_m):
            actm[nmm] = j
            nmm += 1
    return nb, _ring_groups(ci, reach_m, cen, coff, nu, actm, nmm, gl, gn)


@njit(cache=True, inline="always")
def _near_segment(ci, reach, cen, coff_j, U, g):
    """Whether a segment of group g of muscle j comes within its two rings' larger radius plus
    ``reach`` of point ci[:3]."""
    for u in range(g * SEG_GROUP, min(g * SEG_GROUP + SEG_GROUP, U - 1)):
        q, _, _ = _scan_segments(ci, cen, coff_j, U, u, u + 1, 1e300, -1, 0.0)
        lim = reach + max(cen[coff_j + u, 3], cen[coff_j + u + 1, 3])
        if q <= lim * lim:
            return True
    return False


@njit(cache=True)
def _ring_groups(ci, reach, cen, coff, nu, actm, nmm, gl, gn):
    """For a ring (every point within ci[3] of ci[:3]) and each of its neighbours actm[:nmm],
    into gl[jj, :gn[jj]] the groups of :data:`SEG_GROUP` centre segments (bounding spheres
    cen[first, 4:8]) that may hold the nearest centre segment of one of the ring's points:
    those whose least distance from the ring's sphere is at most the largest distance from it
    of the nearest group. Any other group is farther from every point of the ring than that
    group is, so :func:`_query_in` over these finds the same nearest segment as over all. A
    neighbour none of whose candidate groups has a segment within its two rings' larger radius
    plus ``reach`` of the sphere is dropped (for every point of the ring, its nearest segment
    is then farther than that from it: :func:`_query_in` is False); actm and gl are
    compacted. Returns how many neighbours remain."""
    ri = ci[3]
    n = 0
    for jj in range(nmm):
        j = actm[jj]
        ng = (nu[j] - 2) // SEG_GROUP + 1
        ub = 1e300
        for g in range(ng):
            r = coff[j] + g * SEG_GROUP
            d = np.sqrt((ci[0] - cen[r, 4]) ** 2 + (ci[1] - cen[r, 5]) ** 2 + (ci[2] - cen[r, 6]) ** 2)
            if d + cen[r, 7] + ri < ub:
                ub = d + cen[r, 7] + ri
        k = 0
        near = False
        for g in range(ng):
            r = coff[j] + g * SEG_GROUP
            d = np.sqrt((ci[0] - cen[r, 4]) ** 2 + (ci[1] - cen[r, 5]) ** 2 + (ci[2] - cen[r, 6]) ** 2)
            if d - cen[r, 7] - ri <= ub:
                gl[n, k] = g
                k += 1
                if not near and d <= ri + reach + cen[r, 7] + cen[r, 8]:
                    near = _near_segment(ci, ri + reach, cen, coff[j], nu[j], g)
        if near:
            actm[n] = j
            gn[n] = k
            n += 1
    return n


@njit(cache=True, inline="always")
def _polygon_distance2(x, grid, a0, b0, A, bl):
    """Squared distance from x to the closed polygon of rings a0 and b0 (first grid rows)
    blended at bl."""
    best = 1e300
    q0 = (1.0 - bl) * grid[a0 + A - 1, 0] + bl * grid[b0 + A - 1, 0]
    q1 = (1.0 - bl) * grid[a0 + A - 1, 1] + bl * grid[b0 + A - 1, 1]
    q2 = (1.0 - bl) * grid[a0 + A - 1, 2] + bl * grid[b0 + A - 1, 2]
    for k in range(A):
        p0 = (1.0 - bl) * grid[a0 + k, 0] + bl * grid[b0 + k, 0]
        p1 = (1.0 - bl) * grid[a0 + k, 1] + bl * grid[b0 + k, 1]
        p2 = (1.0 - bl) * grid[a0 + k, 2] + bl * grid[b0 + k, 2]
        e0 = p0 - q0
        e1 = p1 - q1
        e2 = p2 - q2
        ee = e0 * e0 + e1 * e1 + e2 * e2
        t = 0.0
        if ee > 0.0:
            t = ((x[0] - q0) * e0 + (x[1] - q1) * e1 + (x[2] - q2) * e2) / ee
            t = min(max(t, 0.0), 1.0)
        d0 = q0 + t * e0 - x[0]
        d1 = q1 + t * e1 - x[1]
        d2 = q2 + t * e2 - x[2]
        dd = d0 * d0 + d1 * d1 + d2 * d2
        if dd < best:
            best = dd
        q0 = p0
        q1 = p1
        q2 = p2
    return best


@njit(cache=True, inline="always")
def _section_distance(x, grid, off_j, U, A, bu, bl):
    """Distance from x to the nearest of some of muscle j's surface curves around x: its
    section there (rings bu and bu + 1 blended at bl) and rings bu - 1 to bu + 2 (mesh edges;
    a pole row is its pole). For a point in the middle of a wide, flat section this is how
    deep it lies (to the nearest side), where the radial ray reads it as deep as the section
    is wide; near an attachment, the pole may be nearer than the section."""
    best = _polygon_distance2(x, grid, off_j + bu * A, off_j + (bu + 1) * A, A, bl)
    for u in range(max(bu - 1, 0), min(bu + 3, U)):
        d = _polygon_distance2(x, grid, off_j + u * A, off_j + u * A, A, 0.0)
        if d < best:
            best = d
    return np.sqrt(best)


@njit(cache=True, parallel=True)
def _measure(grid, off, nu, na, cen, coff, box, nbr_off, nbr, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, out, work):
    """Per muscle: [share of points inside another muscle, share inside a bone, deepest
    penetration (m)] over its vertices (pole rows counted once); ring by ring, each against
    what it may meet (:func:`_ring_lists`). A point's penetration in a muscle: the nearer of
    two points of that muscle's surface, where the radial ray leaves it (R - rho) and the
    nearest point of its section there (:func:`_section_distance`); in a bone, the depth of
    the bone's field. Muscle by muscle on numba's threads (:func:`_measure_one`), each with
    its own scratch arrays of ``work`` (:func:`_work`)."""
    for i in prange(nu.shape[0]):
        _measure_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, inv, fb, fo, fh, fd, foff, fv, fl_off, fl,
                     out, work)


@njit(cache=True)
def _measure_serial(grid, off, nu, na, cen, coff, box, nbr_off, nbr, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, out,
                    work):
    """:func:`_measure` on this thread alone (:func:`use_threads`)."""
    for i in range(nu.shape[0]):
        _measure_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, inv, fb, fo, fh, fd, foff, fv, fl_off, fl,
                     out, work)


@njit(cache=True, _nrt=False)
def _measure_one(i, grid, off, nu, na, cen, coff, box, nbr_off, nbr, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, out,
                 work):
    """:func:`_measure` for muscle i, with its own scratch arrays (row i of work's; compiled
    without reference counting, as :func:`_ring_modes_one`)."""
    q, g, actb, actm, gl, gn = work[0][i], work[1][i], work[4][i], work[5][i], work[6][i], work[7][i]
    U = nu[i]
    A = na[i]
    n_in_m = 0
    n_in_b = 0
    deep = 0.0
    n = 0
    for u in range(U):
        ci = cen[coff[i] + u]
        nb, nmm = _ring_lists(ci, i, inv, fb, fo, fh, fd, foff, fv, fl_off, fl, nbr_off, nbr, box, 0.0, 0.0,
                              actb, actm, cen, coff, nu, gl, gn)
        if nb == 0 and nmm == 0:
            n += A if 0 < u < U - 1 else 1  # nothing near the ring: none of its points is inside
            continue
        for a in range(A if 0 < u < U - 1 else 1):
            k = off[i] + u * A + a
            n += 1
            x = grid[k]
            if nb > 0:
                d = _bone_query(x, inv, fb, fo, fh, fd, foff, fv, actb, 0, nb, -1e300, g)
                if d < 0.0:
                    n_in_b += 1
                    if -d > deep:
                        deep = -d
            inside = False
            for jj in range(nmm):
                j = actm[jj]
                if not _may_meet(x, j, box, 0.0):
                    continue
                if not _query_in(x, grid, off[j], nu[j], na[j], cen, coff[j], 0.0, q, gl, jj, gn[jj]):
                    continue
                if q[0] < q[1]:
                    inside = True
                    if q[1] - q[0] > deep:  # (the depth is at most the radial one)
                        dj = min(q[1] - q[0], _section_distance(x, grid, off[j], nu[j], na[j], int(q[8]), q[9]))
                        if dj > deep:
                            deep = dj
            if inside:
                n_in_m += 1
    out[i, 0] = n_in_m / n
    out[i, 1] = n_in_b / n
    out[i, 2] = deep


@njit(cache=True)
def _normals(grid, off, nu, na, m, out_v, out_n):
    """Vertices and normals of muscle m's grid, as the surface stage writes them."""
    U = nu[m]
    A = na[m]
    o = off[m]
    ga = np.empty((U, A, 3))
    for u in range(U):
        for a in range(A):
            for c in range(3):
                ga[u, a, c] = grid[o + u * A + a, c]
    e0 = np.empty((1, 3))
    e1 = np.empty((1, 3))
    for c in range(3):
        s0 = 0.0
        s1 = 0.0
        for a in range(A):
            s0 += ga[1, a, c]
            s1 += ga[U - 2, a, c]
        e0[0, c] = ga[0, 0, c] - s0 / A
        e1[0, c] = ga[U - 1, 0, c] - s1 / A
    # unit outward directions at the poles, as the surface stage's (-T(0), T(1)): the fan's
    # normal is kept where it is within 60 degrees of them (unnormalized, a few mm long, they
    # replaced every pole's fan normal)
    for e in (e0, e1):
        el = np.sqrt(e[0, 0] ** 2 + e[0, 1] ** 2 + e[0, 2] ** 2)
        if el > 0.0:
            for c in range(3):
                e[0, c] /= el
    kernels.ring_vertices(ga, out_v, out_n, 0)
    kernels.pole_normals(ga, e0, e1, out_n, 0)


@njit(cache=True)
def _normals_into(grid, off, nu, na, m, vo, out_v, out_n):
    """:func:`_normals` of muscle m into rows vo[m]:vo[m + 1] of out_v, out_n (V, 3)."""
    nv = vo[m + 1] - vo[m]
    v = np.empty((1, nv, 3))
    n = np.empty((1, nv, 3))
    _normals(grid, off, nu, na, m, v, n)
    for k in range(nv):
        for c in range(3):
            out_v[vo[m] + k, c] = v[0, k, c]
            out_n[vo[m] + k, c] = n[0, k, c]


@njit(cache=True, parallel=True)
def _normals_all(grid, off, nu, na, touched, vo, out_v, out_n):
    """:func:`_normals_into` for every touched muscle, muscle by muscle on numba's threads."""
    for m in prange(nu.shape[0]):
        if touched[m]:
            _normals_into(grid, off, nu, na, m, vo, out_v, out_n)


@njit(cache=True)
def _normals_all_serial(grid, off, nu, na, touched, vo, out_v, out_n):
    """:func:`_normals_all` on this thread alone (:func:`use_threads`)."""
    for m in range(nu.shape[0]):
        if touched[m]:
            _normals_into(grid, off, nu, na, m, vo, out_v, out_n)


# ----------------------------------------------------------------------------- the frame


@dataclass(frozen=True)
class ContactModel:
    """What contact needs for a run: the pairs, their shares, the bone fields."""

    allow: np.ndarray  # (M, M) bool
    share: np.ndarray  # (M, M) float64
    fields: BoneFields
    shapes: tuple  # ((U, A) per muscle)
    yields: np.ndarray  # (M,) layers
    enabled: bool = True  # False: measure only (--no-contact)


#: Room for each muscle's records of a pass's pulls on thick neighbours (:func:`_work`); a
#: pass that needs more runs again with room for all.
REACTION_RECORDS = 1024


def _work(nu: np.ndarray, na: np.ndarray, fields: "BoneFields", records: int | None = None) -> tuple:
    """Scratch arrays for :func:`_ring_modes` and :func:`_measure`, one of each per muscle
    (allocated here: the per-muscle kernels are compiled without reference counting): q, g,
    p, b, actb, actm, gl, gn, rec (:func:`_point_push`'s pulls on thick neighbours: a count
    in [0, 0], set by :func:`_ring_modes`, then up to ``records`` records; 1024 hold the
    walk's most, 412), tab (the modes at every column of a ring),
    and react (those pulls added up per ring; zeros: it accumulates)."""
    M = max(len(nu), 1)
    records = REACTION_RECORDS if records is None else records
    ng = (int(nu.max()) - 2) // SEG_GROUP + 1
    return (np.empty((M, QUERY_SIZE)), np.empty((M, 6)), np.empty((M, 7)), np.empty((M, NMODES)),
            np.empty((M, max(len(fields.bones), 1)), np.int64), np.empty((M, M), np.int64),
            np.empty((M, M, ng), np.int64), np.empty((M, M), np.int64), np.empty((M, records + 1, 3 * NMODES + 2)),
            np.empty((M, int(na.max()), NMODES)), np.zeros((int(nu.sum()), 3 * NMODES + 1)))


#: The process this module was loaded in: a forked child (another process id) keeps contact
#: on its own thread (:func:`use_threads`).
_HOME_PID = os.getpid()


def use_threads() -> bool:
    """Whether contact's kernels run muscle by muscle on numba's threads (the bytes are the
    same either way): not where ``AXDF_NUM_THREADS`` is 1 (a worker process:
    :func:`axdf_cli.workers.one_thread`), nor in a process forked from the one that loaded
    this module (GNU OpenMP, numba's threading layer here, stops a forked child that starts
    its threads: axdf_cli/__init__.py), nor where numba has one thread."""
    import numba

    return (os.getpid() == _HOME_PID and os.environ.get(THREADS_VAR, "") != "1"
            and numba.config.NUMBA_NUM_THREADS > 1)


def vertices_to_grid(v: np.ndarray, U: int, A: int) -> np.ndarray:
    """(V, 3) vertices with collapsed poles → (U * A, 3) float64 grid rows (poles repeated;
    :func:`_to_grid` for one muscle)."""
    grid = np.empty((U * A, 3))
    _to_grid(np.ascontiguousarray(v, dtype=np.float64), np.array([0, len(v)], np.int64), np.array([0, U * A], np.int64),
             np.array([U], np.int64), np.array([A], np.int64), grid)
    return grid


def resolve_frame(model: ContactModel, vertices: list[np.ndarray], world_inv: np.ndarray,
                  iterations: int = tol.CONTACT_ITERATIONS, measure_before: bool = True,
                  volumes: np.ndarray | None = None, poles: bool = True, relax: tuple = tol.CONTACT_RELAX):
    """Contact for one frame.

    vertices : [(V_m, 3) float64] every muscle's no-contact mesh; world_inv : (B, 4, 4) world
    to bone-local transforms. Returns (vertices [(V_m, 3)] (the input arrays themselves where
    nothing touched), normals [(V_m, 3) or None where unchanged], changed (M,) bool,
    before (M, 3), after (M, 3)): inside-muscle share, inside-bone share and deepest
    penetration before and after contact. ``measure_before`` False (the stage, to halve the
    measuring): before's inside-bone share is that of the first pass's samples, the rest NaN.
    ``volumes`` (M,): filled with each muscle's mesh volume after contact where any moved.
    ``poles`` False: the poles stay where they are (the packer, which fits the rest sections
    to the rings contact gives, the poles being the model's attachments). ``relax``: how many
    times over each pass asks for the muscles' pushes, the bones' and the thick muscles' giving
    way (tol.CONTACT_RELAX; the packer, iterating to the end, asks for them once: (1, 1, 1))."""
    relax = tuple(float(r) for r in relax)
    shapes = model.shapes
    M = len(vertices)
    threads = use_threads()
    measure = _measure if threads else _measure_serial
    ring_modes = _ring_modes if threads else _ring_modes_serial
    apply_and_solve = _apply_and_solve if threads else _apply_and_solve_serial
    normals_all = _normals_all if threads else _normals_all_serial
    centres_and_boxes = _centres_and_boxes if threads else _centres_and_boxes_serial
    if M == 0:
        return [], [], np.zeros(0, bool), np.zeros((0, 3)), np.zeros((0, 3))
    nu = np.array([s[0] for s in shapes], dtype=np.int64)
    na = np.array([s[1] for s in shapes], dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(nu * na)]).astype(np.int64)
    coff = np.concatenate([[0], np.cumsum(nu)]).astype(np.int64)
    vo = np.concatenate([[0], np.cumsum([len(v) for v in vertices])]).astype(np.int64)
    grid = np.empty((int(off[-1]), 3))
    _to_grid(np.concatenate(vertices).astype(np.float64, copy=False), vo, off, nu, na, grid)
    cen = np.zeros((int(coff[-1]), CEN_COLUMNS))
    box = np.empty((M, 6))
    f = model.fields
    centres_and_boxes(grid, off, nu, na, cen, coff, box)
    reach = tol.CONTACT_BONE_MARGIN + iterations * tol.CONTACT_MAX_STEP
    args_b = (world_inv, f.bones, f.origin, f.h, f.dims, f.offset, f.values, *_field_lists(box, f, world_inv, reach))
    before = np.full((M, 3), np.nan)
    work = _work(nu, na, f)
    if measure_before or iterations == 0:
        measure(grid, off, nu, na, cen, coff, box, *_neighbours(box, model.allow, 0.0), *args_b, before, work)
    rad = grid - np.repeat(cen[:, :3], np.repeat(na, nu), axis=0)  # radial offsets of the no-contact shape
    target = np.empty(M)
    _grid_volumes(grid, off, nu, na, target)
    umax, amax = int(nu.max()), int(na.max())
    coef = np.zeros((int(coff[-1]), NMODES, 3))
    coefb = np.zeros_like(coef)
    tmp = np.empty((umax, NMODES, 3))
    sigma = np.zeros(M)
    touched = np.zeros(M, dtype=np.bool_)
    buried = np.zeros(M)
    ga = np.empty((M, umax, amax, 3))
    for it in range(iterations):
        nbr_off, nbr = _neighbours(box, model.allow, tol.CONTACT_MARGIN)
        while True:
            ring_modes(grid, off, nu, na, cen, coff, box, nbr_off, nbr, model.share, *args_b,
                        tol.CONTACT_MARGIN, tol.CONTACT_BONE_MARGIN, tol.CONTACT_DEEP_FADE[0],
                        tol.CONTACT_DEEP_FADE[1], tol.CONTACT_AXES_FADE[0], tol.CONTACT_AXES_FADE[1],
                        tol.CONTACT_RADIAL_BLEND, tol.CONTACT_THIN[0], tol.CONTACT_THIN[1], *relax,
                        tol.CONTACT_SAMPLE_COLUMNS, tol.CONTACT_SAMPLE_RINGS, poles, coef, coefb, touched, buried, work)
            need = int(work[8][:, 0, 0].max())
            if need < work[8].shape[1]:
                break
            work = work[:8] + (np.empty((M, need + 1, work[8].shape[2])),) + work[9:]  # room for all: again
        _add_reactions(work[8], work[10], coef, nu, coff, touched, tol.CONTACT_MARGIN)
        if it == 0 and not measure_before:
            before[:, 1] = buried
        _smooth_rings(coef, nu, coff, tol.CONTACT_SMOOTH_PASSES, False, tmp)
        _smooth_rings(coefb, nu, coff, tol.CONTACT_SMOOTH_PASSES, True, tmp)
        coef += coefb
        apply_and_solve(grid, rad, coef, off, nu, na, coff, touched, target, tol.CONTACT_MAX_STEP, ga, sigma)
        centres_and_boxes(grid, off, nu, na, cen, coff, box)
    if volumes is not None and touched.any():
        _grid_volumes(grid, off, nu, na, volumes)
    if not touched.any() and not np.isnan(before).any():  # nothing moved (or no pass): the first measures
        return list(vertices), [None] * M, touched, before, before.copy()
    after = np.zeros((M, 3))
    measure(grid, off, nu, na, cen, coff, box, *_neighbours(box, model.allow, 0.0), *args_b, after, work)
    if not touched.any():
        return list(vertices), [None] * M, touched, before, after
    all_v = np.empty((int(vo[-1]), 3))
    all_n = np.empty((int(vo[-1]), 3))
    normals_all(grid, off, nu, na, touched, vo, all_v, all_n)
    out_v = [all_v[vo[m]:vo[m + 1]] if touched[m] else vertices[m] for m in range(M)]
    out_n = [all_n[vo[m]:vo[m + 1]] if touched[m] else None for m in range(M)]
    return out_v, out_n, touched, before, after


def _field_lists(box: np.ndarray, fields: "BoneFields", world_inv: np.ndarray, reach: float):
    """Which bone fields each muscle can meet: those whose grid's world box meets the muscle's
    box (M, 6) grown by ``reach`` (m), as CSR rows (offsets (M + 1,), field indices)."""
    K = len(fields.bones)
    if K == 0:
        return np.zeros(len(box) + 1, np.int64), np.zeros(0, np.int64)
    world = np.linalg.inv(world_inv[fields.bones])  # (K, 4, 4) bone-local to world
    corner = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, 8).T  # (8, 3)
    ext = fields.h[:, None] * (fields.dims - 1)  # (K, 3)
    local = fields.origin[:, None, :] + corner[None] * ext[:, None, :]  # (K, 8, 3)
    # w[k,p,c] = sum_d R[k,c,d] local[k,p,d] + t[k,c]
    w = np.einsum("kcd,kpd->kpc", world[:, :3, :3], local) + world[:, None, :3, 3]
    fbox = np.concatenate([w.min(axis=1), w.max(axis=1)], axis=1)  # (K, 6)
    meet = np.all(box[:, None, :3] - reach <= fbox[None, :, 3:], axis=-1) & np.all(
        fbox[None, :, :3] <= box[:, None, 3:] + reach, axis=-1)
    idx = np.nonzero(meet)
    return np.concatenate([[0], np.cumsum(np.bincount(idx[0], minlength=len(box)))]).astype(np.int64), \
        idx[1].astype(np.int64)


def _neighbours(box: np.ndarray, allow: np.ndarray, margin: float):
    """Allowed pairs whose boxes (M, 6) meet within ``margin``, as CSR rows (offsets, indices)."""
    M = len(box)
    nbr_off = np.zeros(M + 1, np.int64)
    nbr = np.empty(M * M, np.int64)
    n = _box_pairs(box, allow, margin, nbr_off, nbr)
    return nbr_off, nbr[:n]


@njit(cache=True)
def _box_pairs(box, allow, margin, nbr_off, nbr):
    """:func:`_neighbours`' rows, in order; returns how many pairs."""
    n = 0
    for i in range(box.shape[0]):
        for j in range(box.shape[0]):
            if not allow[i, j]:
                continue
            meet = True
            for c in range(3):
                if not (box[i, c] <= box[j, 3 + c] + margin and box[j, c] <= box[i, 3 + c] + margin):
                    meet = False
                    break
            if meet:
                nbr[n] = j
                n += 1
        nbr_off[i + 1] = n
    return n


@njit(cache=True)
def _to_grid(verts, vo, off, nu, na, grid):
    """Every muscle's vertices (concatenated; muscle m's from vo[m], poles collapsed) into its
    grid rows from off[m] (:func:`vertices_to_grid`)."""
    for m in range(nu.shape[0]):
        U = nu[m]
        A = na[m]
        v0 = vo[m]
        for a in range(A):
            for c in range(3):
                grid[off[m] + a, c] = verts[v0, c]
                grid[off[m] + (U - 1) * A + a, c] = verts[vo[m + 1] - 1, c]
        for k in range((U - 2) * A):
            for c in range(3):
                grid[off[m] + A + k, c] = verts[v0 + 1 + k, c]


@njit(cache=True)
def _grid_volumes(grid, off, nu, na, out):
    """out[m]: the mesh volume of muscle m's grid (:func:`_grid_volume`)."""
    for m in range(nu.shape[0]):
        U = nu[m]
        A = na[m]
        ga = grid[off[m]:off[m + 1]].reshape(U, A, 3)
        out[m] = kernels.volume_cubic(ga, np.zeros_like(ga))[0]


def _grid_volume(g: np.ndarray, U: int, A: int) -> float:
    """The mesh volume of one muscle's (U * A, 3) grid (:func:`_grid_volumes` for one)."""
    out = np.empty(1)
    _grid_volumes(np.ascontiguousarray(g, dtype=np.float64).reshape(U * A, 3), np.array([0, U * A], np.int64),
                  np.array([U], np.int64), np.array([A], np.int64), out)
    return float(out[0])


def build(specs, models, rest_world: np.ndarray, bone_meshes: dict, enabled: bool = True) -> "ContactModel":
    """The run's contact: pairs (groups, ignore lists), shares from the yields (explicit, or
    :func:`auto_yield`), and the bone fields, each cut to where the muscles' rest meshes,
    grown by tol.CONTACT_REACH, lie in that bone. ``enabled`` False: measure only."""
    names = [s.name for s in specs]
    rest = np.concatenate([m.rest_vertices.astype(np.float64) for m in models])
    fields = []
    for b, (v, f, _) in sorted(bone_meshes.items()):
        inv = np.linalg.inv(rest_world[b])
        # L[p,c] = sum_k inv[c,k] X[p,k] + inv[c,3]
        local = rest @ inv[:3, :3].T + inv[:3, 3]
        clip = np.array([local.min(axis=0) - tol.CONTACT_REACH, local.max(axis=0) + tol.CONTACT_REACH])
        fld = bone_field(b, v, f, clip)
        if fld is not None:
            fields.append(fld)
    packed = BoneFields.pack(fields)
    yields = np.array([s.contact.yield_ if s.contact.yield_ is not None else auto_yield(m, packed, rest_world)
                       for s, m in zip(specs, models)])
    return ContactModel(pair_mask(names, [s.contact for s in specs]), pair_shares(yields), packed,
                        tuple(s.resolution for s in specs), yields, enabled)


def auto_yield(model, fields: BoneFields, rest_world: np.ndarray) -> float:
    """A muscle's depth in layers when its file gives none: minus the distance (in units of
    tol.CONTACT_LAYER) from the bone surface of the centre of its rest mesh's middle ring, so
    that a muscle lying on a bone gives way to one lying over it (0 where no bone is near)."""
    U, A = model.spec.resolution
    ring = model.rest_vertices[1 + ((U - 2) // 2) * A: 1 + ((U - 2) // 2 + 1) * A].astype(np.float64)
    c = ring.mean(axis=0)
    g = np.zeros(6)
    d = _bone_query(c, np.linalg.inv(rest_world), fields.bones, fields.origin, fields.h, fields.dims,
                    fields.offset, fields.values, np.arange(len(fields.bones)), 0, len(fields.bones), -1e300, g)
    if d >= 1e29:
        return 0.0
    return round(-max(d, 0.0) / tol.CONTACT_LAYER, 6)


def apply(model: "ContactModel", results: dict, world: np.ndarray) -> None:
    """The FRAME-scope stage over a chunk: ``results`` maps every muscle index to its
    FrameResult (F frames); each frame's meshes are resolved together (:func:`resolve_frame`)
    and the results updated in place: vertices, normals and volume where contact moved a
    muscle, ``contact`` (F, 3) the measures after contact, warnings for muscles that start a
    frame wholly inside a bone. world : (F, B, 4, 4)."""
    order = sorted(results)
    nf = world.shape[0]
    inv = np.linalg.inv(world)
    for r in results.values():
        r.contact = np.zeros((nf, 3))
    vol = np.empty(len(order))
    finite = np.ones(nf, dtype=bool)
    for j in order:
        finite &= np.isfinite(results[j].vertices.reshape(nf, -1)).all(axis=1)
    for fi in range(nf):
        if not finite[fi]:
            continue  # a frame that cannot be evaluated is written as the rest shape
        verts = [results[j].vertices[fi] for j in order]
        v, n, touched, before, after = resolve_frame(model, verts, inv[fi],
                                                     tol.CONTACT_ITERATIONS if model.enabled else 0, False, vol)
        for k, j in enumerate(order):
            r = results[j]
            r.contact[fi] = after[k]
            if before[k, 1] >= 1.0:
                r.warnings.append((fi, "wholly inside a bone at the start of the frame: contact cannot place it"))
            if touched[k]:
                r.vertices[fi] = v[k]
                r.normals[fi] = n[k]
                r.volume[fi] = vol[k]
