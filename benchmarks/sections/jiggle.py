"""Row 12, jiggle: ``evaluate_plan`` of the gait2392 walk (92 muscles, the whole trial; 54
jiggle) with and without the jiggle stage (timed in turn, medians of 5; 3 with --quick), µs per
muscle-frame, and the stage alone; and a ``--frames`` subset's extra cost (frames not selected
are advanced too)."""
from __future__ import annotations

import dataclasses
import time

import numpy as np

from benchmarks.common import DEMO_JOB, GAIT_JOB, NO_CONTACT, Table, median_time
from benchmarks.settings import Run

UNIT = True


def time_chunks(plan, repeats: int) -> float:
    """Median seconds of evaluating every selected frame of ``plan`` (all muscles, no writing)
    through ``evaluate_plan``, its pre-pass (twist references, TIME stages' block states)
    included."""
    return time_pair(plan, plan, repeats)[0]


def time_pair(a, b, repeats: int) -> tuple[float, float]:
    """Median seconds of evaluating plans ``a`` and ``b`` (as :func:`time_chunks`), timed in
    turn (a, b, a, b, ...): on a shared machine both see the same load."""
    from axdf_cli.pipeline.evaluate import evaluate_plan

    def once(plan):
        t0 = time.perf_counter()
        for _, results in evaluate_plan(plan):
            for _ in results:
                pass
        return time.perf_counter() - t0

    ts = [(once(a), once(b)) for _ in range(max(1, repeats))]
    return float(np.median([t[0] for t in ts])), float(np.median([t[1] for t in ts]))


def chunk_at(plan, rows: slice, frames: np.ndarray, muscles: list[int]):
    """Kinematics and step 1a (axis control points) of ``muscles`` at ``frames``: the chunk
    ``pipeline.evaluate`` hands a TIME stage, made from its public pieces."""
    from axdf_cli.model.pose import sample_activation, sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.pipeline.evaluate import batch_of
    from axdf_cli.pipeline.stages import Chunk

    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    act = sample_activation(plan.pose, plan.names, frames)
    batch = batch_of(plan)
    p, notes = batch.axis_points(world, q, muscles)
    return Chunk(rows, frames, q, world, act, muscles, batch.unpack(p, muscles), notes=notes)


def time_jiggle_stage(plan, repeats: int) -> tuple[float, int]:
    """Median seconds of the jiggle stage alone over the pose's frames from its first to the
    last selected (the axis placed once, outside the timing), and the number of jiggling
    muscles."""
    from axdf_cli.pipeline.evaluate import TIME_BLOCK
    from axdf_cli.pipeline.jiggle_stage import JiggleStage

    stage = JiggleStage()
    which = list(range(len(plan.models)))
    frames = plan.pose.frames[plan.pose.frames <= plan.frames.max()]
    chunks = [chunk_at(plan, slice(s, s + TIME_BLOCK), frames[s:s + TIME_BLOCK], which)
              for s in range(0, len(frames), TIME_BLOCK)]

    def once():
        state = stage.start(plan)
        for ck in chunks:
            state, _ = stage(state, ck)

    return median_time(once, repeats), len(stage.start(plan).muscles)


def jiggle_rows(table: "Table", reps: int) -> None:
    """The jiggle stage's cost on the gait2392 walk (or the demo when not shipped)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job

    job = load_job(GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB)
    base = plan_run(job, stages=NO_CONTACT)
    plan = dataclasses.replace(base, frames=base.pose.frames)  # the whole trial
    off = dataclasses.replace(plan, stages=())
    nm, nf = len(plan.models), len(plan.frames)
    mf = nm * nf
    t_on, t_off = time_pair(plan, off, reps)
    t_stage, n_jig = time_jiggle_stage(plan, reps)
    table.section(f"jiggle ({plan.pose.name}: {nm} muscles, {n_jig} with jiggle, {nf} frames): evaluate_plan "
                  "(all muscles, no writing) with the stage vs without")
    table.add("evaluate with jiggle", f"{t_on / mf * 1e6:.1f} µs/mf", f"without {t_off / mf * 1e6:.1f} µs/mf",
              f"{t_on / t_off:.3f}x")
    table.add("the jiggle stage alone (axis placed outside)", f"{t_stage / mf * 1e6:.2f} µs/mf",
              f"{t_stage / (n_jig * nf) * 1e6:.2f} µs per jiggling muscle-frame")
    every4 = dataclasses.replace(plan, frames=plan.frames[::4])
    t_sub, t_sub_off = time_pair(every4, dataclasses.replace(every4, stages=()), reps)
    per = nm * len(every4.frames)
    table.add("--frames every 4th (frames between advanced too)", f"{t_sub / per * 1e6:.1f} µs/mf",
              f"without {t_sub_off / per * 1e6:.1f} µs/mf", f"{t_sub / t_sub_off:.3f}x")


def rows(table: Table, run: Run) -> list[str]:
    jiggle_rows(table, 2 * run.reps - 1)
    return []
