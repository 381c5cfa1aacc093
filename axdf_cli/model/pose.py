"""Sampling poses: keyed coordinates and activation curves → arrays over frames.

``linear`` and ``cubic`` interpolate between keys; ``step`` holds each key until the next.
``cubic`` is the monotone piecewise-cubic Hermite interpolant (PCHIP, Fritsch & Carlson
1980): smooth through the keys without overshooting them, like Blender's auto-clamped
Bézier handles (a natural spline through sparse keys swings far past them). Before the first key and after the last, a
curve holds that key's value. Coordinates keyed nowhere keep their rest value.

Ranges: a coordinate with a ``range`` (declared, or on a DOF it drives) that a pose takes
outside it is either held at the range's end (the pose's ``clamp_ranges: true`` or
``axdf run --clamp-ranges``) or left as keyed and reported per frame
(:func:`range_warnings`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.errors import nearest

#: Frames sampled at once when scanning a whole sequence (bounds memory for long poses).
SCAN_FRAMES = 65536
#: Frames posed at once when collecting the subject's points for framing (see subject_points).
FRAMING_CHUNK = 256
#: Room around the bones for automatic framing: muscles lie on the bones and bulge past the
#: hull of the posed bone meshes by up to 2.9 cm on the shipped jobs (demo brachioradialis;
#: gait2392: 0); a mesh-less skeleton's muscles lie around its joint chain. Metres, but at most
#: a share of the subject's largest extent (a small model gets a small pad).
FRAMING_PAD = 0.03
FRAMING_PAD_FRACTION = 0.05
#: A bone mesh is framed by its vertices extreme along this many directions (a Fibonacci
#: sphere, ~0.2 rad apart: the kept points' hull lies within 0.5% of the bone's size of the
#: mesh's hull, far inside FRAMING_PAD); it bounds the work per frame for detailed meshes.
FRAMING_DIRECTIONS = 128


def sphere_directions(n: int) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


#: Curves whose arrays (and cubic interpolant) are kept between calls, keyed by the identity
#: of their key tuples: a pose keeps its keys as tuples, and converting 200,000 keys to
#: arrays on every sampled chunk made a late frame of a long keyed pose cost the keys times
#: the chunks before it. At most CURVE_CACHE curves are kept (the oldest go first).
CURVE_CACHE = 512
_CURVES: dict = {}


def _curve(key_frames, key_values, mode: str):
    """(kf, kv, interpolant or None) of a curve, made once for the same key tuples."""
    key = (id(key_frames), id(key_values), mode)
    hit = _CURVES.get(key)
    if hit is not None and hit[0] is key_frames and hit[1] is key_values:
        return hit[2:]
    kf = np.asarray(key_frames, dtype=np.float64)
    kv = np.asarray(key_values, dtype=np.float64)
    cubic = None
    if mode == "cubic" and len(kf) >= 3:
        from scipy.interpolate import PchipInterpolator

        cubic = PchipInterpolator(kf, kv)
    if isinstance(key_frames, tuple) and isinstance(key_values, tuple):  # (immutable: safe to keep)
        while len(_CURVES) >= CURVE_CACHE:
            del _CURVES[next(iter(_CURVES))]
        _CURVES[key] = (key_frames, key_values, kf, kv, cubic)
    return kf, kv, cubic


def interpolate(frames: np.ndarray, key_frames, key_values, mode: str) -> np.ndarray:
    """One curve at ``frames`` (F,) from keys → (F,) float64."""
    kf, kv, cubic = _curve(key_frames, key_values, mode)
    x = np.asarray(frames, dtype=np.float64)
    if len(kf) == 1:
        return np.full(x.shape, kv[0])
    if mode == "step":
        i = np.clip(np.searchsorted(kf, x, side="right") - 1, 0, len(kf) - 1)
        return kv[i]
    if cubic is not None:
        return cubic(np.clip(x, kf[0], kf[-1]))
    return np.interp(x, kf, kv)


def sample_coordinates(pose, frames: np.ndarray, clamp: bool | None = None) -> np.ndarray:
    """Coordinates of the pose's skeleton at ``frames``: (F, C) float64, axdf units; held
    inside their ranges when ``clamp`` (default: the pose's ``clamp_ranges``); coupled
    coordinates then follow their (held) leaders (:meth:`Skeleton.couple`)."""
    skel = pose.skeleton
    clamp = pose.clamp_ranges if clamp is None else clamp
    q = np.broadcast_to(skel.rest_coordinates(), (len(frames), len(skel.coordinates))).copy()
    for c, (kf, kv) in pose.keys.items():
        i = skel.coord_index[c]
        q[:, i] = interpolate(frames, kf, kv, pose.interpolation)
        rng = skel.coordinates[i].range
        if clamp and rng is not None:
            np.clip(q[:, i], rng[0], rng[1], out=q[:, i])
    return skel.couple(q)


@dataclass(frozen=True)
class OutsideRange:
    """A keyed coordinate that the pose takes outside its range at some of a run's frames."""

    coordinate: str
    range: tuple[float, float]  # (lo, hi) in axdf units (degrees, metres)
    frames: tuple[int, ...]  # the frame numbers where the keyed value lies outside, in order
    low: float  # the keyed value's extremes over those frames
    high: float
    clamped: bool  # held at the range's ends (``clamp_ranges``) rather than posed as keyed

    def record(self) -> dict:
        """The run manifest's ``ranges`` entry (frames as compact runs, :func:`frame_spans`)."""
        return {"coordinate": self.coordinate, "range": [float(self.range[0]), float(self.range[1])],
                "frames": frame_spans(self.frames, shown=None), "count": len(self.frames),
                "keyed": [float(f"{self.low:.9g}"), float(f"{self.high:.9g}")], "clamped": self.clamped}

    def text(self, of: int) -> str:
        """One line for the terminal (``of``: the run's frame count)."""
        lo, hi = self.range
        span = f"{self.low:.6g}" if self.low == self.high else f"{self.low:.6g} to {self.high:.6g}"
        if self.clamped:
            return (f"{self.coordinate} was clamped to its range [{lo:g}, {hi:g}] in {len(self.frames)} of {of} "
                    f"frames: {frame_spans(self.frames)} (keyed {span})")
        return (f"{self.coordinate} is outside its range [{lo:g}, {hi:g}] in {len(self.frames)} of {of} frames: "
                f"{frame_spans(self.frames)} (keyed {span}; --clamp-ranges holds it inside)")


def frame_spans(frames, shown: int | None = 6) -> str:
    """Frame numbers as runs: ``36-42, 178-190`` (the first ``shown`` runs, then how many more;
    ``shown`` None: every run)."""
    frames = np.asarray(frames, int)
    if len(frames) == 0:
        return "none"
    cut = np.nonzero(np.diff(frames) != 1)[0]
    starts, ends = np.r_[frames[0], frames[cut + 1]], np.r_[frames[cut], frames[-1]]
    runs = [f"{a}" if a == b else f"{a}-{b}" for a, b in zip(starts.tolist(), ends.tolist())]
    if shown is None or len(runs) <= shown:
        return ", ".join(runs)
    return ", ".join(runs[:shown]) + f" and {len(runs) - shown} more runs"


def outside_ranges(pose, frames: np.ndarray) -> list[OutsideRange]:
    """Every keyed coordinate with a range that the pose's keys take outside it at ``frames``
    (a run's selected frames), in the skeleton's coordinate order: where, and how far, whether
    the pose clamps (``clamped``) or not. Every coordinate counts, those that carry the whole
    body (the root's place and heading in the room) too."""
    skel = pose.skeleton
    frames = np.asarray(frames)
    out = []
    for c in sorted(pose.keys, key=lambda name: skel.coord_index[name]):
        rng = skel.coordinates[skel.coord_index[c]].range
        if rng is None:
            continue
        lo, hi = rng
        kf, kv = pose.keys[c]
        found, low, high = [], np.inf, -np.inf
        for s in range(0, len(frames), SCAN_FRAMES):
            fr = frames[s:s + SCAN_FRAMES]
            v = interpolate(fr, kf, kv, pose.interpolation)
            bad = (v < lo) | (v > hi)
            if bad.any():
                found += [int(f) for f in fr[bad]]
                low, high = min(low, float(v[bad].min())), max(high, float(v[bad].max()))
        if found:
            out.append(OutsideRange(c, (float(lo), float(hi)), tuple(found), low, high, bool(pose.clamp_ranges)))
    return out


def range_warnings(pose, frames: np.ndarray) -> list[tuple[int, str, str]]:
    """Keyed coordinates outside their ranges: ``(index into frames, coordinate, message)``
    for every such frame and coordinate, in frame order; none when the pose clamps."""
    skel = pose.skeleton
    if pose.clamp_ranges:
        return []
    ranged = [(c, skel.coord_index[c], skel.coordinates[skel.coord_index[c]].range) for c in pose.keys
              if skel.coordinates[skel.coord_index[c]].range is not None]
    out = []
    for s in range(0, len(frames), SCAN_FRAMES):
        fr = np.asarray(frames[s:s + SCAN_FRAMES])
        for c, i, (lo, hi) in ranged:
            kf, kv = pose.keys[c]
            v = interpolate(fr, kf, kv, pose.interpolation)
            for k in np.nonzero((v < lo) | (v > hi))[0]:
                out.append((s + int(k), c, f"{c} = {v[k]:.6g} outside its range [{lo:g}, {hi:g}]"
                                          " (--clamp-ranges holds it inside)"))
    out.sort(key=lambda w: w[0])
    return out


def muscle_range_warnings(pose, frames: np.ndarray, muscles) -> list[tuple[int, int, str]]:
    """:func:`range_warnings` for the run's table: ``(index into frames, muscle index,
    message)`` for each muscle the coordinate changes: one with an axis point, a path point or
    a wrap surface (or its side point) on a bone the coordinate moves while another of its
    bones stays, or a path point that moves with the coordinate or is active over a range of
    it. A coordinate that carries all of a muscle's bones (the root's place and heading in the
    room) moves it rigidly and is not its range to check."""
    warns = range_warnings(pose, frames)
    if not warns:
        return []
    moved = pose.skeleton.moved_bones()
    bi = pose.skeleton.bone_index
    bones = [{bi[b] for b in muscle_bones(m) if b in bi} for m in muscles]
    coords = [set() if m.path is None else m.path.coordinates for m in muscles]
    return [(fi, j, msg) for fi, c, msg in warns for j, b in enumerate(bones)
            if (b & moved[c] and not b <= moved[c]) or c in coords[j]]


def muscle_bones(muscle) -> set[str]:
    """The names of the bones a muscle hangs on: its axis points', and its path points' and
    wrap surfaces' (a muscle with both: its belly and its line of action)."""
    names = {p.bone for p in muscle.axis}
    if muscle.path is not None:
        names |= {p.bone for p in muscle.path.points}
        for w in muscle.path.wraps:
            names.add(w.bone)
            if w.side is not None:
                names.add(w.side[0])
    return names


def activation_problems(pose, muscle_names) -> tuple[list[str], list[str]]:
    """Activation curves for muscles that are not in the run: (warnings, notes).

    A name close to a run muscle that has no curve of its own is most likely misspelt: a
    warning naming that muscle (``--strict`` refuses it). Other names are notes: a pose
    shared by several muscle sets (gait2392's walk, the paper's muscles) names muscles of
    the other sets."""
    names = list(muscle_names)
    free = [n for n in names if n not in pose.activation]
    warnings, notes = [], []
    for name, mark in pose.activation_marks.items():
        if name in names:
            continue
        near = nearest(name, free)
        if near is not None:
            warnings.append(f"{mark}: activation for {name!r}, which is not a muscle of this run; "
                            f"did you mean {near!r}? (the curve is ignored)")
        else:
            notes.append(f"{mark}: activation for {name!r}, which is not in this run; ignored")
    return warnings, notes


def sample_activation(pose, muscle_names, frames: np.ndarray) -> np.ndarray:
    """Activation (F, M) in [0, 1]; NaN where the pose has no curve for a muscle."""
    out = np.full((len(frames), len(muscle_names)), np.nan)
    for j, name in enumerate(muscle_names):
        if name in pose.activation:
            kf, kv = pose.activation[name]
            out[:, j] = np.clip(interpolate(frames, kf, kv, pose.interpolation), 0.0, 1.0)
    return out


def effective_tension(tension: float, activation: np.ndarray) -> np.ndarray:
    """Tension over frames: the muscle's ``tension`` is its tone at zero activation and
    activation drives it towards 1: ``e = tension + (1 - tension) a`` (a = 0 without a curve)."""
    a = np.nan_to_num(activation, nan=0.0)
    return tension + (1.0 - tension) * a


def parse_frames(spec, where: Mark, first: int, last: int) -> np.ndarray:
    """``0:48``, ``0:48:2``, ``3,7,10:12`` (ends inclusive, as in Blender), one frame number,
    or ``[first, last]`` (a range, as a pose's ``frames``) → sorted unique frames, all inside
    the pose's [first, last]."""
    allowed = "frames are like 0:48, 0:48:2 or 3,7,10:12 (ends inclusive), or [first, last]"
    if isinstance(spec, (list, tuple)):
        if len(spec) != 2 or not all(isinstance(x, int) and not isinstance(x, bool) for x in spec):
            raise InputError(where, f"frames is {list(spec)}",
                             "a list is [first, last], a range as in a pose's frames; "
                             "single frames are written as a string: '3,7,12'")
        parts = [f"{spec[0]}:{spec[1]}"]
    elif isinstance(spec, int) and not isinstance(spec, bool):
        parts = [str(spec)]
    elif isinstance(spec, str):
        parts = [p.strip() for p in spec.split(",")]
    else:
        raise InputError(where, f"frames is {spec!r}", allowed)
    out: list[int] = []
    for p in parts:
        try:
            bits = [int(b) for b in p.split(":")]
        except ValueError:
            raise InputError(where, f"bad frame range {p!r}", allowed) from None
        if len(bits) == 1:
            out.append(bits[0])
        elif len(bits) in (2, 3):
            step = bits[2] if len(bits) == 3 else 1
            if step <= 0 or bits[1] < bits[0]:
                raise InputError(where, f"bad frame range {p!r}", allowed + "; start <= end, step >= 1")
            if (bits[1] - bits[0]) // step > 10_000_000:
                raise InputError(where, f"frame range {p!r} is too long", "at most 10,000,000 frames")
            out.extend(range(bits[0], bits[1] + 1, step))
        else:
            raise InputError(where, f"bad frame range {p!r}", allowed)
    frames = np.unique(np.array(out, dtype=np.int64))
    if len(frames) == 0:
        raise InputError(where, "no frames selected", allowed)
    if frames[0] < first or frames[-1] > last:
        raise InputError(where, f"frames {frames[0]}..{frames[-1]} outside the pose's [{first}, {last}]",
                         f"frames within {first}..{last}")
    return frames


def hull_points(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of ``points`` (N, 3), in index order (or, for a flat or
    degenerate cloud, its extreme points along 26 directions): every linear function takes
    its maximum over ``points`` on one of them."""
    from scipy.spatial import ConvexHull, QhullError

    points = np.asarray(points, dtype=np.float64)
    if len(points) <= 4:
        return points
    try:
        return points[np.sort(ConvexHull(points).vertices)]
    except (QhullError, ValueError):
        d = np.array([[i, j, k] for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1) if i or j or k], float)
        return points[np.unique(np.argmax(points @ d.T, axis=0))]


def subject_points(pose, bone_vertices: dict, joints: bool = True) -> np.ndarray:
    """Points (N, 3) whose convex hull holds the subject over *every* frame of the pose: each
    bone's points (``bone_vertices``: bone index -> (V, 3) bone-local points: its mesh, or
    the muscles it carries) and, with ``joints``, its joint and the joints at both ends of
    every stick (:meth:`Skeleton.stick_parents`; a mesh-less root such as a floating base's
    world origin is no part of the subject), posed by forward kinematics (batched over
    frames), grown by FRAMING_PAD (at most a share of the extent) each way. What a camera
    frames: it depends on the points and the whole pose, never on which frames are written."""
    from axdf_cli.model.skeleton import forward_kinematics

    skel = pose.skeleton
    with_joints = joints
    joints = set(bone_vertices)
    for b, p in enumerate(skel.stick_parents()):
        if p >= 0:
            joints |= {b, p}
    joints = (joints or set(range(len(skel.bones)))) if with_joints else set()
    origin = np.zeros((1, 3))
    empty = np.zeros((0, 3))
    dirs = sphere_directions(FRAMING_DIRECTIONS)

    def extremes(v):
        v = np.asarray(v, dtype=np.float64)
        return v[np.unique(np.argmax(v @ dirs.T, axis=0))] if len(v) else empty

    local = [np.concatenate([extremes(bone_vertices[b]) if b in bone_vertices else empty,
                             origin if b in joints else empty]) for b in range(len(skel.bones))]
    keep = np.zeros((0, 3))
    frames = pose.frames
    for s in range(0, len(frames), FRAMING_CHUNK):
        world = forward_kinematics(skel, sample_coordinates(pose, frames[s:s + FRAMING_CHUNK]))  # (C, B, 4, 4)
        # x[c, p] = R_b[c] @ local_b[p] + t_b[c], bone by bone
        posed = [(pts @ world[:, b, :3, :3].transpose(0, 2, 1) + world[:, b, None, :3, 3]).reshape(-1, 3)
                 for b, pts in enumerate(local)]
        keep = hull_points(np.concatenate([keep] + posed))
    extent = float(np.max(keep.max(axis=0) - keep.min(axis=0)))
    pad = max(min(FRAMING_PAD, FRAMING_PAD_FRACTION * extent), 1e-3 * FRAMING_PAD)
    cube = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float) * pad
    return hull_points((keep[:, None, :] + cube[None]).reshape(-1, 3))
