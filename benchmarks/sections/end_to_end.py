"""Row 6, end to end: ``axdf run`` of the largest shipped job as a subprocess (frames per
second, with and without contact, peak memory), and the split of its time between evaluation
and writing (cProfile)."""
from __future__ import annotations

import cProfile
import io
import pstats
import time
from pathlib import Path

from benchmarks.common import NO_CONTACT, ROOT, Table, mark, run_subprocess
from benchmarks.settings import Run

UNIT = False


def end_to_end(job: Path, out: Path, fmt: str = "ply", contact: bool = False) -> dict:
    """``axdf run JOB --no-render`` in a subprocess: wall time, frames, peak memory; without
    contact unless ``contact`` (the default of axdf run)."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import plan_run

    r = run_subprocess(["run", str(job), "--out", str(out), "--format", fmt, "--no-render", "--quiet"]
                       + ([] if contact else ["--no-contact"]))
    if r["rc"] != 0:
        raise RuntimeError(f"axdf run {job} failed ({r['rc']}): {r['stderr'][-400:]}")
    plan = plan_run(load_job(job), out_arg=str(out))
    r.update(frames=len(plan.frames), muscles=len(plan.models))
    return r


def _cum(stats: pstats.Stats, file_end: str, func: str) -> float:
    return sum(v[3] for (f, _, fn), v in stats.stats.items() if fn == func and f.endswith(file_end))


def profile_run(job: Path, out: Path, fmt: str = "ply", top: int = 0) -> dict:
    """Run ``execute`` in-process under cProfile (no rendering): seconds in evaluation (the
    pipeline's pre-pass, chunks and surfaces: ``pipeline.evaluate``), in writing (encode, sha256, atomic
    writes) and in total; ``top`` functions by own time as text."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import execute, plan_run

    t0 = time.perf_counter()
    plan = plan_run(load_job(job), out_arg=str(out), fmt_arg=fmt, stages=NO_CONTACT)
    t_plan = time.perf_counter() - t0
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runcall(execute, plan)
    total = time.perf_counter() - t0
    st = pstats.Stats(prof)
    # evaluation: the pre-pass (twist references, time stages' states), the chunks (kinematics,
    # axis points, time stages) and their surfaces (RMF, surface, frame stages), as the mesh pass reads them
    ev = (_cum(st, "evaluate.py", "prepare") + _cum(st, "evaluate.py", "evaluate_plan")
          + _cum(st, "evaluate.py", "_surfaces"))
    enc = _cum(st, f"{fmt}.py", "encode")
    wr = _cum(st, "runfolder.py", "write")  # OutputWriter.write: sha256 + atomic write
    text = ""
    if top:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(top)
        text = buf.getvalue()
    return {"plan": t_plan, "total": total, "evaluation": ev, "writing": enc + wr, "encode": enc,
            "muscle_frames": len(plan.frames) * len(plan.models), "top": text}


def rows(table: Table, run: Run) -> list[str]:
    job = run.job
    profiles = []
    table.section(f"end to end: axdf run {job.relative_to(ROOT)} --no-render --no-contact (subprocess; PLY)")
    e2e = end_to_end(job, run.tmp / "e2e")
    mf = e2e["frames"] * e2e["muscles"]
    table.add(f"axdf run ({e2e['muscles']} muscles x {e2e['frames']} frames)", f"{e2e['frames'] / e2e['wall']:.1f} fps",
              f"{mf / e2e['wall']:.0f} muscle-frames/s, {e2e['wall']:.1f} s")
    e2c = end_to_end(job, run.tmp / "e2e-contact", contact=True)
    table.add("axdf run with contact (the default)", f"{e2c['frames'] / e2c['wall']:.1f} fps",
              f"{mf / e2c['wall']:.0f} muscle-frames/s, {e2c['wall']:.1f} s", f"{e2c['wall'] / e2e['wall']:.2f}x")
    table.add("axdf run peak memory", f"{e2e['maxrss'] / 2**20:.0f} MiB")
    pr = profile_run(job, run.tmp / "e2e-profile", top=15 if run.profile else 0)
    ev, wt = pr["evaluation"], pr["writing"]
    table.add("execute: evaluation / writing (cProfile)", f"{ev:.1f} s / {wt:.1f} s",
              f"of {pr['total']:.1f} s (plan {pr['plan']:.1f} s)", f"{wt / max(ev, 1e-9):.2f}x",
              f"writing >= evaluation {mark(wt >= ev)}")
    if pr["top"]:
        profiles.append(f"== execute {job.name} ==\n{pr['top']}")
    return profiles
