"""Seeded draws: poses, activations and cameras of one sequence.

Every random number comes from its own generator,
``np.random.default_rng(np.random.SeedSequence([seed, stream, sequence, frame, slot]))``,
where ``stream`` names the kind of draw (:data:`STREAM_POSE`, :data:`STREAM_ACTIVATION`,
:data:`STREAM_CAMERA`) and ``slot`` is the view (cameras), a stable number of the muscle's
name (activations) or 0 (poses). Nothing depends on the order in which sequences are made or
on how the work is split: any worker, shard or cluster node draws the same numbers.

Poses. A sampled sequence is a :class:`~axdf_cli.specs.Pose` (the type ``load_pose``
returns), never a file. ``uniform``: at each key frame every coordinate is drawn uniformly in
its range (the dataset file's ``coordinates:`` range, else the skeleton's; ``fixed`` ones are
held; coupled coordinates are not drawn: they follow theirs), and frames between keys are interpolated with PCHIP, which never leaves the span of
its keys, so every frame stays within range. ``perturb``: the base motion plus Gaussian
noise of the given spread (``default`` for every rotation; a translation only when named),
drawn at key frames and interpolated linearly, then clipped to the range (a coordinate
without any range is not clipped).
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import replace

import numpy as np

from axdf_cli.dataset.spec import DatasetSpec, Entry, Sequence
from axdf_cli.specs import Pose
from axdf_cli.model.pose import sample_coordinates

STREAM_POSE = 1
STREAM_ACTIVATION = 2
STREAM_CAMERA = 3


def rng_for(seed: int, stream: int, sequence: int, frame: int, slot: int = 0) -> np.random.Generator:
    """The generator of one draw (see the module docstring)."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), stream, int(sequence), int(frame), int(slot)]))


def name_slot(name: str) -> int:
    """A stable 32-bit number for a name (muscle activations draw in their own slot)."""
    return int(hashlib.sha256(name.encode()).hexdigest()[:8], 16)


def key_frames(frames: np.ndarray, keys: int | None) -> np.ndarray:
    """Key frames among ``frames`` (sorted): all of them, or ``keys`` spread evenly (ends included)."""
    frames = np.asarray(frames)
    if keys is None or keys >= len(frames):
        return frames.copy()
    pick = np.unique(np.rint(np.linspace(0, len(frames) - 1, keys)).astype(int))
    return frames[pick]


def coordinate_bounds(spec: DatasetSpec, skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per coordinate (skeleton order): lo (C,), hi (C,), whether it is held (C,) bool and its
    held value (C,). Without any range lo/hi are -inf/+inf. A coupled coordinate is held at
    its rest value here (it is never keyed: it follows its leader when the pose is sampled)."""
    n = len(skeleton.coordinates)
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    held, value = np.zeros(n, bool), skeleton.rest_coordinates()
    for i, c in enumerate(skeleton.coordinates):
        rule = spec.coordinates.get(c.name)
        if c.follows is not None:
            held[i] = True
            lo[i] = hi[i] = value[i]
        elif rule is not None and rule.fixed is not None:
            held[i], value[i] = True, rule.fixed
            lo[i] = hi[i] = rule.fixed
        elif rule is not None and rule.range is not None:
            lo[i], hi[i] = rule.range
        elif c.range is not None:
            lo[i], hi[i] = c.range
    return lo, hi, held, value


def sample_pose(spec: DatasetSpec, seq: Sequence, skeleton, base: Pose | None, frames: np.ndarray) -> Pose:
    """The pose of a sampled sequence (``uniform`` or ``perturb`` around ``base``)."""
    entry: Entry = spec.entries[seq.entry]
    lo, hi, held, value = coordinate_bounds(spec, skeleton)
    names = [c.name for c in skeleton.coordinates]
    kf = key_frames(frames, entry.keys)
    if entry.kind == "uniform":
        # q[k, c] = lo[c] + u[k, c] (hi[c] - lo[c]) at key frame k; held coordinates keep their value
        u = np.stack([rng_for(spec.seed, STREAM_POSE, seq.index, f).random(len(names)) for f in kf])
        q = np.where(held, value, lo + u * (hi - lo))
        keys = {c: (tuple(int(f) for f in kf), tuple(float(x) for x in q[:, i])) for i, c in enumerate(names)
                if skeleton.coordinates[i].follows is None}  # coupled coordinates follow their keyed leaders
        pose = Pose(seq.name, skeleton, spec.fps, int(frames[0]), int(frames[-1]),
                    "cubic" if len(kf) >= 3 else "linear", keys, {}, {}, "", skeleton.source)
    else:
        # "default" is for rotations (degrees); a translation (metres) moves only when named
        sd = np.array([entry.spread.get(c.name, entry.spread.get("default", 0.0) if c.type == "rotation" else 0.0)
                       for c in skeleton.coordinates])
        # noise[k, c] ~ N(0, sd[c]) at key frame k, linear in between, held beyond the ends
        noise = np.stack([rng_for(spec.seed, STREAM_POSE, seq.index, f).standard_normal(len(names)) for f in kf]) * sd
        every = base.frames
        q = sample_coordinates(base, every)
        if len(kf) == 1:
            q = q + noise[0]
        else:
            q = q + np.stack([np.interp(every, kf, noise[:, i]) for i in range(len(names))], axis=1)
        q = np.where(held, value, np.clip(q, lo, hi))
        fr = tuple(int(f) for f in every)
        keys = {c: (fr, tuple(float(x) for x in q[:, i])) for i, c in enumerate(names)
                if skeleton.coordinates[i].follows is None}
        pose = replace(base, name=seq.name, skeleton=skeleton, keys=keys, interpolation="linear",
                       activation_marks={})
    return pose


def with_activation(spec: DatasetSpec, seq: Sequence, pose: Pose, muscle_names: list[str],
                    frames: np.ndarray) -> Pose:
    """The pose with the data set's activation: the motion's own curves, none, or drawn
    uniformly per muscle at the sequence's key frames."""
    act = spec.activation
    if act.mode == "motion":
        return replace(pose, activation={m: c for m, c in pose.activation.items() if m in muscle_names})
    if act.mode == "none":
        return replace(pose, activation={})
    entry = spec.entries[seq.entry]
    kf = key_frames(frames, entry.keys)
    curves = {}
    for m in muscle_names:
        lo, hi = act.muscles.get(m, act.range)
        slot = name_slot(m)
        a = [lo + (hi - lo) * rng_for(spec.seed, STREAM_ACTIVATION, seq.index, f, slot).random() for f in kf]
        curves[m] = (tuple(int(f) for f in kf), tuple(float(x) for x in a))
    return replace(pose, activation=curves)


# ----------------------------------------------------------------------------- cameras


def sphere_direction(azimuth_deg: np.ndarray, elevation_deg: np.ndarray) -> np.ndarray:
    """(..., 3) unit vectors from the target towards the camera. Azimuth 0 is in front of the
    subject (camera on -Y, as view ``front``), 90 on +X (as view ``side``); elevation up from
    the horizontal plane."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    return np.stack([np.cos(e) * np.sin(a), -np.cos(e) * np.cos(a), np.sin(e)], axis=-1)


def sphere_draw(spec: DatasetSpec, seq: Sequence, frame: int, view: int) -> tuple[float, float, float]:
    """(azimuth, elevation, distance) of one view: azimuth and distance uniform in their ranges,
    elevation uniform in sin(elevation), i.e. uniform over the area of the spherical band."""
    s = spec.sphere
    u = rng_for(spec.seed, STREAM_CAMERA, seq.index, frame, view).random(3)
    az = s.azimuth[0] + u[0] * (s.azimuth[1] - s.azimuth[0])
    s0, s1 = math.sin(math.radians(s.elevation[0])), math.sin(math.radians(s.elevation[1]))
    el = math.degrees(math.asin(min(1.0, max(-1.0, s0 + u[1] * (s1 - s0)))))
    d = s.distance[0] + u[2] * (s.distance[1] - s.distance[0])
    return float(az), float(el), float(d)
