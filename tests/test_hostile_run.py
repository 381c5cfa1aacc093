"""Hostile round on the command line's process: a SIGINT or SIGTERM at any moment
of a command, from its first instant to its teardown, ends it with exit 130 and "axdf:
interrupted", no traceback and no partial output."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from compare_helpers import make_run
from conftest import REPO_ROOT


def _held():
    """The child starts with SIGINT and SIGTERM blocked, so a signal sent before the
    interpreter itself is up (no program's handler can be in place then) waits for axdf's
    entry point, which lets them through once its handlers are installed."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})


def _exited(pid: int) -> bool:
    """Whether the child has already ended (a zombie not yet waited for)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "Z"
    except (OSError, IndexError):
        return True


def test_a_signal_at_any_moment_exits_130_with_no_partial_output(tmp_path):
    golden = make_run(tmp_path / "golden", muscles=1, frames=2)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), os.environ.get("PYTHONPATH", "")])}
    t0 = time.perf_counter()  # how long the command takes here: the signals fall within it
    subprocess.run([sys.executable, "-m", "axdf_cli", "compare", golden, golden], cwd=tmp_path, env=env,
                   capture_output=True, check=True)
    took = time.perf_counter() - t0
    rng = np.random.default_rng(37)
    delays = [0.0, *sorted(rng.uniform(0.0, 0.8 * took, 7))]
    landed = 0
    for k, delay in enumerate(delays):
        sig = (signal.SIGINT, signal.SIGTERM)[k % 2]
        report = tmp_path / f"r{k}" / "report.json"
        p = subprocess.Popen([sys.executable, "-m", "axdf_cli", "compare", golden, golden, "--report", report],
                             cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             preexec_fn=_held)
        time.sleep(delay)
        alive = not _exited(p.pid)
        if alive:
            p.send_signal(sig)
        out, err = p.communicate(timeout=120)
        case = (k, round(delay, 3), sig.name, p.returncode, err[-400:])
        assert "Traceback" not in err and "Exception ignored" not in err, case
        if alive and p.returncode == 0:
            # the signal came as the command was leaving, its work done (a race no delay rules
            # out on a loaded machine): then its output is whole, never a part
            assert report.is_file() and not err.rstrip().endswith("axdf: interrupted"), case
        elif alive:
            landed += 1
            assert p.returncode == 130 and err.rstrip().endswith("axdf: interrupted"), case
        else:
            assert p.returncode == 0, case
        if report.exists():  # whole or absent, never a part
            assert json.loads(report.read_text())["verdict"] == "same", case
        assert not [f for f in tmp_path.rglob(".axdf-tmp-*")], case
    assert landed >= len(delays) // 2  # most signals land while the command runs


def test_pack_refuses_muscles_too_fine_to_pack_before_any_work(tmp_path, capsys):
    """A muscle at the spec's finest resolution would need tens of GB to pack: refused at
    once (exit 2, the muscle named, nothing written), not after the memory is gone."""
    from conftest import run_main

    lib = tmp_path / "lib"
    lib.mkdir()
    src = (REPO_ROOT / "muscles" / "demo" / "biceps_brachii.yaml").read_text()
    assert "resolution: [48, 24]" in src
    (lib / "fine.yaml").write_text(src.replace("resolution: [48, 24]", "resolution: [1000, 1000]"))
    out = tmp_path / "packed"
    rc, _, err = run_main(["pack", lib, "--skeleton", REPO_ROOT / "poses" / "skeletons" / "human_r.yaml",
                           "--out", out, "--allow-outside", "-q"], capsys)
    assert rc == 2, err
    assert "1,000,000 vertices" in err and "resolution 1000x1000" in err and "lower the muscles' resolution" in err
    assert "Traceback" not in err and not out.exists()
