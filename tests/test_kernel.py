"""The compiled surface (tests/surface_kernel.py, on axdf_cli/model/kernels.py's kernels) against
its numpy formulation (tests/reference_surface.py): the same vertices, normals, volumes and scales."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from axdf_cli.model.pose import sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.model.muscle import MuscleModel
import reference_model
import surface_kernel
from reference_surface import reference_surface


@pytest.mark.parametrize("volume", ["exact", "paper", "none"])
def test_kernel_matches_the_numpy_reference(demo, volume):
    """surface_stage on the bound control points of the demo's muscles over its pose (as
    tests/reference_model.py forms them, the old numpy step 1b) against reference_surface."""
    frames = demo.pose.frames[::7]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    tension = np.linspace(0.0, 1.0, len(frames))
    for model in demo.models:
        model = MuscleModel(dataclasses.replace(model.spec, volume=volume), demo.skel.bone_index, demo.rest)
        calls = []
        real = surface_kernel.surface_stage

        def spy(*args):
            calls.append(args)
            return real(*args)

        p = model._axis_points(world)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(reference_model.surface_kernel, "surface_stage", spy)
            reference_model.reference_step_1b(model, world, p, tension)
        (args,) = calls
        fixed, scaled, pole0, pole1, end0, end1 = args[:6]
        exact, v0, s0 = args[10], args[11], args[12]
        target = v0 if exact else None
        v, n, vol, s, bad = args[17:22]
        ends = np.stack([-end0, end1], axis=1)  # (F, 2, 3): the tangents at t = 0 and 1
        rv, rn, rvol, rs, rbad = reference_surface(model, fixed, scaled, p, ends, s0, target)
        name = model.spec.name
        np.testing.assert_allclose(s, rs, rtol=1e-12, err_msg=name)
        np.testing.assert_array_equal(bad, rbad)
        np.testing.assert_allclose(v, rv, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(n, rn, rtol=0, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(vol, rvol, rtol=1e-10, err_msg=name)


def test_kernel_is_deterministic(demo):
    frames = demo.pose.frames[::5]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    for model in demo.models:
        a = model.evaluate(world, np.full(len(frames), 0.5))
        b = model.evaluate(world, np.full(len(frames), 0.5))
        assert a.vertices.tobytes() == b.vertices.tobytes() and a.normals.tobytes() == b.normals.tobytes()
