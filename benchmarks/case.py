"""The in-memory case the evaluation, writer and packed rows time: muscles, skeleton and a
pose sampled over the bench's frames (the gait2392 walk when shipped, else demo muscles
replicated and perturbed under a synthetic pose), and arm26's wrapping case."""
from __future__ import annotations

import dataclasses

import numpy as np

from axdf_cli.model.muscle import MuscleModel, MuscleSpec
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.specs import Pose, expand_muscle_paths, load_muscle_file, load_pose
from benchmarks.common import ARM_MUSCLES, ARM_POSE, DEMO_MUSCLES, DEMO_POSE, GAIT_MUSCLES, GAIT_POSE


@dataclasses.dataclass
class Case:
    """Muscles, skeleton and a pose sampled over ``n_frames`` frames, in memory."""

    name: str  # 'gait2392' or 'synthetic'
    specs: list  # [MuscleSpec]
    skeleton: object
    rest: np.ndarray  # (B, 4, 4) rest world transforms
    world: np.ndarray  # (F, B, 4, 4)
    tension: np.ndarray  # (F, M) effective tension of each spec
    coords: np.ndarray | None = None  # (F, C) skeleton coordinates (moving / conditional path points)

    def models(self, n_muscles: int, resolution: tuple[int, int]) -> list[MuscleModel]:
        specs = [self.specs[i % len(self.specs)] for i in range(n_muscles)]
        return [MuscleModel(dataclasses.replace(s, resolution=tuple(resolution)), self.skeleton.bone_index, self.rest,
                            self.skeleton) for s in specs]


def stretched_pose(pose: Pose, n_frames: int) -> Pose:
    """The pose's keys spread over frames 0 .. n_frames - 1 (same motion, finer in time)."""
    span = max(pose.last - pose.first, 1)
    scale = (n_frames - 1) / span

    def stretch(curves):
        return {k: (tuple((f - pose.first) * scale for f in fr), vals) for k, (fr, vals) in curves.items()}

    return dataclasses.replace(pose, first=0, last=n_frames - 1, keys=stretch(pose.keys),
                               activation=stretch(pose.activation))


def synthetic_pose(skeleton, n_frames: int) -> Pose:
    """A smooth in-memory pose: every rotational coordinate swings within its range."""
    keys = {}
    kf = np.linspace(0, n_frames - 1, max(2, n_frames // 10))
    for i, c in enumerate(skeleton.coordinates):
        if c.type != "rotation":
            continue
        lo, hi = c.range if c.range is not None else (-30.0, 30.0)
        mid, amp = 0.5 * (lo + hi), 0.4 * (hi - lo)
        vals = mid + amp * np.sin(2 * np.pi * kf / max(n_frames, 1) * (1 + i % 3) + i)
        keys[c.name] = (tuple(float(f) for f in kf), tuple(float(v) for v in vals))
    return Pose("synthetic", skeleton, 60.0, 0, n_frames - 1, "linear", keys, {}, {})


def perturbed(spec: MuscleSpec, k: int, rng: np.random.Generator) -> MuscleSpec:
    """A copy of ``spec`` (named ``<name>_<k>``) with axis points moved by up to 5 mm and
    sections scaled by 0.8 .. 1.2."""
    if k == 0:
        return spec
    axis = tuple(dataclasses.replace(p, at=tuple(float(x) for x in np.asarray(p.at) + rng.uniform(-0.005, 0.005, 3)))
                 for p in spec.axis)
    f = float(rng.uniform(0.8, 1.2))
    secs = tuple(dataclasses.replace(s, radii=None if s.radii is None else (s.radii[0] * f, s.radii[1] * f),
                                     outline=None if s.outline is None else tuple((a * f, b * f) for a, b in s.outline))
                 for s in spec.sections)
    return dataclasses.replace(spec, name=f"{spec.name}_{k}", axis=axis, sections=secs)


def load_case(n_frames: int = 1000, n_muscles: int = 92, prefer_gait: bool = True) -> Case:
    """gait2392 muscles and walk (stretched to ``n_frames``) when shipped, else synthetic."""
    if prefer_gait and GAIT_MUSCLES.is_dir() and GAIT_POSE.is_file():
        pose = load_pose(GAIT_POSE)
        specs = [s for f in expand_muscle_paths([(GAIT_MUSCLES, None)]) for s in load_muscle_file(f)]
        name = "gait2392"
        pose = stretched_pose(pose, n_frames)
    else:
        demo = load_pose(DEMO_POSE)
        base = [s for f in expand_muscle_paths([(DEMO_MUSCLES, None)]) for s in load_muscle_file(f)]
        rng = np.random.default_rng(7)
        specs = [perturbed(base[i % len(base)], i // len(base), rng) for i in range(n_muscles)]
        name = "synthetic"
        pose = synthetic_pose(demo.skeleton, n_frames)
    specs = specs[:n_muscles]
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    frames = np.arange(pose.first, pose.last + 1)
    q = sample_coordinates(pose, frames)
    world = forward_kinematics(skel, q)
    act = sample_activation(pose, [s.name for s in specs], frames)
    tension = np.stack([effective_tension(s.tension, act[:, j]) for j, s in enumerate(specs)], axis=1)
    return Case(name, specs, skel, rest, world, tension, q)


def load_wrap_case(n_frames: int, wraps: bool = True) -> Case | None:
    """arm26's muscles (4 of 6 wrap over cylinders and ellipsoids) over its elbow flexion,
    stretched to ``n_frames``; with ``wraps=False`` the same paths without wrap surfaces."""
    if not (ARM_MUSCLES.is_dir() and ARM_POSE.is_file()):
        return None
    pose = stretched_pose(load_pose(ARM_POSE), n_frames)
    specs = [s for f in expand_muscle_paths([(ARM_MUSCLES, None)]) for s in load_muscle_file(f)]
    if not wraps:
        specs = [dataclasses.replace(s, path=dataclasses.replace(s.path, wraps=())) for s in specs]
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    q = sample_coordinates(pose, np.arange(pose.first, pose.last + 1))
    return Case("arm26", specs, skel, rest, forward_kinematics(skel, q), np.zeros((len(q), len(specs))), q)

