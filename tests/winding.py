"""An independent inside test for the contact measures: the generalized winding number
(Jacobson, Kavan and Sorkine-Hornung 2013) of points with respect to a triangle mesh, the sum
of the solid angles of its triangles (Van Oosterom and Strackee 1983) over 4 pi, in numpy.
A point is inside a closed (or nearly closed) mesh where it exceeds 1/2."""
from __future__ import annotations

import numpy as np


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray, block: int = 2048) -> np.ndarray:
    """points (P, 3), vertices (V, 3), faces (T, 3) → winding numbers (P,)."""
    a0, b0, c0 = (vertices[faces[:, k]].astype(np.float64) for k in range(3))
    out = np.empty(len(points))
    for s in range(0, len(points), block):
        p = points[s:s + block, None, :].astype(np.float64)
        a, b, c = a0[None] - p, b0[None] - p, c0[None] - p  # (P, T, 3)
        la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
        # det[p,t] = a . (b x c)
        det = np.einsum("pti,pti->pt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("pti,pti->pt", a, b) * lc + np.einsum("pti,pti->pt", b, c) * la
               + np.einsum("pti,pti->pt", c, a) * lb)
        out[s:s + block] = np.arctan2(det, den).sum(axis=1) / (2.0 * np.pi)
    return out


def inside_shares(meshes: list[tuple[np.ndarray, np.ndarray]], bones: list[tuple[np.ndarray, np.ndarray]],
                  allow: np.ndarray) -> np.ndarray:
    """Per muscle (vertices (V, 3), faces): [share of vertices inside another muscle it may
    collide with (allow (M, M)), share inside a bone (world vertices, faces)] (M, 2)."""
    out = np.zeros((len(meshes), 2))
    for i, (v, _) in enumerate(meshes):
        ins_m = np.zeros(len(v), bool)
        for j, (vj, fj) in enumerate(meshes):
            if allow[i, j]:
                ins_m |= _inside(v, vj, fj)
        ins_b = np.zeros(len(v), bool)
        for vb, fb in bones:
            ins_b |= _inside(v, vb, fb)
        out[i] = ins_m.mean(), ins_b.mean()
    return out


def _inside(points, vertices, faces) -> np.ndarray:
    """Winding number > 1/2, computed only for the points inside the mesh's bounding box."""
    box = np.all((points >= vertices.min(axis=0)) & (points <= vertices.max(axis=0)), axis=1)
    out = np.zeros(len(points), bool)
    if box.any():
        out[box] = winding_numbers(points[box], vertices, faces) > 0.5
    return out
