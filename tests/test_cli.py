"""The command line, in process: `axdf run` and `axdf validate` (SPEC "Command line",
"Output folder of a run", exit codes)."""
from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from axdf_cli.formats import read_triangles
from axdf_cli.model.skeleton import forward_kinematics, matrix_to_quaternion
from axdf_cli.model.pose import sample_coordinates

from conftest import REPO_ROOT, all_files, run_main

DEMO_MUSCLES = ["biceps_brachii", "brachioradialis", "deltoid_anterior", "deltoid_middle", "deltoid_posterior",
                "gastrocnemius_medial", "gastrocnemius_lateral"]  # file order, then order in the file
DEMO_BONES = ["pelvis", "femur_r", "tibia_r", "foot_r", "thorax", "scapula_r", "humerus_r", "ulna_r", "radius_r"]
STATS_COLUMNS = ["frame", "muscle", "length", "volume", "volume_ratio", "tension", "twist", "scale",
                 "inside_muscle", "inside_bone", "depth", "warning"]  # (contact's measures: on by default)
BONES_COLUMNS = ["frame", "bone", "x", "y", "z", "qw", "qx", "qy", "qz"]
POSITION = re.compile(r"^(?P<file>[^\s:]+\.yaml):(?P<line>\d+):(?P<col>\d+): ", re.M)


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.reader(f))


@pytest.fixture(scope="module")
def demo_runs(tmp_path_factory):
    """The demo job, frames 0..3, run twice (for determinism) with cwd = repository root."""
    from axdf_cli.cli.main import main

    base = tmp_path_factory.mktemp("runs")
    old = os.getcwd()
    os.chdir(REPO_ROOT)
    try:
        for name in ("a", "b"):
            rc = main(["run", "poses/jobs/demo.yaml", "--out", str(base / name), "--frames", "0:3", "-q"])
            assert rc == 0
    finally:
        os.chdir(old)
    return base / "a", base / "b"


# ----------------------------------------------------------------------------- run


def test_run_writes_the_spec_layout(demo_runs):
    out, _ = demo_runs
    for muscle in DEMO_MUSCLES:
        files = sorted(p.name for p in (out / "meshes" / muscle).iterdir())
        assert files == [f"{muscle}_{f:04d}.ply" for f in range(4)]
    assert sorted(p.name for p in (out / "meshes").iterdir()) == sorted(DEMO_MUSCLES)
    for name in ("manifest.json", "stats.csv", "bones.csv"):
        assert (out / name).is_file()
    leftovers = [p for p in out.rglob("*") if p.name.startswith(".axdf-tmp")]
    assert leftovers == []


def test_run_meshes_share_topology_and_read_back(demo_runs, demo):
    out, _ = demo_runs
    for model in demo.models:
        name = model.spec.name
        faces0 = None
        for f in range(4):
            path = out / "meshes" / name / f"{name}_{f:04d}.ply"
            pos, nrm, faces = read_triangles(path.read_bytes(), ".ply")
            assert pos.shape == (model.n_vertices, 3)
            assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm))
            faces0 = faces if faces0 is None else faces0
            np.testing.assert_array_equal(faces, faces0)
            m = trimesh.load(path, process=False)
            assert m.is_watertight and m.is_winding_consistent and m.volume > 0


def test_manifest(demo_runs):
    out, _ = demo_runs
    text = (out / "manifest.json").read_text()
    man = json.loads(text)
    assert man["tool"] == "axdf" and man["complete"] is True
    assert man["frames"] == [0, 1, 2, 3]
    assert man["settings"]["format"] == "ply"
    # every output file (but the manifest itself) is listed with its sha256
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()} - {"manifest.json"}
    assert set(man["files"]) == on_disk
    for rel, sha in man["files"].items():
        assert hashlib.sha256((out / rel).read_bytes()).hexdigest() == sha, rel
    # inputs with sha256: the job, pose, skeleton and muscle files
    inputs = man["inputs"]
    for rel in ["poses/jobs/demo.yaml", "poses/demo.yaml", "poses/skeletons/human_r.yaml",
                "muscles/demo/biceps_brachii.yaml", "muscles/demo/deltoid.yaml", "muscles/demo/gastrocnemius.yaml"]:
        assert inputs[rel] == hashlib.sha256((REPO_ROOT / rel).read_bytes()).hexdigest(), rel
    assert [m["name"] for m in man["muscles"]] == DEMO_MUSCLES
    # STYLE: no absolute paths or timestamps in outputs
    assert str(out) not in text and str(REPO_ROOT) not in text


def test_stats_csv(demo_runs, demo):
    out, _ = demo_runs
    rows = read_csv(out / "stats.csv")
    assert rows[0] == STATS_COLUMNS
    body = rows[1:]
    assert [(int(r[0]), r[1]) for r in body] == [(f, m) for f in range(4) for m in DEMO_MUSCLES]
    v0 = {m.spec.name: m.v0 for m in demo.models}
    for r in body:
        length, volume, ratio, tension, twist, scale = map(float, r[2:8])
        assert length > 0 and volume > 0 and scale > 0
        assert ratio == pytest.approx(volume / v0[r[1]], rel=1e-8)
        assert abs(ratio - 1) < 5e-3
        assert 0.0 <= tension <= 1.0
        assert np.isfinite(twist)
        inside_muscle, inside_bone, depth = map(float, r[8:11])
        assert 0.0 <= inside_muscle <= 1.0 and 0.0 <= inside_bone <= 1.0 and 0.0 <= depth < 0.1
        assert r[11] == ""
    frame0 = [r for r in body if r[0] == "0"]
    for r in frame0:  # frame 0 is the rest pose
        assert float(r[4]) == pytest.approx(1.0, abs=1e-9)
        assert float(r[6]) == pytest.approx(0.0, abs=1e-9)


def test_bones_csv(demo_runs, demo):
    out, _ = demo_runs
    rows = read_csv(out / "bones.csv")
    assert rows[0] == BONES_COLUMNS
    body = rows[1:]
    assert [(int(r[0]), r[1]) for r in body] == [(f, b) for f in range(4) for b in DEMO_BONES]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, np.arange(4)))
    vals = np.array([[float(x) for x in r[2:]] for r in body]).reshape(4, len(DEMO_BONES), 7)
    np.testing.assert_allclose(vals[..., :3], world[..., :3, 3], rtol=0, atol=1e-8)
    q = vals[..., 3:]
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-8)
    assert np.all(q[..., 0] >= 0)
    np.testing.assert_allclose(q, matrix_to_quaternion(world[..., :3, :3]), rtol=0, atol=1e-8)


def test_two_runs_are_byte_identical(demo_runs):
    a, b = demo_runs
    fa, fb = all_files(a), all_files(b)
    assert fa.keys() == fb.keys()
    for k in fa:
        assert fa[k] == fb[k], k


def test_run_obj_format(repo_root, tmp_path, capsys, demo):
    rc, out, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", "--frames", "2",
                             "--format", "obj"], capsys)
    assert rc == 0, err
    assert "Traceback" not in err
    man = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert man["settings"]["format"] == "obj"
    for model in demo.models:
        name = model.spec.name
        path = tmp_path / "o" / "meshes" / name / f"{name}_0002.obj"
        m = trimesh.load(path, process=False)
        assert len(m.vertices) == model.n_vertices
        np.testing.assert_array_equal(m.faces, model.faces)
        assert m.is_watertight and m.volume > 0
    assert not list((tmp_path / "o" / "meshes").rglob("*.ply"))
    assert str(tmp_path / "o") in out


def test_dry_run_writes_nothing(repo_root, tmp_path, capsys):
    rc, out, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", "--dry-run"], capsys)
    assert rc == 0, err
    assert "would write" in out
    assert not (tmp_path / "o").exists()
    assert list(tmp_path.iterdir()) == []


def test_non_empty_out_is_refused_unless_overwrite(repo_root, tmp_path, capsys):
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("user data")
    for extra in ([], ["--overwrite"], ["--resume"]):  # a folder that holds no run is never written into
        rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", out, "--frames", "0", *extra], capsys)
        assert rc == 2
        assert "not empty" in err and "--overwrite" in err
        assert "Traceback" not in err
        assert sorted(p.name for p in out.iterdir()) == ["keep.txt"]
    run_dir = tmp_path / "r"
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", run_dir, "--frames", "0", "-q"], capsys)
    assert rc == 0, err
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", run_dir, "--frames", "0", "-q"], capsys)
    assert rc == 2 and "not empty" in err and "--overwrite" in err
    (run_dir / "keep.txt").write_text("user data")
    # a second --overwrite run with other frames leaves no stale meshes behind, and the user's file
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", run_dir, "--frames", "1", "--overwrite", "-q"], capsys)
    assert rc == 0, err
    assert not list(run_dir.rglob("*_0000.ply"))
    assert len(list(run_dir.rglob("*_0001.ply"))) == len(DEMO_MUSCLES)
    assert (run_dir / "keep.txt").read_text() == "user data"


@pytest.mark.parametrize("spec", ["0:abc", "5:2", "0:3:0", "0:9999", "-1", "", "1.5"])
def test_bad_frames(repo_root, tmp_path, capsys, spec):
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", "--frames", spec], capsys)
    assert rc == 2
    assert "--frames" in err
    assert "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_usage_errors_exit_2(repo_root, tmp_path, capsys):
    for argv in (["run", "--format", "stl"], ["frobnicate"], []):
        rc, _, err = run_main(argv, capsys)
        assert rc == 2, argv
        assert "Traceback" not in err


# ----------------------------------------------------------------------------- validate


SHIPPED_YAML = sorted(p.relative_to(REPO_ROOT).as_posix()
                      for d in ("muscles", "poses") for p in (REPO_ROOT / d).rglob("*.yaml"))


def test_there_are_shipped_files():
    assert len(SHIPPED_YAML) >= 6


@pytest.mark.parametrize("rel", SHIPPED_YAML)
def test_validate_every_shipped_file(repo_root, capsys, rel):
    rc, out, err = run_main(["validate", rel], capsys)
    assert rc == 0, err
    assert f"{rel}: ok" in out
    assert err == ""


# ----------------------------------------------------------------------------- bad inputs


@pytest.fixture
def project(tmp_path, monkeypatch):
    """A copy of the demo library (muscles/, poses/) as cwd, for mutation."""
    shutil.copytree(REPO_ROOT / "muscles", tmp_path / "muscles")
    shutil.copytree(REPO_ROOT / "poses", tmp_path / "poses")
    monkeypatch.chdir(tmp_path)
    return tmp_path


BICEPS = "muscles/demo/biceps_brachii.yaml"
POSE = "poses/demo.yaml"
JOB = "poses/jobs/demo.yaml"


def _mutate(path: Path, old: str, new: str) -> int:
    """Replace the first ``old`` by ``new``; return the 1-based line where it happened."""
    text = path.read_text()
    i = text.index(old)
    path.write_text(text[:i] + new + text[i + len(old):])
    return text.count("\n", 0, i) + 1


def _line_of(path: Path, needle: str) -> int:
    text = path.read_text()
    return text.count("\n", 0, text.index(needle)) + 1


def _assert_input_error(project, capsys, target, line=None, validate=None):
    """validate (TARGET, or the files given) and run the job: each exits 2 with
    TARGET:LINE:COL, no traceback, nothing written."""
    before = sorted(p for p in project.rglob("*"))
    checks = [["validate", v] for v in (validate or [target])] + [["run", JOB, "--out", "out", "--frames", "0"]]
    for argv in checks:
        rc, out, err = run_main(argv, capsys)
        assert rc == 2, (argv, out, err)
        assert "Traceback" not in err + out
        m = POSITION.search(err)
        assert m, err
        assert Path(m["file"]).resolve() == (project / target).resolve(), err
        if line is not None:
            assert int(m["line"]) == line, err
    assert not (project / "out").exists()
    assert sorted(p for p in project.rglob("*")) == before
    return err


CASES = {
    # name: (file, old text, new text, expected line or None (= the mutated line), message part)
    "yaml_syntax": (BICEPS, "tendons: [0.15, 0.12]", "tendons: [0.15, 0.12\nresolution: [48, 24]", "", "syntax"),
    "unknown_key": (BICEPS, "color:", "colour: red\ncolor:", 0, "colour"),
    "unknown_bone": (BICEPS, "bone: radius_r", "bone: radius_x", 0, "radius_x"),
    "two_axis_points": (BICEPS, "  - {bone: humerus_r, at: [0.0, -0.035, -0.07]}\n"
                                "  - {bone: humerus_r, at: [0.0, -0.04, -0.17]}\n"
                                "  - {bone: humerus_r, at: [0.005, -0.03, -0.27]}\n", "", None, "at least 3"),
    "outline_7_points": (BICEPS, "[0.009, 0.0], ", "", 0, "8"),
    "negative_radius": (BICEPS, "radii: [0.02, 0.015]", "radii: [-0.02, 0.015]", 0, "radii"),
    "nan_value": (BICEPS, "radii: [0.02, 0.015]", "radii: [.nan, 0.015]", 0, "finite"),
    "python_tag": (BICEPS, 'color: "#c8453a"', "color: !!python/object/apply:os.system [\"echo hi\"]", 0, "tag"),
    "missing_coordinate": (POSE, "ankle_r: 35", "ankle_x: 35", 0, "ankle_x"),
    "pose_skeleton_missing": (POSE, "skeleton: skeletons/human_r.yaml", "skeleton: skeletons/nope.yaml", 0, "nope"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input(project, capsys, case):
    rel, old, new, line, words = CASES[case]
    at = _mutate(project / rel, old, new)
    if line == 0:
        line = at
    elif line == "":
        line = None
    # a muscle file alone names bones of no skeleton: its bones are checked with a job
    validate = [JOB] if case == "unknown_bone" else [rel, JOB]
    err = _assert_input_error(project, capsys, rel, line, validate)
    assert words in err, err


def test_bad_input_line_for_short_axis(project, capsys):
    """Fewer than 3 axis points is reported at the axis list."""
    rel, old, new, _, _ = CASES["two_axis_points"]
    _mutate(project / rel, old, new)
    err = _assert_input_error(project, capsys, rel, None)
    m = POSITION.search(err)
    assert int(m["line"]) in (_line_of(project / rel, "axis:"), _line_of(project / rel, "axis:") + 1)


def test_non_utf8_bytes(project, capsys):
    path = project / BICEPS
    data = path.read_bytes()
    i = data.index(b"muscle:")
    path.write_bytes(data[:i] + b"# caf\xe9 \xff\n" + data[i:])
    line = data[:i].count(b"\n") + 1
    err = _assert_input_error(project, capsys, BICEPS, line)
    assert "UTF-8" in err


def test_alias_bomb(project, capsys):
    lines = ["muscle: bomb", 'a0: &a0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for i in range(1, 9):
        lines.append(f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]")
    (project / "bomb.yaml").write_text("\n".join(lines) + "\n")
    start = time.perf_counter()
    rc, out, err = run_main(["validate", "bomb.yaml"], capsys)
    elapsed = time.perf_counter() - start
    assert rc == 2
    assert "Traceback" not in err
    assert POSITION.search(err) and "alias" in err
    assert elapsed < 30.0


def test_validate_reports_every_bad_file_and_keeps_going(project, capsys):
    _mutate(project / BICEPS, "radii: [0.02, 0.015]", "radii: [-0.02, 0.015]")
    rc, out, err = run_main(["validate", BICEPS, "muscles/demo/deltoid.yaml", JOB], capsys)
    assert rc == 2
    assert "muscles/demo/deltoid.yaml: ok" in out
    assert len(POSITION.findall(err)) == 2  # the muscle itself and the job that uses it


def test_validate_unknown_kind(project, capsys):
    (project / "x.yaml").write_text("hello: world\n")
    rc, _, err = run_main(["validate", "x.yaml"], capsys)
    assert rc == 2 and POSITION.search(err) and "Traceback" not in err


def test_run_on_extreme_poses_is_finite(project, capsys):
    """Joints far past their ranges (+-720 degrees, knee 179): every mesh is written from
    finite vertices (no rest-shape substitution) and the run succeeds."""
    keys = {0: {"knee_flexion_r": 179, "elbow_flexion_r": 179, "pronation_r": 720},
            1: {"hip_flexion_r": -720, "shoulder_abduction_r": 720, "shoulder_flexion_r": -720, "ankle_r": 720},
            2: {"knee_flexion_r": -720, "elbow_flexion_r": 720, "pronation_r": -720}}
    import yaml

    (project / "poses" / "extreme.yaml").write_text(yaml.safe_dump(
        {"pose": "extreme", "skeleton": "skeletons/human_r.yaml", "fps": 24, "frames": [0, 2],
         "interpolation": "step", "keys": keys}))
    rc, _, err = run_main(["run", "--muscles", "muscles/demo", "--pose", "poses/extreme.yaml", "--out", "out", "-q"],
                          capsys)
    assert rc == 0, err
    assert "non-finite" not in err
    for p in (project / "out" / "meshes").rglob("*.ply"):
        pos, nrm, _ = read_triangles(p.read_bytes(), ".ply")
        assert np.all(np.isfinite(pos)) and np.all(np.isfinite(nrm)), p
    rows = read_csv(project / "out" / "stats.csv")[1:]
    assert len(rows) == 3 * len(DEMO_MUSCLES)
    assert all("non-finite" not in r[-1] for r in rows)  # (the warning column)


def test_obj_bone_mesh_is_copied_into_the_run_as_a_ply(project, capsys):
    """A skeleton may name OBJ bone meshes; the run's bones/<bone>.ply is then a PLY of the same
    triangles (it was the OBJ text under a .ply name), and PLY bone meshes are copied as they are."""
    src = project / "poses" / "skeletons" / "human_r_meshes"
    v, _, f = read_triangles((src / "femur_r.ply").read_bytes(), ".ply")
    (src / "femur_r.obj").write_text("".join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in v.tolist())
                                     + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f.tolist()))
    _mutate(project / "poses" / "skeletons" / "human_r.yaml", "femur_r.ply", "femur_r.obj")
    rc, _, err = run_main(["run", JOB, "--no-render", "--frames", "0:1", "--out", "out", "-q"], capsys)
    assert rc == 0, err
    pos, nrm, faces = read_triangles((project / "out" / "bones" / "femur_r.ply").read_bytes(), ".ply")
    assert nrm is None and np.array_equal(faces, f) and np.allclose(pos, v, atol=1e-6)
    assert (project / "out" / "bones" / "tibia_r.ply").read_bytes() == (src / "tibia_r.ply").read_bytes()
