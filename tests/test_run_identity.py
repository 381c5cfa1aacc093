"""What a run records of itself: its inputs named the same from any folder,
the coordinates its pose takes outside their ranges, and an identity that ``--resume``
compares: every flag that changes an output (``--clamp-ranges``) and each stage's own
sources, but none of the tools' constants. Small synthetic projects; the CLI in process."""
from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest

from conftest import CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML, REPO_ROOT, run_main

#: The chain with two ranges: ``turn`` turns the whole chain (b0, every bone: a room
#: coordinate, as pelvis_rotation is, which moves no muscle's shape) and ``bend`` bends b3.
SKELETON = CHAIN_SKELETON_YAML.replace(
    "  roll: {type: rotation, default: 0}\n",
    "  roll: {type: rotation, default: 0}\n  turn: {type: rotation, default: 0, range: [-90, 90]}\n").replace(
    "  - name: b0\n", "  - name: b0\n    dofs:\n      - {coord: turn, type: rotation, axis: [0, 0, 1]}\n").replace(
    "      - {coord: bend, type: rotation, axis: [1, 0, 0]}",
    "      - {coord: bend, type: rotation, axis: [1, 0, 0], range: [-140, 0]}")

#: turn(f) = 30 f and bend(f) = -50 f over frames 0..6, back to 0 at 9 (linear): turn is
#: outside [-90, 90] at 4..7 (120, 150, 180, 120), bend outside [-140, 0] at 3..7 (-150 .. -300 .. -200).
POSE = """\
pose: p
skeleton: chain.yaml
frames: [0, 9]
interpolation: linear
keys:
  0: {turn: 0, bend: 0}
  6: {turn: 180, bend: -300}
  9: {turn: 0, bend: 0}
"""


@pytest.fixture
def proj(tmp_path, monkeypatch):
    """A project folder: chain.yaml, m/chainm.yaml, p.yaml; the current folder is another one."""
    p = tmp_path / "proj"
    (p / "m").mkdir(parents=True)
    (p / "chain.yaml").write_text(SKELETON)
    (p / "m" / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    (p / "p.yaml").write_text(POSE)
    (tmp_path / "elsewhere" / "deeper").mkdir(parents=True)
    monkeypatch.chdir(p)
    return p


def run_args(proj: Path, out: Path, *extra) -> list:
    """``axdf run`` with absolute paths (the same words from any folder)."""
    return ["run", "--muscles", proj / "m", "--pose", proj / "p.yaml", "--out", out, "--no-render", *extra]


def manifest(out: Path) -> dict:
    return json.loads((out / "manifest.json").read_text())


# ----------------------------------------------------------------------------- inputs named from any folder


def test_the_same_inputs_are_named_the_same_from_any_folder_and_resume(proj, capsys, monkeypatch):
    out = proj.parent / "out"
    rc, _, err = run_main(run_args(proj, out), capsys)
    assert rc == 0, err
    first = (out / "manifest.json").read_bytes()
    m = json.loads(first)
    # named from the deepest folder holding every input (here the project), never from the current folder
    assert sorted(m["inputs"]) == ["chain.yaml", "m/chainm.yaml", "p.yaml"]
    assert [x["source"] for x in m["muscles"]] == ["m/chainm.yaml"]

    for i, where in enumerate((proj.parent / "elsewhere", proj.parent / "elsewhere" / "deeper", proj / "m")):
        monkeypatch.chdir(where)
        rc, _, err = run_main(run_args(proj, out, "--resume"), capsys)
        assert rc == 0, f"from {where}: {err}"
        assert (out / "manifest.json").read_bytes() == first, where  # the same inputs, the same bytes
        other = proj.parent / f"o{i}"
        rc, _, err = run_main(run_args(proj, other), capsys)
        assert rc == 0, err
        assert (other / "manifest.json").read_bytes() == first, where

    # relative paths from another folder name the same files the same way
    monkeypatch.chdir(proj.parent / "elsewhere")
    rc, _, err = run_main(["run", "--muscles", "../proj/m", "--pose", "../proj/p.yaml", "--out", out, "--no-render",
                           "--resume"], capsys)
    assert rc == 0, err
    assert (out / "manifest.json").read_bytes() == first


def test_the_shipped_golden_job_keeps_its_input_names(monkeypatch, tmp_path):
    """The shipped jobs' inputs lie below the project: named from its root, as tests/golden's
    manifest names them, whatever the current folder."""
    from axdf_cli.pipeline import plan_run
    from axdf_cli.specs import RefPolicy, load_job

    golden = json.loads((REPO_ROOT / "tests" / "golden" / "manifest.json").read_text())
    monkeypatch.chdir(tmp_path)
    job = REPO_ROOT / "tests" / "golden_job.yaml"
    plan = plan_run(load_job(job, RefPolicy.for_command([job])))
    assert plan.inputs == golden["inputs"]


# ----------------------------------------------------------------------------- coordinates outside their ranges


def test_each_coordinate_outside_its_range_is_reported_with_its_frames(proj, capsys):
    out = proj / "o"
    rc, _, err = run_main(run_args(proj, out), capsys)
    assert rc == 0, err
    lines = [ln for ln in err.splitlines() if "outside its range" in ln]
    assert lines == [
        "warning: bend is outside its range [-140, 0] in 5 of 10 frames: 3-7 (keyed -300 to -150; "
        "--clamp-ranges holds it inside)",
        "warning: turn is outside its range [-90, 90] in 4 of 10 frames: 4-7 (keyed 120 to 180; "
        "--clamp-ranges holds it inside)",
    ], err
    assert manifest(out)["ranges"] == [
        {"coordinate": "bend", "range": [-140.0, 0.0], "frames": "3-7", "count": 5, "keyed": [-300.0, -150.0],
         "clamped": False},
        {"coordinate": "turn", "range": [-90.0, 90.0], "frames": "4-7", "count": 4, "keyed": [120.0, 180.0],
         "clamped": False},
    ]
    # the room coordinate moves the muscle rigidly: stats.csv's per-muscle warnings name bend only
    stats = (out / "stats.csv").read_text()
    assert "bend = " in stats and "turn = " not in stats

    rc, _, err = run_main(run_args(proj, proj / "q", "--quiet", "--frames", "0:2,5,7:9"), capsys)
    assert rc == 0 and "range" not in err, err
    rec = manifest(proj / "q")["ranges"]
    assert [(r["coordinate"], r["frames"], r["count"]) for r in rec] == [("bend", "5, 7", 2), ("turn", "5, 7", 2)]


def test_clamped_coordinates_are_said_to_be_clamped(proj, capsys):
    out = proj / "o"
    rc, _, err = run_main(run_args(proj, out, "--clamp-ranges"), capsys)
    assert rc == 0, err
    assert "note: turn was clamped to its range [-90, 90] in 4 of 10 frames: 4-7 (keyed 120 to 180)" in err, err
    assert "outside its range" not in err
    m = manifest(out)
    assert [r["clamped"] for r in m["ranges"]] == [True, True]
    assert m["settings"]["clamp_ranges"] is True
    (proj / "inside.yaml").write_text(POSE.replace("180", "60").replace("-300", "-100"))
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "inside.yaml", "--out", "in", "--no-render"], capsys)
    assert rc == 0 and "range" not in err
    assert "ranges" not in manifest(proj / "in") and "clamp_ranges" not in manifest(proj / "in")["settings"]


# ----------------------------------------------------------------------------- the identity --resume compares


def test_resume_refuses_another_clamp_ranges(proj, capsys):
    out = proj / "o"
    assert run_main(run_args(proj, out), capsys)[0] == 0
    before = (out / "manifest.json").read_bytes()
    rc, _, err = run_main(run_args(proj, out, "--resume", "--clamp-ranges"), capsys)
    assert rc == 2 and "--resume would mix two runs" in err and "settings.clamp_ranges: null -> true" in err, err
    assert (out / "manifest.json").read_bytes() == before
    assert run_main(run_args(proj, out, "--resume"), capsys)[0] == 0


def test_resume_refuses_a_change_to_a_stage_s_own_sources(proj, capsys, monkeypatch):
    from axdf_cli.pipeline import manifest as mf
    from axdf_cli.pipeline.skin_stage import SkinStage
    from axdf_cli.pipeline.stages import ContactStage

    # the skin stage's numerics (outside model/**) are its own sources
    assert mf.stage_sources(object.__new__(SkinStage)) == ["pipeline/skin_stage.py"]
    out = proj / "o"
    assert run_main(run_args(proj, out), capsys)[0] == 0
    assert manifest(out)["identity"]["stages"] == {"contact": {"pipeline/stages.py": mf.source_sha("pipeline/stages.py")}}
    real = mf.source_sha
    with monkeypatch.context() as m:  # the file's bytes change
        m.setattr(mf, "source_sha", lambda rel, path=None: "0" * 64 if rel == "pipeline/stages.py" else real(rel, path))
        rc, _, err = run_main(run_args(proj, out, "--resume"), capsys)
        assert rc == 2 and "the contact stage's source pipeline/stages.py changed" in err, err
    with monkeypatch.context() as m:  # the stage names another source
        m.setattr(ContactStage, "sources", ("pipeline/evaluate.py",), raising=False)
        rc, _, err = run_main(run_args(proj, out, "--resume"), capsys)
        assert rc == 2 and "the contact stage's source pipeline/evaluate.py is new" in err, err
    rc, _, err = run_main(run_args(proj, out, "--resume", "--no-contact"), capsys)
    assert rc == 2 and "the contact stage's sources are gone" in err, err
    assert run_main(run_args(proj, out, "--resume"), capsys)[0] == 0


def test_a_tool_constant_leaves_a_run_s_resume_alone(proj, capsys, monkeypatch):
    from axdf_cli import tolerances
    from axdf_cli.tools import constants

    out = proj / "o"
    assert run_main(run_args(proj, out), capsys)[0] == 0
    for name in ("FIT_SAMPLES", "ATLAS_WARP_ROUNDS", "SKIN_FAT_SMOOTHING", "RETARGET_RMS_SHARE", "PACK_POSE_FRAMES"):
        monkeypatch.setattr(constants, name, getattr(constants, name) * 2)
        assert not hasattr(tolerances, name), name
    rc, _, err = run_main(run_args(proj, out, "--resume"), capsys)
    assert rc == 0, err
    monkeypatch.setattr(tolerances, "CONTACT_MARGIN", tolerances.CONTACT_MARGIN * 2)  # a run's constant: refused
    rc, _, err = run_main(run_args(proj, out, "--resume"), capsys)
    assert rc == 2 and "tolerances.CONTACT_MARGIN" in err, err


def _names_read(path: Path) -> set[str]:
    return set(re.findall(r"\b([A-Z][A-Z0-9_]{2,})\b", path.read_text()))


def test_tolerances_holds_no_constant_only_the_tools_read():
    """Every constant of axdf_cli/tolerances.py that the package reads is read outside the
    tools (tools/, and the CLI of the tools' commands): a tools-only one belongs in
    axdf_cli/tools/constants.py, where no run's identity sees it."""
    package = REPO_ROOT / "axdf_cli"
    tree = ast.parse((package / "tolerances.py").read_text())
    names = [t.id for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
             for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)]
    tools_only = {"tools", "cli"}
    readers: dict[str, set[str]] = {}
    for path in package.rglob("*.py"):
        if path.name == "tolerances.py":
            continue
        rel = path.relative_to(package)
        for n in _names_read(path):
            readers.setdefault(n, set()).add(rel.parts[0] if len(rel.parts) > 1 else rel.stem)
    only = sorted(n for n in names if readers.get(n) and readers[n] <= tools_only)
    assert not only, f"read only by the tools: {only}; move them to axdf_cli/tools/constants.py"
