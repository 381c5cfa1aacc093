"""Motion onto a muscle model's skeleton: mocap joint centres → the model's coordinates.

Rather than moving muscles onto a mocap skeleton (``axdf transfer``: a BVH has no
``knee_angle``, so muscles whose OpenSim paths follow it cannot go), the *motion* is moved
onto the muscle model's own skeleton, where every muscle keeps its path:

1. **Targets.** Each entry of the map (:func:`load_map`, docs/FORMATS.md "Retarget map") names
   a point of the model (a bone's joint centre, or a point ``at`` in a bone) and the mocap
   joint that drives it, or a weighted blend of several (a hip centre between two markers),
   with a weight in the fit.
2. **Size.** ``scale: fit`` (default): one factor s for the whole model, from the *segments*:
   pairs of mapped points that stay the same distance apart in the model (over sampled poses)
   and in the motion (10th to 90th percentile), s = sum(m d) / sum(d^2) over their model
   lengths d and the motion's median lengths m (the least-squares ratio, as OpenSim's Scale
   tool takes factors from marker distances, but one factor, not one per segment). The
   motion is divided by s: the model keeps its size, so its muscles (their attachments,
   paths and wrap surfaces) are exactly the library's; the subject's proportions that differ
   are reported per segment (the fit's residual is where they show). ``scale: none`` or a
   number fixes s.
3. **World.** ``align: centre`` (default) turns the motion about the vertical and shifts it
   horizontally so that its heading (the root's points, e.g. the hips, against the model's
   rest pose) is centred on the model's forward over the take and the root's path is centred
   on the model's origin: a take anywhere in the capture volume, facing anywhere, stays
   near the model's rest heading and origin. Heights are kept. ``align: none`` keeps the
   motion's world. Together: one similarity transform, y' = (R y − t) / s, reported.
   The subject's place and heading in the room are free: the root bone's translations and
   its turn about the vertical (*room coordinates*, :func:`room_coordinates`) are fitted
   without the ranges the model's file gives them (an OpenSim file needs a range on every
   coordinate: gait2392's pelvis_rotation has ±90°, pelvis_tx ±5 m), unless the map's
   ``ranges:`` names them; their heading is seeded from the motion's (unwrapped over the take)
   on the first frame and follows it without the map's speed limit, so a take that turns
   round and round fits as well as one that walks straight. The map's ``ranges:`` may narrow
   or widen any coordinate's range.
4. **Fit.** :func:`axdf_cli.model.ik.fit_frames`: per frame, the coordinates that move a
   mapped point, within their ranges, by least squares with the analytic Jacobian, warm-started
   from the previous frame. Coordinates the map ``hold``\\ s stay at their value; the others
   that move no point stay at their rest value.
5. **Checks** (:func:`fit_warnings`): a fit whose error, or whose coordinates held at a range's
   end, exceed the bounds of ``tools.constants.RETARGET_*`` is warned with its frames and the fix
   (``--strict`` refuses it); a segment whose ratio is far off the others' (a point's ``at``
   in the wrong unit) is refused, naming the point, and a fitted scale outside
   ``RETARGET_SCALE_BAND`` is warned (a motion in the wrong unit). A map holds at most
   ``RETARGET_MAX_POINTS`` points, and a pose that would pass the YAML size limit is refused
   before any frame is fitted.

:func:`build_retarget` returns every output file's bytes (nothing is written here): the pose
(``DIR/NAME.yaml``), the per-frame residual ``DIR/retarget.csv`` and ``DIR/retarget_report.json``.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.tools import constants as tc
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.yamlio import Fields, YMap, check_name, check_number, did_you_mean, mark_of
from axdf_cli.importers.mocap import Mocap
from axdf_cli.model.ik import FitResult, fit_frames, pose_points
from axdf_cli.model.skeleton import Skeleton, forward_kinematics
from axdf_cli.specs import RefPolicy
from axdf_cli.tools.maps import map_skeleton, open_map, shorthand
from axdf_cli.tools.retarget_checks import fit_bounds, fit_warnings, room_notes

MAP_KEYS = ("retarget", "onto", "scale", "align", "smooth", "max_speed", "hold", "ranges", "joints")
POINT_KEYS = ("bone", "at", "from", "weight")
ALIGN = ("centre", "none")
#: Rotational coordinates without a range are sampled this far (degrees) either side of their
#: rest value to find rigid pairs; translations this far (metres).
SAMPLE_SPAN_ROTATION = 30.0
SAMPLE_SPAN_TRANSLATION = 0.05


# ----------------------------------------------------------------------------- the map


@dataclass(frozen=True)
class MapPoint:
    name: str  # the entry's key
    bone: str  # bone of the model
    at: tuple[float, float, float] | None  # in the bone's frame; None: its joint centre
    sources: tuple[tuple[str, float], ...]  # (mocap joint, blend weight), weights sum to 1
    weight: float  # in the fit
    mark: Mark  # of the entry
    from_mark: Mark  # of its `from:`


@dataclass(frozen=True)
class RetargetMap:
    name: str
    source: str
    skeleton: Skeleton  # the model's, with the map's ranges in place of its own (what the fit keeps to)
    points: tuple[MapPoint, ...]
    hold: dict  # coordinate -> value
    ranges: dict  # coordinate -> (lo, hi): narrower than the skeleton's, for the fit
    scale: object  # "fit" | "none" | float (model -> subject)
    align: str
    smooth: float  # pull towards the previous frame: residual metres per degree
    max_speed: float  # the fastest a rotation may turn, degrees per second (inf: no limit)
    marks: dict = field(default_factory=dict)  # key -> Mark (scale, align, joints)
    model: Skeleton | None = None  # the model's skeleton as loaded (poses are written for it)
    room: tuple = ()  # the root's coordinates fitted without their file's range (room_coordinates)


def load_map(path: Path | str, skeleton: Skeleton | None = None, policy: RefPolicy | None = None) -> RetargetMap:
    """Read and check a retarget map against the model's skeleton (``--onto``, else the
    map's ``onto:``, relative to the map). Mocap joint names are checked by :func:`check_sources`."""
    path, f = open_map(path, "retarget map", MAP_KEYS)
    name = f.name("retarget", required=True)
    skeleton = map_skeleton(f, "onto", skeleton, path, "retarget map names no skeleton", "onto", policy, "skeleton")
    scale = _scale(f.raw("scale", default="fit"), f.vmark("scale"))
    align = f.choice("align", ALIGN, default="centre")
    smooth = float(f.number("smooth", default=tol.IK_SMOOTH_ROTATION, lo=0.0, hi=1.0))
    max_speed = f.number("max_speed", default=None, lo=1.0, hi=1e6)
    max_speed = np.inf if max_speed is None else float(max_speed)
    hold = _hold(f.mapping("hold", default=None), skeleton)
    ranges = _ranges(f.mapping("ranges", default=None), skeleton, hold)
    joints = f.mapping("joints", required=True)
    f.done()
    if len(joints) > tc.RETARGET_MAX_POINTS:
        raise InputError(f.vmark("joints"), f"{len(joints)} points",
                         f"at most {tc.RETARGET_MAX_POINTS} (the scale's segments are pairs of points)")
    points = tuple(_point(key, joints[key], joints, skeleton) for key in joints)
    if not points or sum(p.weight > 0 for p in points) < 2:
        raise InputError(f.vmark("joints"), f"{sum(p.weight > 0 for p in points)} points with a positive weight",
                         "at least 2 (3 or more not on one line to place a body)")
    _check_reach(points, skeleton)
    marks = {k: f.vmark(k) for k in ("scale", "align", "joints", "hold", "ranges")}
    room = tuple(c for c in room_coordinates(skeleton, hold) if c not in ranges)
    fit_ranges = {**{c: None for c in room}, **ranges}
    return RetargetMap(name, str(path), _narrowed(skeleton, fit_ranges), points, hold, ranges, scale, align, smooth,
                       max_speed, marks, skeleton, room)


def _scale(v, where: Mark):
    allowed = "scale is fit (one factor from the segments), none (1), or a number (model → subject) in [0.01, 100]"
    if v in ("fit", "none"):
        return v
    if isinstance(v, str) or isinstance(v, bool) or not isinstance(v, (int, float)):
        raise InputError(where, f"scale is {v!r}", allowed)
    return float(check_number(v, where, "scale", 0.01, 100.0))


def _coordinate_entries(value: YMap | None, skel: Skeleton):
    """(name, value, key mark, value mark, coordinate) of each entry of a ``{COORD: ...}`` mapping."""
    for c, v in (value.items() if value is not None else ()):
        km, vm = value.key_mark(c), value.value_mark(c)
        yield c, v, km, vm, _coordinate(c, km, skel)


def _hold(value: YMap | None, skel: Skeleton) -> dict:
    out = {}
    for c, v, km, vm, coord in _coordinate_entries(value, skel):
        lo, hi = coord.range if coord.range else (None, None)
        out[c] = float(check_number(v, vm, f"hold value of {c}", lo, hi))
    return out


def _coordinate(c, where: Mark, skel: Skeleton):
    if c not in skel.coord_index:
        raise InputError(where, f"unknown coordinate {c!r}",
                         f"{did_you_mean(c, skel.coord_index)}coordinates of skeleton {skel.name}: "
                         + ", ".join(skel.coord_index))
    return skel.coordinates[skel.coord_index[c]]


def _ranges(value: YMap | None, skel: Skeleton, hold: dict) -> dict:
    """``ranges: {COORD: [lo, hi]}``: where the fit may take a coordinate, narrower or wider
    than the skeleton's own range (a wider one: the pose then leaves the skeleton's range,
    which ``axdf run`` reports per frame)."""
    from axdf_cli.fileio.yamlio import check_vector

    out = {}
    for c, v, km, vm, coord in _coordinate_entries(value, skel):
        if c in hold:
            raise InputError(km, f"coordinate {c!r} is both held and given a range", "hold it, or give it a range")
        lo, hi = check_vector(v, vm, f"range of {c}", 2)
        if not lo < hi:
            own = coord.range or (-math.inf, math.inf)
            raise InputError(vm, f"range of {c} is {[lo, hi]}",
                             f"[lo, hi] with lo < hi (narrower or wider than the skeleton's [{own[0]:g}, {own[1]:g}])")
        out[c] = (float(lo), float(hi))
    return out


def room_coordinates(skel: Skeleton, hold: dict) -> tuple[str, ...]:
    """The subject's place and heading in the room: the translations of the root bone (the
    first bone a coordinate that is neither held nor fixed moves) and its rotations whose axis
    is vertical (within 10 degrees) at rest. Their ranges are the model file's, not the body's."""
    from axdf_cli.model.skeleton import forward_kinematics

    def movable(d):
        if d.coord is None or d.coord not in skel.coord_index or d.coord in hold:
            return False
        c = skel.coordinates[skel.coord_index[d.coord]]
        return c.follows is None and not (c.range is not None and c.range[0] == c.range[1])

    root = next((b for b, bone in enumerate(skel.bones) if any(movable(d) for d in bone.dofs)), None)
    if root is None:
        return ()
    q0 = skel.rest_coordinates()
    r0 = forward_kinematics(skel, q0[None])[0, root, :3, :3]
    out = []
    for d in skel.bones[root].dofs:
        if not movable(d) or d.coord in out:
            continue
        c = skel.coord_index[d.coord]
        if skel.coordinates[c].type == "translation":
            out.append(d.coord)
            continue
        q1 = q0.copy()
        q1[c] += 1.0
        turn = forward_kinematics(skel, q1[None])[0, root, :3, :3] @ r0.T  # (3, 3), about the dof's world axis
        axis = np.array([turn[2, 1] - turn[1, 2], turn[0, 2] - turn[2, 0], turn[1, 0] - turn[0, 1]])
        if abs(axis[2]) > math.cos(math.radians(10.0)) * np.linalg.norm(axis):
            out.append(d.coord)
    return tuple(out)


def _check_reach(points, skel: Skeleton) -> None:
    """A point ``at`` farther from its bone's origin than the model's whole rest extent is not
    on the body (a length in the wrong unit): refused at its ``at``."""
    from axdf_cli.model.skeleton import forward_kinematics

    origins = forward_kinematics(skel, skel.rest_coordinates()[None])[0, :, :3, 3]
    extent = max(float(np.linalg.norm(np.ptp(origins, axis=0))), tc.SEGMENT_MIN_LENGTH)
    for p in points:
        if p.at is not None and float(np.linalg.norm(p.at)) > extent:
            raise InputError(p.mark, f"joints entry {p.name}: at {list(p.at)} lies {np.linalg.norm(p.at):.4g} m "
                             f"from bone {p.bone}'s origin, beyond the whole model ({extent:.3g} m across at rest)",
                             "at: metres in the bone's frame, on the body")


def _narrowed(skel: Skeleton, ranges: dict) -> Skeleton:
    """The skeleton with the map's ranges in place of its own (what the fit keeps to; None:
    no range)."""
    from dataclasses import replace

    if not ranges:
        return skel
    return replace(skel, coordinates=tuple(replace(c, range=ranges.get(c.name, c.range)) for c in skel.coordinates))


def _point(key, value, joints: YMap, skel: Skeleton) -> MapPoint:
    km, vm = joints.key_mark(key), joints.value_mark(key)
    check_name(key, km, "joints entry")
    if isinstance(value, str):
        value = shorthand("from", value, vm)
    e = Fields(value, vm, f"joints entry {key}", keys=POINT_KEYS)
    bone = e.name("bone", default=None)
    if bone is None:
        if key not in skel.bone_index:
            raise InputError(km, f"{key!r} is not a bone of skeleton {skel.name}",
                             f"a key is a bone (its joint centre is fitted; {did_you_mean(key, skel.bone_index)}"
                             f"bones: {', '.join(skel.bone_index)}), or any name with bone: and at:")
        bone = key
    elif bone not in skel.bone_index:
        raise InputError(e.vmark("bone"), f"unknown bone {bone!r}",
                         f"{did_you_mean(bone, skel.bone_index)}bones of skeleton {skel.name}: "
                         + ", ".join(skel.bone_index))
    at = e.vector("at", 3, default=None)
    weight = float(e.number("weight", default=1.0, lo=0.0, hi=1e6))
    src = e.raw("from", required=True)
    fm = e.vmark("from")
    if isinstance(src, str):
        sources = ((check_name(src, fm, "mocap joint"), 1.0),)
    elif isinstance(src, dict) and src:
        blend = []
        for j, w in src.items():
            check_name(j, src.key_mark(j), "mocap joint")
            blend.append((j, float(check_number(w, src.value_mark(j), f"blend weight of {j}", 0.0, 1e6, lo_open=True))))
        total = sum(w for _, w in blend)
        sources = tuple((j, w / total) for j, w in blend)
    else:
        raise InputError(mark_of(src, fm), f"from is {src!r}",
                         "from: a mocap joint, or a blend {JOINT: weight, ...} (weights > 0, normalised to sum 1)")
    e.done()
    return MapPoint(key, bone, at, sources, weight, vm, fm)


def check_sources(rmap: RetargetMap, mocap: Mocap) -> None:
    """Every mocap joint the map names exists in the motion (else FILE:LINE:COL of the map)."""
    index = mocap.index
    for p in rmap.points:
        for j, _ in p.sources:
            if j not in index:
                shown = ", ".join(mocap.names[:60]) + (" ..." if len(mocap.names) > 60 else "")
                raise InputError(p.from_mark, f"joint {j!r} is not in {Path(mocap.source).name}",
                                 f"{did_you_mean(j, index)}joints of the motion: {shown}")


# ----------------------------------------------------------------------------- the model's points


@dataclass(frozen=True)
class ModelPoints:
    bones: np.ndarray  # (P,) bone indices
    local: np.ndarray  # (P, 3) in their bones' frames
    weights: np.ndarray  # (P,)
    free: np.ndarray  # (K,) coordinates fitted
    q_start: np.ndarray  # (C,) rest values with the holds
    root: np.ndarray  # root coordinates (fitted alone first on frame 0)
    root_points: np.ndarray  # indices of points rigid with the root bone
    samples: np.ndarray  # (S, C) sampled poses (rest first)


def model_points(rmap: RetargetMap) -> ModelPoints:
    skel = rmap.skeleton
    bi = skel.bone_index
    bones = np.array([bi[p.bone] for p in rmap.points], int)
    local = np.array([p.at if p.at is not None else skel.bones[bi[p.bone]].post_offset for p in rmap.points], float)
    weights = np.array([p.weight for p in rmap.points])
    q0 = skel.rest_coordinates()
    for c, v in rmap.hold.items():
        q0[skel.coord_index[c]] = v
    candidates = [i for i, c in enumerate(skel.coordinates) if c.name not in rmap.hold
                  and not (c.range is not None and c.range[0] == c.range[1])]
    samples = _samples(skel, q0, candidates)
    # a coordinate is fitted when it moves a weighted point in some sampled pose
    from axdf_cli.model.skeleton import dof_frames, point_jacobian

    world, frames = dof_frames(skel, samples)
    _, jac = point_jacobian(skel, frames, world, bones, local)  # (S, P, 3, C)
    moves = np.abs(jac[:, weights > 0]).max(axis=(0, 1, 2)) > 1e-9
    free = np.array([c for c in candidates if moves[c]], int)
    if len(free) == 0:
        raise InputError(rmap.marks["joints"], "the mapped points move with no coordinate of the skeleton",
                         "points on bones that the skeleton's coordinates move")
    root_bone = next((b for b, bone in enumerate(skel.bones)
                      if any(d.coord is not None and skel.coord_index[d.coord] in set(free) for d in bone.dofs)), -1)
    root = np.array(sorted({skel.coord_index[d.coord] for d in skel.bones[root_bone].dofs
                            if d.coord is not None and skel.coord_index[d.coord] in set(free)}), int)
    # points rigid with the root bone: the same place in its frame in every sampled pose
    w = forward_kinematics(skel, samples)
    pts = pose_points(skel, samples, bones, local)  # (S, P, 3)
    rel = np.einsum("sji,spj->spi", w[:, root_bone, :3, :3], pts - w[:, root_bone, None, :3, 3])
    rigid = np.ptp(rel, axis=0).max(axis=1) < tc.ROOT_RIGID
    root_points = np.nonzero(rigid & (weights > 0))[0]
    return ModelPoints(bones, local, weights, free, q0, root, root_points, samples)


def _samples(skel: Skeleton, q0: np.ndarray, coords) -> np.ndarray:
    """(S, C): the rest pose and tc.SEGMENT_SAMPLES - 1 poses drawn (seeded) in the
    coordinates' ranges (without a range: ± SAMPLE_SPAN_* around the rest value)."""
    rng = np.random.default_rng(20)
    out = np.broadcast_to(q0, (tc.SEGMENT_SAMPLES, len(q0))).copy()
    for c in coords:
        coord = skel.coordinates[c]
        if coord.range is not None:
            lo, hi = coord.range
        else:
            span = SAMPLE_SPAN_ROTATION if coord.type == "rotation" else SAMPLE_SPAN_TRANSLATION
            lo, hi = q0[c] - span, q0[c] + span
        out[1:, c] = rng.uniform(lo, hi, tc.SEGMENT_SAMPLES - 1)
    return out


def blend_targets(rmap: RetargetMap, mocap: Mocap) -> np.ndarray:
    """(F, P, 3): each map point's mocap position (its joint, or the weighted blend)."""
    index = mocap.index
    out = np.zeros((mocap.positions.shape[0], len(rmap.points), 3))
    for p, point in enumerate(rmap.points):
        for j, w in point.sources:
            out[:, p] += w * mocap.positions[:, index[j]]
    return out


# ----------------------------------------------------------------------------- size and world


@dataclass(frozen=True)
class Segment:
    a: str
    b: str
    model: float  # the model's length, metres
    subject: float  # the motion's median length, metres
    spread: float  # (p90 - p10) / median of the motion's length


def segments(mp: ModelPoints, rmap: RetargetMap, targets: np.ndarray) -> list[Segment]:
    """Pairs of weighted points a fixed distance apart in the model (over the sampled poses)
    and in the motion (measured on at most SEGMENT_MAX_FRAMES frames, evenly spaced): what the
    size is measured on."""
    skel = rmap.skeleton
    pts = pose_points(skel, mp.samples, mp.bones, mp.local)  # (S, P, 3)
    idx = np.nonzero(mp.weights > 0)[0]
    ii, jj = np.triu_indices(len(idx), k=1)
    ii, jj = idx[ii], idx[jj]
    d = np.linalg.norm(pts[:, ii] - pts[:, jj], axis=2)  # (S, pairs)
    mean = d.mean(axis=0)
    rigid = (mean >= tc.SEGMENT_MIN_LENGTH) & (np.ptp(d, axis=0) <= tc.SEGMENT_MODEL_RIGIDITY * mean)
    ii, jj, d0 = ii[rigid], jj[rigid], d[0, rigid]
    rows = np.unique(np.linspace(0, len(targets) - 1, min(len(targets), tc.SEGMENT_MAX_FRAMES)).round().astype(int))
    y = targets[rows]
    out = []
    for s in range(0, len(ii), 1024):  # bounded memory: (frames, 1024) lengths at a time
        m = np.linalg.norm(y[:, ii[s:s + 1024]] - y[:, jj[s:s + 1024]], axis=2)  # (F', chunk)
        p10, med, p90 = np.percentile(m, [10, 50, 90], axis=0)
        for k in np.nonzero((med >= tc.SEGMENT_MIN_LENGTH) & (p90 - p10 <= tc.SEGMENT_MOCAP_RIGIDITY * med))[0]:
            out.append(Segment(rmap.points[ii[s + k]].name, rmap.points[jj[s + k]].name, float(d0[s + k]),
                               float(med[k]), float((p90[k] - p10[k]) / med[k])))
    return out


def check_segments(segs: list[Segment], rmap: RetargetMap) -> None:
    """A segment whose motion length over the model's is off the segments' median ratio by
    more than RETARGET_SEGMENT_OUTLIER is a map mistake: refused at the point most of the
    outlying segments share (the one of its two with the fewest agreeing segments)."""
    if len(segs) < 2:
        return
    ratio = np.array([g.subject / g.model for g in segs])
    off = np.abs(np.log(ratio / np.median(ratio))) > math.log(tc.RETARGET_SEGMENT_OUTLIER)
    if not off.any():
        return
    bad = {p.name: 0 for p in rmap.points}
    good = dict(bad)
    for g, o in zip(segs, off):
        for n in (g.a, g.b):
            (bad if o else good)[n] += 1
    name = max(bad, key=lambda n: (bad[n] - good[n], bad[n]))
    point = next(p for p in rmap.points if p.name == name)
    g = next(g for g, o in zip(segs, off) if o and name in (g.a, g.b))
    other = g.b if g.a == name else g.a
    raise InputError(point.mark, f"joints entry {name}: {name} to {other} is {g.model:.4g} m in the model but "
                     f"{g.subject:.4g} m in the motion, {g.subject / g.model / np.median(ratio):.3g} times the "
                     f"other segments' ratio (median {np.median(ratio):.3g})",
                     f"a point within a factor {tc.RETARGET_SEGMENT_OUTLIER:g} of the body's proportions: `at:` in "
                     "metres in the bone's frame, and the motion joint (from:) that sits there")


def fit_scale(segs: list[Segment]) -> float | None:
    """s minimising sum (m - s d)^2 over the segments: sum(m d) / sum(d^2); None without any."""
    if not segs:
        return None
    d = np.array([s.model for s in segs])
    m = np.array([s.subject for s in segs])
    return float(np.dot(m, d) / np.dot(d, d))


def heading(model_xy: np.ndarray, target_xy: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Per frame, the turn about the vertical (radians) that best takes the model's points
    ``model_xy`` (P, 2) onto ``target_xy`` (F, P, 2), both about their weighted centroids
    (2D weighted Procrustes: atan2 of the summed cross and dot products)."""
    a = model_xy - np.average(model_xy, axis=0, weights=w)
    b = target_xy - np.einsum("p,fpi->fi", w / w.sum(), target_xy)[:, None, :]
    cross = np.einsum("p,fp->f", w, a[None, :, 0] * b[..., 1] - a[None, :, 1] * b[..., 0])
    dot = np.einsum("p,fp->f", w, a[None, :, 0] * b[..., 0] + a[None, :, 1] * b[..., 1])
    return np.arctan2(cross, dot)


@dataclass(frozen=True)
class World:
    """The similarity taking the motion onto the model: y' = (R_z(-yaw) y - shift) / scale."""

    scale: float
    yaw_deg: float
    shift: tuple[float, float, float]

    def apply(self, y: np.ndarray) -> np.ndarray:
        c, s = math.cos(math.radians(-self.yaw_deg)), math.sin(math.radians(-self.yaw_deg))
        r = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        # y'[..., i] = (r[i, j] y[..., j] - shift[i]) / scale
        return (np.einsum("ij,...j->...i", r, y) - np.asarray(self.shift)) / self.scale


def align_world(mp: ModelPoints, rmap: RetargetMap, targets: np.ndarray, scale: float) -> World:
    if rmap.align == "none":
        return World(scale, 0.0, (0.0, 0.0, 0.0))
    rest = pose_points(rmap.skeleton, mp.q_start[None], mp.bones, mp.local)[0]  # (P, 3)
    use = mp.root_points
    spread = np.ptp(rest[use, :2], axis=0).max() if len(use) >= 2 else 0.0
    if len(use) < 2 or spread < tc.SEGMENT_MIN_LENGTH:
        use = np.nonzero(mp.weights > 0)[0]
    w = mp.weights[use]
    turn = np.unwrap(heading(rest[use, :2], targets[:, use, :2], w))
    yaw = 0.5 * (turn.min() + turn.max())
    yaw_deg = math.degrees(yaw)
    turned = World(1.0, yaw_deg, (0.0, 0.0, 0.0)).apply(targets[:, use])  # (F, U, 3)
    track = np.einsum("u,fui->fi", w / w.sum(), turned[..., :2])
    centre = 0.5 * (track.min(axis=0) + track.max(axis=0))
    rest_centre = np.average(rest[use, :2], axis=0, weights=w) * scale
    shift = centre - rest_centre
    return World(scale, yaw_deg, (float(shift[0]), float(shift[1]), 0.0))


# ----------------------------------------------------------------------------- the whole


@dataclass(frozen=True)
class Retargeted:
    rmap: RetargetMap
    mocap: Mocap
    points: ModelPoints
    world: World
    segments: list
    fit: FitResult
    scale_source: str  # "fit" | "none" | "map"

    @property
    def error(self) -> np.ndarray:
        """(F, P) joint-centre error in the subject's metres."""
        return self.fit.error * self.world.scale


def retarget(rmap: RetargetMap, mocap: Mocap, progress=None, max_pose_bytes: int | None = None) -> Retargeted:
    """Fit the motion (see the module doc). ``max_pose_bytes``: refuse, before fitting, a take
    whose pose file would be larger (:func:`pose_bytes_estimate`)."""
    check_sources(rmap, mocap)
    mp = model_points(rmap)
    if max_pose_bytes is not None:
        n = len(mocap.positions)
        size = pose_bytes_estimate(rmap, mp, n)
        if size > max_pose_bytes:
            raise InputError(Mark(mocap.source), f"the pose would be about {size} bytes ({n} frames of "
                             f"{len(mp.free)} coordinates)", f"axdf reads YAML files up to {max_pose_bytes} bytes; "
                             "a larger --step or a shorter take")
    targets = blend_targets(rmap, mocap)
    segs = segments(mp, rmap, targets)
    check_segments(segs, rmap)
    if rmap.scale == "fit":
        s = fit_scale(segs)
        if s is None:
            raise InputError(rmap.marks["scale"], "scale: fit finds no segment (two mapped points a fixed distance "
                             "apart in both the model and the motion)", "scale: none, or scale: NUMBER")
        source = "fit"
    else:
        s, source = (1.0, "none") if rmap.scale == "none" else (float(rmap.scale), "map")
    world = align_world(mp, rmap, targets, s)
    q_start, step = room_start(mp, rmap, targets, world), np.full(len(mp.free), rmap.max_speed / mocap.fps)
    room = [rmap.skeleton.coord_index[c] for c in rmap.room]
    step[np.isin(mp.free, room)] = np.inf  # the heading in the room turns as fast as the subject does
    fitted = fit_frames(rmap.skeleton, mp.bones, mp.local, mp.weights, world.apply(targets), mp.free, q_start,
                        root=mp.root, root_points=mp.root_points, smooth=rmap.smooth, max_step=step,
                        progress=progress)
    return Retargeted(rmap, mocap, mp, world, segs, fitted, source)


def room_start(mp: ModelPoints, rmap: RetargetMap, targets: np.ndarray, world: World) -> np.ndarray:
    """The fit's start (C,): rest values with the holds, and the room's vertical turn set to the
    motion's heading on its first frame (after the world's turn), so that the first frame's
    root fit starts facing the right way whatever the heading (no range keeps it near rest)."""
    q = mp.q_start.copy()
    skel = rmap.skeleton
    turns = [skel.coord_index[c] for c in rmap.room if skel.coordinates[skel.coord_index[c]].type == "rotation"]
    use = mp.root_points if len(mp.root_points) >= 2 else np.nonzero(mp.weights > 0)[0]
    if len(turns) != 1 or len(use) < 2:
        return q
    c = turns[0]
    rest = pose_points(skel, q[None], mp.bones, mp.local)[0]
    first = world.apply(targets[:1, use])  # (1, U, 3)
    yaw = float(heading(rest[use, :2], first[:, :, :2], mp.weights[use])[0])
    # the coordinate's sign about +z: turn it by 1 degree and see which way the points go
    q1 = q.copy()
    q1[c] += 1.0
    moved = pose_points(skel, q1[None], mp.bones, mp.local)[0]
    sign = math.copysign(1.0, float(heading(rest[use, :2], moved[None, use, :2], mp.weights[use])[0]))
    q[c] += sign * math.degrees(yaw)
    return q


#: Characters a fitted value takes in the pose at least (dump_yaml writes 9 significant digits:
#: "-41.1321989", "0.948403729"); a low estimate, so that a take is refused before fitting only
#: when its pose surely exceeds the limit (the written bytes are checked again).
VALUE_CHARS = 10


def pose_bytes_estimate(rmap: RetargetMap, mp: ModelPoints, frames: int) -> int:
    """About the size of the pose file (a low estimate): per frame ``  F: {NAME: VALUE, ...}``."""
    names = [rmap.skeleton.coordinates[c].name for c in mp.free]
    return frames * (8 + sum(len(n) + 4 + VALUE_CHARS for n in names))


def as_pose(res: Retargeted, name: str):
    """The fitted coordinates as an in-memory :class:`~axdf_cli.specs.Pose` of the model's
    skeleton (what a data set's ``retarget`` motion is): every fitted coordinate keyed at
    every frame, the held ones at frame 0."""
    from axdf_cli.specs import Pose

    skel = res.rmap.model
    frames = tuple(range(len(res.fit.q)))
    keys = {skel.coordinates[c].name: (frames, tuple(float(v) for v in res.fit.q[:, c])) for c in res.points.free}
    for c, v in res.rmap.hold.items():
        keys[c] = ((0,), (float(v),))
    return Pose(name, skel, float(res.mocap.fps), 0, len(frames) - 1, "linear", keys, {}, {},
                res.mocap.source, skel.source)


def jumps(q: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Largest change of each coordinate over 1/30 s (k = round(fps / 30) frames, at least 1):
    (per coordinate (C,), the frame where it starts (C,), k)."""
    k = max(1, int(round(fps / 30.0)))
    if len(q) <= k:
        return np.zeros(q.shape[1]), np.zeros(q.shape[1], int), k
    d = np.abs(q[k:] - q[:-k])
    return d.max(axis=0), d.argmax(axis=0), k


# ----------------------------------------------------------------------------- files


def pose_document(res: Retargeted, name: str, skeleton_ref: str) -> dict:
    skel = res.rmap.skeleton
    q = res.fit.q
    keyed = [int(c) for c in res.points.free]
    held = [skel.coord_index[c] for c in res.rmap.hold]
    keys = {}
    for f in range(len(q)):
        row = {skel.coordinates[c].name: float(q[f, c]) for c in (held if f == 0 else []) + keyed}
        keys[f] = row
    fps = res.mocap.fps
    return {"pose": name, "skeleton": skeleton_ref, "fps": int(fps) if float(fps).is_integer() else fps,
            "frames": [0, len(q) - 1], "interpolation": "linear", "keys": keys}


def frames_csv(res: Retargeted) -> bytes:
    err = res.error
    use = res.points.weights > 0
    names = [p.name for p in res.rmap.points]
    lines = ["frame,rms_m,max_m,worst," + ",".join(f"{n}_m" for n in names)]
    for f in range(len(err)):
        e = err[f]
        rms = float(np.sqrt(np.mean(e[use] ** 2)))
        worst = int(np.nonzero(use)[0][np.argmax(e[use])])
        lines.append(f"{f},{rms:.9g},{e[worst]:.9g},{names[worst]}," + ",".join(f"{v:.9g}" for v in e))
    return ("\n".join(lines) + "\n").encode()


def report(res: Retargeted, name: str, files: dict) -> dict:
    skel = res.rmap.skeleton
    err = res.error
    use = res.points.weights > 0
    per_frame_rms = np.sqrt(np.mean(err[:, use] ** 2, axis=1))
    jump, jump_at, k = jumps(res.fit.q, res.mocap.fps)
    coords = {}
    for c in res.points.free:
        coord = skel.coordinates[c]
        v = res.fit.q[:, c]
        coords[coord.name] = {"min": float(v.min()), "max": float(v.max()), "range": list(coord.range or ()),
                              "file_range": list(res.rmap.model.coordinates[c].range or ()),
                              "frames_at_range_end": int(res.fit.at_bound[:, c].sum()),
                              "largest_change_per_30th_s": float(jump[c]), "at_frame": int(jump_at[c])}
    points = {}
    for i, p in enumerate(res.rmap.points):
        points[p.name] = {"bone": p.bone, "at": list(p.at) if p.at is not None else "joint centre",
                          "from": {j: w for j, w in p.sources}, "weight": p.weight,
                          "rms_m": float(np.sqrt(np.mean(err[:, i] ** 2))), "max_m": float(err[:, i].max()),
                          "worst_frame": int(err[:, i].argmax())}
    s = res.world.scale
    return {
        "tool": "axdf retarget", "pose": name, "skeleton": skel.name,
        "motion": {"file": Path(res.mocap.source).name, "sha256": sha256_file(res.mocap.source), "kind": res.mocap.kind,
                   "joints": len(res.mocap.names), "frames": int(res.mocap.positions.shape[0]), "fps": res.mocap.fps},
        "map": {"file": Path(res.rmap.source).name, "sha256": sha256_file(res.rmap.source), "name": res.rmap.name},
        "similarity": {"scale": s, "scale_from": res.scale_source, "yaw_deg": res.world.yaw_deg,
                       "shift_m": list(res.world.shift),
                       "meaning": "model = (R_z(-yaw) motion - shift) / scale; errors are in the motion's metres"},
        "segments": [{"a": g.a, "b": g.b, "model_m": g.model, "subject_m": g.subject,
                      "subject_over_scaled_model": g.subject / (s * g.model), "spread": g.spread}
                     for g in res.segments],
        "error": {"rms_m": float(np.sqrt(np.mean(err[:, use] ** 2))), "max_m": float(err[:, use].max()),
                  "worst_frame": int(np.argmax(err[:, use].max(axis=1))),
                  "worst_rms_frame": int(np.argmax(per_frame_rms))},
        "points": points,
        "coordinates": coords,
        "held": {c: float(v) for c, v in res.rmap.hold.items()},
        "rest": sorted(c.name for i, c in enumerate(skel.coordinates)
                       if i not in set(res.points.free.tolist()) and c.name not in res.rmap.hold),
        "change_window_frames": k,
        "evaluations": {"total": int(res.fit.evaluations.sum()), "max_per_frame": int(res.fit.evaluations.max())},
        "room": list(res.rmap.room),
        "checks": {"bounds": fit_bounds(res), "warnings": fit_warnings(res)},
        "files": sorted(files),
    }


@dataclass
class RetargetResult:
    files: dict  # output path -> bytes
    report: dict
    retargeted: Retargeted
    notes: list
    warnings: list = field(default_factory=list)  # lines for stderr (``axdf: warning: ...``)


def build_retarget(motion: Path | str, map_path: Path | str, out_dir: Path | str, *, skeleton: Skeleton | None = None,
                   skeleton_path: Path | str | None = None, name: str | None = None, scale: float | None = None,
                   step: int = 1, up: str = "z", policy: RefPolicy | None = None, progress=None) -> RetargetResult:
    """Read the motion and the map, fit, and build the files' bytes (nothing is written).

    Layout: ``DIR/NAME.yaml`` (the pose; its skeleton by a path relative to DIR),
    ``DIR/retarget.csv`` (per frame: RMS, max and every point's error, metres),
    ``DIR/retarget_report.json``."""
    from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name, real_path
    from axdf_cli.importers import emit
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.importers.result import relative_ref

    out_dir = Path(out_dir)
    rmap = load_map(map_path, skeleton, policy)
    mocap = read_motion(motion, scale=scale, step=step, up=up)
    name = name or f"{Path(motion).stem}_{rmap.skeleton.name}"
    if not is_name(name):
        raise InputError(None, f"--name {name!r}", NAME_ALLOWED)
    res = retarget(rmap, mocap, progress, max_pose_bytes=tol.YAML_MAX_BYTES)
    skel_file = Path(skeleton_path) if skeleton_path is not None else Path(rmap.skeleton.source)
    pose_path = out_dir / f"{name}.yaml"
    header = (f"Retargeted from {Path(motion).name} onto {rmap.skeleton.name} by `axdf retarget` "
              f"(map {Path(map_path).name}).\nRegenerate with the command rather than editing by hand.")
    text = emit.dump_yaml(pose_document(res, name, relative_ref(skel_file, out_dir)), header).encode()
    if len(text) > tol.YAML_MAX_BYTES:
        raise InputError(Mark(str(motion)), f"the pose would be {len(text)} bytes ({len(res.fit.q)} frames)",
                         f"axdf reads YAML files up to {tol.YAML_MAX_BYTES} bytes; a larger --step or a shorter take")
    files = {str(pose_path): text, str(out_dir / "retarget.csv"): frames_csv(res)}
    inputs = {real_path(p): p for p in (motion, map_path, skel_file)}
    for out in [*files, str(out_dir / "retarget_report.json")]:
        if real_path(out) in inputs:
            raise InputError(None, f"{out} is an input of this command ({inputs[real_path(out)]})",
                             "an --out folder (or --name) whose files are not the motion, the map or the skeleton")
    rel = [Path(p).name for p in files] + ["retarget_report.json"]
    rep = report(res, name, rel)
    files[str(out_dir / "retarget_report.json")] = (json.dumps(rep, indent=1, sort_keys=True) + "\n").encode()
    return RetargetResult(files, rep, res, list(mocap.notes) + room_notes(res),
                          list(mocap.warnings) + rep["checks"]["warnings"])
