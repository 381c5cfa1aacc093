"""Jiggle's start and bound (axdf_cli/model/jiggle.py, axdf_cli/pipeline/jiggle_stage.py):
a motion already moving at its first frame starts as after a long pre-roll at that
velocity (no start-up transient), through the stage and through ``axdf run``."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from axdf_cli.formats import FORMATS
from axdf_cli.model import jiggle
from axdf_cli.pipeline.jiggle_stage import JiggleStage
from axdf_cli.pipeline.stages import Chunk
from conftest import run_main, write_pose

FPS = 60.0
N_AXIS = 6


def _plan(spec: jiggle.JiggleSpec, n_axis: int = N_AXIS, fps: float = FPS):
    """What the stage reads of a run's plan: one jiggling muscle of ``n_axis`` control points."""
    muscle = SimpleNamespace(jiggle=spec, tension=0.0)
    return SimpleNamespace(muscles=[muscle], models=[SimpleNamespace(n_axis=n_axis)],
                           pose=SimpleNamespace(first=0, fps=fps))


def _stage_output(spec, targets: np.ndarray, fps: float = FPS) -> np.ndarray:
    """The stage's axis (F, n, 3) for targets (F, n, 3), all frames in one chunk."""
    stage = JiggleStage()
    plan = _plan(spec, targets.shape[1], fps)
    f = len(targets)
    chunk = Chunk(slice(0, f), np.arange(f), np.zeros((f, 0)), np.zeros((f, 0, 4, 4)), np.full((f, 1), np.nan),
                  [0], {0: targets.copy()})
    _, out = stage(stage.start(plan), chunk)
    return out.axis[0]


def _moving_targets(frames: int = 90, fps: float = FPS) -> np.ndarray:
    """A muscle's axis targets (F, n, 3), already moving fast at frame 0: a translation at
    1.5 m/s plus a sway and a bend (about a metre off the origin, 0.4 m long)."""
    t = np.arange(frames)[:, None, None] / fps
    u = np.linspace(0.0, 1.0, N_AXIS)[None, :, None]
    base = np.array([0.3, -0.2, 1.0]) + u * np.array([0.0, 0.05, -0.4])
    sway = np.array([0.0, 1.0, 0.0]) * 0.04 * np.sin(2 * np.pi * 1.7 * t + 0.5) * np.sin(np.pi * u)
    bend = np.array([0.0, 0.0, 1.0]) * 0.03 * u * np.cos(2 * np.pi * 0.9 * t)
    return base + np.array([1.5, 0.2, 0.0]) * t + sway + bend


def _long_preroll(spec, targets: np.ndarray, n: int, fps: float = FPS) -> np.ndarray:
    """The law itself (``jiggle.oscillate``), started at rest ``n`` frames before the motion on
    targets extrapolated back at the first step's constant velocity: the written axis on
    the motion's frames (F, n_axis, 3)."""
    h = 1.0 / fps
    step = targets[1] - targets[0]
    before = targets[0] - np.arange(n, 0, -1)[:, None, None] * step  # frames -n .. -1
    path = np.concatenate([before, targets])
    omega, zeta = jiggle.parameters(spec, np.zeros(len(path) - 1))
    phi = jiggle.step_matrices(omega, zeta, h)[:, None].repeat(path.shape[1], axis=1)
    xs, _, _ = jiggle.oscillate(path[0].copy(), np.zeros_like(path[0]), path, phi, h)
    xs = np.concatenate([path[:1], xs])[n:]  # positions at the motion's frames
    w = jiggle.control_weights(spec.weight, path.shape[1])[None, :, None]
    return targets + w * (xs - targets)


def _length(targets: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(targets[0], axis=0), axis=-1).sum())


@pytest.mark.parametrize("hz,zeta", [(4.0, 0.15), (10.0, 0.2), (3.0, 1.0), (8.0, 2.5)])
def test_first_frames_equal_those_of_a_long_constant_velocity_preroll(hz, zeta):
    """Tolerance: 1e-9 of the muscle's length (the pre-roll is long enough that its own
    start, exp(-zeta omega t), has decayed far below it; what is left is rounding)."""
    spec = jiggle.JiggleSpec(hz, zeta)
    targets = _moving_targets()
    # a pre-roll long enough that its start has decayed by exp(-40) (the slow root when over-damped)
    slow = 2 * np.pi * hz * (zeta - np.sqrt(zeta * zeta - 1.0) if zeta > 1 else zeta)
    n = int(np.ceil(40.0 / slow * FPS))
    got = _stage_output(spec, targets)
    ref = _long_preroll(spec, targets, n)
    length = _length(targets)
    assert np.abs(got - ref).max() <= 1e-9 * length
    # and the motion does jiggle after its start (the comparison is not of two still axes)
    assert np.abs(got - targets).max() >= 1e-3 * length


def test_a_motion_at_constant_velocity_rides_on_its_target():
    """Constant velocity from the first frame: no offset at any frame (nothing changed the
    velocity), where a start at rest lags by about speed / omega."""
    spec = jiggle.JiggleSpec(4.0, 0.15)
    t = np.arange(40)[:, None, None] / FPS
    targets = np.linspace([0, 0, 1.0], [0, 0.05, 0.6], N_AXIS)[None] + np.array([1.2, 0.0, -0.3]) * t
    got = _stage_output(spec, targets)
    assert np.abs(got - targets).max() <= 1e-12


def test_steady_state_is_on_the_target_at_the_first_steps_velocity():
    t0 = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    t1 = t0 + np.array([[0.1, 0.0, 0.0], [0.0, -0.2, 0.0], [np.nan, 0.0, 0.0]])
    x, v = jiggle.steady_state(t0, t1, 0.1)
    assert np.array_equal(x, t0)
    assert np.allclose(v, [[1.0, 0, 0], [0, -2.0, 0], [0, 0, 0]])  # a non-finite step starts at rest
    x, v = jiggle.steady_state(t0, None, 0.1)  # a single frame: at rest
    assert np.array_equal(x, t0) and not v.any()


# ----------------------------------------------------------------------------- through axdf run

SLIDE = """\
skeleton: slide
coordinates:
  tx: {type: translation, default: 0, range: [-10, 10]}
  knee: {type: rotation, default: 0, range: [-10, 150]}
bones:
  - name: thigh
    dofs:
      - {coord: tx, type: translation, axis: [1, 0, 0]}
  - name: shank
    parent: thigh
    offset: [0, 0, -0.4]
    dofs:
      - {coord: knee, type: rotation, axis: [1, 0, 0]}
"""

MUSCLE = """\
muscle: calf
color: [0.8, 0.2, 0.2]
axis:
  - {bone: thigh, at: [0.02, 0.03, -0.12]}
  - {bone: thigh, at: [0.02, 0.06, -0.3]}
  - {bone: shank, at: [0.02, 0.06, -0.08]}
  - {bone: shank, at: [0.02, 0.03, -0.28]}
sections:
  - {t: 0.25, radii: [0.02, 0.015], angle: 0}
  - {t: 0.5, radii: [0.03, 0.022], angle: 0}
  - {t: 0.75, radii: [0.02, 0.015], angle: 0}
resolution: [21, 12]
jiggle: {frequency: 4, damping_ratio: 0.5}
"""

SPEED = 0.5 / 60  # m per frame at 60 fps: the subject walks in at 0.5 m/s
PRE = 150  # frames of pre-roll: 2.5 s, the start's transient decays by exp(-zeta omega t) = exp(-31)


def _vertices(out, frames) -> np.ndarray:
    read = FORMATS["ply"].reader
    return np.stack([read((out / "meshes" / "calf" / f"calf_{f:04d}.ply").read_bytes()).vertices
                     for f in frames]).astype(np.float64)


def test_a_run_already_moving_at_its_first_frame_equals_its_long_preroll(tmp_path, capsys):
    """A body that walks in (the root slides at constant speed from frame 0) and bends its knee
    at frames 12-30: the run's meshes equal those of the same motion with 2.5 s of walking
    in front (frames PRE.. of that run), within 1e-6 m (float32 meshes); before the knee
    moves they are the muscle's without jiggle."""
    (tmp_path / "slide.yaml").write_text(SLIDE)
    (tmp_path / "muscles").mkdir()
    (tmp_path / "muscles" / "calf.yaml").write_text(MUSCLE)
    keys = {0: (0.0, 0.0), 12: (12 * SPEED, 0.0), 30: (30 * SPEED, 60.0), 60: (60 * SPEED, 60.0)}
    write_pose(tmp_path, "walk", {f: {"tx": x, "knee": k} for f, (x, k) in keys.items()}, [0, 60],
               skeleton="slide.yaml", fps=60)
    pre = {0: {"tx": -PRE * SPEED, "knee": 0.0}, **{f + PRE: {"tx": x, "knee": k} for f, (x, k) in keys.items()}}
    write_pose(tmp_path, "longer", pre, [0, 60 + PRE], skeleton="slide.yaml", fps=60)
    outs = {}
    for name, pose, extra in (("walk", "walk", []), ("still", "walk", ["--no-jiggle"]),
                              ("longer", "longer", ["--frames", f"{PRE}:{PRE + 60}"])):
        rc, _, err = run_main(["run", "--muscles", tmp_path / "muscles", "--pose", tmp_path / f"{pose}.yaml",
                               "--out", tmp_path / name, "--no-render", "-q", *extra], capsys)
        assert rc == 0, err
        outs[name] = tmp_path / name
    walk = _vertices(outs["walk"], range(61))
    longer = _vertices(outs["longer"], range(PRE, PRE + 61))
    still = _vertices(outs["still"], range(61))
    assert np.abs(walk - longer).max() <= 1e-6
    assert np.abs(walk[:13] - still[:13]).max() <= 1e-6  # constant velocity: on its target
    assert np.abs(walk[13:] - still[13:]).max() >= 1e-3  # the bend rings


# ----------------------------------------------------------------------------- the bound

def _trial_axes(fast: float, bounded: bool = True):
    """The shipped gait2392 walk (its whole trial, from frame 0) on four of its jiggling
    muscles, played ``fast`` times as fast (the same frames at ``fast`` times the fps), through
    the run's own pre-pass: the targets and the written axes, {muscle: (F, n, 3)} each.
    ``bounded=False``: the same with the bound taken away (the reference)."""
    from dataclasses import replace
    from pathlib import Path

    from axdf_cli.pipeline import evaluate
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.stages import Scope, of_scope

    root = Path(__file__).resolve().parents[1]
    names = ("soleus_l", "per_tert_r", "vas_med_r", "med_gas_l")
    plan = plan_run(None, muscle_args=[root / "muscles" / "gait2392_packed" / f"{n}.yaml" for n in names],
                    pose_arg=root / "poses" / "gait2392_walk.yaml")
    plan = replace(plan, pose=replace(plan.pose, fps=plan.pose.fps * fast))
    stages = of_scope(plan.stages, Scope.TIME)
    state = tuple(s.start(plan) for s in stages)
    targets, written = {n: [] for n in names}, {n: [] for n in names}
    every = list(range(len(names)))
    original = jiggle.bounded
    if not bounded:
        jiggle.bounded = lambda offset, length: offset
    try:
        for b in range(-(-len(plan.pose.frames) // evaluate.TIME_BLOCK)):
            state, chunk = evaluate.time_block(plan, stages, state, b)
            raw = evaluate._chunk(plan, chunk.rows, chunk.frames, every)
            for j, n in enumerate(names):
                targets[n].append(raw.axis[j])
                written[n].append(chunk.axis[j])
    finally:
        jiggle.bounded = original
    return ({n: np.concatenate(v) for n, v in targets.items()}, {n: np.concatenate(v) for n, v in written.items()})


def _offset_over_length(targets, written) -> dict:
    return {n: np.linalg.norm(written[n] - targets[n], axis=-1).max(axis=-1) / jiggle.axis_length(targets[n])
            for n in targets}


def test_the_walk_played_10x_fast_stays_within_the_bound():
    """Played 10x fast, the walk's accelerations are 100x: unbounded, soleus_l's axis is
    thrown over twice its length off its target; bounded, no control point leaves the bound
    (a quarter of the length, to rounding) and no axis doubles its length."""
    from axdf_cli import tolerances as tol

    targets, written = _trial_axes(10.0)
    ratio = _offset_over_length(targets, written)
    worst = max(float(r.max()) for r in ratio.values())
    assert worst <= tol.JIGGLE_BOUND * (1 + 1e-9), worst  # (rounding: the written axis is target + offset)
    assert float(ratio["soleus_l"].max()) >= tol.JIGGLE_BOUND_KNEE * tol.JIGGLE_BOUND  # it bit
    for n in targets:
        assert (jiggle.axis_length(written[n]) / jiggle.axis_length(targets[n])).max() < 2.0


def test_the_bound_does_not_bite_on_the_walk_at_its_speed():
    """At its own speed the walk's written axes are those without the bound, to the bit: no
    control point of these muscles comes within the knee (75% of the bound) at any frame."""
    from axdf_cli import tolerances as tol

    targets, written = _trial_axes(1.0)
    ratio = _offset_over_length(targets, written)
    assert max(float(r.max()) for r in ratio.values()) < tol.JIGGLE_BOUND_KNEE * tol.JIGGLE_BOUND
    _, free = _trial_axes(1.0, bounded=False)
    assert all(np.array_equal(written[n], free[n]) for n in written)
