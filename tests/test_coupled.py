"""Coupled coordinates: a skeleton coordinate that `follows` another through
a function is computed, never keyed, wherever coordinates are made (rest pose, pose samples,
data-set draws); its bones move with its leader; bad files are refused at their position;
OpenSim's CoordinateCouplerConstraint imports as one (its scale factor, units and the
motion's column of it), judged by OpenSim; muscles on a FunctionBasedPath are listed, not
imported."""
from __future__ import annotations

import importlib.util
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from conftest import run_main
from osim_common import ARM, ARM_Q, needs_data, run_import

SKELETON = """\
skeleton: coupled
coordinates:
  knee: {type: rotation, default: 20, range: [0, 120]}
  beta: {type: rotation, follows: {coord: knee, function: {linear: [0.5, 10]}}}
  slide: {type: translation, follows: {coord: beta, function: {spline: {x: [0, 30, 60, 90], y: [0, 0.01, 0.03, 0.02]}}}}
bones:
  - name: root
  - name: thigh
    parent: root
    offset: [0, 0, 1]
    dofs:
      - {coord: knee, type: rotation, axis: [1, 0, 0]}
  - name: cap
    parent: root
    offset: [0, 0.1, 1]
    dofs:
      - {coord: slide, type: translation, axis: [0, 0, 1]}
      - {coord: beta, type: rotation, axis: [1, 0, 0]}
"""

POSE = """\
pose: bend
skeleton: coupled.yaml
fps: 30
frames: [0, 10]
keys:
  0: {knee: 0}
  10: {knee: 90}
"""


def _write(tmp_path: Path, skeleton: str = SKELETON, pose: str = POSE) -> tuple[Path, Path]:
    (tmp_path / "coupled.yaml").write_text(skeleton)
    (tmp_path / "bend.yaml").write_text(pose)
    return tmp_path / "coupled.yaml", tmp_path / "bend.yaml"


def _spline(x):
    from axdf_cli.model.skeleton import Spline

    return Spline(np.array([0.0, 30, 60, 90]), np.array([0.0, 0.01, 0.03, 0.02]))(np.asarray(x, float))


def test_followers_are_computed_at_rest_and_in_every_sample(tmp_path):
    """beta = 0.5 knee + 10 and slide = spline(beta), a chain: at rest (knee 20: beta 20) and
    at every frame of a pose that keys only the knee; the cap bone moves by them exactly."""
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import axis_angle, forward_kinematics
    from axdf_cli.specs import load_pose, load_skeleton

    skel_path, pose_path = _write(tmp_path)
    skel = load_skeleton(skel_path)
    ci = skel.coord_index
    assert [(c.name, c.follows) for c in skel.coordinates] == [("knee", None), ("beta", "knee"), ("slide", "beta")]
    rest = skel.rest_coordinates()
    assert rest[ci["beta"]] == 20.0 and rest[ci["slide"]] == pytest.approx(float(_spline(20.0)), abs=1e-15)
    pose = load_pose(pose_path)
    q = sample_coordinates(pose, pose.frames)
    knee = np.linspace(0, 90, 11)
    np.testing.assert_allclose(q[:, ci["knee"]], knee, atol=1e-12)
    np.testing.assert_allclose(q[:, ci["beta"]], 0.5 * knee + 10, atol=1e-12)
    np.testing.assert_allclose(q[:, ci["slide"]], _spline(0.5 * knee + 10), atol=1e-15)
    world = forward_kinematics(skel, q)
    cap = world[:, skel.bone_index["cap"]]
    np.testing.assert_allclose(cap[:, :3, 3], np.stack([np.zeros(11), np.full(11, 0.1), 1 + q[:, ci["slide"]]], 1),
                               atol=1e-12)
    np.testing.assert_allclose(cap[:, :3, :3], axis_angle(np.array([1.0, 0, 0]), np.radians(0.5 * knee + 10)),
                               atol=1e-12)
    # the knee moves the cap (through its followers): range warnings reach muscles on it
    assert skel.bone_index["cap"] in skel.moved_bones()["knee"]


def test_clamped_leader_clamps_its_followers(tmp_path):
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    _, pose_path = _write(tmp_path, pose=POSE.replace("10: {knee: 90}", "10: {knee: 150}") + "clamp_ranges: true\n")
    pose = load_pose(pose_path)
    q = sample_coordinates(pose, pose.frames)
    ci = pose.skeleton.coord_index
    assert q[-1, ci["knee"]] == 120.0 and q[-1, ci["beta"]] == 70.0


def test_a_pose_that_keys_a_coupled_coordinate_is_refused(tmp_path, capsys):
    _, pose_path = _write(tmp_path, pose=POSE.replace("10: {knee: 90}", "10: {knee: 90, beta: 3}"))
    rc, out, err = run_main(["validate", pose_path], capsys)
    assert rc == 2, err
    assert f"{pose_path}:7:" in err and "coupled" in err and "key 'knee' instead" in err, err
    assert "Traceback" not in err


@pytest.mark.parametrize("old,new,line,words", [
    ("follows: {coord: knee,", "follows: {coord: kne,", 4, "follows unknown coordinate 'kne'; did you mean 'knee'?"),
    ("follows: {coord: knee,", "follows: {coord: beta,", 4, "follows itself"),
    ("follows: {coord: knee,", "follows: {coord: slide,", 4, "cycle: beta -> slide -> beta"),
    ("beta: {type: rotation, follows", "beta: {type: rotation, default: 3, follows", 4, "has a default"),
    ("beta: {type: rotation, follows", "beta: {type: rotation, range: [0, 9], follows", 4, "has a range"),
    ("function: {linear: [0.5, 10]}}", "fn: {linear: [0.5, 10]}}", 4, "unknown key 'fn' in follows of beta"),
    ("{coord: beta, type: rotation, axis: [1, 0, 0]}", "{coord: beta, type: rotation, axis: [1, 0, 0], range: [0, 9]}",
     18, "range on a dof of coupled coordinate 'beta'"),
])
def test_bad_coupled_coordinates_exit_2_at_their_position(tmp_path, capsys, old, new, line, words):
    assert old in SKELETON
    skel_path, _ = _write(tmp_path, SKELETON.replace(old, new))
    rc, out, err = run_main(["validate", skel_path], capsys)
    assert rc == 2, err
    m = re.search(re.escape(str(skel_path)) + r":(\d+):(\d+): ", err)
    assert m and int(m.group(1)) == line, err
    assert words in err, err
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- data sets


def test_datasets_draw_leaders_and_never_followers(tmp_path, capsys, monkeypatch):
    """A uniform draw keys free coordinates only (the follower is its function of the drawn
    leader); a data set that sets a coupled coordinate is refused at its position."""
    import dataclasses

    from dataset_helpers import DATASET_YAML, write_tiny

    from axdf_cli.dataset.sampling import sample_pose
    from axdf_cli.dataset.spec import Entry, Sequence
    from axdf_cli.dataset.worker import build_context
    from axdf_cli.model.pose import sample_coordinates

    spec_file = write_tiny(tmp_path)
    chain = (tmp_path / "chain.yaml").read_text()
    twin = "  twin: {type: rotation, follows: {coord: bend, function: {linear: [2, 0]}}}\n"
    (tmp_path / "chain.yaml").write_text(chain.replace("  roll: {type: rotation, default: 0}\n",
                                                       "  roll: {type: rotation, default: 0}\n" + twin))
    ctx = build_context(spec_file)
    skel = ctx.plan_skeleton
    entry = Entry("uniform", 1, None, 5, 3, {})
    spec = dataclasses.replace(ctx.spec, entries=(entry,))
    pose = sample_pose(spec, Sequence(0, "s", 0, 5), skel, None, np.arange(5))
    assert "twin" not in pose.keys and "bend" in pose.keys
    q = sample_coordinates(pose, np.arange(5))
    np.testing.assert_allclose(q[:, skel.coord_index["twin"]], 2 * q[:, skel.coord_index["bend"]], atol=1e-12)
    assert np.ptp(q[:, skel.coord_index["twin"]]) > 0
    # an OpenSim motion for the data set: its column of the coupled coordinate is not read
    from axdf_cli.dataset.door import motion_pose

    (tmp_path / "m.mot").write_text("m\nversion=1\nnRows=2\nnColumns=3\ninDegrees=yes\nendheader\n"
                                    "time\tbend\ttwin\n0.0\t10.0\t99.0\n0.5\t20.0\t99.0\n")
    mp = motion_pose(tmp_path / "m.mot", skel, "m")
    assert set(mp.keys) == {"bend"}
    np.testing.assert_allclose(sample_coordinates(mp, mp.frames)[:, skel.coord_index["twin"]], [20.0, 40.0])
    (tmp_path / "tiny.yaml").write_text(DATASET_YAML.replace("  roll: {range: [-80, 80]}\n",
                                                             "  roll: {range: [-80, 80]}\n  twin: {range: [0, 1]}\n"))
    monkeypatch.chdir(tmp_path)
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "o"], capsys)
    assert rc == 2 and "tiny.yaml:9:" in err and "coupled" in err, err
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- OpenSim

needs_opensim = pytest.mark.skipif(importlib.util.find_spec("opensim") is None,
                                   reason="the OpenSim judge needs `pip install opensim` (test extra)")

#: arm26 with its elbow coupled to the shoulder: elbow = 2 (0.5 shoulder + 0.2) rad, a
#: LinearFunction and a scale factor (Simbody: scale · f(q_ind) − q_dep = 0).
COUPLER = """<ConstraintSet name="constraintset">
			<objects>
				<CoordinateCouplerConstraint name="elbow_follows_shoulder">
					<isEnforced>true</isEnforced>
					<coupled_coordinates_function>
						<LinearFunction>
							<coefficients> 0.5 0.2</coefficients>
						</LinearFunction>
					</coupled_coordinates_function>
					<independent_coordinate_names>r_shoulder_elev</independent_coordinate_names>
					<dependent_coordinate_name>r_elbow_flex</dependent_coordinate_name>
					<scale_factor>2</scale_factor>
				</CoordinateCouplerConstraint>
			</objects>
			<groups />
		</ConstraintSet>"""


def _arm_with(tmp_path: Path, constraint_set: str) -> Path:
    text = ARM.read_text()
    empty = '<ConstraintSet name="constraintset">\n\t\t\t<objects />\n\t\t\t<groups />\n\t\t</ConstraintSet>'
    assert empty in text
    out = tmp_path / "arm26_coupled.osim"
    out.write_text(text.replace(empty, constraint_set))
    return out


@pytest.fixture
def coupled_arm(tmp_path):
    model = _arm_with(tmp_path, COUPLER)
    rc, out = run_import(tmp_path, model, "--motion", str(ARM_Q), "--fps", "20", "--no-meshes")
    assert rc == 0
    return model, out


@needs_data
def test_coupler_imports_with_its_scale_factor_and_units(coupled_arm):
    """degrees: elbow = 2 (0.5 shoulder[rad] + 0.2) = shoulder + 2·0.2·180/π; the motion's own
    elbow column is left out of the pose, its disagreement with the coupler warned."""
    import yaml

    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import RefPolicy, load_pose

    model, out = coupled_arm
    doc = yaml.safe_load((out / "skeletons" / "arm26.yaml").read_text())
    follows = doc["coordinates"]["r_elbow_flex"]["follows"]
    assert follows["coord"] == "r_shoulder_elev"
    pose = load_pose(next(out.glob("*.yaml")), RefPolicy(allow_outside=True))
    assert "r_elbow_flex" not in pose.keys
    q = sample_coordinates(pose, pose.frames)
    ci = pose.skeleton.coord_index
    np.testing.assert_allclose(q[:, ci["r_elbow_flex"]], q[:, ci["r_shoulder_elev"]] + 0.4 * 180 / math.pi,
                               atol=1e-9)
    report = json.loads((out / "import_report.json").read_text())
    assert report["motion"]["coupled_columns"]["r_elbow_flex"]["max_deviation"] > 10.0  # degrees: the CMC elbow
    assert any("r_elbow_flex differs from its coupler" in w for w in report["warnings"])


@needs_data
@needs_opensim
def test_coupled_arm_judged_by_opensim(coupled_arm):
    """OpenSim assembles the elbow from the shoulder by its own constraint: it lands where
    axdf's coupler put it, and every muscle length is within 1% at every frame."""
    from opensim_judge import OpenSimModel, compare, pose_coordinates

    model, out = coupled_arm
    pose_file = next(out.glob("*.yaml"))
    names, ours, ref = compare(model, out / "muscles", pose_file)
    assert len(names) == 6
    assert (np.abs(ours - ref) / ref).max() < 0.01
    pose, frames, q = pose_coordinates(pose_file)
    om = OpenSimModel(model)
    assert om.dependent == {"r_elbow_flex"}
    i = pose.skeleton.coord_index["r_elbow_flex"]
    for row in q[:: max(1, len(q) // 8)]:
        om.set_pose(pose.skeleton, row)
        assert abs(om.values(pose.skeleton)[i] - row[i]) < 1e-6


@pytest.mark.parametrize("edit,why", [
    (("<independent_coordinate_names>r_shoulder_elev</independent_coordinate_names>",
      "<independent_coordinate_names>r_shoulder_elev r_shoulder_elev</independent_coordinate_names>"),
     "of 2 coordinates"),
    (("<isEnforced>true</isEnforced>", "<isEnforced>false</isEnforced>"), "not enforced"),
    (("<LinearFunction>\n\t\t\t\t\t\t\t<coefficients> 0.5 0.2</coefficients>\n\t\t\t\t\t\t</LinearFunction>",
      "<MultivariatePolynomialFunction><dimension>2</dimension></MultivariatePolynomialFunction>"),
     "function MultivariatePolynomialFunction"),
])
@needs_data
def test_couplers_axdf_cannot_follow_are_listed_and_leave_the_coordinate_free(tmp_path, edit, why):
    assert edit[0] in COUPLER
    model = _arm_with(tmp_path, COUPLER.replace(*edit))
    rc, out = run_import(tmp_path, model, "--motion", str(ARM_Q), "--no-meshes")
    assert rc == 0
    report = json.loads((out / "import_report.json").read_text())
    (item,) = [i for i in report["ignored"] if i["kind"] == "constraint"]
    assert item["name"] == "elbow_follows_shoulder" and why in item["why"] and "r_elbow_flex stays free" in item["why"]
    assert "follows" not in next((out / "skeletons").glob("*.yaml")).read_text()
    assert "r_elbow_flex" in report["motion"]["coordinates"]


@pytest.mark.parametrize("edit,words", [
    (("<dependent_coordinate_name>r_elbow_flex<", "<dependent_coordinate_name>r_elbow<"), "unknown coordinate 'r_elbow'"),
    (("<independent_coordinate_names>r_shoulder_elev<", "<independent_coordinate_names>r_elbow_flex<"), "to itself"),
])
@needs_data
def test_bad_coupler_exit_2_at_its_line(tmp_path, capsys, edit, words):
    model = _arm_with(tmp_path, COUPLER.replace(*edit))
    line = model.read_text()[:model.read_text().index(edit[1])].count("\n") + 1
    rc, out = run_import(tmp_path, model, "--motion", str(ARM_Q), out="bad")
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists(), err
    assert f"{model}:{line}:" in err and words in err and "Traceback" not in err, err


@needs_data
def test_function_based_path_muscles_are_listed_not_imported(tmp_path, capsys):
    """OpenSim 4.5's FunctionBasedPath gives a muscle's length as a function of coordinates,
    with no path points: the muscle is skipped with its reason (IMPORT.md, the report, a
    warning), the model's other muscles import."""
    text = ARM.read_text()
    start = text.index('<Thelen2003Muscle name="BIClong">')
    gp0 = text.index("<GeometryPath", start)
    gp1 = text.index("</GeometryPath>", gp0) + len("</GeometryPath>")
    fbp = ("<FunctionBasedPath name=\"path\"><coordinate_paths>/jointset/r_elbow/r_elbow_flex</coordinate_paths>"
           "<length_function><LinearFunction><coefficients> -0.02 0.35</coefficients></LinearFunction>"
           "</length_function></FunctionBasedPath>")
    model = tmp_path / "arm26_fbp.osim"
    model.write_text(text[:gp0] + fbp + text[gp1:])
    line = text[:start].count("\n") + 1
    rc, out = run_import(tmp_path, model, "--no-meshes")
    err = capsys.readouterr().err
    assert rc == 0, err
    assert sorted(p.stem for p in (out / "muscles").glob("*.yaml")) == ["BICshort", "BRA", "TRIlat", "TRIlong", "TRImed"]
    report = json.loads((out / "import_report.json").read_text())
    (item,) = [i for i in report["ignored"] if i["kind"] == "muscle"]
    assert item["name"] == "BIClong" and "FunctionBasedPath" in item["why"] and item["where"] == f"arm26_fbp.osim:{line}:5"
    assert f"arm26_fbp.osim:{line}:5: muscle BIClong skipped" in err
    assert "| muscle | BIClong |" in (out / "IMPORT.md").read_text()
