"""What a camera frames: the one home of the framing rules, for runs, renders and data sets.

- **A run** (``axdf run --render``, ``axdf render``, the USD stage's camera) frames what it
  draws (:func:`run_framing`): its muscles, each muscle's rest mesh riding rigidly on the bones
  of its two nearest anchors (:func:`anchored_points`), and, when bones are drawn, the moving
  bones' meshes and the joints of the sticks drawn (every moving joint of a skeleton without
  meshes), never a joint or frame that is not drawn; the muscles alone when they span less
  than ``FRAMING_CLOSEUP`` of the whole subject (a close-up: a deltoid on a whole arm and
  trunk). The points are posed
  by forward kinematics at a bounded, even sample of the pose's frames
  (:func:`framing_frames`: every frame of a pose up to ``FRAMING_SAMPLE`` frames), so the
  camera depends on the pose, never on ``--frames``, and one frame of a very long pose costs
  a bounded amount. When the subject's root travels farther than the subject is tall over
  the sample, the camera **follows** it: the points are taken relative to the root's
  horizontal position (x, y, 0) at each frame (:func:`follow_offsets`), made symmetric about
  it across (so the root, and with it the body, stays in the middle of the picture, whichever
  way the subject leans or turns), and the camera keeps its orientation and distance while it
  moves with the root; else it stays fixed. The
  framing is recorded in the run's manifest (:func:`framing_record`) so that rendering the
  run again frames it the same way (:func:`recorded_framing`, :func:`recorded_follow`).
- **A ground plate** (a mesh on a root without DOFs, such as OpenSim's ``ground``) is drawn
  under the subject, grown to cover its footprint with a margin (:func:`plate_matrix`); a
  followed subject carries it along.
- **A data set** frames its skeleton (:func:`skeleton_points`): its labels are the joints,
  so every moving bone's joint centre and mesh box stays in view; a data set that wears a skin
  frames the skin too (:func:`skin_points`: its rest extremes carried by their heaviest bones). Its cameras aim at one
  target per frame (:func:`sequence_targets`), by the run's rule: a bone target is the
  bone's origin at each frame, ``auto`` the subject's centre, following the root when the
  subject travels farther than it is tall.
- A scene with no framing points frames the corners of its bounds (:func:`framing_points`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli.model.pose import (FRAMING_CHUNK, FRAMING_DIRECTIONS, FRAMING_PAD, FRAMING_PAD_FRACTION, SCAN_FRAMES,
                                 hull_points, sample_coordinates, sphere_directions)
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.tolerances import (FRAMING_CLOSEUP, FRAMING_SAMPLE, GROUND_FLAT, GROUND_MARGIN,
                                 GROUND_MARGIN_FRACTION)

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


@dataclass(frozen=True)
class Framing:
    """What the automatic camera frames (:func:`run_framing`)."""

    points: np.ndarray  # (N, 3) hull points: world, or relative to the followed root's (x, y, 0)
    follow: str | None = None  # the root bone the camera follows, or None (a fixed camera)
    ground: tuple[str, ...] = ()  # bones drawn as a ground plate under the subject
    footprint: np.ndarray | None = None  # (2, 2) the subject's horizontal box (world) over the pose: [lo, hi]


def framing_frames(first: int, last: int) -> np.ndarray:
    """The pose frames framing looks at: all of ``first..last`` up to FRAMING_SAMPLE frames,
    else FRAMING_SAMPLE of them spread evenly, both ends included (never the whole range)."""
    n = int(last) - int(first) + 1
    if n <= FRAMING_SAMPLE:
        return np.arange(int(first), int(last) + 1)
    return np.unique(np.rint(np.linspace(int(first), int(last), FRAMING_SAMPLE)).astype(np.int64))


def moving_root(skeleton) -> int | None:
    """The first moving bone whose parent does not move (a pelvis under a fixed ground, a
    BVH's hips): the bone a following camera follows; None for a skeleton that does not move."""
    move = set(moving_bones(skeleton))
    for i in sorted(move):
        if skeleton.bones[i].parent not in move:
            return i
    return None


def ground_bones(skeleton) -> tuple[str, ...]:
    """Bones drawn as a ground plate: roots without DOFs that have a mesh."""
    return tuple(b.name for b in skeleton.bones if b.parent < 0 and not b.dofs and b.mesh)


def _pad(keep: np.ndarray) -> np.ndarray:
    """The hull of ``keep`` grown by FRAMING_PAD (at most a share of its extent) each way."""
    extent = float(np.max(keep.max(axis=0) - keep.min(axis=0)))
    pad = max(min(FRAMING_PAD, FRAMING_PAD_FRACTION * extent), 1e-3 * FRAMING_PAD)
    cube = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * pad
    return hull_points((keep[:, None, :] + cube[None]).reshape(-1, 3))


def run_framing(pose, models, bone_meshes: dict | None = None, bones: bool = True) -> Framing:
    """What a run's automatic camera frames (see the module docstring): its muscles
    (``models``), and with ``bones`` the moving bones' meshes (``bone_meshes``: bone index ->
    (V, 3) bone-local vertices) and joints, posed at :func:`framing_frames`; points rounded to
    1 µm so that the manifest holds them exactly."""
    skel = pose.skeleton
    nb = len(skel.bones)
    dirs = sphere_directions(FRAMING_DIRECTIONS)
    empty, origin = np.zeros((0, 3)), np.zeros((1, 3))

    def extremes(v):
        v = np.asarray(v, dtype=np.float64)
        return v[np.unique(np.argmax(v @ dirs.T, axis=0))] if len(v) else empty

    muscles = anchored_points(models, skel)
    move = set(moving_bones(skel))
    meshes = {b: v for b, v in (bone_meshes or {}).items() if b in move} if bones else {}
    joints = set(move) if bones and not meshes else set()  # a stick figure's moving joints
    for b, p in enumerate(skel.stick_parents()):
        if bones and p >= 0:  # both ends of each stick drawn
            joints |= {b, p}
    groups = {"muscles": [extremes(muscles[b]) if b in muscles else empty for b in range(nb)],
              "skeleton": [np.concatenate([extremes(meshes[b]) if b in meshes else empty,
                                           origin if b in joints else empty]) for b in range(nb)]}
    root = moving_root(skel)
    keep = {(g, rel): empty for g in groups for rel in (False, True)}
    path = []
    frames = framing_frames(pose.first, pose.last)
    for s in range(0, len(frames), FRAMING_CHUNK):
        world = forward_kinematics(skel, sample_coordinates(pose, frames[s:s + FRAMING_CHUNK]))  # (C, B, 4, 4)
        off = world[:, root, :3, 3] * [1.0, 1.0, 0.0] if root is not None else np.zeros((len(world), 3))
        path.append(off)
        for g, local in groups.items():
            # x[c, p] = R_b[c] @ local_b[p] + t_b[c], bone by bone
            posed = [pts @ world[:, b, :3, :3].transpose(0, 2, 1) + world[:, b, None, :3, 3]
                     for b, pts in enumerate(local)]
            keep[g, False] = hull_points(np.concatenate([keep[g, False]] + [x.reshape(-1, 3) for x in posed]))
            keep[g, True] = hull_points(np.concatenate([keep[g, True]] + [(x - off[:, None]).reshape(-1, 3)
                                                                           for x in posed]))
    whole = hull_points(np.concatenate([keep["muscles", False], keep["skeleton", False]]))
    if not len(whole):
        whole = origin
    path = np.concatenate(path)
    travel = float(np.linalg.norm(np.ptp(path[:, :2], axis=0))) if len(path) else 0.0
    follow = root is not None and travel > float(np.ptp(whole[:, 2]))
    if len(keep["muscles", False]) and (not len(keep["skeleton", False]) or np.ptp(keep["muscles", False], axis=0).max()
                                        < FRAMING_CLOSEUP * np.ptp(whole, axis=0).max()):
        group = ["muscles"]  # a close-up: a few muscles on a whole skeleton
    else:
        group = [g for g in groups if len(keep[g, False])]  # everything drawn
    pts = hull_points(np.concatenate([keep[g, follow] for g in group])) if group else origin
    if follow:  # the followed root in the middle of the picture: the hull made symmetric about it across
        pts = hull_points(np.concatenate([pts, pts * [-1.0, -1.0, 1.0]]))  # (a walk's reach ahead and behind)
    foot = np.round(np.stack([whole[:, :2].min(0), whole[:, :2].max(0)]), 6) + 0.0
    return Framing(np.round(_pad(pts), 6) + 0.0, skel.bones[root].name if follow else None, ground_bones(skel), foot)


def plan_framing(plan) -> Framing:
    """:func:`run_framing` of a run plan: its pose, muscles and bone meshes, the bones framed
    when its render draws them (or when it does not render)."""
    bones = plan.render.bones if plan.render is not None else True
    return run_framing(plan.pose, plan.models, {i: v for i, (v, _, _) in plan.bone_meshes.items()}, bones)


def follow_offsets(pose, bone: str, frames) -> np.ndarray:
    """(F, 3) the followed root's horizontal position (x, y, 0) at each of ``frames`` (only
    those frames are posed)."""
    skel = pose.skeleton
    b = skel.bone_index[bone]
    frames = np.asarray(frames)
    out = np.zeros((len(frames), 3))
    for s in range(0, len(frames), SCAN_FRAMES):
        world = forward_kinematics(skel, sample_coordinates(pose, frames[s:s + SCAN_FRAMES]))
        out[s:s + SCAN_FRAMES] = follow_rows(world[:, b, :3, 3])
    return out


def follow_rows(origins: np.ndarray) -> np.ndarray:
    """(F, 3) a following camera's offsets from the followed bone's origins (F, 3): (x, y, 0),
    rounded to 1 µm (as ``bones.csv`` holds them, so a render of the run folder moves alike)."""
    out = np.round(np.asarray(origins, dtype=np.float64), 6) + 0.0
    out[:, 2] = 0.0
    return out


def scene_framing(framing: Framing, pose, frames) -> dict:
    """The :class:`~axdf_cli.render.scene.Scene` fields of ``framing`` for output ``frames``."""
    follow = follow_offsets(pose, framing.follow, frames) if framing.follow is not None else None
    return {"framing": framing.points, "follow": follow, "ground": framing.ground, "footprint": framing.footprint}


def framing_record(framing: Framing, first_frame: int) -> dict:
    """The manifest's ``framing``: the points a run framed, its pose's first frame (where an
    orbit's angle is 0), the bone the camera follows (points relative to it) and the ground
    plates."""
    out = {"first_frame": int(first_frame), "points": np.asarray(framing.points).tolist()}
    if framing.follow is not None:
        out["follow"] = framing.follow
    if framing.ground and framing.footprint is not None:
        out["ground"] = list(framing.ground)
        out["footprint"] = np.asarray(framing.footprint).tolist()
    return out


def recorded_follow(m) -> tuple[str | None, tuple[str, ...], np.ndarray | None]:
    """A run manifest's ``framing.follow``, ``framing.ground`` and ``framing.footprint``
    (absent: None, () and None)."""
    if m.get(("framing",), (dict, type(None)), "{first_frame, points}", required=False) is None:
        return None, (), None
    follow = m.get(("framing", "follow"), (str, type(None)), "a bone name", required=False, default=None)
    ground = m.get(("framing", "ground"), list, "a list of bone names", required=False, default=[])
    for i, g in enumerate(ground):
        m.get(("framing", "ground", i), str, "a bone name")
    if not ground:
        return follow, (), None
    raw = m.get(("framing", "footprint"), list, "[[x0, y0], [x1, y1]]")
    try:
        foot = np.array(raw, dtype=np.float64)
    except (TypeError, ValueError):
        foot = np.zeros(0)
    if foot.shape != (2, 2) or not np.isfinite(foot).all():
        raise m.error(("framing", "footprint"), "is not [[x0, y0], [x1, y1]]", "the subject's box axdf run framed")
    return follow, tuple(ground), foot


def placed_plates(scene, bone_world: np.ndarray | None) -> np.ndarray | None:
    """``bone_world`` (n_scene_bones, 4, 4) with each ground plate of ``scene`` (``scene.ground``)
    moved under the subject's footprint (``scene.footprint``) by :func:`plate_matrix`; a mesh
    on such a bone that is not flat (height over GROUND_FLAT of its width) stays where it is."""
    foot = getattr(scene, "footprint", None)
    names = set(getattr(scene, "ground", ()) or ())
    if bone_world is None or foot is None or not names:
        return bone_world
    out = np.array(bone_world, dtype=np.float64)
    lo, hi = np.asarray(foot, dtype=np.float64)
    for j, b in enumerate(scene.bones):
        if b.name in names and len(b.vertices):
            v = np.asarray(b.vertices, np.float64) @ out[j, :3, :3].T + out[j, :3, 3]
            size = np.ptp(v, axis=0)
            if size[2] <= GROUND_FLAT * max(size[0], size[1]):  # a plate, not a fixed prop (a ball)
                out[j] = plate_matrix(v, 0.5 * (lo + hi), hi - lo) @ out[j]
    return out


def plate_matrix(vertices: np.ndarray, centre, size) -> np.ndarray:
    """(4, 4) the world transform that moves a ground plate (``vertices`` (V, 3), world, as
    its bone places it) under a subject whose horizontal footprint has ``centre`` (2,) and
    ``size`` (2,): the plate is scaled horizontally (never shrunk) to cover the footprint
    plus GROUND_MARGIN (or GROUND_MARGIN_FRACTION of ``size``) each way, and centred under it;
    its height and thickness are kept."""
    v = np.asarray(vertices, dtype=np.float64)
    lo, hi = v[:, :2].min(0), v[:, :2].max(0)
    own = np.maximum(hi - lo, 1e-9)
    margin = max(GROUND_MARGIN, GROUND_MARGIN_FRACTION * float(np.max(size)))
    scale = np.maximum(1.0, (np.asarray(size, float) + 2 * margin) / own)
    M = np.eye(4)
    M[0, 0], M[1, 1] = scale
    M[:2, 3] = np.asarray(centre, float) - scale * 0.5 * (lo + hi)
    return M


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


def skin_anchors(skeleton, skin) -> list:
    """[(bone index, (P, 3) bone-local points)]: the extremes of a skin's rest mesh over
    ``FRAMING_DIRECTIONS``, vertex by vertex on its heaviest bone (the hands of a skeleton
    without hand bones ride on the forearm), for :func:`skin_points`."""
    rest = forward_kinematics(skeleton, skeleton.rest_coordinates()[None])[0]
    heaviest = np.argmax(np.asarray(skin.weights), axis=1)
    dirs = sphere_directions(FRAMING_DIRECTIONS)
    out = []
    for k, name in enumerate(skin.bones):
        v = np.asarray(skin.vertices, np.float64)[heaviest == k]
        if len(v):
            v = v[np.unique(np.argmax(v @ dirs.T, axis=0))]
            b = skeleton.bone_index[name]
            out.append((b, (v - rest[b, :3, 3]) @ rest[b, :3, :3]))  # R^T (v - t), row by row
    return out


def skin_points(anchors: list, world: np.ndarray) -> np.ndarray:
    """(F, P, 3) the skin's framing points (:func:`skin_anchors`) posed rigidly by ``world``
    (F, B, 4, 4): a data set's subject wears its skin (hands and head included)."""
    if not anchors:
        return np.zeros((len(world), 0, 3))
    # x[f,p,i] = sum_j R_b[f,i,j] local[p,j] + t_b[f,i], bone by bone
    return np.concatenate([np.einsum("fij,pj->fpi", world[:, b, :3, :3], local) + world[:, b, None, :3, 3]
                           for b, local in anchors], axis=1)


def sequence_targets(skeleton, world: np.ndarray, subject: np.ndarray, target) -> np.ndarray:
    """(F, 3) where a data set's cameras aim at each frame of a sequence, by the run's rule:
    ``target`` ``("bone", NAME)``: the bone's origin at each frame; ``(x, y, z)``: that point;
    ``"auto"``: the centre of the box around ``subject`` (F, P, 3, :func:`skeleton_points`)
    over the sequence, carried along with the root's horizontal position when the root travels
    farther than the subject is tall (as :func:`run_framing` follows), else fixed."""
    nf = len(world)
    if isinstance(target, tuple) and target and target[0] == "bone":
        return np.array(world[:, skeleton.bone_index[target[1]], :3, 3], dtype=np.float64)
    if target != "auto":
        return np.broadcast_to(np.asarray(target, dtype=np.float64), (nf, 3)).copy()
    pts = subject.reshape(-1, 3)
    centre = 0.5 * (pts.min(0) + pts.max(0))
    root = moving_root(skeleton)
    if root is not None and nf:
        off = follow_rows(world[:, root, :3, 3])
        if float(np.linalg.norm(np.ptp(off[:, :2], axis=0))) > float(np.ptp(pts[:, 2])):
            rel = (subject - off[:, None]).reshape(-1, 3)
            return 0.5 * (rel.min(0) + rel.max(0)) + off
    return np.broadcast_to(centre, (nf, 3)).copy()
