"""The first hour, round two: a golden check that fails only where a change is
(the golden's camera pinned with ``--camera``, the report naming the muscle), framing by the
body's bounds for every skeleton, a data set's dry run that says its size quickly, and
myoarm's rest pose without a stray rod."""
from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from conftest import REPO_ROOT, run_main

GOLDEN_JOB = REPO_ROOT / "tests" / "golden_job.yaml"
DEMO = REPO_ROOT / "muscles" / "demo"


def _thicker(src, dst, factor: float) -> None:
    """A copy of muscle file ``src`` with every section's radii and outline scaled by ``factor``."""
    def scale(m):
        return "[" + ", ".join(f"{float(x) * factor:.9g}" for x in m.group(1).split(",")) + "]"

    text = src.read_text()
    # radii [a, b] and outline points [v, w]: the pairs followed by "," or "]" (not tendons: [o, i])
    out, n = re.subn(r"\[(-?[0-9.]+, -?[0-9.]+)\](?=[,\]])", scale, text)
    assert n == 3 + 8 and "tendons: [0.15, 0.12]" in out
    dst.write_text(out)


def _compare(tmp_path, capsys, actual, golden):
    report = tmp_path / f"{actual.name}.json"
    rc, out, _ = run_main(["compare", actual, golden, "--report", report], capsys)
    return rc, out, json.loads(report.read_text())


def test_a_one_percent_thicker_muscle_fails_only_its_own_files_and_is_named(tmp_path, capsys):
    golden = tmp_path / "golden"
    rc, _, err = run_main(["run", GOLDEN_JOB, "--out", golden, "--quiet"], capsys)
    assert rc == 0, err
    _thicker(DEMO / "biceps_brachii.yaml", tmp_path / "biceps_brachii.yaml", 1.01)
    muscles = ["--muscles", tmp_path / "biceps_brachii.yaml", DEMO / "brachioradialis.yaml"]

    # the automatic camera frames the muscles: a thicker biceps moves it, and every file fails
    free = tmp_path / "free"
    rc, _, err = run_main(["run", GOLDEN_JOB, *muscles, "--out", free, "--quiet"], capsys)
    assert rc == 0, err
    rc, _, doc = _compare(tmp_path, capsys, free, golden)
    failed = {f["path"] for f in doc["files"] if f["verdict"] != "pass"}
    frames = {f["path"] for f in doc["files"] if f["path"].startswith("frames/")}
    assert rc == 1 and "camera.json" in failed and len(frames) == 6 and frames <= failed, failed

    # pinned to the golden's cameras: only the biceps' meshes, its stats rows and its pixels
    pinned = tmp_path / "pinned"
    rc, _, err = run_main(["run", GOLDEN_JOB, *muscles, "--camera", golden / "camera.json", "--out", pinned,
                           "--quiet"], capsys)
    assert rc == 0, err
    assert json.loads((pinned / "camera.json").read_text())["frames"] == \
        json.loads((golden / "camera.json").read_text())["frames"]
    rc, out, doc = _compare(tmp_path, capsys, pinned, golden)
    assert rc == 1
    verdict = {f["path"]: f for f in doc["files"]}
    failed = {p for p, f in verdict.items() if f["verdict"] != "pass"}
    biceps = {p for p in verdict if p.startswith("meshes/biceps_brachii/")}
    assert len(biceps) == 3 and biceps <= failed
    assert failed - biceps <= {"stats.csv"} | {p for p in verdict if p.startswith("frames/")}, failed
    assert verdict["camera.json"]["verdict"] == "pass" and verdict["bones.csv"]["verdict"] == "pass"
    assert not any(p.startswith("meshes/brachioradialis/") for p in failed)
    if "stats.csv" in failed:
        assert verdict["stats.csv"]["metrics"]["differing_names"].keys() == {"biceps_brachii"}
    on = {}  # failing pixels by the part they show: the biceps' (and a few of its outline it shares)
    for p in failed & {p for p in verdict if p.startswith("frames/")}:
        for name, n in verdict[p]["metrics"]["failing_pixels_by_part"].items():
            on[name] = on.get(name, 0) + n
    assert on.get("(background)", 0) + on.get("brachioradialis", 0) <= 0.1 * on.get("biceps_brachii", 0), on
    assert list(doc["differing_parts"]) == ["biceps_brachii"]
    assert set(doc["pixels_on_unchanged_parts"]) <= {"brachioradialis"}
    assert "parts that differ" in out and "  biceps_brachii: 3 mesh file(s)" in out, out
    assert "brachioradialis:" not in out


def test_a_camera_file_must_fit_the_run(tmp_path, capsys):
    cam = REPO_ROOT / "tests" / "golden" / "camera.json"
    base = ["run", GOLDEN_JOB, "--camera", cam, "--out", tmp_path / "o", "--dry-run"]
    rc, _, err = run_main(base, capsys)
    assert rc == 0, err
    rc, _, err = run_main([*base, "--size", "64x64"], capsys)
    assert rc == 2 and "128x128" in err and "64x64" in err, err
    rc, _, err = run_main([*base, "--frames", "105"], capsys)  # its camera is fixed: any frame has it
    assert rc == 0, err
    moving = json.loads(cam.read_text())
    moving["frames"][1]["cameras"][0]["world_to_camera"][0][3] += 0.1
    (tmp_path / "moving.json").write_text(json.dumps(moving))
    rc, _, err = run_main([*base[:3], tmp_path / "moving.json", *base[4:], "--frames", "105"], capsys)
    assert rc == 2 and "no camera for frame 105" in err, err
    (tmp_path / "bad.json").write_text("{}")
    rc, _, err = run_main([*base[:3], tmp_path / "bad.json", *base[4:]], capsys)
    assert rc == 2 and "bad.json" in err and "frames" in err, err


# ----------------------------------------------------------------------------- sticks
def test_myoarm_draws_no_stick_for_a_frame_without_a_mesh():
    from axdf_cli.specs import load_skeleton

    skel = load_skeleton(REPO_ROOT / "poses" / "skeletons" / "myoarm.yaml")
    meshless = [b.name for b in skel.bones if not b.mesh]
    assert "Arm_attachment" in meshless
    assert skel.stick_parents() == [-1] * len(skel.bones)  # drawn: the bone meshes, nothing more


# ----------------------------------------------------------------------------- a data set's size before it is made
def test_a_dry_run_says_the_size_a_build_makes(tmp_path, capsys):
    src = (REPO_ROOT / "poses" / "datasets" / "demo_small.yaml").read_text()
    src = src.replace("../skeletons/", f"{REPO_ROOT}/poses/skeletons/").replace("../../muscles/", f"{REPO_ROOT}/muscles/")
    src = src.replace("../demo.yaml", f"{REPO_ROOT}/poses/demo.yaml")
    src = re.sub(r"sequences:\n(  - .*\n)+", "sequences:\n  - {sample: uniform, count: 2, frames: 1}\n"
                 "  - {motion: calf}\n", src)
    (tmp_path / "tiny.yaml").write_text(src)
    argv = ["dataset", "build", tmp_path / "tiny.yaml", "--out", tmp_path / "ds", "--allow-outside"]
    rc, out, err = run_main([*argv, "--dry-run"], capsys)
    assert rc == 0, err
    m = re.search(r"would make 3 of 3 sequences \((\d+) frames x 2 view\(s\) = (\d+) samples\)", out)
    assert m and int(m.group(1)) == 2 + 4 and int(m.group(2)) == 12, out
    size = re.search(r"size: about ([0-9.]+) (kB|MB) and (\d+) (s|min) with --jobs 1; estimated from sequences made now: "
                     r"[0-9.]+ s a sequence and [0-9.]+ s and [0-9.]+ (?:kB|MB|B) a sample", out)
    assert size, out
    assert not (tmp_path / "ds").exists()
    rc, out, err = run_main([*argv, "--quiet"], capsys)
    assert rc == 0, err
    made = [p for p in (tmp_path / "ds").rglob("*.png")]
    assert len(made) == 12  # one PNG a sample, as the dry run said
    written = sum(p.stat().st_size for p in (tmp_path / "ds").rglob("*") if p.is_file())
    estimate = float(size.group(1)) * (1e3 if size.group(2) == "kB" else 1e6)
    assert 0.5 * written < estimate < 2 * written, (estimate, written)
