"""``--long``: the memory check of 10,000 frames x 92 muscles streamed through
``pipeline.evaluate_chunks`` in a subprocess (several minutes), keeping what ``execute`` keeps
(stats, the manifest's file list); peak RSS. Measured with ``--long`` or ``--only long``."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

from benchmarks.common import DEMO_JOB, GAIT_JOB, ROOT, Table, mark
from benchmarks.settings import Run

UNIT = False


LONG_FRAMES = 10_000
LONG_MEMORY = 1 << 30  # 1 GiB


LONG_SCRIPT = r"""
import json, sys, time
import numpy as np
from benchmarks.case import stretched_pose
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, evaluate_chunks, chunk_frames
job, n = sys.argv[1], int(sys.argv[2])
plan = plan_run(load_job(job), stages={"contact": False})
plan.pose = stretched_pose(plan.pose, n)
plan.frames = plan.pose.frames
nm = len(plan.models)
stats = np.zeros((n, nm, 6))
files = {}
t0 = time.perf_counter()
for sl, world, results in evaluate_chunks(plan):
    for j, res in results:  # what execute keeps per muscle-frame: float32 meshes, stats, file list
        pos = res.vertices.astype(np.float32); nrm = res.normals.astype(np.float32)
        stats[sl, j, 0] = res.length; stats[sl, j, 1] = res.volume
        for f in plan.frames[sl]:
            files[f"meshes/{plan.names[j]}/{plan.names[j]}_{int(f):04d}.ply"] = "%064x" % (f * nm + j)
dt = time.perf_counter() - t0
manifest = json.dumps({"files": files}, indent=1)
# VmHWM: this process's own peak (ru_maxrss would include the forking parent's, kept across exec)
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) * 1024
print(json.dumps({"seconds": dt, "muscle_frames": n * nm, "chunk": chunk_frames(plan),
                  "manifest_bytes": len(manifest), "maxrss": hwm}))
"""


def long_memory(job: Path, n_frames: int = LONG_FRAMES) -> dict:
    """Stream ``n_frames`` (the job's pose stretched) x all muscles through evaluate_chunks in
    a subprocess, keeping what ``execute`` keeps (stats, the manifest's file list); peak RSS."""
    import json

    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", LONG_SCRIPT, str(job), str(n_frames)], cwd=ROOT,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"long run failed: {p.stderr[-600:]}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r["wall"] = time.perf_counter() - t0
    return r


def rows(table: Table, run: Run) -> list[str]:
    lj = GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB
    lr = long_memory(lj)
    table.section(f"--long: {LONG_FRAMES} frames x all muscles through pipeline.evaluate_chunks "
                  "(+ stats and the manifest's file list)")
    table.add(f"peak memory ({lr['muscle_frames']} muscle-frames, chunk {lr['chunk']})",
              f"{lr['maxrss'] / 2**20:.0f} MiB", f"{lr['seconds']:.0f} s evaluating",
              f"{lr['maxrss'] / LONG_MEMORY:.2f} of 1 GiB", f"< 1 GiB {mark(lr['maxrss'] < LONG_MEMORY)}")
    table.add("manifest JSON (files list only)", f"{lr['manifest_bytes'] / 2**20:.0f} MiB")
    return []
