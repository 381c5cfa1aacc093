"""The muscle-under-skin pass: for each pixel of an opaque skin, the muscle nearest beneath it.

A skin pixel's point is its depth unprojected through the camera (the data pass samples pixel
centres: ``(u + 0.5, v + 0.5)``, camera ``z`` forward). Its **muscle** is the one whose surface
is nearest to that point, and its **depth under the skin** the distance to that surface
(metres). Nearest, not along the inward normal: the normal of a skin point can miss every
muscle beside a joint, while the nearest surface is always defined. The distance is exact to
the triangles (libigl's AABB tree, ``point_mesh_squared_distance``), not to the vertices.
A skin pixel with no muscle within ``tolerances.SKIN_UNDER_MAX_DEPTH`` (the head, an arm without
muscles) has none beneath it: id :data:`NO_MUSCLE`, depth 0.
"""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol

#: ``under_id`` of a pixel that is not skin.
NO_MUSCLE = 0


def unproject(depth: np.ndarray, mask: np.ndarray, K: np.ndarray, world_to_camera: np.ndarray) -> np.ndarray:
    """(N, 3) world points of the pixels of ``mask`` (H, W) at their camera depth ``depth``."""
    v, u = np.nonzero(mask)
    z = depth[v, u].astype(np.float64)
    pix = np.stack([u + 0.5, v + 0.5, np.ones_like(z)], 1)
    cam = (pix @ np.linalg.inv(K).T) * z[:, None]
    c2w = np.linalg.inv(world_to_camera)
    return cam @ c2w[:3, :3].T + c2w[:3, 3]


def under_skin(depth: np.ndarray, ids: np.ndarray, skin: int, K: np.ndarray, world_to_camera: np.ndarray,
               meshes: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """The pass for one view: ``depth`` and ``ids`` (H, W) of an opaque-skin render, ``skin``
    its id, ``K`` (3, 3) and ``world_to_camera`` (4, 4) its camera, ``meshes`` each muscle's
    (V, 3) world vertices and (T, 3) faces in id order (muscle k has id k + 1). Returns
    ``under_id`` (H, W) uint16 (the muscle's id; :data:`NO_MUSCLE` off the skin) and
    ``under_depth`` (H, W) float32 (metres; 0 off the skin and where no muscle is near)."""
    import igl

    H, W = ids.shape
    under_id = np.zeros((H, W), np.uint16)
    under_depth = np.zeros((H, W), np.float32)
    mask = ids == skin
    if not mask.any() or not meshes:
        return under_id, under_depth
    offsets = np.cumsum([0] + [len(v) for v, _ in meshes])
    V = np.concatenate([np.asarray(v, np.float64) for v, _ in meshes])
    F = np.concatenate([np.asarray(f, np.int64) + o for (_, f), o in zip(meshes, offsets[:-1])])
    owner = np.repeat(np.arange(1, len(meshes) + 1), [len(f) for _, f in meshes])
    sq, face, _ = igl.point_mesh_squared_distance(unproject(depth, mask, K, world_to_camera), V, F)
    d = np.sqrt(np.maximum(sq, 0.0))
    near = d <= tol.SKIN_UNDER_MAX_DEPTH
    under_id[mask] = np.where(near, owner[np.asarray(face, np.int64)], NO_MUSCLE)
    under_depth[mask] = np.where(near, d, 0.0)
    return under_id, under_depth


def face_parts(faces: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(F,) each skin triangle's body part: the bone (a column of the skin's ``weights``
    (V, K)) with the largest weight summed over its three corners."""
    f = np.asarray(faces, np.int64)
    w = np.asarray(weights, np.float64)
    return np.argmax(w[f[:, 0]] + w[f[:, 1]] + w[f[:, 2]], axis=1)


def body_parts(depth: np.ndarray, ids: np.ndarray, skin: int, K: np.ndarray, world_to_camera: np.ndarray,
               vertices: np.ndarray, faces: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """The body-part pass for one view of an opaque skin: (H, W) uint16, 1 + the part
    (``parts`` (F,), :func:`face_parts`) of the skin triangle each skin pixel's unprojected point
    lies on (nearest, exact to the triangles), 0 off the skin."""
    import igl

    out = np.zeros(ids.shape, np.uint16)
    mask = ids == skin
    if not mask.any():
        return out
    _, face, _ = igl.point_mesh_squared_distance(unproject(depth, mask, K, world_to_camera),
                                                 np.asarray(vertices, np.float64), np.asarray(faces, np.int64))
    out[mask] = np.asarray(parts, np.int64)[np.asarray(face, np.int64)] + 1
    return out
