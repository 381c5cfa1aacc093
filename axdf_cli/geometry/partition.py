"""Tissues as a partition of space: every point of a grid belongs to at most one tissue, and
neighbouring tissues keep a thin gap; and the measure of how far closed meshes lie inside each
other (by depth, not by count: touching meshes share faces).

**The partition** (:func:`partition`). Each tissue is a closed mesh with a level: a tissue of a
higher level wins outright (bones over muscles, an atlas' muscles over the muscles it lacks);
among tissues of one level a point goes to the one it lies deepest in. On a grid of spacing h,
each tissue's signed distance d (metres, positive inside) is computed on its own box: inside
by the generalized winding number (:mod:`~axdf_cli.geometry.winding`), depth by the Euclidean
distance transform (scipy), exact point-to-mesh distances (libigl) within 2 h of the surface.
A muscle's territory is where

    T_i = min(d_i,  (d_i - max_j d_j - gap) / 2,  -max_k d_k - gap) > 0

over the other tissues j of its level and the tissues k of higher levels: inside its mesh,
nearer its own than its neighbour's by the gap (the two territories' edges lie ``gap`` apart
where the meshes touch or cross), and ``gap`` clear of every tissue that wins over it. T is
stored on the muscle's box as a float32 grid; :meth:`Partition.value` reads it anywhere
(trilinear), :meth:`Partition.surface` turns it into a closed mesh (marching cubes, libigl).

Only each tissue's box is ever sampled, and the tissues' values are compared voxel by voxel
through sorted voxel indices: memory and time in proportion to the tissues' volumes, not the
body's box.

**A mesh as a bound** (:class:`MeshField`): a closed mesh's signed distance and the
direction it grows in, anywhere: what a fit kept inside its mesh (``axdf fit --inside``) is
held by.

**The measure** (:func:`depth_inside`): for each query point, the depth (metres) it lies
inside any of a set of closed meshes other than its own (winding number for inside, libigl's
exact distance for how deep); 0 outside all of them.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from axdf_cli.geometry.winding import inside as inside_mesh

#: the distance band outside a tissue (in grid steps beyond the gap) where its signed
#: distance is kept for the comparisons: enough for every territory's edge
_BAND_STEPS = 2


@dataclass(frozen=True)
class Tissue:
    """One closed mesh of the partition: a name, a level (a higher level wins outright) and
    whether it gets a territory (muscles do; bones only take space)."""

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    level: int
    territory: bool = True


@dataclass
class Territory:
    """A tissue's territory field T (metres, positive inside) on its box of the grid: the box
    starts at grid index ``lo`` (3,), T has the box's shape."""

    lo: np.ndarray
    field: np.ndarray


@dataclass
class Partition:
    """The territories on one grid (``origin`` (3,) world metres, ``spacing`` metres) with the
    gap they keep."""

    origin: np.ndarray
    spacing: float
    gap: float
    territories: dict = field(default_factory=dict)
    seconds: float = 0.0

    def value(self, name: str, points: np.ndarray) -> np.ndarray:
        """T of tissue ``name`` at points (P, 3) (metres, positive inside; trilinear; outside its
        box: minus a spacing)."""
        from scipy.ndimage import map_coordinates

        t = self.territories[name]
        idx = (np.asarray(points, dtype=np.float64) - self.origin) / self.spacing - t.lo
        return map_coordinates(t.field, idx.T, order=1, mode="constant", cval=-self.spacing)

    def surface(self, name: str) -> tuple[np.ndarray, np.ndarray] | None:
        """The territory's boundary as one closed mesh (vertices (V, 3) metres, faces (F, 3),
        wound outward): marching cubes of T = 0, its largest piece; None where it is empty."""
        import igl
        import trimesh

        t = self.territories[name]
        f = np.pad(t.field, 1, constant_values=-self.spacing)
        if not (f > 0).any():
            return None
        n = f.shape
        axes = [self.origin[k] + self.spacing * (t.lo[k] - 1 + np.arange(n[k])) for k in range(3)]
        gx, gy, gz = np.meshgrid(*axes, indexing="ij")
        grid = np.stack([gx.ravel(order="F"), gy.ravel(order="F"), gz.ravel(order="F")], axis=1)
        s = -f.ravel(order="F").astype(np.float64)  # positive outside, as igl's marching cubes takes it
        # a corner on (or within float32's reach of) the surface makes triangles that collapse
        # once written: every value is kept a thousandth of a step from zero (vertices move 1 µm)
        tiny = 1e-3 * self.spacing
        s[np.abs(s) < tiny] = np.where(s[np.abs(s) < tiny] < 0, -tiny, tiny)
        V, F, _ = igl.marching_cubes(s, grid, int(n[0]), int(n[1]), int(n[2]), 0.0)
        mesh = trimesh.Trimesh(np.asarray(V, np.float64), np.asarray(F, np.int64), process=True)
        pieces = mesh.split(only_watertight=False)
        if len(pieces) == 0:
            return None
        big = max(pieces, key=lambda m: abs(m.volume))
        if big.volume < 0:
            big.invert()
        return np.asarray(big.vertices, np.float64), np.asarray(big.faces, np.int64)


class MeshField:
    """A closed mesh (vertices (V, 3), faces (F, 3)) as a field: :meth:`value` its signed
    distance (metres, positive inside: winding number, libigl's exact distance), :meth:`inward`
    the direction in which that grows (away from the closest surface point inside, towards it
    outside; the face's inward normal on the surface)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import trimesh

        self.v = np.ascontiguousarray(vertices, np.float64)
        self.f = np.ascontiguousarray(faces, np.int64)
        self.normals = np.asarray(trimesh.Trimesh(self.v, self.f, process=False).face_normals, np.float64)

    def _closest(self, points: np.ndarray):
        import igl

        p = np.ascontiguousarray(points, np.float64)
        d2, face, c = igl.point_mesh_squared_distance(p, self.v, self.f)
        inside = inside_mesh(self.v, self.f, p)
        return p, np.sqrt(np.asarray(d2)), np.asarray(face), np.asarray(c), inside

    def value(self, points: np.ndarray) -> np.ndarray:
        """(P,) the signed distance at points (P, 3)."""
        _, d, _, _, inside = self._closest(points)
        return np.where(inside, d, -d)

    def inward(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) unit directions in which the signed distance grows at points (P, 3)."""
        p, d, face, c, inside = self._closest(points)
        away = (p - c) / np.maximum(d, 1e-300)[:, None]
        g = np.where(inside[:, None], away, -away)
        on = d < 1e-9
        g[on] = -self.normals[face[on]]
        return g


def _box(v: np.ndarray, origin: np.ndarray, h: float, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """A mesh's box on the grid, grown by ``pad``: (lo index (3,), shape (3,))."""
    lo = np.floor((v.min(axis=0) - pad - origin) / h).astype(np.int64)
    hi = np.ceil((v.max(axis=0) + pad - origin) / h).astype(np.int64)
    return lo, hi - lo + 1


def signed_distance(v: np.ndarray, f: np.ndarray, origin: np.ndarray, h: float, lo: np.ndarray,
                    shape: np.ndarray) -> np.ndarray:
    """The mesh's signed distance (metres, positive inside; float32, ``shape``) at the grid
    points origin + h (lo + index): inside by winding number, the distance transform's depth,
    exact distances within 2 h of the surface."""
    import igl
    from scipy.ndimage import distance_transform_edt

    axes = [origin[k] + h * (lo[k] + np.arange(shape[k])) for k in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    ins = _inside_coarse_to_fine(v, f, pts, axes, tuple(shape))
    d = np.where(ins, distance_transform_edt(ins) * h - 0.5 * h, -(distance_transform_edt(~ins) * h - 0.5 * h))
    near = np.abs(d.ravel()) < 2.0 * h
    if near.any():
        d2, _, _ = igl.point_mesh_squared_distance(pts[near], np.ascontiguousarray(v, np.float64),
                                                   np.ascontiguousarray(f, np.int64))
        exact = np.sqrt(np.asarray(d2))
        d.ravel()[near] = np.where(ins.ravel()[near], exact, -exact)
    return d.astype(np.float32)


def _inside_coarse_to_fine(v: np.ndarray, f: np.ndarray, pts: np.ndarray, axes: list, shape: tuple) -> np.ndarray:
    """Which grid points (``pts`` (N, 3), the grid of ``axes`` in ``shape``) lie inside the mesh:
    the winding number on every second point each way, trilinear between them, and exact
    (fast winding number) wherever that is not clearly inside or out
    (|w| within _UNSURE of 0.5): near the surface and in what is thinner than two steps."""
    from scipy.ndimage import map_coordinates

    from axdf_cli.geometry.winding import winding_numbers

    coarse = [a[::2] if len(a) % 2 else np.concatenate([a[::2], a[-1:] + (a[1] - a[0] if len(a) > 1 else 0.0)])
              for a in axes]
    cp = np.stack(np.meshgrid(*coarse, indexing="ij"), axis=-1).reshape(-1, 3)
    wc = np.abs(winding_numbers(v, f, cp)).reshape(tuple(len(c) for c in coarse))
    fine = np.stack(np.meshgrid(*[np.arange(n) / 2.0 for n in shape], indexing="ij"), axis=0).reshape(3, -1)
    w = map_coordinates(wc, fine, order=1, mode="nearest")
    unsure = (np.abs(w - 0.5) < _UNSURE) | _near_surface(v, f, axes, shape).ravel()
    if unsure.any():
        w[unsure] = np.abs(winding_numbers(v, f, pts[unsure]))
    return (w > 0.5).reshape(shape)


def _near_surface(v: np.ndarray, f: np.ndarray, axes: list, shape: tuple) -> np.ndarray:
    """(shape) bool: the grid voxels a triangle passes through or next to (every triangle
    sampled finer than the grid, each sample's voxel and its neighbours)."""
    from scipy.ndimage import binary_dilation

    h = float(axes[0][1] - axes[0][0]) if len(axes[0]) > 1 else 1.0
    tri = v[f]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    longest = np.max(np.linalg.norm(np.stack([e1, e2, e2 - e1], axis=1), axis=2), axis=1)
    k = np.maximum(1, np.ceil(2.0 * longest / h)).astype(np.int64)  # steps per edge
    # the points (a/k, b/k) with a + b <= k of each triangle
    n = (k + 1) * (k + 2) // 2
    which = np.repeat(np.arange(len(f)), n)
    start = np.concatenate([[0], np.cumsum(n)[:-1]])
    j = np.arange(n.sum()) - np.repeat(start, n)
    kk = k[which]
    # row a holds k - a + 1 points: a from the triangular index j
    a = np.floor((2 * kk + 3 - np.sqrt((2 * kk + 3) ** 2 - 8 * j)) / 2).astype(np.int64)
    b = j - (a * (2 * kk + 3) - a * a) // 2
    pts = tri[which, 0] + (a / kk)[:, None] * e1[which] + (b / kk)[:, None] * e2[which]
    lo = np.array([ax[0] for ax in axes])
    idx = np.clip(np.rint((pts - lo) / h).astype(np.int64), 0, np.array(shape) - 1)
    mark = np.zeros(shape, dtype=bool)
    mark[idx[:, 0], idx[:, 1], idx[:, 2]] = True
    return binary_dilation(mark, np.ones((3, 3, 3), bool))


#: a trilinear winding number this close to 0.5 is computed again exactly
_UNSURE = 0.45


def _top_two(idx: np.ndarray, val: np.ndarray, who: np.ndarray):
    """Per distinct voxel of ``idx``: (voxels sorted, the largest value, its tissue, the second
    largest value or -inf)."""
    order = np.lexsort((-val, idx))
    idx, val, who = idx[order], val[order], who[order]
    first = np.concatenate([[True], idx[1:] != idx[:-1]]) if len(idx) else np.zeros(0, bool)
    starts = np.flatnonzero(first)
    second = np.full(len(starts), -np.inf)
    has = (starts + 1 < len(idx))
    has[has] = ~first[starts[has] + 1]
    second[has] = val[starts[has] + 1]
    return idx[starts], val[starts], who[starts], second


def _lookup(keys: np.ndarray, vals: np.ndarray, q: np.ndarray, default: float = -np.inf) -> np.ndarray:
    """vals at the positions of q in the sorted ``keys``; ``default`` where q is absent."""
    if len(keys) == 0:
        return np.full(len(q), default)
    pos = np.minimum(np.searchsorted(keys, q), len(keys) - 1)
    return np.where(keys[pos] == q, vals[pos], default)


def _sparse_distance(t: Tissue, wanted: np.ndarray, origin: np.ndarray, h: float, dims: np.ndarray, pad: float,
                     band: float) -> tuple:
    """A tissue's signed distance at the grid voxels ``wanted`` (flat indices) within its box:
    (None, the voxels kept, their values) where it is above ``band``."""
    import igl

    v = np.ascontiguousarray(t.vertices, np.float64)
    f = np.ascontiguousarray(t.faces, np.int64)
    pts = origin + h * np.stack(np.unravel_index(wanted, tuple(dims)), axis=1)
    near = np.flatnonzero(np.all((pts >= v.min(axis=0) - pad) & (pts <= v.max(axis=0) + pad), axis=1))
    if len(near) == 0:
        return None, np.zeros(0, np.int64), np.zeros(0)
    d2, _, _ = igl.point_mesh_squared_distance(pts[near], v, f)
    d = np.sqrt(np.asarray(d2))
    d = np.where(inside_mesh(v, f, pts[near]), d, -d)
    keep = d > band
    return None, wanted[near[keep]], d[keep]


def partition(tissues: list[Tissue], spacing: float, gap: float, tell=None) -> Partition:
    """The partition of ``tissues`` (see the module's note) on a grid of ``spacing`` with
    neighbours ``gap`` apart; a territory for every tissue with ``territory``."""
    import time

    t0 = time.perf_counter()
    tell = tell or (lambda text: None)
    h = float(spacing)
    pad = gap + (_BAND_STEPS + 2) * h
    allv = np.concatenate([t.vertices for t in tissues])
    origin = np.floor((allv.min(axis=0) - 2 * pad) / h) * h
    dims = np.ceil((allv.max(axis=0) + 2 * pad - origin) / h).astype(np.int64) + 1
    band = -(gap + _BAND_STEPS * h)
    boxes, reach = [None] * len(tissues), [None] * len(tissues)
    for i, t in enumerate(tissues):
        if not t.territory:
            continue
        lo, shape = _box(np.asarray(t.vertices, np.float64), origin, h, pad)
        d = signed_distance(t.vertices, t.faces, origin, h, lo, shape)
        keep = np.flatnonzero(d.ravel() > band)
        loc = np.stack(np.unravel_index(keep, tuple(shape)), axis=1) + lo
        gidx = np.ravel_multi_index(loc.T, tuple(dims))
        boxes[i] = (lo, shape, d)
        reach[i] = (keep, gidx, d.ravel()[keep].astype(np.float64))
    # a tissue without a territory only takes space: its signed distance is needed only where
    # the others' are kept (exact distance, winding-number sign, at those voxels in its box)
    wanted = np.unique(np.concatenate([r[1] for r in reach if r is not None])) if any(r is not None for r in reach) \
        else np.zeros(0, np.int64)
    for i, t in enumerate(tissues):
        if t.territory:
            continue
        reach[i] = _sparse_distance(t, wanted, origin, h, dims, pad, band)
    tell(f"partition: signed distances of {len(tissues)} tissues ({time.perf_counter() - t0:.0f} s)")
    levels = sorted({t.level for t in tissues})
    tops = {}
    for L in levels:
        ids = [i for i, t in enumerate(tissues) if t.level == L]
        idx = np.concatenate([reach[i][1] for i in ids])
        val = np.concatenate([reach[i][2] for i in ids])
        who = np.concatenate([np.full(len(reach[i][1]), i) for i in ids])
        tops[L] = _top_two(idx, val, who)
    out = Partition(origin=origin, spacing=h, gap=float(gap))
    for i, t in enumerate(tissues):
        if not t.territory:
            continue
        keep, gidx, d = reach[i]
        uniq, best, bwho, second = tops[t.level]
        pos = np.searchsorted(uniq, gidx)  # every reach voxel of i is among its level's
        same = np.where(bwho[pos] == i, second[pos], best[pos])
        higher = np.full(len(gidx), -np.inf)
        for L in levels:
            if L > t.level:
                higher = np.maximum(higher, _lookup(tops[L][0], tops[L][1], gidx))
        T = np.minimum(d, np.minimum(0.5 * (d - same - gap), -higher - gap))
        lo, shape, dfull = boxes[i]
        fld = dfull.copy()
        fld.ravel()[keep] = T.astype(np.float32)
        out.territories[t.name] = Territory(lo=lo, field=fld)
    out.seconds = time.perf_counter() - t0
    return out


def depth_inside(points: np.ndarray, owner: np.ndarray, meshes: list, chunk: int = 200_000) -> np.ndarray:
    """How deep (metres) each of ``points`` (P, 3) lies inside the meshes of ``meshes`` (a list
    of (vertices (V, 3), faces (F, 3))) other than its own (``owner`` (P,): the index of its
    mesh there, or -1): the largest depth over the meshes it is inside of (winding number),
    each mesh tested only against the points within its box; 0 where it is inside none."""
    import igl

    pts = np.asarray(points, dtype=np.float64)
    depth = np.zeros(len(pts))
    for k, (v, f) in enumerate(meshes):
        v = np.ascontiguousarray(v, np.float64)
        f = np.ascontiguousarray(f, np.int64)
        near = np.flatnonzero(np.all((pts >= v.min(axis=0)) & (pts <= v.max(axis=0)), axis=1) & (owner != k))
        for s in range(0, len(near), chunk):
            sel = near[s:s + chunk]
            ins = inside_mesh(v, f, pts[sel])
            if ins.any():
                d2, _, _ = igl.point_mesh_squared_distance(pts[sel[ins]], v, f)
                depth[sel[ins]] = np.maximum(depth[sel[ins]], np.sqrt(np.asarray(d2)))
    return depth
