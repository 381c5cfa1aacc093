"""What a camera frames: the one home of the framing rules, for runs, renders and data sets.

- **A run** (``axdf run --render``, ``axdf render``, the USD stage's camera) frames its
  muscles over the whole pose (:func:`run_framing`): each muscle's rest mesh rides rigidly
  on the bones of its two nearest anchors (:func:`anchored_points`), posed by forward
  kinematics at every frame of the pose (:func:`axdf_cli.model.pose.subject_points`). The
  camera so depends on the muscles' rest shapes, the skeleton and the whole pose, never on
  ``--frames``. The points are recorded in the run's manifest (:func:`framing_record`) so
  that rendering the run again frames it the same way (:func:`recorded_framing`).
- **A data set** frames its skeleton (:func:`skeleton_points`): its labels are the joints,
  so every moving bone's joint centre and mesh box stays in view, over the sequence or at
  each frame. The muscles lie between the bones and are framed with them.
- A scene with no framing points frames the corners of its bounds (:func:`framing_points`).
"""
from __future__ import annotations

import numpy as np

from axdf_cli.model.pose import subject_points
from axdf_cli.model.skeleton import forward_kinematics

#: Smallest extent (metres) used for framing, so a point-like scene still frames.
MIN_EXTENT = 1e-3


# ----------------------------------------------------------------------------- a run


def anchored_points(models, skel) -> dict:
    """Bone index -> (N, 3) bone-local points: each muscle's rest vertices (V, 3), carried by
    the bones of the two anchors nearest each vertex at rest (its axis control points'
    bones, or its path points' for a path muscle): a muscle between two bones lies between
    the copies its bones carry, so the hull of the posed points holds it."""
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]  # (B, 4, 4)
    out: dict[int, list] = {}
    for m in models:
        src = m.path.points if m.path is not None else m
        bones, at = np.asarray(src.bones), np.asarray(src.at, dtype=np.float64)
        # a[k,i] = sum_j R[bones_k,i,j] at[k,j] + t[bones_k,i]: the anchors at rest (world)
        anchors = np.einsum("kij,kj->ki", rest[bones, :3, :3], at) + rest[bones, :3, 3]
        v = m.rest_vertices.astype(np.float64)  # (V, 3) world at rest
        d = np.linalg.norm(v[:, None] - anchors[None], axis=2)  # (V, K)
        near = np.argsort(d, axis=1, kind="stable")[:, :2]  # (V, 2) the two nearest anchors
        for b in np.unique(bones):
            sel = np.isin(bones[near], b).any(axis=1)
            R, t = rest[b, :3, :3], rest[b, :3, 3]
            out.setdefault(int(b), []).append((v[sel] - t) @ R)  # world -> bone-local: R^T (v - t)
    return {b: np.concatenate(p) for b, p in out.items()}


def run_framing(pose, models) -> np.ndarray:
    """(N, 3) what a run's automatic camera frames: its muscles (``models``) swept over the
    whole ``pose`` (not the selected frames), rounded to 1 µm so that the manifest holds it
    exactly."""
    pts = subject_points(pose, anchored_points(models, pose.skeleton), joints=False)
    return np.round(pts, 6) + 0.0


def framing_record(points: np.ndarray, first_frame: int) -> dict:
    """The manifest's ``framing``: the points a run framed and its pose's first frame (where
    an orbit's angle is 0)."""
    return {"first_frame": int(first_frame), "points": np.asarray(points).tolist()}


def recorded_framing(m) -> tuple[np.ndarray | None, int | None]:
    """A run manifest's ``framing`` (:func:`framing_record`) read back: (points (N, 3) or
    None, the pose's first frame or None). ``m``: a :class:`~axdf_cli.fileio.runfolder.Manifest`
    (a damaged record is an input error at its position)."""
    if m.get(("framing",), (dict, type(None)), "{first_frame, points}", required=False) is None:
        return None, None
    raw = m.get(("framing", "points"), list, "a list of [x, y, z] points")
    try:
        pts = np.array(raw, dtype=np.float64)
    except (TypeError, ValueError):
        pts = np.zeros((0, 0))
    if pts.ndim != 2 or pts.shape[1:] != (3,) or not len(pts) or not np.isfinite(pts).all():
        raise m.error(("framing", "points"), "is not a list of [x, y, z] numbers", "the points axdf run framed")
    first = m.get(("framing", "first_frame"), int, "the pose's first frame", required=False, default=None)
    return pts, first


# ----------------------------------------------------------------------------- a scene


def box_corners(bounds: np.ndarray) -> np.ndarray:
    """(8, 3) corners of a (2, 3) AABB, grown to at least MIN_EXTENT each way."""
    lo, hi = np.asarray(bounds, float)
    c = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 0.5 * MIN_EXTENT)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    return c + signs * half


def framing_points(scene) -> np.ndarray:
    """(N, 3) world points the automatic camera frames: ``scene.framing``, else the corners
    of ``scene.bounds``."""
    framing = getattr(scene, "framing", None)
    if framing is not None and len(framing):
        return np.asarray(framing, dtype=np.float64)
    return box_corners(scene.bounds)


# ----------------------------------------------------------------------------- a data set


def joint_centres(skeleton, world: np.ndarray) -> np.ndarray:
    """(F, B, 3) world joint centres from bone frames ``world`` (F, B, 4, 4): the origin of
    each bone's joint frame, ``world_b @ [post_offset_b, 1]``."""
    post = np.array([b.post_offset for b in skeleton.bones], dtype=np.float64)  # (B, 3)
    # J[f,b,i] = sum_j R[f,b,i,j] post[b,j] + t[f,b,i]
    return np.einsum("fbij,bj->fbi", world[:, :, :3, :3], post) + world[:, :, :3, 3]


def moving_bones(skeleton) -> list[int]:
    """Bones that move with the pose: all but a root without DOFs (a fixed "ground" frame)."""
    return [i for i, b in enumerate(skeleton.bones) if b.parent >= 0 or b.dofs]


def skeleton_points(skeleton, world: np.ndarray, bone_meshes: dict) -> np.ndarray:
    """(F, P, 3) world points that bound a data set's subject at each frame: the joint
    centres of the moving bones and the corners of their meshes' boxes (``bone_meshes``:
    bone index -> (vertices, ...), bone-local)."""
    move = moving_bones(skeleton)
    pts = [joint_centres(skeleton, world)[:, move]]
    meshed = [i for i in move if i in bone_meshes]
    if meshed:
        lo = np.array([bone_meshes[i][0].min(0) for i in meshed], np.float64)
        hi = np.array([bone_meshes[i][0].max(0) for i in meshed], np.float64)
        pick = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)])  # (8, 3) corner choice
        corners = np.where(pick[None], hi[:, None], lo[:, None])  # (Bm, 8, 3) bone-local
        w = world[:, meshed]
        # c[f,b,k,i] = sum_j R[f,b,i,j] corners[b,k,j] + t[f,b,i]
        c = np.einsum("fbij,bkj->fbki", w[..., :3, :3], corners) + w[:, :, None, :3, 3]
        pts.append(c.reshape(len(world), -1, 3))
    return np.concatenate(pts, axis=1)
