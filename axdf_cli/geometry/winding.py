"""Inside and outside of a triangle mesh by the generalized winding number (libigl), one rule
and one sign convention for every caller: a point is inside where ``|w| > 0.5``
(:data:`INSIDE_WINDING`). The absolute value makes a mesh wound inward (its normals pointing
in, w near -1 inside) count the same as one wound outward; on an outward mesh it is the plain
``w > 0.5``. Outside is the complement (``|w| <= 0.5``).

``signed=True`` keeps the older ``w > 0.5``, under which a mesh or a patch of one wound inward
is not inside, for the callers whose shipped outputs were made with it and change under
``|w|`` on the real data: the atlas' push out of gait2392's bones (its torso is wound
inconsistently: 35 more of psoas_r's vertices count as inside), the fit's IoU against a mesh
(atlas muscles with inward patches: ext_dig_r, ext_hal_r) and tools/atlas_measure.py (the
numbers of docs/FIT.md). Everything else, and every new caller, takes the one rule.

The fast winding number (libigl's ``fast_winding_number``: a hierarchical approximation) is
the default; ``exact`` takes libigl's ``winding_number`` (a sum over every triangle: slower,
exact for points close to the surface, as a skin vertex against a bone).
"""
from __future__ import annotations

import numpy as np

#: |winding number| above this: inside (1 inside a closed surface, 0 outside it)
INSIDE_WINDING = 0.5


def winding_numbers(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, exact: bool = False) -> np.ndarray:
    """(N,) float64: the generalized winding number of the mesh (vertices (V, 3), faces (T, 3))
    at each of ``points`` (N, 3); ``exact``: libigl's exact sum, else its fast approximation."""
    import igl

    v = np.ascontiguousarray(vertices, dtype=np.float64)
    f = np.ascontiguousarray(faces, dtype=np.int64)
    p = np.ascontiguousarray(points, dtype=np.float64)
    return np.asarray(igl.winding_number(v, f, p) if exact else igl.fast_winding_number(v, f, p))


def inside_of(w: np.ndarray, signed: bool = False) -> np.ndarray:
    """(N,) bool: the rule on winding numbers w (N,): ``|w| > 0.5`` (either winding);
    ``signed``: ``w > 0.5`` (see the module's note)."""
    return (w if signed else np.abs(w)) > INSIDE_WINDING


def inside(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray, exact: bool = False,
           signed: bool = False) -> np.ndarray:
    """(N,) bool: which of ``points`` (N, 3) lie inside the mesh (vertices (V, 3), faces (T, 3));
    outside is ``~inside(...)``."""
    return inside_of(winding_numbers(vertices, faces, points, exact), signed)


def inside_share(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> float:
    """The share (0 to 1) of ``points`` (N, 3) inside the mesh (vertices (V, 3), faces (T, 3))."""
    return float(inside(vertices, faces, points).mean())


def push_out_of_meshes(points: np.ndarray, meshes, margin: float, signed: bool = False) -> tuple[np.ndarray, int]:
    """``points`` (N, 3) with every one inside a mesh of ``meshes`` (an iterable of (vertices
    (V, 3), faces (T, 3)), e.g. bones) moved to its nearest point on that mesh's surface and
    ``margin`` beyond it, mesh after mesh (fast winding number, only points within the mesh's
    box grown by ``margin`` tested; ``signed``: inside is ``w > 0.5``, see the module's note)
    → (the moved points (N, 3) float64, a new array; how many moves there were)."""
    import igl

    out = np.array(points, dtype=np.float64)
    moved = 0
    for V, F in meshes:
        V, F = np.asarray(V, np.float64), np.asarray(F, np.int64)
        lo, hi = V.min(axis=0) - margin, V.max(axis=0) + margin
        near = np.flatnonzero(((out >= lo) & (out <= hi)).all(axis=1))
        if len(near) == 0:
            continue
        into = near[inside(V, F, out[near], signed=signed)]
        if len(into) == 0:
            continue
        _, _, c = igl.point_mesh_squared_distance(out[into], V, F)
        d = c - out[into]
        out[into] = c + margin * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        moved += len(into)
    return out, moved


#: How far out along a skin vertex's normal the fold test looks (m): a point 2 mm out from the
#: skin that lies inside it is skin folded onto skin (a crease collapsed into itself).
FOLD_DISTANCE = 0.002


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) float64: area-weighted unit vertex normals (outward on a mesh wound outward;
    zero at a vertex on no triangle or only degenerate ones)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    # fn[t] = (v[f1] - v[f0]) x (v[f2] - v[f0]), twice the triangle's area along its normal
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n = np.zeros_like(v)
    for c in range(3):
        np.add.at(n, f[:, c], fn)
    r = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, r, out=np.zeros_like(n), where=r > 0)


def folded(vertices: np.ndarray, faces: np.ndarray, distance: float = FOLD_DISTANCE,
           normals: np.ndarray | None = None) -> np.ndarray:
    """(V,) bool: which vertices of the closed mesh (vertices (V, 3), faces (T, 3)) are folded:
    the point ``distance`` out along the vertex's outward normal (``normals`` (V, 3), else
    :func:`vertex_normals`) lies inside the mesh by the winding number. On a surface that
    folds into itself (a crease collapsed, skin through skin) that point is under the other
    side; on an unfolded one it is outside wherever the surface is flatter than ``distance``."""
    v = np.asarray(vertices, np.float64)
    n = vertex_normals(v, faces) if normals is None else np.asarray(normals, np.float64)
    return inside(v, faces, v + distance * n)


def folded_share(vertices: np.ndarray, faces: np.ndarray, distance: float = FOLD_DISTANCE,
                 normals: np.ndarray | None = None) -> float:
    """The share (0 to 1) of the mesh's vertices that are :func:`folded`."""
    return float(folded(vertices, faces, distance, normals).mean()) if len(vertices) else 0.0
