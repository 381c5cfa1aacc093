"""One rule for how many axis control points an imported path muscle gets (``axdf import osim``
and ``axdf import mjcf``: importers/emit.py ``axis_points_for``): the default count unless the
axis length is more than AXIS_SHORTFALL_MAX off the wrapped path's in some measured pose, then
the first count of one schedule that keeps it within. The measure is PathModel.shortfall
(checked here against a dense polyline of the axis); the poses are the importer's choice."""
from __future__ import annotations

import numpy as np
import pytest

from axdf_cli import tolerances as tol
from axdf_cli.importers import emit

BENT = """skeleton: bent
coordinates:
  knee: {type: rotation, range: [0, 150]}
bones:
  - {name: ground}
  - {name: thigh, parent: ground, offset: [0, 0, 1]}
  - name: shank
    parent: thigh
    offset: [0, 0, -0.4]
    dofs: [{coord: knee, type: rotation, axis: [0, 1, 0]}]
"""
#: A hamstring-like path: down the thigh, a hook 6 mm behind the knee, down the shank. Flexed to
#: 150 degrees it turns sharply at the hook, which a smooth axis cuts.
PATH = [{"bone": "thigh", "at": [-0.03, 0.0, -0.1]}, {"bone": "shank", "at": [-0.006, 0.0, -0.006]},
        {"bone": "shank", "at": [-0.02, 0.0, -0.12]}]


@pytest.fixture(scope="module")
def bent():
    from axdf_cli.specs import parse_skeleton_text

    skel = parse_skeleton_text(BENT, "bent.yaml")
    q = np.linspace(0.0, 150.0, 31)[:, None]  # the rest pose first, then flexion to 150 degrees
    return skel, q


def test_one_schedule_for_both_importers():
    assert emit.axis_point_counts(12) == [16, 20, 24, 28, 32, 36, 40, 44, 48, 64, 80, 96, 112, 128]
    assert emit.axis_point_counts(48) == [64, 80, 96, 112, 128]
    assert emit.axis_point_counts(20)[:8] == [24, 28, 32, 36, 40, 44, 48, 64]


def _errors(skel, q, n: int) -> tuple[float, float]:
    """(largest |PathModel.shortfall|, the same from a 20000-segment polyline of the axis)."""
    import dataclasses

    from axdf_cli.fileio.yamlio import Fields
    from axdf_cli.errors import Mark
    from axdf_cli.model import bspline
    from axdf_cli.model.paths.path import PathModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import parse_muscle_path

    spec = parse_muscle_path(Fields({"path": PATH}, Mark("<t>"), "muscle"))
    pm = PathModel(dataclasses.replace(spec, control_points=n), skel.bone_index, skel.coord_index)
    world = forward_kinematics(skel, q)
    samples, length, _ = pm.wrapped(world, q)
    ctrl = np.einsum("nk,fkc->fnc", pm.fit, samples)
    basis = bspline.basis_matrix(bspline.clamped_knots(n, 2), 2, np.linspace(0.0, 1.0, 20001))
    # axis[f,s,c] = sum_n basis[s,n] ctrl[f,n,c]
    axis = np.einsum("sn,fnc->fsc", basis, ctrl)
    polyline = np.linalg.norm(np.diff(axis, axis=1), axis=2).sum(axis=1)
    return float(np.abs(pm.shortfall(world, q)).max()), float(np.abs(1.0 - polyline / length).max())


def test_the_fewest_points_that_keep_the_axis_within(bent):
    skel, q = bent
    got = emit.axis_points_for("hook", PATH, [], skel, q)
    assert got.default == 12 and got.raised
    assert got.error_default > tol.AXIS_SHORTFALL_MAX >= got.error
    counts = emit.axis_point_counts(got.default)
    before = counts[counts.index(got.n) - 1] if counts.index(got.n) else got.default
    assert _errors(skel, q, before)[0] > tol.AXIS_SHORTFALL_MAX  # the count before it does not do
    e, poly = _errors(skel, q, got.n)
    assert e == pytest.approx(got.error, abs=1e-12)
    assert poly == pytest.approx(e, abs=1e-5)  # Gauss-Legendre and a fine polyline measure the same axis
    # at rest alone the path is straight enough: the default stays
    rest = emit.axis_points_for("hook", PATH, [], skel, q[:1])
    assert not rest.raised and rest.n == 12 and rest.error <= tol.AXIS_SHORTFALL_MAX


def test_both_importers_measure_with_the_one_rule(bent, tmp_path, monkeypatch):
    """import mjcf calls emit.axis_points_for once per muscle over the rest pose, its probe poses
    and the motion's frames; import osim (tests/test_rajagopal.py, test_osim_cli) over the rest
    pose and the motion's frames (emit.motion_poses)."""
    from test_outputs import ARM_XML, PARTS_XML

    import trimesh

    from axdf_cli.cli.main import main

    calls = []
    real = emit.axis_points_for

    def spy(name, path, wraps, skel, q):
        calls.append((name, q.shape))
        return real(name, path, wraps, skel, q)

    monkeypatch.setattr(emit, "axis_points_for", spy)
    (tmp_path / "arm.xml").write_text(ARM_XML)
    (tmp_path / "parts.xml").write_text(PARTS_XML)
    (tmp_path / "assets").mkdir()
    (tmp_path / "assets" / "upper.ply").write_bytes(trimesh.creation.box(extents=(0.04, 0.04, 0.3)).export(file_type="ply"))
    np.savez(tmp_path / "q.npz", qpos=np.radians([[0.0], [30.0], [60.0]]))
    assert main(["import", "mjcf", str(tmp_path / "arm.xml"), "--motion", str(tmp_path / "q.npz"), "--out",
                 str(tmp_path / "imp"), "-q"]) == 0
    assert calls == [("flexor", (1 + tol.AXIS_PROBE_POSES + 3, 1))]
    skel, _ = bent  # an OpenSim import's poses: the rest pose and at most AXIS_FIT_FRAMES of the motion's
    poses = emit.motion_poses(skel, np.full((5000, 1), 30.0))
    assert poses.shape == (1 + tol.AXIS_FIT_FRAMES, 1) and poses[0, 0] == 0.0 and np.all(poses[1:] == 30.0)
