"""The pieces of `axdf fit` (axdf_cli/tools/fit_sections.py, tools/fit.py) as functions: the
surface the rows are solved through is the muscle model's own rest surface, the solve recovers
a surface's rows exactly, the sections' parameters make the surface's row at u lie at axis
parameter u, the medial axis of a straight tube is its centre line from tip to tip, tendons
come from thin ends, and points bind to the nearest bone segment."""
from __future__ import annotations

import numpy as np
import pytest

from axdf_cli.model import bspline
from axdf_cli.model.muscle import OCT, AxisPoint, MuscleModel, MuscleSpec, Section
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.specs.skeleton import parse_skeleton_text
from axdf_cli.tools import fit_sections as fs
from axdf_cli.tools.fit import nearest_bones, tendon_fractions

SKELETON = """\
skeleton: leg
coordinates:
  knee: {type: rotation, range: [0, 150]}
bones:
  - name: femur
    offset: [0, 0, 1.0]
  - name: tibia
    parent: femur
    offset: [0.02, 0, -0.42]
    orient: [10, 0, 20]
    dofs:
      - {coord: knee, type: rotation, axis: [1, 0, 0]}
"""


@pytest.fixture(scope="module")
def leg():
    skel = parse_skeleton_text(SKELETON, "leg.yaml")
    return skel, forward_kinematics(skel, skel.rest_coordinates()[None])[0]


def _spec(n: int, seed: int = 3) -> MuscleSpec:
    rng = np.random.default_rng(seed)
    axis = (AxisPoint("femur", (0.0, 0.0, -0.05)), AxisPoint("femur", (0.03, 0.01, -0.2)),
            AxisPoint("femur", (0.02, -0.02, -0.38)), AxisPoint("tibia", (0.01, 0.0, -0.05)),
            AxisPoint("tibia", (0.0, 0.02, -0.2)))
    th = np.arange(OCT) * 2 * np.pi / OCT
    secs = []
    for t in fs.greville(n):
        o = np.stack([0.03 * np.cos(th), 0.015 * np.sin(th)], axis=1) * (1 + 0.2 * rng.random((OCT, 1)))
        secs.append(Section(float(t), None, 0.0, tuple(map(tuple, o + 0.004 * rng.standard_normal(2)))))
    return MuscleSpec("m", (1.0, 0.0, 0.0), axis, tuple(secs), resolution=(30, 16))


def _rows(model: MuscleModel, rest: np.ndarray, n: int) -> fs.RowFit:
    c, r, s, _ = model.rest_frames(rest, fs.greville(n))
    poles = np.array([model.rest_vertices[0], model.rest_vertices[-1]], dtype=np.float64)
    return fs.RowFit(c, r, s, poles)


def test_rows_surface_is_the_models_rest_surface(leg):
    skel, rest = leg
    spec = _spec(6)
    model = MuscleModel(spec, skel.bone_index, rest, skel)
    rows = _rows(model, rest, 6)
    xy = np.array([s.outline for s in spec.sections])
    U, A = spec.resolution
    u = np.repeat(np.linspace(0, 1, U)[1:-1], A)
    v = np.tile(np.arange(A) / A, U - 2)
    ours = rows.evaluate(xy, u, v)
    np.testing.assert_allclose(ours, model.rest_vertices[1:-1], atol=2e-6)


def test_solve_recovers_the_rows(leg):
    skel, rest = leg
    spec = _spec(9)
    model = MuscleModel(spec, skel.bone_index, rest, skel)
    rows = _rows(model, rest, 9)
    xy = np.array([s.outline for s in spec.sections])
    u = np.repeat((np.arange(60) + 0.5) / 60, 32)
    v = np.tile(np.arange(32) / 32, 60)
    target = rows.evaluate(xy, u, v)
    got = rows.solve([(u, v, target, 1.0, None)])
    # (the smoothing biases the solve a little; the surface is what is measured)
    assert np.abs(rows.evaluate(got, u, v) - target).max() < 2e-4
    np.testing.assert_allclose(got, xy, atol=2e-3)


def test_sections_at_greville_give_linear_precision():
    for n in (3, 8, 16):
        tau = np.concatenate([[0.0], fs.greville(n), [1.0]])
        assert np.all(np.diff(tau) > 0)
        u = np.linspace(0, 1, 101)
        B = bspline.basis_matrix(bspline.clamped_knots(n + 2, 2), 2, u)
        np.testing.assert_allclose(B @ tau, u, atol=1e-12)


def test_medial_axis_of_a_straight_tube():
    z = np.repeat(np.linspace(0.1, 0.4, 200), 40)
    th = np.tile(np.arange(40) * 2 * np.pi / 40, 200)
    pts = np.stack([0.2 + 0.02 * np.cos(th), -0.1 + 0.01 * np.sin(th), z], axis=1)
    ctrl = fs.medial_axis(pts)
    assert ctrl.shape == (fs.N_AXIS, 3)
    np.testing.assert_allclose(ctrl[:, :2], [[0.2, -0.1]] * fs.N_AXIS, atol=1e-6)
    assert sorted([ctrl[0, 2], ctrl[-1, 2]]) == pytest.approx([0.1, 0.4], abs=3e-3)


def test_tendons_from_thin_ends():
    arc = np.linspace(0.05, 0.95, 10)
    areas = np.array([0.01, 0.05, 0.5, 1, 1, 1, 0.8, 0.3, 0.05, 0.02])
    a0, a1 = tendon_fractions(areas, arc)
    assert a0 == pytest.approx(arc[1]) and a1 == pytest.approx(1 - arc[8])
    assert tendon_fractions(np.ones(10), arc) == (0.0, 0.0)


def test_points_bind_to_the_nearest_segment():
    seg = [("segments", np.array([[[0, 0, 1.0], [0, 0, 0.5]]])), ("segments", np.array([[[0, 0, 0.5], [0, 0, 0.0]]])),
           None]
    pts = np.array([[0.05, 0, 0.9], [0.05, 0, 0.3], [0.0, 0.1, 0.52]])
    assert nearest_bones(pts, seg).tolist() == [0, 1, 0]


def test_iou_of_small_muscles_is_measured_on_a_grid_of_their_size():
    """A 3.3 mm muscle against itself 0.001 mm off reads IoU ~1 (a 2 mm grid read 0.00), and a
    2.2 mm one against a copy of 0.87 of its volume reads ~0.87 (it read 1.00); a muscle of an
    ordinary size keeps the 2 mm grid."""
    import trimesh

    small = trimesh.creation.icosphere(4, 1.0)
    small.apply_scale([0.0033, 0.0015, 0.0015])
    m = fs.measure(small.vertices, small.faces, small.vertices + 1e-6, small.faces)
    assert m["iou"] > 0.97 and m["grid_mm"] < 0.1, m
    tiny = trimesh.creation.icosphere(4, 1.0)
    tiny.apply_scale([0.0022, 0.0011, 0.0011])
    less = tiny.vertices * 0.87 ** (1.0 / 3.0)
    m = fs.measure(tiny.vertices, tiny.faces, less, tiny.faces)
    assert m["volume_ratio"] == pytest.approx(0.87, abs=0.001)
    assert m["iou"] == pytest.approx(0.87, abs=0.02), m
    big = trimesh.creation.icosphere(3, 1.0)
    big.apply_scale([0.1, 0.02, 0.02])
    assert fs.measure(big.vertices, big.faces, big.vertices * 0.99, big.faces)["grid_mm"] == 2.0
