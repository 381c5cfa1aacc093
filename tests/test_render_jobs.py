"""`axdf run --jobs N` and `axdf render --jobs N` render over N worker processes.

The frames are split in blocks over render workers that come from a fork server (never
forked from the process that may have rendered before), each with its own GL context: the
bytes are those of one process; the manifest is incomplete while frames are written and
lists the whole ones, so --resume keeps them; workers stop with the parent (SIGTERM: exit
130, no traceback, no temporaries; SIGKILL: they die too).
"""
from __future__ import annotations

import json
import os
import time

import pytest

from axdf_cli.workers import WorkerDied, process_map
from conftest import run_main
from test_safety import (alive, interrupt, kill_parent_of_frozen, own_leftovers, project, snapshot,  # noqa: F401
                         spawn, wait_for)  # (project: a fixture)

FEW = ["--size", "64x64", "--frames", "0:191:24", "-q"]  # 8 frames: 2 blocks of 4 with --jobs 2
LONG = ["run", "poses/jobs/demo.yaml", "--size", "64x64", "--frames", "0:191", "--out", "out"]


def count_frames(folder) -> int:
    return sum(1 for _ in (folder / "frames").glob("*.png")) if (folder / "frames").exists() else 0


def descendants(pid: int) -> list[int]:
    """Every live process below ``pid`` (render workers are children of a fork server)."""
    parent = {}
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                stat = open(f"/proc/{d}/stat").read()
            except OSError:
                continue
            parent[int(d)] = int(stat.rsplit(")", 1)[1].split()[1])
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def test_run_jobs_renders_the_same_bytes_and_never_makes_gl_here(project, capsys, monkeypatch):
    # one process first: this process has used llvmpipe when the render workers start
    assert run_main(["run", "poses/jobs/demo.yaml", "--out", "one", *FEW], capsys)[0] == 0
    from axdf_cli.render import context

    made = []
    real = context.create_gl_context

    def spy(*a, **k):
        made.append(os.getpid())
        return real(*a, **k)

    monkeypatch.setattr(context, "create_gl_context", spy)  # (the EGL check's forked child inherits it)
    here = os.getpid()
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", "two", "--jobs", "2", *FEW], capsys)
    assert rc == 0, err
    assert here not in made  # frames drawn by the workers; this process made no GL context
    one, two = snapshot(project / "one"), snapshot(project / "two")
    assert len([k for k in one if k.startswith("frames/")]) == 16 and "camera.json" in one
    assert one == two  # PNG, EXR, camera.json, manifest, meshes
    m = json.loads((project / "two" / "manifest.json").read_text())
    assert m["complete"] is True and m["gl"]["renderer"]


def test_render_jobs_gives_the_same_bytes(project, capsys):
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", "r", "--no-render", "--frames", "0:191:16",
                           "--format", "ply,npz", "-q"], capsys)
    assert rc == 0, err
    for jobs in ("1", "3"):
        rc, _, err = run_main(["render", "r", "--out", f"r{jobs}", "--size", "48x40", "--view", "sheet",
                               "--jobs", jobs, "-q"], capsys)
        assert rc == 0, err
    assert snapshot(project / "r1") == snapshot(project / "r3")
    assert count_frames(project / "r3") == 12


@pytest.mark.parametrize("how", ["SIGTERM", "Ctrl-C to the group"])
def test_an_interrupted_jobs_render_is_incomplete_and_resume_completes_it(project, capsys, how):
    assert run_main(["run", "poses/jobs/demo.yaml", "--out", "ref", "--size", "64x64", "--frames", "0:191", "-q"],
                    capsys)[0] == 0
    out = project / "out"
    p = spawn(LONG + ["--jobs", "2"], project, start_new_session=True)
    assert wait_for(lambda: count_frames(out) >= 40, timeout=120)  # a few blocks rendered
    workers = descendants(p.pid)
    assert interrupt(p, how).decode().strip() == "axdf: interrupted"  # no traceback, no warning
    assert wait_for(lambda: not any(alive(w) for w in workers), timeout=20)
    assert own_leftovers(out) == []
    m = json.loads((out / "manifest.json").read_text())
    assert m["complete"] is False and "camera.json" not in m["files"]
    listed = sorted(r for r in m["files"] if r.startswith("frames/"))
    assert listed and len(listed) < 2 * 192  # the whole blocks so far
    kept = {r: os.stat(out / r).st_ino for r in listed}
    rc, text, err = run_main(LONG[:-2] + ["--out", "out", "--jobs", "2", "--resume"], capsys)
    assert rc == 0, err
    assert {r: os.stat(out / r).st_ino for r in listed} == kept  # not drawn again
    assert snapshot(out) == snapshot(project / "ref")


def test_render_workers_die_with_the_parent(project):
    out = project / "out"
    p = spawn(LONG + ["--jobs", "2"], project)
    assert wait_for(lambda: count_frames(out) >= 8, timeout=120)
    workers = descendants(p.pid)  # the fork server and its render workers
    assert len(workers) >= 3
    kill_parent_of_frozen(p, workers)
    assert count_frames(out) < 192  # they stopped, not finished


def _square(shared, x):
    return shared * x * x


def _dies(shared, x):
    if x == 2:
        os._exit(1)
    time.sleep(0.05)
    return x


def test_process_map_results_in_order_and_a_dead_worker_is_an_error():
    got = []
    assert process_map(_square, [1, 2, 3, 4, 5], 2, jobs=2, on_result=got.append) == [2, 8, 18, 32, 50]
    assert sorted(got) == [2, 8, 18, 32, 50]
    with pytest.raises(WorkerDied) as e:
        process_map(_dies, [1, 2, 3], None, jobs=2)
    assert e.value.exit_code == 3 and "--resume" in e.value.hint


def test_frame_blocks_cover_every_frame_once():
    from axdf_cli.render.framefiles import RENDER_CHUNK, frame_blocks

    for n, jobs in [(1, 2), (5, 2), (8, 2), (100, 3), (7, 16)]:
        frames = list(range(10, 10 + 2 * n, 2))
        blocks = frame_blocks(frames, jobs)
        assert [f for b in blocks for f in b] == frames
        assert all(0 < len(b) <= RENDER_CHUNK for b in blocks)
        assert len(blocks) >= min(jobs, n)


def test_bench_render_jobs_helper(tmp_path):
    from benchmarks import common
    from benchmarks.sections import render_jobs

    r = render_jobs.run_jobs(common.DEMO_JOB, tmp_path / "o", 2, frames="0:3")
    assert r["rc"] == 0 and r["wall"] > 0 and r["load"] >= 0
    assert len(list((tmp_path / "o" / "frames").glob("*.png"))) == 4
