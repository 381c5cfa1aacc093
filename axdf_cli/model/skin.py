"""The skin stage's kernels (:mod:`axdf_cli.pipeline.skin_stage`): one frame of a skin mesh
skinned by its bones, its normals and volume, and the push of the points under it.

Each kernel is a plain loop in a fixed order (no ``parallel``, no ``fastmath``), so the same
inputs give the same bytes whichever frames a process computes. Compiled once and cached.
"""
from __future__ import annotations

import numpy as np

try:
    from numba import njit
except ImportError as e:  # a dependency: make setup installs it
    raise ImportError(f"axdf needs numba for its skin kernels ({e}); run `make setup` or "
                      "`pip install numba`") from None


@njit(cache=True)
def blend(weights, rel, rest, out):
    """Linear blend skinning: ``out[v] = sum_k weights[v, k] * rel[k] @ (rest[v], 1)``;
    weights (V, K), rel (K, 3, 4) each bone's world transform relative to rest, rest (V, 3)."""
    nv, nk = weights.shape
    for v in range(nv):
        x = rest[v, 0]
        y = rest[v, 1]
        z = rest[v, 2]
        for c in range(3):
            acc = 0.0
            for k in range(nk):
                w = weights[v, k]
                if w != 0.0:
                    acc += w * (rel[k, c, 0] * x + rel[k, c, 1] * y + rel[k, c, 2] * z + rel[k, c, 3])
            out[v, c] = acc


@njit(cache=True)
def normals_volume(v, faces, out):
    """Area-weighted unit vertex normals of the triangle mesh (v, faces) into ``out`` (V, 3);
    returns its signed volume (positive when wound outward)."""
    out[:] = 0.0
    vol = 0.0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e1x, e1y, e1z = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        e2x, e2y, e2z = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        for i in (a, b, c):
            out[i, 0] += nx
            out[i, 1] += ny
            out[i, 2] += nz
        # a . (b x c) / 6 per face
        vol += (v[a, 0] * (v[b, 1] * v[c, 2] - v[b, 2] * v[c, 1])
                + v[a, 1] * (v[b, 2] * v[c, 0] - v[b, 0] * v[c, 2])
                + v[a, 2] * (v[b, 0] * v[c, 1] - v[b, 1] * v[c, 0]))
    for i in range(v.shape[0]):
        r = np.sqrt(out[i, 0] ** 2 + out[i, 1] ** 2 + out[i, 2] ** 2)
        if r > 0.0:
            out[i, 0] /= r
            out[i, 1] /= r
            out[i, 2] /= r
    return vol / 6.0


@njit(cache=True)
def nearest_heights(points, x, n, candidates, nearest, height):
    """For each point, the nearest of its candidate skin vertices (``nearest``) and how far the
    point lies above the skin there, along that vertex's normal (``height``: > 0 outside)."""
    for p in range(points.shape[0]):
        best = -1
        bd = np.inf
        for j in range(candidates.shape[1]):
            s = candidates[p, j]
            d = (points[p, 0] - x[s, 0]) ** 2 + (points[p, 1] - x[s, 1]) ** 2 + (points[p, 2] - x[s, 2]) ** 2
            if d < bd:
                bd = d
                best = s
        if best < 0:  # a non-finite point: it pushes nothing
            best = candidates[p, 0]
            nearest[p] = best
            height[p] = -np.inf
            continue
        nearest[p] = best
        height[p] = (n[best, 0] * (points[p, 0] - x[best, 0]) + n[best, 1] * (points[p, 1] - x[best, 1])
                     + n[best, 2] * (points[p, 2] - x[best, 2]))


@njit(cache=True)
def push_floor(points, x, n, pairs, target, spread_in, spread_out, room, soft_height, max_height, floor):
    """The least offset each skin vertex may take along its normal ``n`` (``floor``, V) and
    still hold every point under it at its target depth; where the floor is above 0 the vertex
    is pushed out to it. Each point ``p`` is compared with each skin vertex ``u = pairs[p, j]``
    it lies under (-1: none): ``h``, its height above ``u`` along ``n[u]``, and ``t``, its
    distance from ``u`` across that normal. It asks ``u`` for ``h + target[p, j]``, weighed by ``w``:
    1 within ``spread_in[u]`` across, falling smoothly to nothing at ``spread_out[u]``, and
    fading linearly to nothing between ``soft_height`` and ``max_height`` above (a crease,
    where the normal does not say whether the point is inside). Where ``w < 1`` the ask bends
    towards ``-room[u]``, the floor of a vertex no point asks anything of (how far it may come
    in at all).

    The floor is the largest ask, and every ask is a continuous function of the positions: a
    point sliding under the skin hands its push from vertex to vertex without a jump, and one
    rising through the height limit lets go of it gradually, so the skin never pops between
    frames (with a nearest vertex and its ring, a point changing its nearest vertex dropped
    whole pushes from the ring's far side)."""
    for u in range(floor.shape[0]):
        floor[u] = -room[u]
    for p in range(points.shape[0]):
        px, py, pz = points[p, 0], points[p, 1], points[p, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)):
            continue  # a non-finite point pushes nothing
        for j in range(pairs.shape[1]):
            u = pairs[p, j]
            if u < 0:
                continue
            dx, dy, dz = px - x[u, 0], py - x[u, 1], pz - x[u, 2]
            h = n[u, 0] * dx + n[u, 1] * dy + n[u, 2] * dz
            if h >= max_height:
                continue
            t = np.sqrt(max(dx * dx + dy * dy + dz * dz - h * h, 0.0))
            if t >= spread_out[u]:
                continue
            w = 1.0
            if t > spread_in[u]:
                f = (t - spread_in[u]) / (spread_out[u] - spread_in[u])
                w = 1.0 - f * f * (3.0 - 2.0 * f)
            if h > soft_height:
                w *= (max_height - h) / (max_height - soft_height)
            c = w * (h + target[p, j]) - (1.0 - w) * room[u]
            if c > floor[u]:
                floor[u] = c


@njit(cache=True)
def ring_mean(values, ring_ptr, ring_idx, s):
    """The mean of ``values`` over vertex ``s``'s ring (its own value where it has none)."""
    a, b = ring_ptr[s], ring_ptr[s + 1]
    acc = 0.0
    for k in range(a, b):
        acc += values[ring_idx[k]]
    return acc / (b - a) if b > a else values[s]


@njit(cache=True)
def relax(need, ring_ptr, ring_idx, iterations, out):
    """Uniform Laplacian smoothing of the offsets, each held at least at ``need`` (sticky; NaN:
    free): ``iterations`` passes of ``out = max(need, mean of the neighbours' out)``, from
    ``need`` (free vertices from 0)."""
    for s in range(need.shape[0]):
        out[s] = 0.0 if np.isnan(need[s]) else need[s]
    tmp = out.copy()
    for _ in range(iterations):
        for s in range(need.shape[0]):
            m = ring_mean(out, ring_ptr, ring_idx, s)
            tmp[s] = need[s] if need[s] > m else m
        out[:] = tmp


@njit(cache=True)
def taper(shift, cap, ring_ptr, ring_idx, iterations):
    """Smooth the edges of a volume shift in place: ``iterations`` passes of ``shift =
    min(cap, mean of the neighbours' shift)`` (a vertex held at its floor keeps its neighbours'
    shift from stepping beside it; where every neighbour takes the whole shift it stays)."""
    tmp = shift.copy()
    for _ in range(iterations):
        for s in range(shift.shape[0]):
            m = ring_mean(shift, ring_ptr, ring_idx, s)
            tmp[s] = cap[s] if cap[s] < m else m
        shift[:] = tmp


@njit(cache=True)
def count_outside(points, y, n, nearest, allowed):
    """How many points lie above the skin ``y`` (along their nearest vertex's normal ``n``)
    by more than ``allowed``."""
    c = 0
    for p in range(points.shape[0]):
        s = nearest[p]
        h = (n[s, 0] * (points[p, 0] - y[s, 0]) + n[s, 1] * (points[p, 1] - y[s, 1])
             + n[s, 2] * (points[p, 2] - y[s, 2]))
        if h > allowed[p]:
            c += 1
    return c
