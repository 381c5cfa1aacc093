"""The skin stage's skinning methods (:data:`SKINNING`): where a skin's rest vertices go for
its bones' transforms relative to rest, before any push.

- ``linear``: linear blend skinning, each vertex the weighted sum of its bones' transforms of
  it (:func:`axdf_cli.model.skin.blend`). At a bending joint the blended matrix is no rotation:
  the crease collapses into itself, and a twist pinches (the candy wrapper);
- ``dual_quaternion``: the bones' rigid transforms blended as unit dual quaternions (Kavan,
  Collins, Žára and O'Sullivan 2008, *Geometric skinning with approximate dual quaternion
  blending*, ACM TOG 27(4)): every vertex moves rigidly, so a twist keeps its volume; a bend
  bulges out of the crease instead of collapsing;
- ``delta_mush``: linear blend, then Laplacian-smoothed, then each vertex's rest detail put
  back in a frame that turns with the smoothed mesh (Mancewicz, Derksen, Rijpkema and Wilson
  2014, *Delta Mush: smoothing deformations while preserving detail*, DigiPro '14): the rest
  mesh's deltas from its own smoothing, stored in each vertex's local frame (the smoothed
  normal and the first ring neighbour's direction across it) once, re-applied every frame.

Every kernel is a plain loop in a fixed order (no ``parallel``, no ``fastmath``), so the same
inputs give the same bytes whichever frames a process computes. Arrays: rest and out (V, 3)
float64, weights (V, K) float64 rows summing to 1, rel (K, 3, 4) the bones' rigid world
transforms relative to rest; the ring as CSR (ptr (V + 1,), idx) int64.
"""
from __future__ import annotations

import numpy as np

from axdf_cli.model.skin import blend, njit, normals_volume

#: The skinning methods a skin file's ``skinning:`` may name (the default, for a file that
#: names none, is :data:`axdf_cli.pipeline.skin_stage.DEFAULT_SKINNING`: docs/SKIN.md).
SKINNING = ("linear", "dual_quaternion", "delta_mush")


def dual_quaternions(rel: np.ndarray) -> np.ndarray:
    """(K, 8) float64: each rigid transform of ``rel`` (K, 3, 4) as a unit dual quaternion
    ``(w, x, y, z)`` real part (the rotation, w >= 0) then its dual part ``0.5 (0, t) q``."""
    r = np.asarray(rel[:, :3, :3], np.float64)
    t = np.asarray(rel[:, :3, 3], np.float64)
    k = len(r)
    q = np.empty((k, 4))
    tr = np.trace(r, axis1=1, axis2=2)
    # Shepperd's method: the largest of the four squared components first, for precision
    d = np.stack([tr, r[:, 0, 0], r[:, 1, 1], r[:, 2, 2]], axis=1)
    which = np.argmax(d, axis=1)
    for i in range(k):  # K bones (tens), not vertices
        m = r[i]
        if which[i] == 0:
            s = 2.0 * np.sqrt(max(1.0 + tr[i], 1e-300))
            q[i] = (0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
        elif which[i] == 1:
            s = 2.0 * np.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 1e-300))
            q[i] = ((m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
        elif which[i] == 2:
            s = 2.0 * np.sqrt(max(1.0 - m[0, 0] + m[1, 1] - m[2, 2], 1e-300))
            q[i] = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s)
        else:
            s = 2.0 * np.sqrt(max(1.0 - m[0, 0] - m[1, 1] + m[2, 2], 1e-300))
            q[i] = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q *= np.where(q[:, :1] < 0.0, -1.0, 1.0)
    w, v = q[:, 0], q[:, 1:]
    # dual part 0.5 (0, t) q = 0.5 (-t.v, w t + t x v)
    qe = 0.5 * np.concatenate([-np.einsum("kc,kc->k", t, v)[:, None], w[:, None] * t + np.cross(t, v)], axis=1)
    return np.ascontiguousarray(np.concatenate([q, qe], axis=1))


@njit(cache=True)
def blend_dq(weights, dq, rest, out):
    """Dual quaternion skinning (Kavan et al. 2008, DLB): each vertex's bones' dual quaternions
    ``dq`` (K, 8) summed by its weights, each turned to the hemisphere of the vertex's heaviest
    bone's (the shortest way round), normalized, and applied to ``rest[v]``."""
    nv, nk = weights.shape
    b = np.empty(8)
    for v in range(nv):
        piv = 0
        for k in range(nk):
            if weights[v, k] > weights[v, piv]:
                piv = k
        b[:] = 0.0
        for k in range(nk):
            w = weights[v, k]
            if w == 0.0:
                continue
            if dq[k, 0] * dq[piv, 0] + dq[k, 1] * dq[piv, 1] + dq[k, 2] * dq[piv, 2] + dq[k, 3] * dq[piv, 3] < 0.0:
                w = -w
            for c in range(8):
                b[c] += w * dq[k, c]
        r = np.sqrt(b[0] * b[0] + b[1] * b[1] + b[2] * b[2] + b[3] * b[3])
        w0, x0, y0, z0 = b[0] / r, b[1] / r, b[2] / r, b[3] / r
        we, xe, ye, ze = b[4] / r, b[5] / r, b[6] / r, b[7] / r
        # t = 2 (w0 ve - we v0 + v0 x ve)
        tx = 2.0 * (w0 * xe - we * x0 + y0 * ze - z0 * ye)
        ty = 2.0 * (w0 * ye - we * y0 + z0 * xe - x0 * ze)
        tz = 2.0 * (w0 * ze - we * z0 + x0 * ye - y0 * xe)
        px, py, pz = rest[v, 0], rest[v, 1], rest[v, 2]
        # p + 2 v0 x (v0 x p + w0 p): the unit quaternion's rotation
        cx = y0 * pz - z0 * py + w0 * px
        cy = z0 * px - x0 * pz + w0 * py
        cz = x0 * py - y0 * px + w0 * pz
        out[v, 0] = px + 2.0 * (y0 * cz - z0 * cy) + tx
        out[v, 1] = py + 2.0 * (z0 * cx - x0 * cz) + ty
        out[v, 2] = pz + 2.0 * (x0 * cy - y0 * cx) + tz


@njit(cache=True)
def smooth(x, ptr, idx, iterations, step, out):
    """``iterations`` passes of uniform Laplacian smoothing, ``out = x + step (mean of the ring - x)``,
    of ``x`` (V, 3) into ``out`` (Jacobi: each pass from the last)."""
    out[:] = x
    tmp = x.copy()
    for _ in range(iterations):
        for s in range(x.shape[0]):
            a, b = ptr[s], ptr[s + 1]
            if b == a:
                for c in range(3):
                    tmp[s, c] = out[s, c]
                continue
            for c in range(3):
                acc = 0.0
                for k in range(a, b):
                    acc += out[idx[k], c]
                tmp[s, c] = out[s, c] + step * (acc / (b - a) - out[s, c])
        out[:] = tmp


@njit(cache=True)
def _frame(s, n, ptr, idx, v, f):
    """Vertex v's frame on the smoothed mesh ``s`` into f (3, 3), rows: the tangent (its first
    ring neighbour's direction across the normal), the bitangent, the normal ``n[v]``."""
    nx, ny, nz = n[v, 0], n[v, 1], n[v, 2]
    u = idx[ptr[v]] if ptr[v + 1] > ptr[v] else v
    ex, ey, ez = s[u, 0] - s[v, 0], s[u, 1] - s[v, 1], s[u, 2] - s[v, 2]
    d = ex * nx + ey * ny + ez * nz
    ex, ey, ez = ex - d * nx, ey - d * ny, ez - d * nz
    r = np.sqrt(ex * ex + ey * ey + ez * ez)
    if r < 1e-300:  # (no neighbour across the normal: any tangent)
        ex, ey, ez = (1.0, 0.0, 0.0) if abs(nx) < 0.9 else (0.0, 1.0, 0.0)
        d = ex * nx + ey * ny + ez * nz
        ex, ey, ez = ex - d * nx, ey - d * ny, ez - d * nz
        r = np.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / r, ey / r, ez / r
    f[0, 0], f[0, 1], f[0, 2] = ex, ey, ez
    f[1, 0], f[1, 1], f[1, 2] = ny * ez - nz * ey, nz * ex - nx * ez, nx * ey - ny * ex
    f[2, 0], f[2, 1], f[2, 2] = nx, ny, nz


@njit(cache=True)
def mush_deltas(rest, s, n, ptr, idx, out):
    """Each rest vertex's delta from its smoothed position ``s`` in that vertex's frame
    (:func:`_frame`, smoothed normals ``n``): ``out[v] = F (rest[v] - s[v])``."""
    f = np.empty((3, 3))
    for v in range(rest.shape[0]):
        _frame(s, n, ptr, idx, v, f)
        for a in range(3):
            out[v, a] = (f[a, 0] * (rest[v, 0] - s[v, 0]) + f[a, 1] * (rest[v, 1] - s[v, 1])
                         + f[a, 2] * (rest[v, 2] - s[v, 2]))


@njit(cache=True)
def mush_apply(s, n, ptr, idx, deltas, out):
    """The deltas put back on the smoothed, skinned mesh ``s``: ``out[v] = s[v] + F^T deltas[v]``."""
    f = np.empty((3, 3))
    for v in range(s.shape[0]):
        _frame(s, n, ptr, idx, v, f)
        for c in range(3):
            out[v, c] = s[v, c] + f[0, c] * deltas[v, 0] + f[1, c] * deltas[v, 1] + f[2, c] * deltas[v, 2]


def mush_rest(rest: np.ndarray, faces: np.ndarray, ptr: np.ndarray, idx: np.ndarray, iterations: int,
              step: float) -> np.ndarray:
    """(V, 3) float64: the rest mesh's delta mush deltas (:func:`mush_deltas`) for smoothing by
    ``iterations`` passes of ``step``."""
    s, n, d = np.empty_like(rest), np.empty_like(rest), np.empty_like(rest)
    smooth(rest, ptr, idx, iterations, step, s)
    normals_volume(s, faces, n)
    mush_deltas(rest, s, n, ptr, idx, d)
    return d


def skin_points(method: str, weights: np.ndarray, rel: np.ndarray, rest: np.ndarray, out: np.ndarray,
                mush=None) -> None:
    """Skin ``rest`` (V, 3) by ``rel`` (K, 3, 4) with ``weights`` (V, K) into ``out`` (V, 3) by
    ``method`` (one of :data:`SKINNING`); ``mush``: for ``delta_mush``, (faces (T, 3), ptr,
    idx, iterations, step, deltas (V, 3))."""
    if method == "linear":
        blend(weights, rel, rest, out)
    elif method == "dual_quaternion":
        blend_dq(weights, dual_quaternions(rel), rest, out)
    elif method == "delta_mush":
        faces, ptr, idx, iterations, step, deltas = mush
        x, s, n = np.empty_like(out), np.empty_like(out), np.empty_like(out)
        blend(weights, rel, rest, x)
        smooth(x, ptr, idx, iterations, step, s)
        normals_volume(s, faces, n)
        mush_apply(s, n, ptr, idx, deltas, out)
    else:
        raise ValueError(f"skinning is {method!r}; one of {', '.join(SKINNING)}")
