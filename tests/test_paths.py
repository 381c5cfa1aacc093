"""Muscle paths: wrap surfaces against closed-form geometry, continuity as wrapping engages,
a hand-written path muscle through the CLI, and bad path input (FILE:LINE:COL, exit 2)."""
from __future__ import annotations

import math
import re
import shutil

import numpy as np
import pytest

from axdf_cli.model.paths import wrap as W
from conftest import REPO_ROOT, run_main

POSITION = re.compile(r"^(?P<file>[^\s:]+\.yaml):(?P<line>\d+):(?P<col>\d+): ", re.M)


def _wrap_one(kind, prm, p1, p2, quadrant="all", method="hybrid"):
    arc = np.empty((W.ARC_SEGMENTS + 1, 3))
    ax, sg = W.QUADRANTS[quadrant]
    return W.wrap_line(kind, np.asarray(prm, float), ax, sg, W.METHODS[method], np.asarray(p1, float),
                       np.asarray(p2, float), arc, np.zeros(3), False), arc


def _planar_length(p1, p2, r):
    """Shortest path from p1 to p2 around a disc of radius r at the origin (both outside)."""
    a, b = np.linalg.norm(p1), np.linalg.norm(p2)
    ang = math.acos(np.dot(p1, p2) / (a * b)) - math.acos(r / a) - math.acos(r / b)
    return math.sqrt(a * a - r * r) + math.sqrt(b * b - r * r) + r * ang


@pytest.mark.parametrize("h", [0.0, 0.01, 0.02])
def test_sphere_and_cylinder_lengths_are_the_closed_form(h):
    r = 0.03
    p1, p2 = np.array([-0.1, h, 0.0]), np.array([0.08, h + 0.01, 0.0])
    want = _planar_length(p1, p2, r)
    (code, n, arc_len), arc = _wrap_one(W.SPHERE, [r, 0, 0], p1, p2)
    assert code in (W.WRAPPED, W.MANDATORY) and n == W.ARC_SEGMENTS + 1
    got = np.linalg.norm(arc[0] - p1) + arc_len + np.linalg.norm(p2 - arc[n - 1])
    assert got == pytest.approx(want, rel=1e-9)
    assert np.allclose(np.linalg.norm(arc, axis=1), r)  # on the surface
    (code, n, arc_len), arc = _wrap_one(W.CYLINDER, [r, 0.2, 0], p1, p2)  # axis Z, path in z = 0
    got = np.linalg.norm(arc[0] - p1) + arc_len + np.linalg.norm(p2 - arc[n - 1])
    assert got == pytest.approx(want, rel=1e-9)


def test_ellipsoid_of_equal_radii_is_the_sphere():
    r = 0.03
    p1, p2 = np.array([-0.1, 0.01, 0.003]), np.array([0.08, 0.02, -0.002])
    (code, n, arc_len), arc = _wrap_one(W.ELLIPSOID, [r, r, r], p1, p2)
    assert code == W.MANDATORY
    got = np.linalg.norm(arc[0] - p1) + arc_len + np.linalg.norm(p2 - arc[n - 1])
    assert got == pytest.approx(_planar_length(p1, p2, r), rel=2e-3)  # chords of the arc polyline


def test_inside_and_missing_segments():
    (code, _, _), _ = _wrap_one(W.SPHERE, [0.03, 0, 0], [0.01, 0, 0], [0.1, 0, 0])
    assert code == W.INSIDE
    (code, _, _), _ = _wrap_one(W.SPHERE, [0.03, 0, 0], [-0.1, 0.05, 0], [0.1, 0.05, 0])
    assert code == W.NO_WRAP
    # quadrant: the +y side only; a path below the sphere crossing it does not wrap over the top
    (code, n, _), arc = _wrap_one(W.CYLINDER, [0.03, 0.2, 0], [-0.1, -0.01, 0], [0.1, -0.01, 0], "+y")
    assert code in (W.MANDATORY, W.WRAPPED) and np.all(arc[:n, 1] >= -1e-9)


def _path_model(wraps):
    from axdf_cli.model.paths import PathPoint, PathSpec, WrapSurface
    from axdf_cli.model.paths.path import PathModel

    spec = PathSpec((PathPoint("a", (0.0, 0.0, 0.0)), PathPoint("b", (0.0, 0.0, 0.0))), tuple(wraps), 12)
    return PathModel(spec, {"a": 0, "b": 1, "g": 2}, None)


def test_wrapping_engages_without_a_pop():
    """A path swept across a sphere: samples, length and axis move continuously as the
    straight segment starts to touch the sphere and wraps."""
    from axdf_cli.model.paths import WrapSurface

    pm = _path_model([WrapSurface("ball", "g", "sphere", (0.03, 0.0, 0.0), at=(0.0, 0.0, 0.0))])
    hs = np.linspace(0.06, 0.002, 233)  # height of the straight segment over the centre
    world = np.tile(np.eye(4), (len(hs), 3, 1, 1))
    world[:, 0, :3, 3] = np.stack([np.full_like(hs, -0.1), hs, 0 * hs], 1)
    world[:, 1, :3, 3] = np.stack([np.full_like(hs, 0.1), hs, 0 * hs], 1)
    samples, length, inside = pm.wrapped(world, None)
    assert not inside.any()
    straight = 0.2
    assert np.allclose(length[hs >= 0.03], straight) and np.all(length[hs < 0.029] > straight)
    step = np.abs(np.diff(samples, axis=0)).max()
    dh = hs[0] - hs[1]
    assert step < 3 * dh  # no sample jumps by more than a few times the sweep step
    ctrl, _ = pm.control_points(world, None)
    assert np.abs(np.diff(ctrl, axis=0)).max() < 4 * dh


# ----------------------------------------------------------------------------- CLI

MUSCLE = """# a hand-written path muscle with a wrap surface at the elbow
muscle: elbow_wrapper
color: "#b03a2e"
path:
  - {bone: humerus_r, at: [0.0, -0.03, -0.12]}
  - {bone: humerus_r, at: [0.0, -0.025, -0.22]}
  - {bone: radius_r, at: [0.0, -0.02, -0.08]}
wrap:
  - {name: elbow, shape: cylinder, bone: humerus_r, radius: 0.02, length: 0.1, at: [0.0, 0.0, -0.29], orient: [0, 90, 0], quadrant: all, range: [2, 3]}
sections:
  - {t: 0.3, radii: [0.01, 0.01]}
  - {t: 0.6, radii: [0.012, 0.012]}
tendons: [0.1, 0.1]
resolution: [16, 8]
"""


@pytest.fixture
def project(tmp_path, monkeypatch):
    shutil.copytree(REPO_ROOT / "poses", tmp_path / "poses")
    (tmp_path / "m.yaml").write_text(MUSCLE)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_hand_written_path_muscle_runs(project, capsys):
    rc, out, err = run_main(["run", "--muscles", "m.yaml", "--pose", "poses/demo.yaml", "--out", "out",
                             "--no-render", "--frames", "0:40:4"], capsys)
    assert rc == 0, err
    rows = (project / "out" / "stats.csv").read_text().splitlines()
    assert len(rows) > 5


BAD = {
    "radius": ("radius: 0.02", "radius: -0.02", "radius"),
    "quadrant": ("quadrant: all", "quadrant: +w", "quadrant"),
    "range": ("range: [2, 3]", "range: [2, 9]", "range"),
    "coordinate": ("{bone: humerus_r, at: [0.0, -0.025, -0.22]}",
                   "{bone: humerus_r, at: [0.0, -0.025, -0.22], active: {coord: elbow_x, range: [0, 90]}}", "elbow_x"),
    "shape": ("shape: cylinder", "shape: cone", "shape"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_path_input(project, capsys, case):
    old, new, words = BAD[case]
    text = MUSCLE.replace(old, new)
    (project / "m.yaml").write_text(text)
    line = text[:text.index(new)].count("\n") + 1
    rc, out, err = run_main(["run", "--muscles", "m.yaml", "--pose", "poses/demo.yaml", "--out", "out"], capsys)
    assert rc == 2, err
    assert "Traceback" not in err
    m = POSITION.search(err)
    assert m and m["file"].endswith("m.yaml") and int(m["line"]) == line, err
    assert words in err
    assert not (project / "out").exists()
