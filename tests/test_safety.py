"""Never lose a user's files and `axdf render`'s frame
discipline.

Each case runs in a copy of the library in a tmp folder. Where a command must not touch
anything outside OUT (or anything at all), the test snapshots the whole tmp tree (file
list + sha256 of every file, the target of every link) before and after.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML, REPO_ROOT, run_main

POSITION = re.compile(r"manifest\.json:\d+:\d+: ")
DEMO = ["run", "poses/jobs/demo.yaml", "--no-render"]
LONG = DEMO + ["--frames", "0:191"]  # about 1300 meshes: long enough to interrupt


def snapshot(root: Path, skip: Path | None = None) -> dict:
    """Every file (sha256) and link (its target) below ``root``, links not followed."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            p = Path(dirpath) / name
            if skip is not None and (p == skip or skip in p.parents):
                continue
            rel = p.relative_to(root).as_posix()
            out[rel] = ("link", os.readlink(p)) if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def own_leftovers(out: Path) -> list[str]:
    return [p.name for p in out.rglob("*") if p.name.startswith((".axdf-tmp-", ".axdf-new-", ".axdf-lock"))]


@pytest.fixture
def project(tmp_path, monkeypatch):
    """The demo library (muscles/demo, poses/) in tmp_path/project, as the current folder."""
    root = tmp_path / "project"
    shutil.copytree(REPO_ROOT / "muscles" / "demo", root / "muscles" / "demo")
    shutil.copytree(REPO_ROOT / "poses", root / "poses")
    monkeypatch.chdir(root)
    return root


def spawn(args, cwd, **kw):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "axdf_cli", *map(str, args)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw)


def wait_for(predicate, timeout=60.0):
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if predicate():
            return True
        time.sleep(0.01)
    return False


def count_meshes(folder: Path) -> int:
    return sum(1 for _ in folder.rglob("*.ply")) if folder.exists() else 0


# ----------------------------------------------------------------------------- 1. --overwrite


def test_overwrite_refuses_a_folder_that_holds_no_run(project, capsys):
    before = snapshot(project)
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "poses/skeletons", "--overwrite"], capsys)
    assert rc == 2 and "holds no axdf run" in err and "Traceback" not in err
    assert snapshot(project) == before


def test_overwrite_deletes_only_the_files_the_old_run_lists(project, capsys):
    assert run_main(DEMO + ["--frames", "0:1", "--out", "out"], capsys)[0] == 0
    mine = {"out/notes.txt": "mine", "out/meshes/biceps_brachii/sketch.ply": "mine too", "out/extra/x.txt": "x"}
    for rel, text in mine.items():
        (project / rel).parent.mkdir(parents=True, exist_ok=True)
        (project / rel).write_text(text)
    outside = snapshot(project, skip=project / "out")
    rc, _, err = run_main(DEMO + ["--frames", "2", "--out", "out", "--overwrite", "-q"], capsys)
    assert rc == 0, err
    for rel, text in mine.items():
        assert (project / rel).read_text() == text
    assert not list((project / "out").rglob("*_0000.ply")) and not list((project / "out").rglob("*_0001.ply"))
    assert len(list((project / "out").rglob("*_0002.ply"))) == 7
    manifest = json.loads((project / "out" / "manifest.json").read_text())
    assert manifest["complete"] and manifest["frames"] == [2]
    assert not set(manifest["files"]) & {"notes.txt", "meshes/biceps_brachii/sketch.ply"}
    assert own_leftovers(project / "out") == []
    assert snapshot(project, skip=project / "out") == outside


@pytest.mark.parametrize("fault", ["full disk", "interrupt"])
def test_a_failed_overwrite_keeps_the_old_run(project, capsys, monkeypatch, fault):
    from axdf_cli.fileio import atomic
    from axdf_cli.errors import EnvironmentProblem

    assert run_main(DEMO + ["--frames", "0:3", "--out", "out"], capsys)[0] == 0
    before = snapshot(project)
    real = atomic.write_parts
    calls = {"n": 0}

    def failing(path, parts):
        calls["n"] += 1
        if calls["n"] > 15:
            if fault == "interrupt":
                raise KeyboardInterrupt
            raise EnvironmentProblem(f"{path}: no space left on device", "free disk space")
        return real(path, parts)

    monkeypatch.setattr(atomic, "write_parts", failing)
    rc, _, err = run_main(DEMO + ["--frames", "0:5", "--format", "obj", "--out", "out", "--overwrite"], capsys)
    monkeypatch.undo()
    assert rc == (130 if fault == "interrupt" else 3), err
    assert snapshot(project) == before  # the old run as it was; no staging folder, lock or temporary


def test_sigkill_during_overwrite_keeps_the_old_run(project, capsys):
    out = project / "out"
    assert run_main(DEMO + ["--frames", "0:3", "--out", "out"], capsys)[0] == 0
    before = snapshot(out)
    p = spawn(LONG + ["--out", "out", "--overwrite"], project)
    assert wait_for(lambda: any(count_meshes(s) > 50 for s in out.glob(".axdf-new-*")))
    p.kill()
    p.wait(timeout=30)
    after = snapshot(out)
    assert {k: v for k, v in after.items() if not k.startswith((".axdf-new-", ".axdf-lock"))} == before
    # the next run cleans up what the killed one left
    rc, _, err = run_main(DEMO + ["--frames", "0:3", "--out", "out", "--overwrite", "-q"], capsys)
    assert rc == 0, err
    assert own_leftovers(out) == [] and snapshot(out) == before


# ----------------------------------------------------------------------------- 2. checks before writes


@pytest.fixture
def degenerate(project):
    from test_robustness import DEGENERATE_MUSCLES, DEGENERATE_POSE, DEGENERATE_SKELETON

    (project / "slide.yaml").write_text(DEGENERATE_SKELETON)
    (project / "crush.yaml").write_text(DEGENERATE_POSE)
    (project / "m").mkdir()
    for name, text in DEGENERATE_MUSCLES.items():
        (project / "m" / name).write_text(text)
    return ["run", "--muscles", "m", "--pose", "crush.yaml", "--no-render"]


def test_strict_refuses_before_writing_anything(project, degenerate, capsys):
    rc, _, err = run_main(degenerate + ["--out", "fresh", "--strict"], capsys)
    assert rc == 2 and "--strict" in err
    assert not (project / "fresh").exists()
    assert run_main(degenerate + ["--out", "out"], capsys)[0] == 0  # an earlier, complete run
    before = snapshot(project)
    rc, _, err = run_main(degenerate + ["--out", "out", "--strict", "--overwrite"], capsys)
    assert rc == 2 and "--strict" in err
    assert snapshot(project) == before


def test_render_checks_come_before_the_mesh_pass(project, capsys, tmp_path):
    args = ["run", "poses/jobs/demo.yaml", "--frames", "0", "--size", "64x64"]
    rc, _, err = run_main(args + ["--out", "fresh", "--egl-library", tmp_path / "none" / "libEGL.so.1"], capsys)
    assert rc == 3 and "apt-get" in err
    assert not (project / "fresh").exists()
    assert run_main(DEMO + ["--frames", "0", "--out", "out"], capsys)[0] == 0
    before = snapshot(project)
    rc, _, err = run_main(args + ["--out", "out", "--overwrite", "--egl-library", tmp_path / "x.so"], capsys)
    assert rc == 3
    assert snapshot(project) == before


# ----------------------------------------------------------------------------- 3. symbolic links


def test_a_linked_folder_inside_out_is_refused_and_never_written_through(project, capsys, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    assert run_main(DEMO + ["--frames", "0", "--out", "out"], capsys)[0] == 0
    shutil.move(project / "out" / "meshes", elsewhere / "meshes")
    (project / "out" / "meshes").symlink_to(elsewhere / "meshes")
    before = snapshot(tmp_path)
    for flag in ("--overwrite", "--resume"):
        rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "out", flag], capsys)
        assert rc == 2, err
        assert f"{Path('out') / 'meshes'} is a symbolic link" in err
        assert snapshot(tmp_path) == before
    # one muscle's folder linked out
    (project / "out" / "meshes").unlink()
    shutil.move(elsewhere / "meshes", project / "out" / "meshes")
    shutil.move(project / "out" / "meshes" / "biceps_brachii", elsewhere / "biceps_brachii")
    (project / "out" / "meshes" / "biceps_brachii").symlink_to(elsewhere / "biceps_brachii")
    before = snapshot(tmp_path)
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "out", "--overwrite"], capsys)
    assert rc == 2 and "biceps_brachii is a symbolic link" in err
    assert snapshot(tmp_path) == before


def test_a_job_out_through_a_link_out_of_the_tree_is_refused(project, capsys, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (project / "link").symlink_to(elsewhere)
    job = project / "poses" / "jobs" / "demo.yaml"
    job.write_text(job.read_text().replace("out: ../../out/demo", "out: ../../link/run"))  # relative to the job
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0"], capsys)
    assert rc == 2 and re.search(r"demo\.yaml:\d+:\d+: out '../../link/run' .*leaves the project", err), err
    assert list(elsewhere.iterdir()) == []
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0", "--allow-outside", "-q"],
                          capsys)
    assert rc == 0, err
    assert (elsewhere / "run" / "manifest.json").is_file()


def test_a_manifest_listing_paths_outside_the_folder_is_refused(project, capsys, tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    assert run_main(DEMO + ["--frames", "0", "--out", "out"], capsys)[0] == 0
    path = project / "out" / "manifest.json"
    m = json.loads(path.read_text())
    m["files"]["../../victim.txt"] = "0" * 64
    path.write_text(json.dumps(m, indent=1))
    before = snapshot(tmp_path)
    rc, _, err = run_main(DEMO + ["--frames", "1", "--out", "out", "--overwrite"], capsys)
    assert rc == 2 and POSITION.search(err) and "../../victim.txt" in err, err
    assert snapshot(tmp_path) == before


# ----------------------------------------------------------------------------- 4. --resume and the lock


@pytest.mark.parametrize("change", ["resolution", "format", "frames"])
def test_resume_refuses_other_inputs_or_settings(project, capsys, change):
    assert run_main(DEMO + ["--frames", "0:2", "--out", "out"], capsys)[0] == 0
    args = DEMO + ["--frames", "0:2", "--out", "out", "--resume"]
    if change == "resolution":
        f = project / "muscles" / "demo" / "biceps_brachii.yaml"
        f.write_text(f.read_text().replace("resolution: [48, 24]", "resolution: [8, 6]"))
        expect = "input muscles/demo/biceps_brachii.yaml changed"
    elif change == "format":
        args += ["--format", "obj"]
        expect = 'settings.format: "ply" -> "obj"'
    else:
        args[args.index("0:2")] = "0:4"
        expect = "frames: 3 frames 0..2 -> 5 frames 0..4"
    before = snapshot(project)
    rc, _, err = run_main(args, capsys)
    assert rc == 2 and expect in err and "--resume would mix two runs" in err, err
    assert POSITION.search(err)
    assert snapshot(project) == before


@pytest.mark.parametrize("change", ["tolerance", "model"])
def test_resume_refuses_a_changed_model_naming_it(project, capsys, monkeypatch, change):
    """A run records its identity (pipeline/manifest.py: the model's sources and every numeric
    tolerance): --resume of an interrupted run after a tolerance or the model's code changed
    is refused (exit 2), naming the constant, and writes nothing; unchanged, it finishes."""
    import importlib

    from axdf_cli import tolerances as tol
    from axdf_cli.pipeline import manifest

    execute = importlib.import_module("axdf_cli.pipeline.execute")  # (the package's `execute` is the function)
    args = DEMO + ["--frames", "0:2", "--out", "out"]

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(execute, "stats_csv", interrupted)  # the meshes are written, the tables not
        assert run_main(args, capsys)[0] == 130
    written = json.loads((project / "out" / "manifest.json").read_text())
    assert written["complete"] is False and "stats.csv" not in written["files"]
    assert sum(r.startswith("meshes/") for r in written["files"]) == 3 * len(written["muscles"])
    assert written["identity"]["tolerances"]["CONTACT_RELAX"] == list(tol.CONTACT_RELAX)
    assert written["identity"]["model"] == manifest.model_sources_sha()
    before = snapshot(project)
    with monkeypatch.context() as m:
        if change == "tolerance":
            relaxed = (tol.CONTACT_RELAX[0] + 0.1,) + tuple(tol.CONTACT_RELAX[1:])
            expect = f"tolerances.CONTACT_RELAX {json.dumps(list(tol.CONTACT_RELAX))} -> {json.dumps(list(relaxed))}"
            m.setattr(tol, "CONTACT_RELAX", relaxed)
        else:
            m.setattr(manifest, "model_sources_sha", lambda: "0" * 64)
            expect = "the model's sources changed"
        rc, _, err = run_main(args + ["--resume"], capsys)
    assert rc == 2 and "--resume would mix two runs" in err and expect in err, err
    assert POSITION.search(err)
    assert snapshot(project) == before
    rc, _, err = run_main(args + ["--resume"], capsys)
    assert rc == 0, err
    done = json.loads((project / "out" / "manifest.json").read_text())
    assert done["complete"] is True and "stats.csv" in done["files"] and done["identity"] == written["identity"]


def test_the_run_identity_names_each_change():
    """identity_differences names every tolerance that changed, came or went, and an identity
    missing from an older manifest; the identity holds every numeric tolerance."""
    from axdf_cli import tolerances as tol
    from axdf_cli.pipeline.manifest import identity_differences, run_identity

    new = run_identity()
    assert new["tolerances"]["CONTACT_RELAX"] == list(tol.CONTACT_RELAX)
    assert new["tolerances"]["MAX_SEED"] == tol.MAX_SEED and len(new["model"]) == 64
    assert all(isinstance(v, (int, float, list)) and not isinstance(v, bool) for v in new["tolerances"].values())
    old = {"model": new["model"], "tolerances": {**new["tolerances"], "CONTACT_MARGIN": 0.5, "GONE": 1}}
    del old["tolerances"]["PACK_GAIN"]
    assert identity_differences(old, new) == [
        f"tolerances.CONTACT_MARGIN 0.5 -> {json.dumps(tol.CONTACT_MARGIN)}", "tolerances.GONE is gone",
        "tolerances.PACK_GAIN is new"]
    assert identity_differences(dict(new, model="0" * 64), new) == ["the model's sources changed (sha256 differs)"]
    assert identity_differences(None, new) == [
        "the interrupted run records no identity of the model (an older axdf wrote it)"]
    assert identity_differences(new, new) == []


def test_dry_run_makes_the_folder_checks(project, capsys):
    assert run_main(DEMO + ["--frames", "0", "--out", "out"], capsys)[0] == 0
    before = snapshot(project)
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "out", "--dry-run"], capsys)
    assert rc == 2 and "not empty" in err
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "out", "--dry-run", "--resume", "--format", "obj"], capsys)
    assert rc == 2 and "settings.format" in err
    rc, out, err = run_main(DEMO + ["--frames", "0", "--out", "out", "--dry-run", "--overwrite"], capsys)
    assert rc == 0 and "would write" in out
    assert snapshot(project) == before


def test_resume_refuses_a_folder_that_holds_no_run(project, capsys):
    out = project / "out"
    (out / "sub").mkdir(parents=True)
    (out / "user.txt").write_text("mine")
    (out / "sub" / ".axdf-tmp-1-notes.txt").write_text("a user's file with that name")
    before = snapshot(project)
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", "out", "--resume"], capsys)
    assert rc == 2 and "holds no axdf run" in err
    assert snapshot(project) == before


def test_resume_removes_only_temporaries_whose_writer_is_gone(project, capsys):
    assert run_main(DEMO + ["--frames", "0:1", "--out", "out"], capsys)[0] == 0
    live = subprocess.Popen(["sleep", "60"])
    dead = subprocess.Popen(["true"])
    dead.wait()
    try:
        folder = project / "out" / "meshes" / "biceps_brachii"
        keep = folder / f".axdf-tmp-{live.pid}-biceps_brachii_0000.ply"
        gone = folder / f".axdf-tmp-{dead.pid}-biceps_brachii_0001.ply"
        keep.write_bytes(b"half")
        gone.write_bytes(b"half")
        rc, _, err = run_main(DEMO + ["--frames", "0:1", "--out", "out", "--resume", "-q"], capsys)
        assert rc == 0, err
        assert keep.exists() and not gone.exists()
    finally:
        live.kill()
        live.wait()


def test_a_second_writer_is_refused_while_the_lock_is_held(project, capsys):
    assert run_main(DEMO + ["--frames", "0:1", "--out", "out"], capsys)[0] == 0
    before = snapshot(project)
    fd = os.open(project / "out" / ".axdf-lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        os.write(fd, b"4242\n")
        for flag in ("--resume", "--overwrite"):
            rc, _, err = run_main(DEMO + ["--frames", "0:1", "--out", "out", flag], capsys)
            assert rc == 3 and "another axdf process (pid 4242) is writing" in err, err
    finally:
        os.close(fd)
        os.unlink(project / "out" / ".axdf-lock")
    assert snapshot(project) == before
    rc, _, err = run_main(DEMO + ["--frames", "0:1", "--out", "out", "--resume", "-q"], capsys)
    assert rc == 0, err
    assert own_leftovers(project / "out") == []
    assert ".axdf-lock" not in json.loads((project / "out" / "manifest.json").read_text())["files"]


def test_two_simultaneous_runs_into_one_folder_the_second_is_refused(project, capsys):
    out = project / "out"
    first = spawn(LONG + ["--out", "out"], project)
    assert wait_for(lambda: count_meshes(out) > 20)
    first.send_signal(signal.SIGSTOP)  # still running (and holding the lock) while the second starts
    try:
        second = spawn(LONG + ["--out", "out", "--resume"], project)
        _, err2 = second.communicate(timeout=120)
    finally:
        first.send_signal(signal.SIGCONT)
    _, err1 = first.communicate(timeout=300)
    assert first.returncode == 0, err1.decode()
    assert second.returncode == 3 and b"another axdf process" in err2, err2.decode()
    assert json.loads((out / "manifest.json").read_text())["complete"]
    assert own_leftovers(out) == []


# ----------------------------------------------------------------------------- 5. --jobs workers


def children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                out.append(int(d.name))
    return out


def alive(pid: int) -> bool:
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def kill_parent_of_frozen(p, workers: list[int]) -> None:
    """SIGKILL the parent ``p`` while its ``workers`` are frozen (so they cannot simply have
    finished); every worker must then end, and nothing print a traceback."""
    for w in workers:
        os.kill(w, signal.SIGSTOP)
    p.kill()
    p.wait(timeout=30)
    for w in workers:
        os.kill(w, signal.SIGCONT)
    assert wait_for(lambda: not any(alive(w) for w in workers), timeout=20)
    _, err = p.communicate(timeout=30)  # every writer of the pipe is gone
    assert b"Traceback" not in err and b"BrokenPipeError" not in err, err.decode()


def test_workers_die_with_their_parent(project):
    out = project / "out"
    p = spawn(LONG + ["--out", "out", "--jobs", "2"], project)
    assert wait_for(lambda: count_meshes(out) > 50)
    workers = children(p.pid)
    assert len(workers) >= 2
    kill_parent_of_frozen(p, workers)
    assert count_meshes(out) < 7 * 192  # they stopped, not finished


def interrupt(p, how: str) -> bytes:
    """Stop ``p`` (spawned with start_new_session) with SIGTERM or Ctrl-C to its group: exit
    130 without a traceback; returns its stderr."""
    if how == "SIGTERM":
        p.send_signal(signal.SIGTERM)
    else:
        os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err.decode()
    assert b"Traceback" not in err and b"KeyboardInterrupt" not in err, err.decode()
    return err


@pytest.mark.parametrize("how", ["SIGTERM", "Ctrl-C to the group"])
def test_stopping_a_jobs_run_exits_130_without_tracebacks(project, how):
    out = project / "out"
    p = spawn(LONG + ["--out", "out", "--jobs", "2"], project, start_new_session=True)
    assert wait_for(lambda: count_meshes(out) > 50)
    interrupt(p, how)
    assert own_leftovers(out) == []
    json.loads((out / "manifest.json").read_text())


CALLBACK_INTERRUPT = """
import ctypes, signal, sys, time
from axdf_cli.fileio import atomic
signal.signal(signal.SIGTERM, atomic.on_signal)
atomic.catch_interrupts_in_callbacks()
libc = ctypes.CDLL(None)
CMP = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
def compare(a, b):  # Python inside a C callback, as llvmlite's object cache while numba loads a kernel
    signal.raise_signal(signal.SIGTERM)
    for _ in range(100):
        pass
    return 0
arr = (ctypes.c_int * 4)(4, 3, 2, 1)
try:
    libc.qsort(arr, 4, ctypes.sizeof(ctypes.c_int), CMP(compare))
    print("after the callback", flush=True)
    time.sleep(5)
    print("never stopped", flush=True)
except KeyboardInterrupt:
    print("stopped", flush=True)
"""


def test_an_interrupt_inside_a_c_callback_stops_quietly_once_it_returns():
    """A SIGTERM that lands while Python runs inside a C callback (numba loading a kernel
    from its cache, in a worker the pool is stopping) cannot raise there: no traceback, and
    the interrupt arrives again once the callback has returned."""
    r = subprocess.run([sys.executable, "-c", CALLBACK_INTERRUPT], capture_output=True, timeout=60,
                       cwd=REPO_ROOT, env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    assert r.stdout.decode().split() == ["after", "the", "callback", "stopped"], r
    assert b"Traceback" not in r.stderr and b"Exception ignored" not in r.stderr, r.stderr.decode()


# ----------------------------------------------------------------------------- 6. axdf render


@pytest.fixture
def small_run(project, capsys):
    """Two muscles, frames 0..5, no frames rendered yet."""
    rc, _, err = run_main(["run", "--muscles", "muscles/demo/biceps_brachii.yaml", "muscles/demo/deltoid.yaml",
                           "--pose", "poses/demo.yaml", "--frames", "100:105", "--out", "r", "--no-render", "-q"],
                          capsys)
    assert rc == 0, err
    return project / "r"


def frame_files(run: Path) -> list[str]:
    return sorted(p.name for p in (run / "frames").iterdir()) if (run / "frames").exists() else []


def test_an_interrupted_render_is_incomplete_and_resumes(small_run, capsys, monkeypatch, tmp_path):
    from axdf_cli.render import framefiles

    reference = tmp_path / "reference"
    shutil.copytree(small_run, reference)
    assert run_main(["render", reference, "--size", "48x32", "-q"], capsys)[0] == 0

    real = framefiles.FRAME_WRITERS["exr"]
    calls = {"n": 0}

    def interrupted(path, img):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(path, img)

    monkeypatch.setitem(framefiles.FRAME_WRITERS, "exr", interrupted)
    rc, _, err = run_main(["render", small_run, "--size", "48x32"], capsys)
    monkeypatch.undo()
    assert rc == 130, err
    m = json.loads((small_run / "manifest.json").read_text())
    assert m["complete"] is False and m["settings"]["render"]["size"] == [48, 32]
    assert not (small_run / "camera.json").exists() and "camera.json" not in m["files"]
    assert own_leftovers(small_run) == []
    rc, _, err = run_main(["render", small_run, "--size", "48x32"], capsys)
    assert rc == 2 and "--overwrite" in err and "--resume" in err
    rc, out, err = run_main(["render", small_run, "--size", "48x32", "--resume"], capsys)
    assert rc == 0, err
    assert "2 were complete" in out
    m = json.loads((small_run / "manifest.json").read_text())
    assert m["complete"] is True and m["gl"]["renderer"]
    assert snapshot(small_run / "frames") == snapshot(reference / "frames")
    assert (small_run / "camera.json").read_bytes() == (reference / "camera.json").read_bytes()
    assert json.loads((reference / "manifest.json").read_text())["files"] == m["files"]


def test_render_frames_overwrite_and_settings(small_run, capsys):
    rc, out, err = run_main(["render", small_run, "--size", "40x32", "--frames", "101:102"], capsys)
    assert rc == 0, err
    assert frame_files(small_run) == ["0101.exr", "0101.png", "0102.exr", "0102.png"]
    before = snapshot(small_run)
    rc, _, err = run_main(["render", small_run, "--size", "40x32", "--frames", "102:103"], capsys)
    assert rc == 2 and "--overwrite" in err
    # other settings for some frames while others keep the old ones: refused
    rc, _, err = run_main(["render", small_run, "--size", "64x32", "--frames", "102", "--overwrite"], capsys)
    assert rc == 2 and "0101.exr" in err and "size" in err
    rc, _, err = run_main(["render", small_run, "--frames", "107"], capsys)
    assert rc == 2 and "--frames" in err
    assert snapshot(small_run) == before
    rc, _, err = run_main(["render", small_run, "--size", "64x32", "--overwrite", "-q"], capsys)
    assert rc == 0, err
    m = json.loads((small_run / "manifest.json").read_text())
    assert m["settings"]["render"]["size"] == [64, 32] and m["complete"]
    assert len(frame_files(small_run)) == 12
    assert all(f"frames/{f:04d}.png" in m["files"] for f in range(100, 106))


def test_render_reads_the_recorded_mesh_format(small_run, capsys, project):
    rc, _, err = run_main(["run", "--muscles", "muscles/demo/biceps_brachii.yaml", "--pose", "poses/demo.yaml",
                           "--frames", "100:101", "--out", "r", "--no-render", "--format", "obj", "--overwrite", "-q"],
                          capsys)
    assert rc == 0, err
    assert not list(small_run.rglob("*.ply")) or all(p.parent.name == "bones" for p in small_run.rglob("*.ply"))
    stray = small_run / "meshes" / "biceps_brachii" / "biceps_brachii_0100.ply"
    stray.write_bytes(b"ply\nnot a mesh\n")  # a stale file of the other format is not read
    rc, _, err = run_main(["render", small_run, "--size", "32x32", "-q"], capsys)
    assert rc == 0, err


# ----------------------------------------------------------------------------- 7. smaller cases


def test_render_size_beyond_the_gl_limit(project, capsys):
    from axdf_cli.render.context import probe
    from axdf_cli.specs.render import RenderSettings

    _, limit = probe(RenderSettings())
    args = ["run", "--muscles", "muscles/demo/biceps_brachii.yaml", "--pose", "poses/demo.yaml", "--frames", "100",
            "--bones" if False else "--no-bones", "--render"]
    expect = min(3, limit // 6000)
    rc, _, err = run_main(args + ["--size", "6000x16", "--supersample", "3", "--out", "wide"], capsys)
    assert rc == 0, err
    assert ("supersample lowered to 2" in err) == (expect == 2)
    assert json.loads((project / "wide" / "manifest.json").read_text())["settings"]["render"]["supersample"] == expect
    if limit >= 8192 * 3:
        pytest.skip(f"this GL draws {limit} pixels a side: a sheet of 8192-pixel panels fits")
    rc, _, err = run_main(args + ["--size", "8192x16", "--view", "sheet", "--out", "sheet"], capsys)
    assert rc == 2 and f"limit {limit}" in err and "--size" in err
    assert not (project / "sheet").exists()


def test_a_missing_egl_device_names_the_devices(project, capsys):
    from axdf_cli.render.context import egl_devices

    devices = egl_devices()
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--frames", "0", "--device", "57", "--out", "o"], capsys)
    assert rc == 3
    assert "apt-get" not in err and "no EGL device 57" in err
    if devices:
        assert f"0 ({devices[0]})" in err
    assert not (project / "o").exists()


def _mutate(m: dict, case: str) -> str:
    if case == "invalid json":
        return json.dumps(m, indent=1)[:-3] + ",}"
    if case == "frames abc":
        m["frames"] = ["abc"] + m["frames"][1:]
    elif case == "frames empty":
        m["frames"] = []
    elif case == "frames missing":
        del m["frames"]
    elif case == "muscles string":
        m["muscles"] = "biceps"
    elif case == "muscle name":
        m["muscles"][0]["name"] = "../../evil"
    elif case == "files list":
        m["files"] = ["meshes"]
    elif case == "sha":
        m["files"][next(iter(m["files"]))] = 7
    elif case == "not axdf":
        m["tool"] = "blender"
    elif case == "not an object":
        m = [m]
    elif case == "render size":
        m["settings"]["render"] = {"size": "big"}
    elif case == "settings string":
        m["settings"] = "fast"
    return json.dumps(m, indent=1)


@pytest.mark.parametrize("case", ["invalid json", "frames abc", "frames empty", "frames missing", "muscles string",
                                  "muscle name", "files list", "sha", "not axdf", "not an object", "render size",
                                  "settings string"])
def test_a_damaged_manifest_is_exit_2_with_its_position(small_run, capsys, project, case):
    path = small_run / "manifest.json"
    path.write_text(_mutate(json.loads(path.read_text()), case))
    before = snapshot(project)
    rc, _, err = run_main(["render", small_run, "--size", "32x32"], capsys)
    assert rc == 2 and POSITION.search(err) and "Traceback" not in err, err
    if case not in ("render size", "muscles string", "muscle name"):  # what --resume reads
        rc, _, err = run_main(["run", "--muscles", "muscles/demo/biceps_brachii.yaml", "muscles/demo/deltoid.yaml",
                               "--pose", "poses/demo.yaml", "--frames", "100:105", "--out", "r", "--no-render",
                               "--resume"], capsys)
        assert rc == 2 and "Traceback" not in err, err
        assert POSITION.search(err) or "holds no axdf run" in err, err
    assert snapshot(project) == before


def test_an_empty_out_is_refused(project, capsys):
    rc, _, err = run_main(DEMO + ["--frames", "0", "--out", ""], capsys)
    assert rc == 2 and "--out" in err
    job = project / "poses" / "jobs" / "demo.yaml"
    job.write_text(job.read_text().replace("out: ../../out/demo", "out: ''"))
    rc, _, err = run_main(DEMO + ["--frames", "0"], capsys)
    assert rc == 2 and re.search(r"demo\.yaml:\d+:\d+: out ", err), err
    assert not (project / "out").exists()


# ----------------------------------------------------------------------------- twist references


@pytest.fixture
def chain(tmp_path, monkeypatch):
    (tmp_path / "chain.yaml").write_text(CHAIN_SKELETON_YAML)
    (tmp_path / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    monkeypatch.chdir(tmp_path)

    def pose(name, keys, frames, interpolation="linear"):
        doc = {"pose": name, "skeleton": "chain.yaml", "fps": 24, "frames": frames, "interpolation": interpolation,
               "keys": keys}
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(doc))
        return f"{name}.yaml"

    return pose


def _plan(pose: str, frames: str):
    from axdf_cli.pipeline import plan_run

    return plan_run(None, muscle_args=["chainm.yaml"], pose_arg=pose, frames_arg=frames)


def test_twist_reference_cost_follows_what_is_computed_not_the_pose_length(chain, monkeypatch):
    from axdf_cli.pipeline import evaluate

    pose = chain("long", {0: {"roll": 0, "bend": 0}, 9_999_999: {"roll": 720, "bend": 90}}, [0, 9_999_999])
    seen = {"frames": 0}
    real = evaluate.forward_kinematics

    def counting(skel, q):
        seen["frames"] += len(q)
        return real(skel, q)

    monkeypatch.setattr(evaluate, "forward_kinematics", counting)
    for frames in ("0:1", "9999999", "5000000:5000003"):
        seen["frames"] = 0
        ref = evaluate.twist_references(_plan(pose, frames))
        assert seen["frames"] < 1000, (frames, seen)  # the pose has 10,000,000 frames
        assert np.isfinite(ref).all()
    # 720 degrees over the pose: the last frame's branch is two turns on, not wrapped
    assert ref is not None
    last = evaluate.twist_references(_plan(pose, "9999999"))
    assert abs(np.degrees(last[0, 0]) - 720.0) < 5.0


@pytest.mark.parametrize("interpolation", ["linear", "cubic", "step"])
def test_any_frame_subset_gets_the_same_twist_branch(chain, interpolation):
    from axdf_cli.pipeline import evaluate

    keys = {0: {"roll": 0}, 300: {"roll": 400}, 310: {"roll": -200}, 2000: {"roll": 1000}, 2400: {"roll": 1000}}
    pose = chain("spin", keys, [0, 2600], interpolation)
    full = evaluate.twist_references(_plan(pose, "0:2600"))
    assert np.all(np.abs(np.diff(full[:, 0])) < np.pi)  # no flip: the roll is followed past 180 degrees
    for frames in ("2600", "150,305,1999:2003", "0:2600:97", "2401"):
        plan = _plan(pose, frames)
        np.testing.assert_array_equal(evaluate.twist_references(plan), full[plan.frames])


@pytest.mark.parametrize("interpolation", ["linear", "cubic"])
def test_a_key_every_frame_is_unwrapped_on_a_coarser_grid_with_the_same_branches(chain, monkeypatch, interpolation):
    """A key every frame (motion capture): whole-frame intervals merge while the rotations'
    summed change stays under TWIST_STEP_DEG, so the twist is unwrapped on a fraction of the
    frames, and every frame keeps the branch of unwrapping at every key (1e-9 rad: the same
    branch; the arithmetic of np.unwrap against the nearest-branch rule may differ in the last bit)."""
    from axdf_cli.pipeline import evaluate

    rng = np.random.default_rng(7)
    roll = np.cumsum(rng.normal(1.2, 0.8, 3001))  # about 3,600 degrees: ten turns, never stopping
    pose = chain("mocap", {f: {"roll": float(roll[f]), "bend": float(20 * np.sin(f / 50))} for f in range(3001)},
                 [0, 3000], interpolation)
    plan = _plan(pose, "0:3000")
    grid = evaluate.twist_grid(plan.pose, 3000)
    assert len(grid) < 3001 / 3
    got = evaluate.twist_references(plan)
    merged = evaluate.twist_grid
    monkeypatch.setattr(evaluate, "twist_grid", lambda p, upto: np.arange(0, upto + 1))  # every key
    every = evaluate.twist_references(plan)
    monkeypatch.setattr(evaluate, "twist_grid", merged)
    np.testing.assert_allclose(got, every, rtol=0, atol=1e-9)
    assert abs(np.degrees(got[-1, 0] - got[0, 0]) - (roll[-1] - roll[0])) < 5.0  # the turns are kept
    for frames in ("2999", "17,1500:1503"):  # a subset: the same grid, the same bytes
        sub = _plan(pose, frames)
        np.testing.assert_array_equal(evaluate.twist_references(sub), got[sub.frames])
