"""The compiled pass over every muscle of a chunk (axdf_cli/model/batch.py, batch_kernels.py,
batch_surface.py) against the numpy formulation of step 1b (tests/reference_model.py).

The compiled arithmetic follows numpy's operation for operation, so with the arc length summed
in order in both, every float64 of every output is the same bit for bit. Summed with ``@``
instead (OpenBLAS's dot, whose order changes with the number of frames: a frame's length can
differ in its last bit with the chunk it is evaluated in), against that
the difference is the length's last bits and what they move (a few 1e-16 m), and the packed
outputs' float32 bytes are the same but for a handful of values one float32 step apart.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import reference_model
from axdf_cli.model.batch import MuscleBatch
from axdf_cli.model.muscle import FrameResult, MuscleModel
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics

REPO = Path(__file__).resolve().parent.parent
FIELDS = ("vertices", "normals", "length", "volume", "scale", "twist", "tension")


def _case(job: str, step: int):
    """A shipped job's plan, every ``step``-th frame: (plan, world, coords, tension (F, M))."""
    from axdf_cli.pipeline import plan_run
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(REPO / "poses" / "jobs" / job), out_arg=str(REPO / "out" / "unused"))
    frames = plan.frames[::step]
    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    act = sample_activation(plan.pose, plan.names, frames)
    tension = np.stack([effective_tension(s.tension, act[:, j]) for j, s in enumerate(plan.muscles)], axis=1)
    return plan, world, q, tension


def _results(batch, *args, **kw) -> dict:
    """MuscleBatch.surfaces as FrameResults."""
    return {j: FrameResult(**f) for j, f in batch.surfaces(*args, **kw).items()}


def _same_bits(a, b, name):
    for k in FIELDS:
        x, y = np.asarray(getattr(a, k)), np.asarray(getattr(b, k))
        assert x.shape == y.shape, (name, k)
        assert x.tobytes() == y.tobytes(), (name, k, float(np.max(np.abs(x - y))))


@pytest.mark.parametrize("job, step", [("demo.yaml", 3), ("arm26_flex.yaml", 2), ("gait2392_walk.yaml", 6),
                                       ("myoarm_elbow.yaml", 5)])
def test_every_muscle_at_once_is_numpys_step_1b_bit_for_bit(job, step):
    """All muscles in one compiled pass (the run's path) = the numpy formulation, muscle by
    muscle, every float64 equal (demo: fixed axes, every volume mode and tension; arm26:
    paths over wrap cylinders and ellipsoids; gait2392: 92 path muscles)."""
    plan, world, q, tension = _case(job, step)
    batch = MuscleBatch(plan.models)
    every = range(len(plan.models))
    p, _ = batch.axis_points(world, q, every)
    got = _results(batch, world, p, tension, None, every)
    for j, m in enumerate(plan.models):
        want = reference_model.reference_step_1b(m, world, p[:, batch.a_off[j]:batch.a_off[j + 1]], tension[:, j],
                                                 blas=False)
        _same_bits(got[j], want, m.spec.name)


@pytest.mark.parametrize("volume", ["exact", "paper", "none"])
def test_one_muscle_alone_with_twist_references_and_volume_modes(demo, volume):
    """MuscleModel.surface (a batch of one) with a twist reference, a rest-volume target and
    tension beyond [0, 1] = the numpy formulation bit for bit."""
    frames = demo.pose.frames[::5]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    tension = np.linspace(-0.5, 1.5, len(frames))
    ref = np.linspace(-7.0, 7.0, len(frames))  # branches up to a turn away
    for spec in demo.specs:
        model = MuscleModel(dataclasses.replace(spec, volume=volume), demo.skel.bone_index, demo.rest)
        p = model._axis_points(world)
        for kw in ({}, {"rest_volume": 1.1 * model.v0}, {"rest_volume": None}):
            got = model.surface(world, p, tension, ref, **kw)
            want = reference_model.reference_step_1b(model, world, p, tension, ref, blas=False, **kw)
            _same_bits(got, want, spec.name)


def test_against_the_numpy_code_as_it_was_the_difference_is_the_arc_length_sum():
    """With numpy's BLAS sum of the arc length (whose order changes with the number of frames):
    lengths within 2e-15 relative, vertices within 2e-15 m, normals 1e-10, volumes 1e-15
    relative, over the walk as imported."""
    plan, world, q, tension = _case("gait2392_walk.yaml", 4)
    batch = MuscleBatch(plan.models)
    every = range(len(plan.models))
    p, _ = batch.axis_points(world, q, every)
    got = _results(batch, world, p, tension, None, every)
    for j, m in enumerate(plan.models):
        want = reference_model.reference_step_1b(m, world, p[:, batch.a_off[j]:batch.a_off[j + 1]], tension[:, j])
        a = got[j]
        np.testing.assert_allclose(a.length, want.length, rtol=2e-15, atol=0)
        np.testing.assert_allclose(a.vertices, want.vertices, rtol=0, atol=2e-15)
        np.testing.assert_allclose(a.normals, want.normals, rtol=0, atol=1e-10)
        np.testing.assert_allclose(a.volume, want.volume, rtol=1e-15, atol=0)
        np.testing.assert_array_equal(a.twist, want.twist)


def test_packing_subsets_and_chunks_do_not_change_a_muscle():
    """A muscle's bytes do not depend on which muscles share its pass, in what order, nor on how
    many frames (the arc length is summed in order: one frame alone = the same frame in a
    block)."""
    plan, world, q, tension = _case("arm26_flex.yaml", 5)
    batch = MuscleBatch(plan.models)
    every = list(range(len(plan.models)))
    p, _ = batch.axis_points(world, q, every)
    full = _results(batch, world, p, tension, None, every)
    some = [4, 1]
    sub = _results(batch, world, p, tension[:, some], None, some)
    for j in some:
        _same_bits(sub[j], full[j], plan.names[j])
    ref = np.stack([full[j].twist for j in every], axis=1)  # the unwrapped roll, as a reference
    for f in (0, 3, len(world) - 1):
        one = _results(batch, world[f:f + 1], p[f:f + 1], tension[f:f + 1], np.radians(ref[f:f + 1]), every)
        for j in every:
            for k in FIELDS:
                assert np.asarray(getattr(one[j], k))[0].tobytes() == np.asarray(getattr(full[j], k))[f].tobytes(), \
                    (plan.names[j], k, f)


def test_results_are_contiguous_per_muscle_and_independent():
    """Each result's vertices and normals are a C-contiguous (F, V, 3) block of their own."""
    plan, world, q, tension = _case("demo.yaml", 16)
    batch = MuscleBatch(plan.models)
    every = range(len(plan.models))
    p, _ = batch.axis_points(world, q, every)
    res = _results(batch, world, p, tension, None, every)
    for j, m in enumerate(plan.models):
        v = res[j].vertices
        assert v.shape == (len(world), m.n_vertices, 3) and v.flags.c_contiguous and res[j].normals.flags.c_contiguous
    before = res[1].vertices.copy()
    res[0].vertices[:] = 0.0
    np.testing.assert_array_equal(res[1].vertices, before)


def test_coarse_roll_is_the_reference_roll():
    """The twist references' coarse roll (one compiled call for every muscle) = the numpy
    roll on the coarse samples, bit for bit."""
    plan, world, q, _ = _case("arm26_flex.yaml", 3)
    batch = MuscleBatch(plan.models)
    every = range(len(plan.models))
    p, _ = batch.axis_points(world, q, every)
    got = batch.coarse_roll(world, p, every)
    for j, m in enumerate(plan.models):
        pj = p[:, batch.a_off[j]:batch.a_off[j + 1]]
        _, t, r = reference_model.axis_frames(m, world, pj, coarse=True)
        want = reference_model.roll(m, world, t[:, -1], r[:, -1])
        assert got[:, j].tobytes() == want.tobytes(), m.spec.name


@pytest.mark.parametrize("job", ["demo.yaml", "arm26_flex.yaml", "gait2392_walk.yaml", "myoarm_elbow.yaml"])
def test_axis_points_are_the_models(job):
    """The packed axis points (one compiled call for the fixed muscles, one for the paths:
    moving and conditional points, wrap cylinders and ellipsoids, MuJoCo's sphere and cylinder
    wrapping with side points) = each model's axis_points,
    bit for bit, with the same could-not-wrap warnings."""
    plan, world, q, _ = _case(job, 3)
    batch = MuscleBatch(plan.models)
    p, notes = batch.axis_points(world, q, range(len(plan.models)))
    for j, m in enumerate(plan.models):
        want, w = m.axis_points(world, q)
        assert p[:, batch.a_off[j]:batch.a_off[j + 1]].tobytes() == np.ascontiguousarray(want).tobytes()
        assert notes[j] == w


def test_buffers_are_reused_only_once_no_result_refers_to_them():
    """A chunk's outputs go into memory the batch hands out again, but never while a result
    of an earlier call is alive: results kept across calls keep their values."""
    plan, world, q, tension = _case("demo.yaml", 12)
    batch = MuscleBatch(plan.models)
    every = list(range(len(plan.models)))
    p, _ = batch.axis_points(world, q, every)
    a = _results(batch, world[:3], p[:3], tension[:3], None, every)
    kept = {j: r.vertices.copy() for j, r in a.items()}
    for _ in range(2 * len(batch.pool.buffers) + 2):  # more calls than the pool holds buffers
        b = _results(batch, world[3:6], p[3:6], tension[3:6], None, every)
        assert not np.shares_memory(b[0].vertices, a[0].vertices)
    for j, r in a.items():
        np.testing.assert_array_equal(r.vertices, kept[j])
    base = b[0].vertices.base
    del a, b, r
    c = _results(batch, world[:3], p[:3], tension[:3], None, every)
    assert any(np.shares_memory(c[0].vertices, buf) for buf in batch.pool.buffers)  # reused once free
    assert base is not None


def test_what_is_written_is_the_numpy_formulation():
    """kernels.written (one compiled pass: float32, non-finite frames to the rest shape, each
    frame's bounds) = astype(float32), isfinite, replacement and min/max in numpy, including
    NaN, inf and a float64 too large for float32 in some frames."""
    from axdf_cli.model import kernels

    rng = np.random.default_rng(3)
    f, v = 7, 53
    verts = rng.normal(size=(f, v, 3)) * 0.1
    norms = rng.normal(size=(f, v, 3))
    verts[1, 5, 2] = np.nan
    norms[3, 0, 0] = np.inf
    verts[4, 9, 1] = 1e39  # finite in float64, inf in float32
    verts[6, 2, 0] = -0.0
    rest_v = rng.normal(size=(v, 3)).astype(np.float32)
    rest_n = rng.normal(size=(v, 3)).astype(np.float32)
    pos, nrm = np.empty((f, v, 3), np.float32), np.empty((f, v, 3), np.float32)
    box, bad = np.empty((f, 2, 3), np.float32), np.empty(f, np.bool_)
    kernels.written(verts, norms, rest_v, rest_n, pos, nrm, box, bad)
    with np.errstate(over="ignore"):
        want_p, want_n = verts.astype(np.float32), norms.astype(np.float32)
    want_bad = ~(np.isfinite(want_p).all(axis=(1, 2)) & np.isfinite(want_n).all(axis=(1, 2)))
    want_p[want_bad], want_n[want_bad] = rest_v, rest_n
    np.testing.assert_array_equal(bad, want_bad)
    assert list(np.nonzero(bad)[0]) == [1, 3, 4]
    assert pos.tobytes() == want_p.tobytes() and nrm.tobytes() == want_n.tobytes()
    np.testing.assert_array_equal(box[:, 0], want_p.min(axis=1))
    np.testing.assert_array_equal(box[:, 1], want_p.max(axis=1))
