"""The compiled pass: a whole run of the walk stretched to 1051 frames at 48x24 into npz
(subprocess) against tofile of the same bytes, the same run writing no meshes, a data-set
sample's evaluation (92 muscles x 1 frame), a chunk's outputs into fresh memory against steady
state (first touch), and numba's first-run compile cost."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from axdf_cli.model.skeleton import forward_kinematics
from benchmarks.common import DATASET_FILE, DEMO_JOB, GAIT_JOB, NO_CONTACT, ROOT, Table, mark, median_time
from benchmarks.sections.dataset import dataset_evaluation
from benchmarks.settings import Run

UNIT = True


TARGET_RUN_US = 20.0  # a whole run (npz, 92 muscles, 48x24) per muscle-frame, after start-up
TARGET_SAMPLE_MS = 10.0  # 92 muscles x 1 frame (a data-set sample's evaluation)
RUN_FRAMES = 1051  # the walk stretched to this many frames for the whole-run row


RUN_SCRIPT = r"""
import dataclasses, json, os, resource, sys, time
t_start = time.perf_counter()
from pathlib import Path
from benchmarks.case import stretched_pose
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, execute
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.skeleton import forward_kinematics
job, n, fmt, out, res, profile = sys.argv[1], int(sys.argv[2]), sys.argv[3], Path(sys.argv[4]), sys.argv[5], sys.argv[6]
plan = plan_run(load_job(job), out_arg=str(out), fmt_arg=None if fmt == "none" else fmt, stages={"contact": False})
if res != "library":
    skel = plan.pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    plan.muscles = [dataclasses.replace(s, resolution=tuple(map(int, res.split("x")))) for s in plan.muscles]
    plan.models = [MuscleModel(s, skel.bone_index, rest, skel) for s in plan.muscles]
plan.pose = stretched_pose(plan.pose, n)
plan.frames = plan.pose.frames
plan.render = dataclasses.replace(plan.render, enabled=False)
if fmt == "none":
    plan.formats = ()
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
t_ready, c0 = time.perf_counter(), cpu()
if profile != "-":
    import cProfile, io, pstats
    prof = cProfile.Profile()
    prof.runcall(execute, plan, overwrite=True)
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(int(profile))
    top = buf.getvalue()
else:
    execute(plan, overwrite=True)
    top = ""
dt, dc = time.perf_counter() - t_ready, cpu() - c0
nbytes = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) * 1024
print(json.dumps({"startup": t_ready - t_start, "seconds": dt, "cpu": dc, "bytes": nbytes, "top": top,
                  "maxrss": hwm, "muscle_frames": len(plan.frames) * len(plan.models)}))
"""


def whole_run(job: Path, n_frames: int, fmt: str, out: Path, resolution: str = "48x24", top: int = 0) -> dict:
    """``execute`` of ``job`` (pose stretched to ``n_frames``, muscles at ``resolution`` or
    "library") in a subprocess: start-up (imports, plan, models) and run seconds (wall and CPU
    of all threads), bytes written, muscle-frames; cProfile's ``top`` functions when asked."""
    import json

    shutil.rmtree(out, ignore_errors=True)
    p = subprocess.run([sys.executable, "-c", RUN_SCRIPT, str(job), str(n_frames), fmt, str(out), resolution,
                        str(top) if top else "-"], cwd=ROOT, capture_output=True, text=True)
    shutil.rmtree(out, ignore_errors=True)
    if p.returncode != 0:
        raise RuntimeError(f"whole run ({fmt}) failed: {p.stderr[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def tofile_seconds(nbytes: int, folder: Path, block: int = 64 << 20) -> float:
    """Seconds for ``ndarray.tofile`` to write ``nbytes`` into one new file, 64 MiB at a time
    (after os.sync(), as the run starts with no dirty pages of its own)."""
    data = np.random.default_rng(0).random(block // 8)
    path = folder / "tofile.raw"
    os.sync()
    t0 = time.perf_counter()
    with open(path, "wb") as fh:
        left = nbytes
        while left > 0:
            data[:max(1, min(left, block) // 8)].tofile(fh)
            left -= block
    dt = time.perf_counter() - t0
    path.unlink(missing_ok=True)
    return dt


COMPILE_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
from pathlib import Path
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, evaluate_plan
t1 = time.perf_counter()
plan = plan_run(load_job(sys.argv[1]), out_arg="unused", frames_arg="0:1", stages={"contact": False})
t2 = time.perf_counter()
for chunk, results in evaluate_plan(plan):
    for _ in results:
        pass
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "plan": t2 - t1, "evaluate": t3 - t2}))
"""


def compile_cost(job: Path, cache: Path) -> dict:
    """Start-up of a two-frame evaluation in a subprocess whose numba cache is ``cache``:
    seconds to import, plan (the models: the first compiled calls) and evaluate."""
    import json

    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    p = subprocess.run([sys.executable, "-c", COMPILE_SCRIPT, str(job)], cwd=ROOT, capture_output=True, text=True,
                       env=env)
    if p.returncode != 0:
        raise RuntimeError(f"compile-cost run failed: {p.stderr[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def first_touch(job: Path, repeats: int) -> tuple[float, float, int]:
    """µs per muscle-frame of the compiled step 1b (every muscle of a chunk of
    ``chunk_frames`` frames, :meth:`MuscleBatch.surfaces`) into fresh memory (every output
    page faulted in and zeroed by the kernel on first touch) and in steady state (the batch's
    buffers reused, warm); and the chunk's frames."""
    from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
    from axdf_cli.pipeline import chunk_frames, plan_run
    from axdf_cli.pipeline.evaluate import batch_of
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(job), out_arg="unused", stages=NO_CONTACT)
    batch = batch_of(plan)
    nf = chunk_frames(plan)
    frames = plan.pose.frames[:nf]
    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    act = sample_activation(plan.pose, plan.names, frames)
    every = list(range(len(plan.models)))
    tension = np.stack([effective_tension(s.tension, act[:, j]) for j, s in enumerate(plan.muscles)], axis=1)
    p, _ = batch.axis_points(world, q, every)
    mf = len(every) * len(frames)

    def once():
        batch.surfaces(world, p, tension, None, every)

    once()
    batch.pool.free = False  # np.empty each call: fresh pages
    cold = median_time(once, repeats)
    batch.pool.free = True
    once()
    warm = median_time(once, repeats)
    return cold / mf * 1e6, warm / mf * 1e6, len(frames)


def compiled_rows(table: "Table", tmp: Path, quick: bool, top: int = 0) -> list[str]:
    """The compiled pass: a whole run per muscle-frame against tofile of the
    same bytes, the data-set sample's evaluation (92 muscles x 1 frame), the first-touch cost
    of a chunk's outputs, and numba's first-run compile cost. Returns cProfile texts (``top``)."""
    job = GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB
    n = 200 if quick else RUN_FRAMES
    runs = {fmt: whole_run(job, n, fmt, tmp / f"run-{fmt}", top=top) for fmt in ("none", "npz")}
    r, base = runs["npz"], runs["none"]
    mf = r["muscle_frames"]
    ref = tofile_seconds(r["bytes"], tmp)
    table.section(f"the compiled pass: axdf run {job.relative_to(ROOT)}, walk stretched to {n} frames, "
                  f"{mf // n} muscles at 48x24, no render (subprocess; after start-up; wall and CPU of all threads)")
    table.add(f"whole run --format npz ({r['bytes'] / 2**20:.0f} MiB)", f"{r['seconds'] / mf * 1e6:.1f} µs/mf",
              f"CPU {r['cpu'] / mf * 1e6:.1f} µs/mf; tofile {ref / mf * 1e6:.1f} µs/mf", f"{r['seconds'] / ref:.1f}x tofile",
              f"<= {TARGET_RUN_US:g} µs/mf {mark(r['seconds'] / mf * 1e6 <= TARGET_RUN_US)}")
    table.add("whole run, no meshes (evaluation, stats, manifest)", f"{base['seconds'] / mf * 1e6:.1f} µs/mf",
              f"CPU {base['cpu'] / mf * 1e6:.1f} µs/mf")
    table.add("peak memory: npz / no meshes", f"{r['maxrss'] / 2**20:.0f} / {base['maxrss'] / 2**20:.0f} MiB")
    table.add("start-up (imports, plan, 92 models)", f"{r['startup']:.2f} s")
    cold, warm, nf = first_touch(job, 3 if quick else 7)
    table.add(f"step 1b, {mf // n} muscles x {nf} frames, outputs in fresh memory", f"{cold:.1f} µs/mf",
              f"steady state (buffers reused) {warm:.1f} µs/mf", f"{cold / warm:.2f}x first touch")
    if DATASET_FILE.is_file():
        ms = dataset_evaluation(5 if quick else 20) * 1000
        table.add("92 muscles x 1 frame (a data-set sample's evaluation)", f"{ms:.1f} ms", "",
                  "", f"<= {TARGET_SAMPLE_MS:g} ms {mark(ms <= TARGET_SAMPLE_MS)}")
    empty = tmp / "numba-cache"
    cold_c = compile_cost(job, empty)
    warm_c = compile_cost(job, empty)
    first = cold_c["plan"] + cold_c["evaluate"]
    again = warm_c["plan"] + warm_c["evaluate"]
    table.add("numba: first run (empty cache; compiles)", f"{first:.1f} s", f"cached {again:.2f} s",
              f"{first - again:.1f} s compiling")
    return [f"== whole run --format {fmt} ==\n{v['top']}" for fmt, v in runs.items() if v.get("top")]


def rows(table: Table, run: Run) -> list[str]:
    """:func:`compiled_rows`; with --profile, cProfile's top 25 functions when the section runs
    alone (--only), its top 15 in a whole bench."""
    return compiled_rows(table, run.tmp, run.quick, top=(25 if run.alone else 15) if run.profile else 0)
