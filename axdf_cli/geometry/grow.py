"""A closed surface grown outward over points until they lie inside it (a skin over the
muscles and bones it must hold): ``axdf skin --push`` grows the fitted body once, and the skin
stage grows a skin worn over muscles it was not fitted to before the run's first frame.

Each round, the points still outside (winding number, :func:`~axdf_cli.geometry.winding.inside`)
push every corner of their nearest triangle out along the vertex normals by how far out they
are plus ``tol.SKIN_PUSH_CLEARANCE``; the push is spread over the surface around it
(``tol.SKIN_PUSH_SMOOTHING`` passes of neighbour averaging, never less where it is needed), so
the surface bulges instead of spiking; at most ``tol.SKIN_PUSH_ROUNDS`` rounds.
"""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.geometry.winding import inside


def neighbour_mean(faces: np.ndarray, n: int):
    """The averaging over each vertex and its edge neighbours, as a sparse (n, n) matrix."""
    from scipy import sparse

    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2], np.arange(n)])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0], np.arange(n)])
    m = sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    m = ((m + m.T) > 0).astype(np.float64)
    return sparse.diags(1.0 / np.asarray(m.sum(axis=1)).ravel()) @ m


def grow_over(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """A closed surface (vertices (V, 3), faces (T, 3)) grown outward over ``points`` (N, 3)
    so that they lie inside it → vertices (V, 3) float64 (a new array; the faces are kept). Not
    :func:`~axdf_cli.geometry.winding.push_out_of_meshes`, which moves points out of meshes:
    here the surface moves, the points stay."""
    import igl
    import trimesh

    v = np.array(vertices, dtype=np.float64)
    f64 = np.ascontiguousarray(faces, dtype=np.int64)
    points = np.asarray(points, dtype=np.float64)
    points = points[np.isfinite(points).all(axis=1)]
    avg = neighbour_mean(f64, len(v))
    for _ in range(tol.SKIN_PUSH_ROUNDS):
        out = ~inside(v, f64, points)
        if not out.any():
            break
        d2, tri, _ = igl.point_mesh_squared_distance(points[out], v, f64)
        need = np.zeros(len(v))
        depth = np.sqrt(d2) + tol.SKIN_PUSH_CLEARANCE
        np.maximum.at(need, f64[tri].ravel(), np.repeat(depth, 3))  # every corner of the nearest triangle
        spread = need.copy()
        for _ in range(tol.SKIN_PUSH_SMOOTHING):  # the push spread over the surface around it, no less where needed
            spread = np.maximum(need, avg @ spread)
        normals = trimesh.Trimesh(v, f64, process=False).vertex_normals
        v = v + normals * spread[:, None]
    return v
