"""Faults and hostile input: resume after SIGKILL, signals, full disk, unwritable
output, hostile YAML, degenerate geometry. Each fault class has its own test."""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
DEMO_ARGS = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:191"]


def _tree(folder: Path) -> dict[str, bytes]:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def _spawn(args, cwd=ROOT):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.Popen([sys.executable, "-m", "axdf_cli", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)


@pytest.fixture(scope="module")
def reference_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref") / "out"
    p = _spawn(DEMO_ARGS + ["--out", str(out)])
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err.decode()
    return out


def _wait_for_meshes(out: Path, n: int, timeout: float = 60.0) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        mesh_dir = out / "meshes"
        if mesh_dir.exists() and sum(1 for _ in mesh_dir.rglob("*.ply")) >= n:
            return
        time.sleep(0.01)


@pytest.mark.parametrize("kill_after_meshes", [1, 150, 700])
def test_sigkill_then_resume_is_byte_identical(tmp_path, reference_run, kill_after_meshes):
    out = tmp_path / "out"
    p = _spawn(DEMO_ARGS + ["--out", str(out)])
    _wait_for_meshes(out, kill_after_meshes)
    p.send_signal(signal.SIGKILL)
    p.wait(timeout=30)
    # the manifest is valid JSON at every moment (when it exists at all)
    if (out / "manifest.json").exists():
        json.loads((out / "manifest.json").read_text())
    # without --resume a non-empty OUT is refused
    r = _spawn(DEMO_ARGS + ["--out", str(out)])
    _, err = r.communicate(timeout=60)
    assert r.returncode == 2 and b"--resume" in err
    r = _spawn(DEMO_ARGS + ["--out", str(out), "--resume"])
    _, err = r.communicate(timeout=300)
    assert r.returncode == 0, err.decode()
    assert _tree(out) == _tree(reference_run)


def test_sigterm_and_sigint_exit_130_without_partial_files(tmp_path):
    for sig in (signal.SIGTERM, signal.SIGINT):
        out = tmp_path / f"out{int(sig)}"
        p = _spawn(DEMO_ARGS + ["--out", str(out)])
        _wait_for_meshes(out, 100)
        t0 = time.monotonic()
        p.send_signal(sig)
        _, err = p.communicate(timeout=30)
        assert p.returncode == 130, err.decode()
        assert time.monotonic() - t0 < 10.0
        assert b"Traceback" not in err
        assert not [q for q in out.rglob("*") if q.name.startswith(".axdf-tmp-")]
        json.loads((out / "manifest.json").read_text())


def test_overwrite_replaces_and_plain_rerun_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "o"
    args = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:2", "--out", str(out)]
    assert main(args) == 0
    assert main(args) == 2
    assert "not empty" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0


@pytest.mark.parametrize("err", [errno.ENOSPC, errno.EROFS, errno.EACCES])
def test_full_disk_or_unwritable_out_exits_3_and_leaves_nothing_half_written(tmp_path, monkeypatch, capsys, err):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "o"
    real_open = open
    calls = {"n": 0}

    def failing_open(file, mode="r", *a, **k):
        if "w" in mode and str(out) in str(file):
            calls["n"] += 1
            if calls["n"] > 20:  # the disk fills up part way through
                raise OSError(err, os.strerror(err), str(file))
        return real_open(file, mode, *a, **k)

    real_os_open = os.open
    real_os_write = os.write

    def failing_os_open(file, flags, *a, **k):  # the writers' own path (atomic.write_parts)
        if flags & os.O_WRONLY and str(out) in str(file):
            calls["n"] += 1
            if calls["n"] > 20 and err != errno.ENOSPC:
                raise OSError(err, os.strerror(err), str(file))
        return real_os_open(file, flags, *a, **k)

    def failing_os_write(fd, data):  # a full disk fails in the middle of a write
        if err == errno.ENOSPC and calls["n"] > 20:
            real_os_write(fd, bytes(memoryview(data)[:100]))
            raise OSError(err, os.strerror(err))
        return real_os_write(fd, data)

    monkeypatch.setattr("builtins.open", failing_open)
    monkeypatch.setattr(os, "open", failing_os_open)
    monkeypatch.setattr(os, "write", failing_os_write)
    rc = main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:20", "--out", str(out)])
    monkeypatch.undo()
    captured = capsys.readouterr()
    assert rc == 3, captured.err
    assert "Traceback" not in captured.err
    assert not [q for q in out.rglob("*") if q.name.startswith(".axdf-tmp-")]
    for ply in out.rglob("*.ply"):  # every file that exists is whole
        import trimesh

        assert len(trimesh.load(ply, process=False).faces) > 0


@pytest.mark.parametrize("fmt", ["pc2", "npz"])
def test_full_disk_while_streaming_a_packed_format_exits_3(tmp_path, monkeypatch, capsys, fmt):
    """The packed formats write through atomic.StreamingFile (os.pwrite), not write_parts."""
    monkeypatch.chdir(ROOT)
    out = tmp_path / "o"
    real_pwrite = os.pwrite
    calls = {"n": 0}

    def failing_pwrite(fd, data, offset):
        calls["n"] += 1
        if calls["n"] > 3:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(os, "pwrite", failing_pwrite)
    rc = main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:20", "--format", fmt, "--out", str(out)])
    monkeypatch.undo()
    captured = capsys.readouterr()
    assert calls["n"] > 3
    assert rc == 3, captured.err
    assert "no space left on device" in captured.err
    assert "Traceback" not in captured.err
    assert not [q for q in out.rglob("*") if q.name.startswith(".axdf-tmp-")]
    assert not list(out.rglob("*." + fmt))


def test_output_under_a_file_exits_2(tmp_path, monkeypatch, capsys):
    """A path mistake (a file where a folder must be) is bad input, found before anything is
    written (docs/OUTPUTS.md, rule 6); it was exit 3 ("cannot write (Not a directory)")."""
    monkeypatch.chdir(ROOT)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc = main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", str(blocker / "sub")])
    assert rc == 2
    assert "file is not a folder" in capsys.readouterr().err
    assert blocker.read_text() == "x"


# ----------------------------------------------------------------------------- hostile input


@pytest.fixture
def project(tmp_path, monkeypatch):
    """A copy of the shipped library in tmp_path, as the current folder."""
    for d in ("muscles", "poses"):
        shutil.copytree(ROOT / d, tmp_path / d)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run_bad(project, capsys, args=None):
    before = {p for p in project.rglob("*")}
    rc = main(args or ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "out"])
    err = capsys.readouterr().err
    after = {p for p in project.rglob("*")}
    assert "Traceback" not in err
    assert not [p for p in after - before if "out" not in p.relative_to(project).parts[:1]]
    return rc, err


HOSTILE = {
    "alias bomb": ("muscles/demo/biceps_brachii.yaml",
                   'a: &a ["x","x","x","x","x","x","x","x","x"]\n' +
                   "".join(f"{c}: &{c} [*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p}]\n"
                           for p, c in zip("abcdefgh", "bcdefghi"))),
    "python tag": ("muscles/demo/biceps_brachii.yaml", "muscle: !!python/object/apply:os.system ['touch pwned']\n"),
    "nan": ("muscles/demo/biceps_brachii.yaml", None),
    "deep nesting": ("muscles/demo/biceps_brachii.yaml", "muscle: " + "[" * 5000 + "]" * 5000 + "\n"),
    "non-utf8": ("muscles/demo/biceps_brachii.yaml", b"muscle: b\xff\xfeceps\n"),
    "slash in name": ("muscles/demo/biceps_brachii.yaml", None),
    "dotdot name": ("muscles/demo/biceps_brachii.yaml", None),
    "absolute skeleton": ("poses/demo.yaml", None),
    "escaping skeleton": ("poses/demo.yaml", None),
    "escaping out": ("poses/jobs/demo.yaml", None),
    "huge number": ("muscles/demo/biceps_brachii.yaml", None),
    "inf in pose": ("poses/demo.yaml", None),
}


def _mutate(project: Path, case: str) -> None:
    rel, content = HOSTILE[case]
    path = project / rel
    text = path.read_text()
    if content is not None:
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
    elif case == "nan":
        path.write_text(text.replace("radii: [0.02, 0.015]", "radii: [.nan, 0.015]"))
    elif case == "slash in name":
        path.write_text(text.replace("muscle: biceps_brachii", "muscle: ../../evil"))
    elif case == "dotdot name":
        path.write_text(text.replace("muscle: biceps_brachii", "muscle: '..'"))
    elif case == "absolute skeleton":
        path.write_text(text.replace("skeleton: skeletons/human_r.yaml", "skeleton: /etc/passwd"))
    elif case == "escaping skeleton":
        path.write_text(text.replace("skeleton: skeletons/human_r.yaml", "skeleton: ../../../etc/skel.yaml"))
    elif case == "escaping out":
        path.write_text(text.replace("out: ../../out/demo", "out: ../../../tmp/evil"))
    elif case == "huge number":
        path.write_text(text.replace("twist: 0", "twist: 1e308").replace("tendons: [0.15, 0.12]",
                                                                         "tendons: [0.15, 0.12]\ntwist: 1e308"))
    elif case == "inf in pose":
        path.write_text(text.replace("72:  {shoulder_abduction_r: 90}", "72:  {shoulder_abduction_r: .inf}"))


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_input_exits_2_with_position(project, capsys, case):
    _mutate(project, case)
    args = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1"]
    if case != "escaping out":
        args += ["--out", "out"]
    rc, err = _run_bad(project, capsys, args)
    assert rc == 2, err
    assert ".yaml:" in err and err.split(":")[1].isdigit(), err  # FILE:LINE:...
    assert not (project / "pwned").exists()
    assert not (project / "out").exists()


def test_allow_outside_flag_permits_leaving_the_tree(project, capsys, tmp_path_factory):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    shutil.copytree(project / "poses" / "skeletons", elsewhere / "skeletons")
    pose = project / "poses" / "demo.yaml"
    pose.write_text(pose.read_text().replace("skeleton: skeletons/human_r.yaml",
                                             f"skeleton: {elsewhere / 'skeletons' / 'human_r.yaml'}"))
    args = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "out"]
    assert main(args) == 2
    capsys.readouterr()
    assert main(args + ["--allow-outside"]) == 0


# ----------------------------------------------------------------------------- degenerate geometry


DEGENERATE_SKELETON = """
skeleton: slide
bones:
  - name: a
  - name: b
    parent: a
    offset: [0, 0, 0.3]
    dofs:
      - {coord: slide, type: translation, axis: [0, 0, 1]}
      - {coord: bend, type: rotation, axis: [1, 0, 0]}
"""

DEGENERATE_MUSCLES = {
    "coincident.yaml": """
muscle: coincident
axis:
  - {bone: a, at: [0, 0, 0.05]}
  - {bone: a, at: [0, 0, 0.05]}
  - {bone: a, at: [0, 0, 0.2]}
  - {bone: b, at: [0, 0, 0.1]}
  - {bone: b, at: [0, 0, 0.1]}
sections:
  - {t: 0.3, radii: [0.02, 0.015]}
  - {t: 0.7, radii: [0.02, 0.015]}
""",
    "squash.yaml": """
muscle: squash
axis:
  - {bone: a, at: [0, 0, 0.2]}
  - {bone: b, at: [0, 0, 0.0]}
  - {bone: b, at: [0, 0, 0.0]}
""",
}

DEGENERATE_POSE = """
pose: crush
skeleton: slide.yaml
frames: [0, 8]
keys:
  0: {slide: 0, bend: 0}
  2: {slide: -0.1, bend: 0}       # the squash muscle's length reaches zero
  4: {slide: -0.4, bend: 0}       # and folds back on itself
  6: {slide: 0.0, bend: 179.9}    # folded axis
  8: {slide: 0.0, bend: 1440}     # far past any range
"""


@pytest.fixture
def degenerate(tmp_path, monkeypatch):
    (tmp_path / "slide.yaml").write_text(DEGENERATE_SKELETON)
    (tmp_path / "crush.yaml").write_text(DEGENERATE_POSE)
    (tmp_path / "m").mkdir()
    for name, text in DEGENERATE_MUSCLES.items():
        (tmp_path / "m" / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_degenerate_poses_give_finite_meshes_and_recorded_warnings(degenerate, capsys):
    rc = main(["run", "--muscles", "m", "--pose", "crush.yaml", "--out", "out", "--no-render"])
    assert rc == 0, capsys.readouterr().err
    from axdf_cli.formats import read_triangles

    for ply in (degenerate / "out" / "meshes").rglob("*.ply"):
        pos, nrm, faces = read_triangles(ply.read_bytes(), ".ply")
        assert np.isfinite(pos).all() and np.isfinite(nrm).all(), ply
    stats = (degenerate / "out" / "stats.csv").read_text().splitlines()
    warned = [line for line in stats[1:] if not line.endswith(",")]
    assert any(line.split(",")[0] == "2" and "squash" in line for line in warned), stats
    assert "nan" not in "\n".join(stats).lower() and "inf" not in "\n".join(stats).lower()
    manifest = json.loads((degenerate / "out" / "manifest.json").read_text())
    assert any("squash frame 2" in w for w in manifest["warnings"])


def test_degenerate_poses_with_strict_exit_2_and_write_nothing(degenerate, capsys):
    rc = main(["run", "--muscles", "m", "--pose", "crush.yaml", "--out", "out", "--no-render", "--strict"])
    assert rc == 2
    assert "--strict" in capsys.readouterr().err
    assert not (degenerate / "out" / "meshes").exists()


def test_jobs_gives_the_same_bytes_as_one_process(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    base = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:191:16"]
    assert main(base + ["--out", str(tmp_path / "one")]) == 0
    assert main(base + ["--out", str(tmp_path / "two"), "--jobs", "3"]) == 0
    assert _tree(tmp_path / "one") == _tree(tmp_path / "two")
