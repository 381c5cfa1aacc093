"""Row 10, rendering split over processes: ``make demo``'s first job (poses/jobs/demo.yaml,
meshes and 512x512 frames; every 2nd frame with ``--quick``) as a subprocess at ``--jobs 1`` and
``--jobs 2``, and their ratio; only where the rendering row renders."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

from benchmarks.common import DEMO_JOB, ROOT, Table, mark, run_subprocess
from benchmarks.sections import render
from benchmarks.settings import Run

UNIT = False


def run_jobs(job: Path, out: Path, jobs: int, frames: str | None = None) -> dict:
    """``axdf run JOB --jobs N`` (meshes and frames, as the job says) in a subprocess: wall
    seconds, with the load average of the minute before it started (the machine may be shared)."""
    load = os.getloadavg()[0]
    args = ["run", str(job), "--out", str(out), "--overwrite", "--jobs", str(jobs), "--quiet", "--no-contact"]
    r = run_subprocess(args + (["--frames", frames] if frames else []))
    if r["rc"] != 0:
        raise RuntimeError(f"axdf run {job} --jobs {jobs} failed ({r['rc']}): {r['stderr'][-400:]}")
    r["load"] = load
    return r


def render_jobs_rows(table: "Table", tmp: Path, quick: bool) -> None:
    """``make demo``'s first job at --jobs 1 and --jobs 2 (the frames split over render workers)."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import plan_run

    frames = "0:191:2" if quick else None
    plan = plan_run(load_job(DEMO_JOB), out_arg=str(tmp / "unused"), frames_arg=frames)
    w, h = plan.render.size
    table.section(f"rendering over processes: axdf run {DEMO_JOB.relative_to(ROOT)} ({len(plan.models)} muscles x "
                  f"{len(plan.frames)} frames, meshes + {w}x{h} PNG + EXR; subprocess) at --jobs 1 and --jobs 2")
    one = run_jobs(DEMO_JOB, tmp / "jobs-1", 1, frames)
    two = run_jobs(DEMO_JOB, tmp / "jobs-2", 2, frames)
    shutil.rmtree(tmp / "jobs-1", ignore_errors=True)
    shutil.rmtree(tmp / "jobs-2", ignore_errors=True)
    n = len(plan.frames)
    table.add("axdf run --jobs 1", f"{one['wall']:.1f} s", f"{n / one['wall']:.1f} frames/s; load before {one['load']:.2f}")
    table.add("axdf run --jobs 2 (frames over 2 render workers)", f"{two['wall']:.1f} s",
              f"--jobs 1 {one['wall']:.1f} s; load before {two['load']:.2f}", f"{one['wall'] / two['wall']:.2f}x",
              f"faster than --jobs 1 {mark(two['wall'] < one['wall'])}")


def rows(table: Table, run: Run) -> list[str]:
    rf = render.measure(run)
    if "error" in rf:
        table.section(f"rendering over processes: no rendering here ({rf['error'][:60]}); skipped")
        return []
    render_jobs_rows(table, run.tmp, run.quick)
    return []
