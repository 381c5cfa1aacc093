"""Row 14, whole_body: a frame of the whole body (poses/jobs/myobody_atlas_walk.yaml: myobody's
416 atlas muscles and 12 added, on the CMU walk, contact on, under skins/myobody) beside a
frame of gait2392's (poses/jobs/gait2392_walk_skin.yaml: 92 packed muscles on the measured walk under
skins/gait2392), each through ``evaluate_plan``: the muscles alone, with contact, and with
contact and the skin, ms per frame (the skin stage's start, once per run, left out). The
target: the whole body's full frame at most 5x gait2392's."""
from __future__ import annotations

import dataclasses
import time

from benchmarks.common import NO_CONTACT, ROOT, Table, mark
from benchmarks.sections.jiggle import time_chunks
from benchmarks.settings import Run

UNIT = False
BODY_JOB = ROOT / "poses" / "jobs" / "myobody_atlas_walk.yaml"
GAIT_SKIN_JOB = ROOT / "poses" / "jobs" / "gait2392_walk_skin.yaml"
#: (label, job, frames, frames with --quick)
CASES = (("gait2392 (92 packed muscles, skins/gait2392)", GAIT_SKIN_JOB, "18:84:3", "18:84:16"),
         ("myobody (416 atlas muscles, skins/myobody)", BODY_JOB, "0:248:8", "0:248:62"))
#: the three ways a frame is timed: stages off by name, and whether the skin is worn
VARIANTS = (("muscles alone", NO_CONTACT, False), ("muscles + contact", {}, False),
            ("muscles + contact + skin", {}, True))


def case_ms(job, frames: str) -> tuple[dict, int]:
    """ms per frame of each variant of ``job`` over ``frames`` (warmed on two frames first)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.skin_stage import SkinStage
    from axdf_cli.specs import load_job

    out = {}
    for name, stages, skin in VARIANTS:
        plan = plan_run(load_job(job), frames_arg=frames, stages=stages or None)
        start = 0.0
        if not skin:
            plan = dataclasses.replace(plan, stages=tuple(s for s in plan.stages if not isinstance(s, SkinStage)))
        else:
            stage = next(s for s in plan.stages if isinstance(s, SkinStage))
            t0 = time.perf_counter()
            stage.start(plan)
            start = time.perf_counter() - t0
        time_chunks(dataclasses.replace(plan, frames=plan.frames[:2]), 1)  # compiled code and caches warm
        out[name] = (time_chunks(plan, 1) - start) / len(plan.frames) * 1e3
    return out


def rows(table: Table, run: Run) -> list[str]:
    measured = []
    for label, job, frames, quick in CASES:
        if not job.is_file():
            continue
        ms = case_ms(job, quick if run.quick else frames)
        measured.append((label, frames if not run.quick else quick, ms))
    table.section("a frame of the whole body beside gait2392's (evaluate_plan, ms per frame; the skin stage's "
                  "start once per run left out)")
    base = measured[0][2] if measured and measured[0][0] == CASES[0][0] else None
    for k, (label, frames, ms) in enumerate(measured):
        compared = k > 0 and base is not None  # the first case (gait2392) is the reference
        for name, _, _ in VARIANTS:
            ratio = ms[name] / base[name] if compared else None
            target = f"<= 5x {mark(ratio <= 5.0)}" if compared and name == VARIANTS[-1][0] else ""
            table.add(f"{label}, frames {frames}: {name}", f"{ms[name]:.0f} ms",
                      f"gait2392 {base[name]:.0f} ms" if compared else "", f"{ratio:.2f}x" if compared else "", target)
    return []
