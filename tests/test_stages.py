"""The pipeline's rules, proven with the test stages of tests/stage_doubles.py: a
TIME stage that carries a real state (exponential smoothing of the axis from the pose's first
frame) and a FRAME stage that depends on every muscle of a frame (each muscle moved by the
others' mean centroid). With either or both, ``--jobs 2``, an interrupted or killed run
finished with ``--resume``, and ``--frames`` subsets give the bytes of one plain run; the
render sink, ``--strict``, the manifest and data sets go through the same stages."""
from __future__ import annotations

import csv
import io
import json
import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import stage_doubles
from conftest import all_files, run_main
from test_safety import project  # noqa: F401  (the demo library in a tmp folder, as the current folder)

RUN = ["run", "poses/jobs/demo.yaml", "--no-render", "-q"]
FULL = "0:150"  # with TIME_BLOCK 32 (set below): five timeline blocks
FORMATS = "ply,npz,pc2"
SETS = [("smooth",), ("push",), ("smooth", "push")]
SMALL_BLOCK = 32  # the timeline block in these tests, so that 150 frames span several


PRODUCT_FRAME_STAGES = ("contact", "penetration")


def use_stages(monkeypatch, names, block: int | None = SMALL_BLOCK) -> None:
    """Register the test stages ``names`` in the package's table (the product's FRAME stages,
    contact and penetration, are left out; the real jiggle stays; forked workers inherit the
    table)."""
    from axdf_cli.pipeline import evaluate, stages

    monkeypatch.setattr(stages, "STAGES", {k: v for k, v in stages.STAGES.items() if k not in PRODUCT_FRAME_STAGES})
    for n in names:
        monkeypatch.setitem(stages.STAGES, n, stage_doubles.DOUBLES[n])
    if block is not None:
        monkeypatch.setattr(evaluate, "TIME_BLOCK", block)


def run(capsys, out, *extra) -> None:
    rc, _, err = run_main(RUN + ["--out", out, *extra], capsys)
    assert rc == 0, err


def rows_of(text: str, frames) -> list:
    """The CSV's rows (header kept) whose first column is one of ``frames``."""
    rows = list(csv.reader(io.StringIO(text)))
    keep = {str(f) for f in frames}
    return [rows[0]] + [r for r in rows[1:] if r[0] in keep]


def assert_same_frames(sub: Path, full: Path, frames) -> None:
    """Every file of the subset run ``sub`` holds what the full run ``full`` holds at those frames."""
    from axdf_cli.formats import read_sequence

    full_frames = json.loads((full / "manifest.json").read_text())["frames"]
    at = [full_frames.index(f) for f in frames]
    plys = sorted(p.relative_to(sub) for p in sub.rglob("meshes/*/*.ply"))
    assert len(plys) == 7 * len(frames)
    for rel in plys:
        assert (sub / rel).read_bytes() == (full / rel).read_bytes(), rel
    for rel in sorted(p.relative_to(sub) for p in sub.glob("npz/*.npz")):
        a, b = np.load(sub / rel), np.load(full / rel)
        np.testing.assert_array_equal(a["points"], b["points"][at], err_msg=str(rel))
        np.testing.assert_array_equal(a["normals"], b["normals"][at], err_msg=str(rel))
    for rel in sorted(p.relative_to(sub) for p in sub.glob("pc2/*.pc2")):
        np.testing.assert_array_equal(np.asarray(read_sequence(sub / rel).points),
                                      np.asarray(read_sequence(full / rel).points)[at], err_msg=str(rel))
    for table in ("stats.csv", "bones.csv"):
        assert rows_of((sub / table).read_text(), frames) == rows_of((full / table).read_text(), frames), table


# ----------------------------------------------------------------------------- what the stages declare


def test_the_split_follows_the_declared_scopes(project, monkeypatch):
    from axdf_cli.pipeline import evaluate_plan, plan_run
    from axdf_cli.pipeline.execute import split_of
    from axdf_cli.specs import load_job

    def plan():
        return plan_run(load_job("poses/jobs/demo.yaml"), frames_arg="0:3")

    # the demo's gastrocnemius jiggles (TIME); contact and its measures are FRAME stages
    assert [s.name for s in plan().stages] == ["jiggle", "contact"]  # contact is on by default
    assert split_of(plan()) == "frames"  # (a FRAME stage needs every muscle of a frame)
    off = plan_run(load_job("poses/jobs/demo.yaml"), frames_arg="0:3", stages={"contact": False})
    assert [s.name for s in off.stages] == ["jiggle"] and split_of(off) == "muscles"
    use_stages(monkeypatch, [])
    assert [s.name for s in plan().stages] == ["jiggle"] and split_of(plan()) == "muscles"
    use_stages(monkeypatch, ["smooth"])
    assert [s.name for s in plan().stages] == ["jiggle", "smooth"] and split_of(plan()) == "muscles"
    (chunk, results), = list(evaluate_plan(plan(), muscles=[2]))
    assert chunk.muscles == [2] and [j for j, _ in results] == [2]
    use_stages(monkeypatch, ["push"])
    assert split_of(plan()) == "frames"
    (chunk, results), = list(evaluate_plan(plan(), muscles=[2]))  # a FRAME stage needs every muscle
    assert chunk.muscles == list(range(7)) and [j for j, _ in results] == list(range(7))


@pytest.mark.parametrize("names", SETS, ids="+".join)
def test_the_stages_change_the_meshes(project, capsys, monkeypatch, names):
    use_stages(monkeypatch, [])
    run(capsys, "plain", "--frames", "100:101")
    use_stages(monkeypatch, names)
    run(capsys, "staged", "--frames", "100:101")
    for rel in ("meshes/biceps_brachii/biceps_brachii_0101.ply", "meshes/deltoid_middle/deltoid_middle_0100.ply"):
        assert (project / "plain" / rel).read_bytes() != (project / "staged" / rel).read_bytes(), rel


# ----------------------------------------------------------------------------- the same bytes, however split


@pytest.mark.parametrize("names", SETS, ids="+".join)
def test_two_jobs_give_the_bytes_of_one(project, capsys, monkeypatch, names):
    use_stages(monkeypatch, names)
    run(capsys, "one", "--frames", FULL, "--format", FORMATS)
    run(capsys, "two", "--frames", FULL, "--format", FORMATS, "--jobs", "2")
    one, two = all_files(project / "one"), all_files(project / "two")
    assert sorted(one) == sorted(two)
    assert [k for k in one if one[k] != two[k]] == []
    assert not [p for p in (project / "two").iterdir() if p.name.startswith(".axdf-tmp-")]  # no spill left


@pytest.mark.parametrize("names", SETS, ids="+".join)
def test_frame_subsets_give_the_bytes_of_the_whole_run(project, capsys, monkeypatch, names):
    use_stages(monkeypatch, names)
    run(capsys, "full", "--frames", FULL, "--format", FORMATS)
    for k, frames in enumerate(["37:150:9", "100", "31:33"]):  # (31:33 crosses a timeline block)
        run(capsys, f"sub{k}", "--frames", frames, "--format", FORMATS, "--jobs", str(1 + k % 2))
        sel = json.loads((project / f"sub{k}" / "manifest.json").read_text())["frames"]
        assert_same_frames(project / f"sub{k}", project / "full", sel)


def test_a_subset_computes_the_frames_before_it(project, capsys, monkeypatch):
    """The smoothing's state at frame 149 comes from frames 0..148, none of them selected: a
    run that started its state at the first selected frame would give other bytes."""
    from axdf_cli.pipeline import evaluate, evaluate_plan, plan_run
    from axdf_cli.specs import load_job

    use_stages(monkeypatch, ["smooth"])
    plan = plan_run(load_job("poses/jobs/demo.yaml"), frames_arg="149", stages={"jiggle": False})
    prep = evaluate.prepare(plan)
    assert sorted(prep.states) == [149 // SMALL_BLOCK]  # one state kept: the block holding frame 149
    (_, results), = list(evaluate_plan(plan, prep))
    kept = {j: r.vertices for j, r in results}
    fresh = evaluate.Prepass(prep.twist, {b: (stage_doubles.SmoothAxis().start(plan),) for b in prep.states})
    (_, results), = list(evaluate_plan(plan, fresh))  # the state of an empty history at the block's start
    assert any(not np.array_equal(kept[j], r.vertices) for j, r in results)


@pytest.mark.parametrize("names", SETS, ids="+".join)
def test_an_interrupted_run_resumed_gives_the_bytes_of_one_run(project, capsys, monkeypatch, names):
    from axdf_cli.fileio import atomic

    use_stages(monkeypatch, names)
    run(capsys, "whole", "--frames", FULL, "--format", FORMATS)
    real = atomic.write_parts
    calls = {"n": 0}

    def interrupted(path, parts):
        calls["n"] += 1
        if calls["n"] == 400:
            raise KeyboardInterrupt
        return real(path, parts)

    monkeypatch.setattr(atomic, "write_parts", interrupted)
    rc, _, err = run_main(RUN + ["--out", "cut", "--frames", FULL, "--format", FORMATS], capsys)
    monkeypatch.setattr(atomic, "write_parts", real)
    assert rc == 130, err
    assert not json.loads((project / "cut" / "manifest.json").read_text())["complete"]
    rc, _, err = run_main(RUN + ["--out", "cut", "--frames", FULL, "--format", FORMATS, "--resume", "--jobs", "2"],
                          capsys)
    assert rc == 0, err
    assert all_files(project / "cut") == all_files(project / "whole")


def test_a_killed_jobs_run_resumed_gives_the_bytes_of_one_run(project, capsys, monkeypatch):
    """SIGKILL to a real ``axdf run --jobs 2`` with both stages (frames split over workers,
    spilled blocks), then --resume in process."""
    use_stages(monkeypatch, ["smooth", "push"], block=None)
    args = ["--frames", "0:191", "--format", "ply,npz"]
    run(capsys, "whole", *args)
    env = dict(os.environ, AXDF_TEST_STAGES="smooth,push", PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, str(Path(stage_doubles.__file__)), *RUN, "--out", "cut", *args,
                          "--jobs", "2"], cwd=project, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    t0 = time.monotonic()
    while sum(1 for _ in (project / "cut").rglob("*.ply")) < 100 and time.monotonic() - t0 < 120:
        time.sleep(0.01)
    p.send_signal(signal.SIGKILL)
    p.communicate(timeout=60)
    assert p.returncode == -signal.SIGKILL  # killed mid-run, not finished
    rc, _, err = run_main(RUN + ["--out", "cut", *args, "--resume"], capsys)
    assert rc == 0, err
    assert all_files(project / "cut") == all_files(project / "whole")  # (no temporary or spill left either)


# ----------------------------------------------------------------------------- one evaluation path


class NoBones:
    """A bone layout that draws no bone (picklable, as a render worker receives it)."""

    def transforms(self, world):
        return None


def test_render_frames_are_the_meshes_the_run_wrote(project, capsys, monkeypatch):
    """The frames sink (what render workers evaluate, pickled to them) gives the written meshes
    for any frames, the resumed render's gaps included."""
    from axdf_cli.formats import read_triangles
    from axdf_cli.pipeline import plan_run, prepare
    from axdf_cli.pipeline.frames import PlanFrames
    from axdf_cli.specs import load_job

    use_stages(monkeypatch, ["smooth", "push"])
    run(capsys, "out", "--frames", FULL)
    plan = plan_run(load_job("poses/jobs/demo.yaml"), frames_arg=FULL)
    source = pickle.loads(pickle.dumps(PlanFrames(plan, prepare(plan), NoBones())))
    wanted = [3, 4, 5, 40, 96, 97, 150]
    got = [f for c in source.chunks(wanted) for f in c.frames]
    assert got == wanted
    for c in source.chunks(wanted):
        for k, f in enumerate(c.frames):
            for j, name in enumerate(plan.names):
                v, n, _ = read_triangles((project / "out" / "meshes" / name / f"{name}_{f:04d}.ply").read_bytes(),
                                         ".ply")
                np.testing.assert_array_equal(c.positions[j][k], v)
                np.testing.assert_array_equal(c.normals[j][k], n)


def test_strict_and_stats_see_a_stage_s_warnings(project, capsys, monkeypatch):
    use_stages(monkeypatch, ["warn"])
    rc, _, err = run_main(RUN + ["--out", "strict", "--frames", "0:2", "--strict"], capsys)
    assert rc == 2 and "a test stage's warning" in err, err
    assert not (project / "strict").exists()  # refused before the first byte
    run(capsys, "loose", "--frames", "0:2")
    assert (project / "loose" / "stats.csv").read_text().count("a test stage's warning") == 3


def test_the_manifest_records_the_stages_and_resume_refuses_a_change(project, capsys, monkeypatch):
    use_stages(monkeypatch, [])
    run(capsys, "none", "--frames", "0:2", "--no-jiggle")  # (the demo's gastrocnemius jiggles)
    use_stages(monkeypatch, ["smooth", "push"])
    run(capsys, "both", "--frames", "0:2", "--no-jiggle")
    settings = json.loads((project / "both" / "manifest.json").read_text())["settings"]
    assert settings["stages"] == [{"name": "smooth", "scope": "time", "alpha": stage_doubles.ALPHA},
                                  {"name": "push", "scope": "frame", "gain": stage_doubles.GAIN}]
    assert "stages" not in json.loads((project / "none" / "manifest.json").read_text())["settings"]
    rc, _, err = run_main(RUN + ["--out", "both", "--frames", "0:2", "--resume", "--no-push", "--no-jiggle"], capsys)
    assert rc == 2 and "--resume would mix two runs" in err and "settings.stages" in err, err
    # every stage switched off: the bytes of a run without stages, manifest included
    run(capsys, "off", "--frames", "0:2", "--no-push", "--no-smooth", "--no-jiggle")
    assert all_files(project / "off") == all_files(project / "none")


def test_a_data_set_goes_through_the_stages(tmp_path, monkeypatch):
    """A data set's sequences are runs of the same pipeline: the smoothing moves the walk's
    frame 8 (its state runs over frames 0..8, only 0, 4, 8 selected), and dataset.json names
    the stage. (Its pool's workers build their context from the stage table as the package
    defines it, so this test, which registers a stage at run time, builds with one worker.)"""
    from dataset_helpers import build_in, write_tiny

    write_tiny(tmp_path)
    use_stages(monkeypatch, [])
    ref = build_in(tmp_path, "ref")
    use_stages(monkeypatch, ["smooth"])
    staged = build_in(tmp_path, "staged")
    mesh = "seq_00005/meshes/chainm/chainm_0008.ply"
    assert (ref / mesh).read_bytes() != (staged / mesh).read_bytes()
    assert "stages" not in json.loads((ref / "dataset.json").read_text())
    assert json.loads((staged / "dataset.json").read_text())["stages"][0]["name"] == "smooth"


def test_the_job_keys_that_switch_stages_are_the_stages(capsys):
    """specs/job.py (below the pipeline) names the job keys of the stages; they are the table's,
    and each stage has --<name> and --no-<name>."""
    from axdf_cli.cli.main import build_parser
    from axdf_cli.pipeline.stages import stage_default, switched
    from axdf_cli.specs.job import STAGE_KEYS

    assert STAGE_KEYS == switched()
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "--help"])
    out = capsys.readouterr().out
    for name in switched():
        assert f"--{name}, --no-{name}" in out
        assert ("else on" if stage_default(name) else "else off") in out


def test_contact_is_on_by_default_and_off_with_the_flag_or_the_job(project, capsys):
    """`axdf run` runs contact (stats.csv with its measures, the manifest naming the stage);
    `--no-contact` or a job's `contact: false` leaves it out, and the measures with it."""
    import csv as _csv

    from axdf_cli.pipeline.stages import stage_default

    assert stage_default("contact") and not stage_default("penetration")
    run(capsys, "plain", "--frames", "20", "--no-jiggle", "--no-contact")
    run(capsys, "touch", "--frames", "20", "--no-jiggle")
    head = {n: next(_csv.reader(open(f"{n}/stats.csv"))) for n in ("plain", "touch")}
    assert "inside_muscle" not in head["plain"] and head["touch"][-4:] == ["inside_muscle", "inside_bone", "depth",
                                                                          "warning"]
    stages = {n: json.loads(Path(n, "manifest.json").read_text())["settings"].get("stages") for n in head}
    assert stages["plain"] is None and [s["name"] for s in stages["touch"]] == ["contact"]
    job = Path("poses/jobs/demo.yaml").read_text() + "\ncontact: false\n"
    Path("poses/jobs/plain_job.yaml").write_text(job.replace("out:", "# out:"))
    rc, _, err = run_main(["run", "poses/jobs/plain_job.yaml", "--frames", "20", "--no-jiggle", "--no-render", "--out", "plain2",
                           "-q"], capsys)
    assert rc == 0, err
    assert all_files(Path("plain2")).keys() == all_files(Path("plain")).keys()
    assert next(_csv.reader(open("plain2/stats.csv"))) == head["plain"]


def test_a_data_set_file_switches_contact_off(tmp_path, capsys, monkeypatch):
    """A data-set file takes a job's stage keys: every sequence collides by default, as with
    `contact: true` (dataset.json names the stage; the chain's muscle runs through its joint
    balls, so contact moves it); `contact: false` leaves it out; `contact: 3` is exit 2 at its
    line."""
    from dataset_helpers import DATASET_YAML, build_in, write_tiny

    write_tiny(tmp_path / "plain", DATASET_YAML + "contact: false\n")
    write_tiny(tmp_path / "touch", DATASET_YAML + "contact: true\n")
    write_tiny(tmp_path / "default")
    plain, touch = build_in(tmp_path / "plain", "out"), build_in(tmp_path / "touch", "out")
    default = build_in(tmp_path / "default", "out")
    assert json.loads((default / "dataset.json").read_text())["stages"] == json.loads(
        (touch / "dataset.json").read_text())["stages"]
    assert "stages" not in json.loads((plain / "dataset.json").read_text())
    assert [s["name"] for s in json.loads((touch / "dataset.json").read_text())["stages"]] == ["contact"]
    mesh = "seq_00005/meshes/chainm/chainm_0008.ply"
    assert (plain / mesh).read_bytes() != (touch / mesh).read_bytes() == (default / mesh).read_bytes()
    write_tiny(tmp_path / "bad", DATASET_YAML + "contact: 3\n")
    monkeypatch.chdir(tmp_path / "bad")
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "out"], capsys)
    line = DATASET_YAML.count("\n") + 1
    assert rc == 2 and f"tiny.yaml:{line}:10: contact" in err and "true or false" in err, err
    assert not (tmp_path / "bad" / "out").exists()
