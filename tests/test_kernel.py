"""The compiled surface stage (axdf_cli/model/kernels.py) against its numpy formulation
(tests/reference_surface.py): the same vertices, normals, volumes and scales."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from axdf_cli.model.pose import sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.model.muscle import MuscleModel
from reference_surface import reference_surface


@pytest.mark.parametrize("volume", ["exact", "paper", "none"])
def test_kernel_matches_the_numpy_reference(demo, monkeypatch, volume):
    frames = demo.pose.frames[::7]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    tension = np.linspace(0.0, 1.0, len(frames))
    for model in demo.models:
        model = MuscleModel(dataclasses.replace(model.spec, volume=volume), demo.skel.bone_index, demo.rest)
        calls = []
        orig = model._surface

        def spy(*args, orig=orig):
            out = orig(*args)
            calls.append((args, out))
            return out

        monkeypatch.setattr(model, "_surface", spy)
        model.evaluate(world, tension)
        monkeypatch.undo()
        (args, (v, n, vol, s, bad)), = calls
        rv, rn, rvol, rs, rbad = reference_surface(model, *args)
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
