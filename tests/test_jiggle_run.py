"""Jiggle through ``axdf run`` (in process): a hinge that bends and stops makes a muscle ring
with the set frequency and damping ratio, measured from the written meshes; the ring settles
and is the same at 60 and 120 fps; ``--no-jiggle`` gives the bytes of muscle files without
the key; ``--jobs 2``, a SIGKILL plus ``--resume``, frame subsets and render workers give the
bytes of a plain run (twist included: stats.csv)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import curve_fit

from axdf_cli.formats import FORMATS
from conftest import all_files, run_main, write_pose

HZ, ZETA = 4.0, 0.15

HINGE = """\
skeleton: hinge
coordinates:
  knee: {type: rotation, default: 0, range: [-10, 150]}
bones:
  - name: thigh
  - name: shank
    parent: thigh
    offset: [0, 0, -0.4]
    dofs:
      - {coord: knee, type: rotation, axis: [1, 0, 0]}
"""


def muscle_yaml(name: str, side: float, jiggle: bool) -> str:
    text = f"""\
muscle: {name}
color: [0.8, 0.2, 0.2]
axis:
  - {{bone: thigh, at: [{side}, 0.03, -0.12]}}
  - {{bone: thigh, at: [{side}, 0.06, -0.3]}}
  - {{bone: shank, at: [{side}, 0.06, -0.08]}}
  - {{bone: shank, at: [{side}, 0.03, -0.28]}}
sections:
  - {{t: 0.25, radii: [0.02, 0.015], angle: 0}}
  - {{t: 0.5, radii: [0.03, 0.022], angle: 0}}
  - {{t: 0.75, radii: [0.02, 0.015], angle: 0}}
resolution: [21, 12]
"""
    if jiggle:
        text += f"jiggle: {{frequency: {HZ}, damping_ratio: {ZETA}}}\n"
    return text


def hinge_folder(root: Path, fps: int = 120, jiggle: bool = True) -> Path:
    """The hinge skeleton, two muscles across it and a pose at ``fps``: still for 0.1 s, the
    knee bends 60 degrees at constant speed in 0.2 s and stops dead, then holds for 2.7 s."""
    root.mkdir(parents=True, exist_ok=True)
    (root / "hinge.yaml").write_text(HINGE)
    (root / "muscles").mkdir(exist_ok=True)
    (root / "muscles" / "front.yaml").write_text(muscle_yaml("front", 0.02, jiggle))
    (root / "muscles" / "back.yaml").write_text(muscle_yaml("back", -0.02, jiggle))
    k = fps // 60
    write_pose(root, "bend", {0: {"knee": 0}, 6 * k: {"knee": 0}, 18 * k: {"knee": 60}}, [0, 180 * k],
               skeleton="hinge.yaml", fps=fps)
    return root


def run(folder: Path, out: str, capsys, *extra) -> Path:
    render = [] if "--render" in extra else ["--no-render"]
    rc, _, err = run_main(["run", "--muscles", folder / "muscles", "--pose", folder / "bend.yaml",
                           "--out", folder / out, "-q", *render, *extra], capsys)
    assert rc == 0, err
    return folder / out


def centroids(out: Path, muscle: str) -> tuple[np.ndarray, np.ndarray]:
    """Frame numbers and mesh centroids (F, 3) of a muscle, read back from its PLY files."""
    read = FORMATS["ply"].reader
    files = sorted((out / "meshes" / muscle).glob("*.ply"))
    frames = np.array([int(f.stem.rsplit("_", 1)[1]) for f in files])
    return frames, np.array([read(f.read_bytes()).vertices.astype(np.float64).mean(axis=0) for f in files])


def outputs(out: Path) -> dict[str, bytes]:
    """What a run writes but the manifest (which records inputs and settings)."""
    return {k: v for k, v in all_files(out).items() if k != "manifest.json"}


@pytest.fixture(scope="module")
def hinge(tmp_path_factory):
    return hinge_folder(tmp_path_factory.mktemp("hinge"))


@pytest.fixture(scope="module")
def hinge_runs(hinge):
    """The plain run with jiggle and with --no-jiggle (module-wide: several tests read them)."""
    from axdf_cli.cli.main import main

    for out, extra in (("full", []), ("still", ["--no-jiggle"])):
        assert main(["run", "--muscles", str(hinge / "muscles"), "--pose", str(hinge / "bend.yaml"),
                     "--out", str(hinge / out), "--no-render", "-q", *extra]) == 0
    return hinge / "full", hinge / "still"


def ring(full: Path, still: Path, fps: int, muscle: str = "front"):
    """Times (s) and the jiggle's centroid offset (F, 3): the muscle with jiggle minus without."""
    frames, c = centroids(full, muscle)
    _, c0 = centroids(still, muscle)
    return frames / fps, c - c0


def test_a_hinge_that_stops_rings_at_the_set_frequency_and_damping(hinge_runs):
    t, off = ring(*hinge_runs, fps=120)
    assert np.abs(off[t <= 0.1]).max() == 0.0  # at rest before the bend: the pre-roll settled it
    after = t >= 0.3  # the knee stopped at 0.3 s: from here on the muscle rings freely
    ta, oa = t[after] - 0.3, off[after]
    direction = np.linalg.svd(oa, full_matrices=False)[2][0]
    y = oa @ direction
    peak = np.abs(y).max()
    assert peak > 1e-3  # a visible ring: more than a millimetre

    def damped(tt, a, s, wd, ph):
        return a * np.exp(-s * tt) * np.cos(wd * tt + ph)

    # start the fit away from the answer (a tenth off in frequency and damping), from 8 phases
    wd0, s0 = 0.9 * 2 * np.pi * HZ, 1.1 * ZETA * 2 * np.pi * HZ
    best = None
    for ph in np.linspace(-np.pi, np.pi, 8, endpoint=False):
        try:
            p, _ = curve_fit(damped, ta, y, p0=[peak, s0, wd0, ph], maxfev=20000)
        except RuntimeError:
            continue
        r = np.sum((damped(ta, *p) - y) ** 2)
        if best is None or r < best[1]:
            best = (p, r)
    (a, s, wd, _), resid = best
    assert resid < 0.01 * np.sum(y ** 2)  # it is a damped sinusoid
    omega = np.hypot(wd, s)
    assert abs(omega / (2 * np.pi) - HZ) <= 0.1 * HZ, omega / (2 * np.pi)
    assert abs(s / omega - ZETA) <= 0.05, s / omega
    # it settles: the last half second moves less than 1% of the peak
    assert np.abs(y[ta > 2.2]).max() < 0.01 * peak


def test_the_ring_is_the_same_at_60_and_120_fps(tmp_path, hinge_runs, capsys):
    slow = hinge_folder(tmp_path / "h60", fps=60)
    full, still = run(slow, "full", capsys), run(slow, "still", capsys, "--no-jiggle")
    t60, off60 = ring(full, still, 60)
    t120, off120 = ring(*hinge_runs, fps=120)
    assert np.allclose(t120[::2], t60)
    peak = np.linalg.norm(off120, axis=1).max()
    assert np.linalg.norm(off120[::2] - off60, axis=1).max() <= 0.05 * peak


def test_no_jiggle_equals_muscles_without_the_key(tmp_path, hinge_runs, capsys):
    plain = hinge_folder(tmp_path / "plain", jiggle=False)
    out = run(plain, "out", capsys)
    still = outputs(hinge_runs[1])
    assert outputs(out) == still
    assert outputs(hinge_runs[0]) != still  # (and jiggle does change them)
    # the manifest: the stage is recorded when it runs; off, the run is that of muscles without
    # jiggle but for the inputs' sha256 (the muscle files differ)
    on, off, plain_m = (json.loads((d / "manifest.json").read_text()) for d in (*hinge_runs, out))
    assert on["settings"]["stages"][0] == {"name": "jiggle", "scope": "time", "bound": 0.25, "knee": 0.75,
                                           "warmup_eps": 1e-9}
    assert [s["name"] for s in on["settings"]["stages"]] == ["jiggle", "contact"]  # (contact: on by default)
    assert [s["name"] for s in off["settings"]["stages"]] == ["contact"]
    for m in (off, plain_m):
        del m["inputs"]
        for muscle in m["muscles"]:
            del muscle["source"]
    assert off == plain_m


def test_jobs_and_frame_subsets_give_the_same_bytes(hinge, hinge_runs, capsys):
    full = outputs(hinge_runs[0])
    jobs = run(hinge, "jobs", capsys, "--jobs", "2")
    assert outputs(jobs) == full
    sub = outputs(run(hinge, "sub", capsys, "--frames", "37,41:120:13,200"))
    meshes = {k: v for k, v in sub.items() if k.startswith("meshes/")}
    assert len(meshes) == 2 * 9
    assert all(full[k] == v for k, v in meshes.items())
    # stats.csv (length, volume, twist ...): the subset's rows are the full run's
    rows = dict.fromkeys(full["stats.csv"].decode().splitlines())
    assert all(r in rows for r in sub["stats.csv"].decode().splitlines())


def test_a_job_switches_jiggle_off_and_resume_refuses_the_change(hinge, hinge_runs, capsys):
    job = hinge / "job.yaml"
    job.write_text(f"muscles: [muscles]\npose: bend.yaml\nout: jobout\njiggle: false\nframes: '30:40'\n")
    rc, _, err = run_main(["run", job, "--no-render", "-q"], capsys)
    assert rc == 0, err
    still = outputs(hinge_runs[1])
    assert all(still[k] == v for k, v in outputs(hinge / "jobout").items() if k.startswith("meshes/"))
    # the command line has the last word: --jiggle over the job's `jiggle: false`
    rc, _, err = run_main(["run", job, "--no-render", "-q", "--jiggle", "--out", hinge / "jobon"], capsys)
    assert rc == 0, err
    full = outputs(hinge_runs[0])
    on = outputs(hinge / "jobon")
    assert on and all(full[k] == v for k, v in on.items() if k.startswith("meshes/"))
    assert any(still[k] != v for k, v in on.items() if k.startswith("meshes/"))
    # --resume refuses to switch it (here on again, over a --no-jiggle run)
    run(hinge, "off", capsys, "--frames", "30:40", "--no-jiggle")
    rc, _, err = run_main(["run", "--muscles", hinge / "muscles", "--pose", hinge / "bend.yaml", "--frames", "30:40",
                           "--out", hinge / "off", "--no-render", "-q", "--resume"], capsys)
    assert rc == 2 and "jiggle" in err and "--resume would mix two runs" in err, err


def test_sigkill_then_resume_gives_the_same_bytes(hinge, hinge_runs):
    out = hinge / "killed"
    args = [sys.executable, "-m", "axdf_cli", "run", "--muscles", str(hinge / "muscles"), "--pose",
            str(hinge / "bend.yaml"), "--out", str(out), "--no-render", "-q"]
    p = subprocess.Popen(args, env=dict(os.environ, PYTHONUNBUFFERED="1"), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    t0 = time.monotonic()
    while time.monotonic() - t0 < 60 and sum(1 for _ in out.rglob("*.ply")) < 150:
        time.sleep(0.005)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=30)
    assert sum(1 for _ in out.rglob("*.ply")) < 2 * 361  # killed part way
    r = subprocess.run(args + ["--resume"], capture_output=True, timeout=300)
    assert r.returncode == 0, r.stderr.decode()
    assert outputs(out) == outputs(hinge_runs[0])


def test_render_workers_draw_the_jiggled_muscles(hinge, capsys):
    """Render workers evaluate blocks of frames on their own: their frames are those of one
    process (which renders from the same evaluation as the meshes)."""
    one = run(hinge, "r1", capsys, "--frames", "30:45", "--render", "--size", "32x32")
    two = run(hinge, "r2", capsys, "--frames", "30:45", "--render", "--size", "32x32", "--jobs", "2")
    a, b = outputs(one), outputs(two)
    assert any(k.startswith("frames/") for k in a)
    assert a == b


JIGGLE_DATASET = """\
dataset: jig
seed: 3
skeleton: chain.yaml
muscles: [chainm.yaml]
coordinates:
  stretch: {range: [0.0, 0.4]}
  bend: {range: [-50, 50]}
  roll: {range: [-80, 80]}
motions:
  walk: {pose: walk.yaml, frames: "2:8:3"}
sequences:
  - {motion: walk}
  - {sample: uniform, count: 1, frames: 1}
activation: none
cameras:
  sphere: {views: 1, distance: [1.2, 1.5], elevation: [0, 20], fov: 40}
render: {size: [24, 24], supersample: 1}
"""

# The tiny data set's walk, but its stretch (which alone moves the chain muscle's free control
# points) stops at frame 3: a change of velocity that rings. (At constant velocity from its
# first frame the muscle would ride on its target: jiggle starts from a constant-velocity
# pre-roll, tests/test_jiggle_preroll.py.)
JIGGLE_WALK = """\
pose: walk
skeleton: chain.yaml
fps: 24
frames: [0, 8]
keys:
  0: {bend: 0, roll: 0, stretch: 0.1}
  3: {bend: 15, roll: 20, stretch: 0.3}
  8: {bend: 40, roll: 60, stretch: 0.3}
"""


def test_data_set_sequences_honour_jiggle(tmp_path, monkeypatch, capsys):
    """A data set's motion sequence is the run of its frames (jiggle carried from the motion's
    first frame, though the sequence starts at frame 2); a single-frame sample has no
    history: it is the muscle at rest on its pose, as without jiggle."""
    from dataset_helpers import write_tiny

    from conftest import CHAIN_MUSCLE_YAML

    sets = {}
    for name, muscle in (("jig", CHAIN_MUSCLE_YAML + "jiggle: {frequency: 3, damping_ratio: 0.1}\n"),
                         ("still", CHAIN_MUSCLE_YAML)):
        d = tmp_path / name
        write_tiny(d, JIGGLE_DATASET)
        (d / "walk.yaml").write_text(JIGGLE_WALK)
        (d / "chainm.yaml").write_text(muscle)
        monkeypatch.chdir(d)
        rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "ds", "-q"], capsys)
        assert rc == 0, err
        rc, _, err = run_main(["run", "--muscles", "chainm.yaml", "--pose", "walk.yaml", "--frames", "2:8:3",
                               "--out", "run", "--no-render", "-q"], capsys)
        assert rc == 0, err
        sets[name] = d
    for name, d in sets.items():
        seq = {k: v for k, v in all_files(d / "ds" / "seq_00000" / "meshes").items()}
        assert seq == all_files(d / "run" / "meshes") and len(seq) == 3
    jig, still = (all_files(sets[n] / "ds" / "seq_00000" / "meshes") for n in ("jig", "still"))
    assert jig != still  # the motion rings
    one = [all_files(sets[n] / "ds" / "seq_00001" / "meshes") for n in ("jig", "still")]
    assert one[0] == one[1]  # one frame: at rest


def test_a_frequency_the_frames_cannot_show_is_noted(tmp_path, capsys):
    h = hinge_folder(tmp_path / "h")
    write_pose(h, "slow", {0: {"knee": 0}, 4: {"knee": 30}}, [0, 4], skeleton="hinge.yaml", fps=6)
    rc, _, err = run_main(["run", "--muscles", h / "muscles", "--pose", h / "slow.yaml", "--out", h / "o",
                           "--no-render", "--verbose"], capsys)
    assert rc == 0, err
    assert "note: jiggle at up to 4 Hz (back, front) is above half the pose's 6 fps" in err
    rc, _, err = run_main(["run", "--muscles", h / "muscles", "--pose", h / "bend.yaml", "--out", h / "o2",
                           "--frames", "0:3", "--no-render", "--verbose"], capsys)
    assert rc == 0 and "aliases" not in err


def test_a_late_frame_costs_a_warm_up_not_the_pose_before_it(tmp_path, capsys, monkeypatch):
    """Jiggle's memory is bounded (pipeline/evaluate.py, TIME_EPOCH_BLOCKS; jiggle_stage.py):
    a frame of a later epoch is evaluated from a warm-up before its epoch, not from the pose's
    first frame. What it writes equals the uninterrupted integration from frame 0 to 1e-6 m
    (float32 positions near 1 m resolve 60 nm; JIGGLE_WARMUP_EPS leaves far less), and
    subsets on either side of an epoch's start give the same bytes."""
    from axdf_cli.model import jiggle
    from axdf_cli.pipeline import evaluate

    folder = hinge_folder(tmp_path / "long")
    # the knee swings on for 9,000 frames (3 epochs at 120 fps): still moving at every epoch's start
    write_pose(folder, "bend", {f: {"knee": 60.0 * ((f // 30) % 2)} for f in range(0, 9001, 30)}, [0, 9000],
               skeleton="hinge.yaml", fps=120)
    epoch = evaluate.TIME_EPOCH_BLOCKS * evaluate.TIME_BLOCK
    assert epoch < 4100 < 2 * epoch < 8300 < 9000
    walked = []
    block = evaluate.time_block
    monkeypatch.setattr(evaluate, "time_block", lambda plan, stages, state, b: (walked.append(b),
                                                                               block(plan, stages, state, b))[1])
    late = run(folder, "late", capsys, "--frames", "8300")
    lead = int(np.ceil(jiggle.warmup_frames(jiggle.JiggleSpec(HZ, ZETA), 1 / 120) / evaluate.TIME_BLOCK))
    assert 0 < lead and len(walked) <= lead + 8300 // evaluate.TIME_BLOCK - 2 * evaluate.TIME_EPOCH_BLOCKS + 1
    assert min(walked) == 2 * evaluate.TIME_EPOCH_BLOCKS - lead  # the warm-up, not frame 0
    near = run(folder, "near", capsys, "--frames", "4090:4101,8300")
    assert outputs(near)["meshes/front/front_8300.ply"] == outputs(late)["meshes/front/front_8300.ply"]
    monkeypatch.setattr(evaluate, "TIME_EPOCH_BLOCKS", 10 ** 9)  # one epoch: from frame 0
    whole = run(folder, "whole", capsys, "--frames", "4090:4101,8300")
    read = FORMATS["ply"].reader
    for name in ("front/front_4090", "front/front_4100", "back/back_8300"):
        a, b = (read((o / "meshes" / f"{name}.ply").read_bytes()).vertices.astype(np.float64) for o in (near, whole))
        assert np.abs(a - b).max() <= 1e-6, name
    still = run(folder, "still", capsys, "--frames", "4100", "--no-jiggle")  # (the jiggle moves it)
    assert np.abs(read((still / "meshes/front/front_4100.ply").read_bytes()).vertices
                  - read((near / "meshes/front/front_4100.ply").read_bytes()).vertices).max() > 1e-4
