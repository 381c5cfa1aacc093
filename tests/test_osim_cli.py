"""``axdf import osim`` end to end: every shipped model, poses and activation, bad input → exit 2."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from osim_common import (ARM, ARM_CTRL, ARM_Q, FK_MODEL, FK_Q, GAIT, GAIT_CTRL, GAIT_Q, REPO, needs_data,
                         run_import)

pytestmark = needs_data


@pytest.mark.parametrize("model,extra", [
    (ARM, ["--motion", str(ARM_Q), "--controls", str(ARM_CTRL), "--fps", "60"]),
    (GAIT, ["--motion", str(GAIT_Q), "--controls", str(GAIT_CTRL)]),
    (FK_MODEL, ["--motion", str(FK_Q)]),
], ids=["arm26", "gait2392", "gait2354"])
def test_every_model_imports_and_loads(tmp_path, model, extra):
    from axdf_cli.specs import load_muscle_file, load_pose, load_skeleton

    rc, out = run_import(tmp_path, model, *extra)
    assert rc == 0
    report = json.loads((out / "import_report.json").read_text())
    (skel_file,) = (out / "skeletons").glob("*.yaml")
    skel = load_skeleton(skel_file)
    assert skel.bones[0].name == "ground" and skel.bones[0].orient == (90.0, -90.0, 0.0)
    muscles = sorted((out / "muscles").glob("*.yaml"))
    assert len(muscles) == report["counts"]["muscles"] == {"arm26": 6, "3DGaitModel2392": 92,
                                                           "subject01": 54}[report["source"]["model_name"]]
    for m in muscles:
        load_muscle_file(m)
    (pose_file,) = out.glob("*.yaml")
    pose = load_pose(pose_file)
    assert pose.skeleton.name == skel.name
    for b in skel.bones:
        if b.mesh is not None:
            assert Path(b.mesh).read_bytes().startswith(b"ply\nformat binary_little_endian 1.0\n")
    text = "".join(p.read_text() for p in out.rglob("*") if p.suffix in (".yaml", ".json", ".md"))
    assert str(REPO.parent) not in text and str(tmp_path) not in text  # no absolute paths


def test_import_is_deterministic(tmp_path):
    a = run_import(tmp_path, ARM, "--motion", str(ARM_Q), "--controls", str(ARM_CTRL), out="a")[1]
    b = run_import(tmp_path, ARM, "--motion", str(ARM_Q), "--controls", str(ARM_CTRL), out="b")[1]
    fa = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert fa == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for p in fa:
        assert (a / p).read_bytes() == (b / p).read_bytes(), p


def test_activation_columns_map_to_their_muscles(tmp_path):
    from axdf_cli.importers.storage import read_storage
    from axdf_cli.specs import load_pose

    for model, q, ctrl, fps in ((ARM, ARM_Q, ARM_CTRL, 60), (GAIT, GAIT_Q, GAIT_CTRL, None)):
        extra = ["--motion", str(q), "--controls", str(ctrl)] + (["--fps", str(fps)] if fps else [])
        rc, out = run_import(tmp_path, model, *extra, out=model.stem)
        assert rc == 0
        pose = load_pose(next(out.glob("*.yaml")))
        report = json.loads((out / "import_report.json").read_text())
        c = read_storage(ctrl)
        qt = read_storage(q)
        keep = np.append(np.diff(c.time) > 0, True)
        mapped = 0
        for i, lab in enumerate(c.labels):
            muscle = lab.removesuffix(".excitation")
            if muscle not in pose.activation:  # reserve / residual actuators, not muscles
                assert lab in report["controls"]["ignored_columns"]
                continue
            frames, values = pose.activation[muscle]
            t = qt.time[0] + np.asarray(frames) / pose.fps
            expect = np.clip(np.interp(t, c.time[keep], c.data[keep, i]), 0, 1)
            np.testing.assert_allclose(values, expect, atol=1e-9, err_msg=muscle)  # 9 significant digits
            mapped += 1
        assert mapped == {"arm26": 6, "gait2392_thelen2003muscle": 92}[model.stem]


def test_motion_values_and_angle_units(tmp_path):
    from axdf_cli.importers.storage import read_storage
    from axdf_cli.specs import load_pose

    rc, out = run_import(tmp_path, GAIT, "--motion", str(GAIT_Q))
    pose = load_pose(out / "subject01_walk1_ik.yaml")
    q = read_storage(GAIT_Q)
    assert pose.fps == 60 and pose.last - pose.first + 1 == len(q.time)
    frames, vals = pose.keys["knee_angle_r"]
    np.testing.assert_allclose(vals, q.column("knee_angle_r"), rtol=1e-8)  # degrees stay degrees (9 digits)
    # arm26_Kinematics_q.sto says inDegrees=yes and holds degrees (the elbow flexes 0.26 -> 90.02):
    # as radians that would be 14 turns, so the header is believed and no warning is given.
    rc, out = run_import(tmp_path, ARM, "--motion", str(ARM_Q), out="arm")
    report = json.loads((out / "import_report.json").read_text())
    assert report["motion"]["rotations_read_as"] == "degrees" and report["warnings"] == []


def _table(path: Path, in_degrees: str, rows):
    lines = ["Coordinates", "version=1", f"nRows={len(rows)}", "nColumns=3", f"inDegrees={in_degrees}", "endheader",
             "time\tr_shoulder_elev\tr_elbow_flex"]
    lines += ["\t".join(repr(float(v)) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_radians_labelled_degrees_are_detected(tmp_path, capsys):
    from axdf_cli.specs import load_pose

    t = np.linspace(0, 1, 51)
    rows = np.stack([t, 0.1 * np.sin(t), 1.5 * t], axis=1)  # elbow 0 -> 1.5 rad
    mot = _table(tmp_path / "rad.sto", "yes", rows)
    rc, out = run_import(tmp_path, ARM, "--motion", str(mot))
    assert rc == 0
    assert "reading the values as radians" in capsys.readouterr().err
    pose = load_pose(out / "rad.yaml")
    np.testing.assert_allclose(pose.keys["r_elbow_flex"][1], np.degrees(1.5 * t), rtol=1e-8)  # 9 digits
    # and degrees labelled radians
    rows = np.stack([t, 10 * t, 90 * t], axis=1)
    mot = _table(tmp_path / "deg.sto", "no", rows)
    rc, out = run_import(tmp_path, ARM, "--motion", str(mot), out="d")
    assert "reading the values as degrees" in capsys.readouterr().err
    np.testing.assert_allclose(load_pose(out / "deg.yaml").keys["r_elbow_flex"][1], 90 * t, rtol=1e-8)


# ----------------------------------------------------------------------------- bad input


def _edit(src: Path, dst: Path, old: str, new: str, count: int = 1) -> tuple[Path, int]:
    text = src.read_text()
    i = text.index(old)
    dst.write_text(text.replace(old, new, count))
    return dst, text[:i].count("\n") + 1


def _expect_error(tmp_path, capsys, model, *extra, file: Path, line: int | None, words: str):
    rc, out = run_import(tmp_path, model, *extra, out="bad")
    err = capsys.readouterr().err
    assert rc == 2, err
    assert not out.exists(), "nothing is written on bad input"
    m = re.search(re.escape(str(file)) + r":(\d+):(\d+): ", err)
    assert m, err
    if line is not None:
        assert int(m.group(1)) == line, err
    assert words in err
    assert "Traceback" not in err


def test_missing_body(tmp_path, capsys):
    bad, line = _edit(ARM, tmp_path / "a.osim", "<socket_parent_frame>/bodyset/r_humerus</socket_parent_frame>",
                      "<socket_parent_frame>/bodyset/r_humerusX</socket_parent_frame>")
    _expect_error(tmp_path, capsys, bad, file=bad, line=line, words="unknown body 'r_humerusX'")


def test_unknown_coordinate_in_joint(tmp_path, capsys):
    bad, line = _edit(ARM, tmp_path / "a.osim", "<coordinates>r_elbow_flex</coordinates>",
                      "<coordinates>r_elbow_flexx</coordinates>")
    _expect_error(tmp_path, capsys, bad, file=bad, line=line, words="unknown coordinate 'r_elbow_flexx'")


def test_malformed_number_in_model(tmp_path, capsys):
    bad, line = _edit(ARM, tmp_path / "a.osim", "<translation>0.0061000000000000004 -0.29039999999999999",
                      "<translation>0.0061000000000000004 -0.29O39999999999999")
    _expect_error(tmp_path, capsys, bad, file=bad, line=line, words="malformed number")


def test_truncated_model(tmp_path, capsys):
    text = ARM.read_text()
    bad = tmp_path / "a.osim"
    bad.write_text(text[: len(text) // 2])
    _expect_error(tmp_path, capsys, bad, file=bad, line=None, words="malformed XML")


def test_unknown_coordinate_in_motion(tmp_path, capsys):
    bad, line = _edit(ARM_Q, tmp_path / "q.sto", "time\tr_shoulder_elev", "time\tr_shoulder_elevation")
    _expect_error(tmp_path, capsys, ARM, "--motion", str(bad), file=bad, line=line,
                  words="unknown coordinate 'r_shoulder_elevation'")


def test_malformed_and_truncated_motion(tmp_path, capsys):
    bad, line = _edit(ARM_Q, tmp_path / "q.sto", "0.32036639", "0.32x36639")
    _expect_error(tmp_path, capsys, ARM, "--motion", str(bad), file=bad, line=line, words="malformed number '0.32x36639'")
    text = ARM_Q.read_text().splitlines()
    short = tmp_path / "short.sto"
    short.write_text("\n".join(text[:100]) + "\n")
    _expect_error(tmp_path, capsys, ARM, "--motion", str(short), file=short, line=None, words="truncated")
    cut = tmp_path / "cut.sto"
    cut.write_text("\n".join(text[:100]) + "\n" + text[100][:12] + "\n")
    _expect_error(tmp_path, capsys, ARM, "--motion", str(cut), file=cut, line=101, words="row has 1 values")


def test_controls_need_a_motion(tmp_path, capsys):
    rc, out = run_import(tmp_path, ARM, "--controls", str(ARM_CTRL))
    assert rc == 2 and "--controls needs --motion" in capsys.readouterr().err



@pytest.mark.parametrize("flag,value", [("--pose-name", "../escape"), ("--pose-name", ".."), ("--name", "a b")])
def test_bad_name_or_pose_name_exit_2_nothing_written(tmp_path, capsys, flag, value):
    rc, out = run_import(tmp_path, ARM, "--motion", str(ARM_Q), flag, value)
    err = capsys.readouterr().err
    assert rc == 2 and f"{flag} {value!r}" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == []

#: The committed library against a fresh import: numbers within these (the importer rounds
#: positions to 1e-7 m and other numbers to 9 significant digits, so another CPU's or BLAS
#: build's last bits can move a value by one rounding step: <= 1e-7 absolute or 1e-8
#: relative; any change of the importer itself moves numbers by far more).
LIBRARY_ATOL = 2e-7
LIBRARY_RTOL = 1e-7


def assert_same_tree(actual, expected, where: str = "") -> None:
    """Two parsed YAML documents: the same keys, list lengths and strings; numbers within
    LIBRARY_ATOL + LIBRARY_RTOL * |expected|."""
    if isinstance(expected, dict):
        assert isinstance(actual, dict) and list(actual) == list(expected), f"{where}: keys differ"
        for k in expected:
            assert_same_tree(actual[k], expected[k], f"{where}.{k}")
    elif isinstance(expected, list):
        assert isinstance(actual, list) and len(actual) == len(expected), f"{where}: lengths differ"
        for i, (a, e) in enumerate(zip(actual, expected)):
            assert_same_tree(a, e, f"{where}[{i}]")
    elif isinstance(expected, (int, float)) and not isinstance(expected, bool):
        assert isinstance(actual, (int, float)) and not isinstance(actual, bool), f"{where}: {actual!r} is no number"
        assert abs(actual - expected) <= LIBRARY_ATOL + LIBRARY_RTOL * abs(expected), \
            f"{where}: {actual!r} != {expected!r}"
    else:
        assert actual == expected, f"{where}: {actual!r} != {expected!r}"


def test_library_tree_comparison_sees_changes():
    doc = {"muscle": "m", "axis": [{"bone": "b", "at": [0.1, 0.2, 0.3]}], "tendons": [0.2, 0.3]}
    assert_same_tree({"muscle": "m", "axis": [{"bone": "b", "at": [0.1 + 1e-7, 0.2, 0.3]}],
                      "tendons": [0.2 * (1 + 1e-8), 0.3]}, doc)  # one rounding step: same
    for bad in ({"muscle": "n", "axis": doc["axis"], "tendons": doc["tendons"]},
                {"muscle": "m", "axis": [{"bone": "b", "at": [0.1 + 1e-6, 0.2, 0.3]}], "tendons": [0.2, 0.3]},
                {"muscle": "m", "axis": doc["axis"], "tendons": [0.2, 0.3, 0.0]},
                {"muscle": "m", "axis": doc["axis"]}):
        with pytest.raises(AssertionError):
            assert_same_tree(bad, doc)


def test_shipped_library_is_up_to_date(tmp_path):
    """`make import` output committed in the repository equals a fresh import, within the
    rounding of its numbers (not byte for byte: see LIBRARY_ATOL)."""
    import yaml

    lib = REPO / "muscles" / "arm26"
    if not lib.is_dir():
        pytest.skip("library not generated")
    for name, model, extra in (
        ("arm26", ARM, ["--motion", str(ARM_Q), "--controls", str(ARM_CTRL), "--fps", "60",
                        "--pose-name", "arm26_flex"]),
        ("gait2392", GAIT, ["--motion", str(GAIT_Q), "--controls", str(GAIT_CTRL), "--pose-name", "gait2392_walk"]),
    ):
        rc, out = run_import(tmp_path, model, "--name", name, *extra, out=name)
        assert rc == 0
        pose = next(out.glob("*.yaml"))
        pairs = [(p, REPO / "muscles" / name / p.name) for p in sorted((out / "muscles").glob("*.yaml"))]
        pairs += [(out / "skeletons" / f"{name}.yaml", REPO / "poses" / "skeletons" / f"{name}.yaml"),
                  (pose, REPO / "poses" / pose.name)]
        assert sorted(p.name for p in (REPO / "muscles" / name).glob("*.yaml")) == \
            sorted(p.name for p in (out / "muscles").glob("*.yaml"))
        for fresh, committed in pairs:
            assert_same_tree(yaml.safe_load(fresh.read_text()), yaml.safe_load(committed.read_text()),
                             committed.relative_to(REPO).as_posix())
        for mesh in sorted((out / "skeletons" / "meshes" / name).glob("*.ply")):  # read and scaled only: exact
            assert mesh.read_bytes() == (REPO / "poses" / "skeletons" / "meshes" / name / mesh.name).read_bytes()


def test_bad_body_name_points_at_the_osim_line(tmp_path, capsys):
    """A body name axdf cannot use is reported at its line in the .osim, not in a
    YAML that was never written."""
    from osim_common import ARM, run_import

    text = ARM.read_text()
    bad = tmp_path / "bad.osim"
    bad.write_text(text.replace('"r_humerus"', '"r humerus"').replace(">r_humerus<", ">r humerus<")
                   .replace("/r_humerus<", "/r humerus<"))
    line = text[:text.index('<Body name="r_humerus"')].count("\n") + 1
    rc, out = run_import(tmp_path, bad, "--no-meshes")
    err = capsys.readouterr().err
    assert rc == 2
    assert f"bad.osim:{line}:" in err and "r humerus" in err, err
    assert not out.exists()


def test_an_import_names_the_pack_command_that_runs(tmp_path, capsys, monkeypatch):
    """The import's last line names the next step, `axdf pack` for the muscles, skeleton and pose
    it wrote (paths from the current folder), and that command runs as printed: the packed
    muscles then keep under a tenth of the overlap the imported ones have at rest."""
    import shlex

    from axdf_cli.cli.main import main

    monkeypatch.chdir(tmp_path)
    assert main(["import", "osim", str(ARM), "--out", "imp", "--motion", str(ARM_Q), "--fps", "60"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("next: axdf pack imp/muscles --skeleton imp/skeletons/arm26.yaml --pose imp/")
    argv = shlex.split(line[len("next: "):].split("  (")[0])
    assert argv[-2:] == ["--out", "imp/muscles_packed"]
    assert main(argv[1:] + ["-q"]) == 0
    report = json.loads((tmp_path / "imp" / "muscles_packed" / "pack_report.json").read_text())
    assert report["after"]["inside_muscle"] < 0.1 * report["before"]["inside_muscle"]
    # -q: no summary, no next step
    assert main(["import", "osim", str(ARM), "--out", "imp2", "-q"]) == 0
    assert "next:" not in capsys.readouterr().out


@needs_data
def test_handsfield_volumes_size_the_lower_limb_by_height_and_mass(tmp_path, capsys):
    """--volumes handsfield: each lower limb muscle's rest volume is the regression's
    (Handsfield 2014: b1 x (47 h m + 1285) + b2 cm^3), a paper muscle of several model muscles
    (gluteus maximus: glut_max1..3) is split by max force and sums to it, a muscle the paper did
    not measure (erector spinae) keeps the PCSA law's volume, and IMPORT.md says which law."""
    from axdf_cli.importers.volumes import HANDSFIELD, Subject

    rc, base = run_import(tmp_path, GAIT, out="pcsa")
    assert rc == 0
    rc, hf = run_import(tmp_path, GAIT, "--volumes", "handsfield", "--height", "1.80", "--mass", "75", out="hf")
    assert rc == 0
    pcsa = {m["muscle"]: m for m in json.loads((base / "import_report.json").read_text())["muscles"]}
    rows = {m["muscle"]: m for m in json.loads((hf / "import_report.json").read_text())["muscles"]}
    coef = {name: (b1, b2) for name, b1, b2, *_ in HANDSFIELD}
    total = Subject(1.80, 75.0).total_cm3
    assert total == pytest.approx(7630.0)

    def expected(group):
        b1, b2 = coef[group]
        return (b1 * total + b2) * 1e-6

    for side in "rl":
        vl = rows[f"vas_lat_{side}"]
        assert vl["volume_law"] == "handsfield2014" and vl["volume_group"] == "vastus lateralis"
        assert vl["rest_volume_m3"] == pytest.approx(expected("vastus lateralis"), rel=0.02)  # the mesh holds it
        glut = [rows[f"glut_max{k}_{side}"] for k in (1, 2, 3)]
        assert sum(g["volume_m3"] for g in glut) == pytest.approx(expected("gluteus maximus"), rel=1e-6)
        forces = [pcsa[f"glut_max{k}_{side}"]["pcsa_m2"] for k in (1, 2, 3)]
        assert [g["volume_share"] for g in glut] == pytest.approx([f / sum(forces) for f in forces], rel=1e-6)
        assert rows[f"ercspn_{side}"]["volume_law"] == "pcsa"
        assert rows[f"ercspn_{side}"]["volume_m3"] == pytest.approx(pcsa[f"ercspn_{side}"]["volume_m3"], rel=1e-9)
    # the example: vastus lateralis was 0.29x its prediction, the short head 2.1x
    assert pcsa["vas_lat_r"]["volume_m3"] < 0.35 * rows["vas_lat_r"]["volume_m3"]
    assert pcsa["bifemsh_r"]["volume_m3"] > 2.0 * rows["bifemsh_r"]["volume_m3"]
    assert "Handsfield et al. (2014)" in (hf / "IMPORT.md").read_text()
    assert "volume_law" not in pcsa["vas_lat_r"]  # the default import's report is as it was


@pytest.mark.parametrize("extra,expect", [
    (["--volumes", "handsfield", "--height", "1.8"], "--volumes handsfield without --mass"),
    (["--volumes", "handsfield", "--height", "18", "--mass", "75"], "--height 18"),
    (["--mass", "75"], "--mass without --volumes handsfield"),
])
def test_handsfield_volumes_need_a_plausible_subject(tmp_path, capsys, extra, expect):
    rc, out = run_import(tmp_path, ARM, *extra)
    err = capsys.readouterr().err
    assert rc == 2 and expect in err and "Traceback" not in err, err
    assert not out.exists()


def test_handsfield_groups_cover_the_rajagopal_and_myosuite_legs(repo_root):
    """Every leg muscle of MyoSuite's myobody (Rajagopal 2016's names) belongs to one of the
    paper's muscles, and the four adductor magnus heads share its volume by force."""
    from axdf_cli.importers.volumes import Subject, regression_volumes

    legs = sorted(p.stem for p in (repo_root / "muscles" / "myobody").glob("*_r.yaml")
                  if re.match(r"(add|bf|e[dh]l|f[dh]l|gas|gl|grac|iliacus|per|piri|psoas|recfem|sart|semi|soleus|tfl|tib|vas)",
                              p.stem))
    assert len(legs) == 40
    sized = regression_volumes([(n, 100.0 * (k + 1)) for k, n in enumerate(legs)], Subject(1.70, 70.0))
    assert sorted(sized) == legs
    heads = [sized[n] for n in legs if n.startswith("addmag")]
    assert len(heads) == 4 and {h.group for h in heads} == {"adductor magnus"}
    assert sum(h.share for h in heads) == pytest.approx(1.0)
