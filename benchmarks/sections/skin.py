"""Row 13, skin: the skin stage (``axdf run --skin``) over the gait2392 walk and the CMU walk onto
gait2392 (packed muscles, contact on): its ms per frame against the muscles plus contact,
measured side by side, the skin's volume against rest, muscle vertices outside it (the
product's normal test and libigl's winding numbers), skin vertices inside a bone, and pops."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from benchmarks.common import CMU_GAIT_JOB, GAIT_JOB, ROOT, Table, mark

HOP_JOB = ROOT / "poses" / "jobs" / "gait2392_hop.yaml"
from benchmarks.settings import Run

UNIT = False


def skin_pass(plan) -> tuple[float, np.ndarray]:
    """Evaluate every frame of ``plan`` with its stages: wall time (s) and, where the plan has
    a skin, its measures per frame (F, len(SKIN_COLUMNS)); zeros without one."""
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS, SKIN_CSV

    out = np.zeros((len(plan.frames), len(SKIN_COLUMNS)))
    t0 = time.perf_counter()
    for chunk, results in evaluate_plan(plan):
        for _ in results:
            pass
        if SKIN_CSV in chunk.tables:
            out[np.arange(len(plan.frames))[chunk.rows]] = chunk.tables[SKIN_CSV]
    return time.perf_counter() - t0, out


def skin_checks(plan) -> dict:
    """Over every frame of ``plan`` (a run with a skin), by libigl's winding numbers on the
    meshes the stage leaves: the share of muscle vertices outside the skin and of skin vertices
    inside a bone (each bone mesh with its holes capped), at the worst frame; and the largest
    change, between consecutive frames of the plan, of a skin vertex's offset from where
    skinning alone puts it (m): a pop is the stage's own jump, not the motion's; and the share
    of skin vertices folded (a point 2 mm out along the skin's normal inside the skin,
    :func:`~axdf_cli.geometry.winding.folded`) at the worst frame: ``folded_all`` all of them,
    ``folded`` those not folded in the rest skin as worn (``folded_rest``: MakeHuman's lips,
    eyelids and toes, and the thighs' crotch, touch at rest; a crease is a new fold)."""
    from axdf_cli.geometry.mesh import capped
    from axdf_cli.geometry.winding import folded
    from axdf_cli.geometry.winding import inside as within
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SKIN_NAME, SkinStage, skinned

    model = next(s for s in plan.stages if isinstance(s, SkinStage)).start(plan)
    worn = set(model.bones.tolist())
    bones = {b: capped(v, f) for b, (v, f, _) in plan.bone_meshes.items() if b in worn}
    outside = inside = step = folded_all = folded_new = 0.0
    at_rest = folded(model.rest, model.faces)  # lips, eyelids, toes and the crotch touch at rest
    prev = None
    for chunk, results in evaluate_plan(plan):
        res = {j: r for j, r in results}
        for i in range(len(chunk.frames)):
            y = chunk.parts[SKIN_NAME].positions[i].astype(np.float64)
            mus = np.concatenate([res[j].vertices[i] for j in sorted(res)]).astype(np.float64)
            outside = max(outside, float((~within(y, model.faces, mus)).mean()))
            ins = np.zeros(len(y), bool)
            for b, (bv, bf) in bones.items():
                w = chunk.world[i, b]
                wv = bv @ w[:3, :3].T + w[:3, 3]
                near = np.flatnonzero(np.all((y > wv.min(axis=0)) & (y < wv.max(axis=0)), axis=1))
                if len(near):
                    ins[near[within(wv, bf, y[near], exact=True)]] = True
            inside = max(inside, float(ins.mean()))
            fold = folded(y, model.faces)
            folded_all = max(folded_all, float(fold.mean()))
            folded_new = max(folded_new, float((fold & ~at_rest).mean()))
            x = skinned(model, chunk.world[i])
            if prev is not None:
                step = max(step, float(np.linalg.norm((y - x) - prev, axis=1).max()))
            prev = y - x
    return {"outside": outside, "inside_bone": inside, "offset_step": step, "folded": folded_new,
            "folded_all": folded_all, "folded_rest": float(at_rest.mean())}


#: Pops are looked for at 1/POP_SUBSTEPS of a frame, and the largest steps found again at
#: 1/POP_SUBSTEPS of that.
POP_SUBSTEPS = 8
#: Where pops are looked for: the walk's swing, and the CMU walk's crouch into its turn (its
#: deepest hip flexion, where the skin's pushes are largest).
POP_WINDOWS = {"gait2392 walk": (54, 66), "CMU walk retargeted onto gait2392": (66, 78)}


def skin_offsets(plan, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The skin's offset from where skinning alone puts it (F, V, 3) at ``frames`` (fractional
    frames: the pose interpolated between its keys), and those frames, sorted. TIME stages
    (jiggle) are left out: they integrate at the pose's own frame rate."""
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SKIN_NAME, SkinStage, skinned
    from axdf_cli.pipeline.stages import Scope

    plan = dataclasses.replace(plan, frames=np.asarray(frames, np.float64),
                               stages=tuple(s for s in plan.stages if s.scope != Scope.TIME))
    model = next(s for s in plan.stages if isinstance(s, SkinStage)).start(plan)
    at, out = [], []
    for chunk, results in evaluate_plan(plan):
        for _ in results:
            pass
        for i in range(len(chunk.frames)):
            y = chunk.parts[SKIN_NAME].positions[i].astype(np.float64)
            x = skinned(model, chunk.world[i])
            at.append(float(chunk.frames[i]))
            out.append(y - x)
    order = np.argsort(at, kind="stable")
    return np.asarray(at)[order], np.stack(out)[order]


def skin_pops(plan, first: int, last: int, look: int = 3) -> dict:
    """Pops, as jumps: a continuous skin's step shrinks with the time step, a pop's does not.
    The skin's offsets from skinning over frames ``first..last`` at 1/POP_SUBSTEPS of a frame;
    the ``look`` largest sub-steps (each a vertex and an interval) are sampled again at
    1/POP_SUBSTEPS of that. ``share``: the largest part of a sub-step that one of its finer
    steps takes (about 1/POP_SUBSTEPS where the skin moves smoothly, all of it at a jump)."""
    at, off = skin_offsets(plan, np.linspace(first, last, (last - first) * POP_SUBSTEPS + 1))
    steps = np.linalg.norm(np.diff(off, axis=0), axis=2)  # (S, V)
    share, coarse = 0.0, float(steps.max(initial=0.0))
    for flat in np.argsort(steps, axis=None)[::-1][:look]:
        k, v = np.unravel_index(flat, steps.shape)
        _, fine = skin_offsets(plan, np.linspace(at[k], at[k + 1], POP_SUBSTEPS + 1))
        fine_steps = np.linalg.norm(np.diff(fine[:, v], axis=0), axis=1)
        share = max(share, float(fine_steps.max() / max(steps[k, v], 1e-12)))
    return {"substep": coarse, "share": share}


def make_skin(tmp: Path) -> Path | None:
    """The bench's skin: ``axdf skin --push`` of gait2392 against its packed muscles, in
    ``tmp/skin_gait2392`` (made once per bench run); None where axdf skin failed."""
    from axdf_cli.cli.main import main as axdf_main

    skin_dir = tmp / "skin_gait2392"
    if (skin_dir / "skin.yaml").is_file():
        return skin_dir
    if axdf_main(["skin", "--skeleton", str(ROOT / "poses" / "skeletons" / "gait2392.yaml"), "--muscles",
                  str(ROOT / "muscles" / "gait2392_packed"), "--push", "--out", str(skin_dir), "-q"]) != 0:
        return None
    return skin_dir


def skin_rows(table: "Table", quick: bool, tmp: Path) -> None:
    """The skin stage (``axdf run --skin``) over the shipped gait2392 walk and the CMU walk
    retargeted onto gait2392 (packed muscles, contact on), the skin made by ``axdf skin --push``
    against those muscles: its cost per frame against the muscles' evaluation plus contact,
    measured side by side, and per frame the skin's volume against its rest volume, the share
    of muscle vertices outside it, and the largest push."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS, SkinStage
    from axdf_cli.specs import load_job

    skin_dir = make_skin(tmp)
    if skin_dir is None:
        table.section("skin stage: axdf skin failed (no rows)")
        return
    skin = str(skin_dir / "skin.yaml")
    for label, job, frames in (("gait2392 walk", GAIT_JOB, "18:84:6" if quick else None),
                               ("CMU walk retargeted onto gait2392", CMU_GAIT_JOB, "0:248:24" if quick else None)):
        if not job.is_file():
            continue
        without = plan_run(load_job(job), frames_arg=frames)
        with_skin = plan_run(load_job(job), frames_arg=frames, skin_arg=skin)
        skin_pass(dataclasses.replace(with_skin, frames=with_skin.frames[:2]))  # compiled code and the start warm
        t_base, _ = skin_pass(without)
        t_skin, m = skin_pass(with_skin)
        stage = next(s for s in with_skin.stages if isinstance(s, SkinStage))
        t0 = time.perf_counter()
        stage.start(with_skin)  # once per run (its candidates and their rest skin vertices)
        t_start = time.perf_counter() - t0
        nf = len(without.frames)
        ms = lambda t: t / nf * 1e3  # noqa: E731
        cost = (t_skin - t_start - t_base) / t_base
        table.section(f"skin stage ({label}, {nf} frames x {len(without.models)} packed muscles, contact on; "
                      f"skin: MakeHuman's body fitted by axdf skin --push)")
        table.add("skin stage per frame", f"{ms(t_skin - t_start - t_base):.1f} ms",
                  f"muscles + contact {ms(t_base):.1f} ms", f"{cost:.2f}x", f"<= 1x {mark(cost <= 1.0)}")
        table.add("skin stage start, once per run (and per worker)", f"{t_start * 1e3:.0f} ms")
        ratio = m[:, SKIN_COLUMNS.index("volume_ratio")]
        table.add("skin volume against rest (worst frame)", f"{np.abs(ratio - 1).max() * 100:.2f}% off",
                  f"range {ratio.min():.4f}..{ratio.max():.4f}", "", f"<= 3% {mark(np.abs(ratio - 1).max() <= 0.03)}")
        out = m[:, SKIN_COLUMNS.index("outside")]
        table.add("muscle vertices above the skin by the normal test (skin.csv outside, worst frame; the bound is "
                  "the winding number's below)", f"{out.max() * 100:.2f}%", f"mean {out.mean() * 100:.2f}%")
        table.add("largest push", f"{m[:, SKIN_COLUMNS.index('push')].max() * 1000:.0f} mm")
        window = {"gait2392 walk": "54:66", "CMU walk retargeted onto gait2392": "66:78"}[label] if quick else frames
        c = skin_checks(plan_run(load_job(job), frames_arg=window, skin_arg=skin))
        where = f"frames {window}" if window else "every frame"
        table.add(f"muscle vertices outside the skin, winding number ({where}, worst)", f"{c['outside'] * 100:.3f}%",
                  "", "", f"<= 0.5% {mark(c['outside'] <= 0.005)}")
        table.add(f"skin vertices inside a bone, winding number, holes capped ({where}, worst)",
                  f"{c['inside_bone'] * 100:.3f}%", "", "", f"<= 0.5% {mark(c['inside_bone'] <= 0.005)}")
        table.add(f"skin vertices folded where the rest skin is not: 2 mm out along the skin's normal lies inside "
                  f"the skin, winding number ({where}, worst)", f"{c['folded'] * 100:.3f}%",
                  f"all folded {c['folded_all'] * 100:.2f}%, at rest {c['folded_rest'] * 100:.2f}%", "",
                  f"<= 0.1% {mark(c['folded'] <= 0.001)}")
        table.add(f"largest change of a skin vertex's offset from skinning, frame to frame ({where})",
                  f"{c['offset_step'] * 1000:.1f} mm")
        first, last = POP_WINDOWS[label]
        pops = skin_pops(plan_run(load_job(job), frames_arg=f"{first}:{last + 1}", skin_arg=skin), first, last)
        table.add(f"pops: the largest offset steps at 1/{POP_SUBSTEPS} frame (frames {first}:{last}), sampled "
                  f"{POP_SUBSTEPS}x finer: the most one finer step takes (a jump: all)",
                  f"{pops['share'] * 100:.0f}%", f"of {pops['substep'] * 1000:.1f} mm", "",
                  f"< 50% {mark(pops['share'] < 0.5)}")


def rows(table: Table, run: Run) -> list[str]:
    skin_rows(table, run.quick, run.tmp)
    skinning_rows(table, run.quick, run.tmp)
    return []


#: The skinning methods' comparison (:func:`skinning_rows`): each case's window of its deepest
#: flexion (frames A:B) and, inside it, the pops' window. The hop crouches to 50 degrees of hip
#: and 65 of knee flexion at frame 36 and lands into 45 and 60 at 72.
SKINNING_CASES = (("gait2392 walk", GAIT_JOB, (54, 66), (58, 62)),
                  ("CMU walk retargeted onto gait2392", CMU_GAIT_JOB, (66, 78), (70, 74)),
                  ("gait2392 hop", HOP_JOB, (30, 42), (34, 38)))


def method_skin(skin_dir: Path, method: str) -> Path:
    """The bench's skin file with ``skinning: method`` (beside the original, its files shared)."""
    out = skin_dir / f"skin_{method}.yaml"
    text = (skin_dir / "skin.yaml").read_text()
    out.write_text("\n".join(line for line in text.splitlines() if not line.startswith("skinning:"))
                   + f"\nskinning: {method}\n")
    return out


def skinning_measures(job: Path, skin: Path, window: tuple, pop_window: tuple, quick: bool) -> dict:
    """One skinning method on one case: the folded share, the muscle vertices outside (winding
    numbers, :func:`skin_checks`) and the volume against rest (skin.csv), at the window's worst
    frame; pops (:func:`skin_pops`) over ``pop_window``; the skin stage's ms per frame (against
    the same frames without a skin, side by side)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS, SkinStage, skinned
    from axdf_cli.specs import load_job

    a, b = window
    frames = f"{a}:{b}:{2 if quick else 1}"
    without = plan_run(load_job(job), frames_arg=frames)
    with_skin = plan_run(load_job(job), frames_arg=frames, skin_arg=str(skin))
    skin_pass(dataclasses.replace(with_skin, frames=with_skin.frames[:1]))  # compiled code warm
    t_base, _ = skin_pass(without)
    t_skin, m = skin_pass(with_skin)
    t0 = time.perf_counter()
    next(s for s in with_skin.stages if isinstance(s, SkinStage)).start(with_skin)
    t_start = time.perf_counter() - t0
    c = skin_checks(with_skin)
    model = next(s for s in with_skin.stages if isinstance(s, SkinStage)).start(with_skin)
    world = forward_kinematics(with_skin.pose.skeleton, sample_coordinates(with_skin.pose, with_skin.frames))
    t0 = time.perf_counter()
    for w in world:
        skinned(model, w)
    t_skinning = (time.perf_counter() - t0) / len(world)
    first, last = pop_window
    pops = skin_pops(plan_run(load_job(job), frames_arg=f"{first}:{last + 1}", skin_arg=str(skin)), first, last)
    ratio = m[:, SKIN_COLUMNS.index("volume_ratio")]
    return {"folded": c["folded"], "folded_all": c["folded_all"], "outside": c["outside"], "volume": float(ratio[np.argmax(np.abs(ratio - 1))] - 1),
            "pops": pops["share"], "ms": (t_skin - t_start - t_base) / len(without.frames) * 1e3,
            "base_ms": t_base / len(without.frames) * 1e3, "skinning_ms": t_skinning * 1e3}


def skinning_rows(table: "Table", quick: bool, tmp: Path) -> None:
    """The skinning methods (:data:`axdf_cli.model.skinning.SKINNING`) measured against each
    other over the deepest flexion of the walk, the CMU walk and the hop (:data:`SKINNING_CASES`;
    every 2nd frame with ``--quick``): a row per case and method."""
    from axdf_cli.model.skinning import SKINNING

    skin_dir = make_skin(tmp)
    if skin_dir is None:
        table.section("skinning methods: axdf skin failed (no rows)")
        return
    table.section("skinning methods, side by side (the skin stage as it ships, but for its skinning): folded "
                  "where the rest skin is not (worst frame; all folded, with the rest's) | volume against rest (worst) | muscle vertices outside, winding (worst) | pops "
                  "(the most one finer step takes) | skin stage ms per frame (of which the skinning)")
    for label, job, window, pop_window in SKINNING_CASES:
        if not job.is_file():
            continue
        for method in SKINNING:
            r = skinning_measures(job, method_skin(skin_dir, method), window, pop_window, quick)
            ok = r["folded"] <= 0.001 and abs(r["volume"]) <= 0.03 and r["outside"] <= 0.005 and r["pops"] < 0.5
            table.add(f"{label}, frames {window[0]}:{window[1]}: {method}",
                      f"folded {r['folded'] * 100:.3f}% (all {r['folded_all'] * 100:.2f}%) | volume {r['volume'] * 100:+.2f}% | outside "
                      f"{r['outside'] * 100:.3f}% | pops {r['pops'] * 100:.0f}% | {r['ms']:.1f} ms (skinning alone "
                      f"{r['skinning_ms']:.1f} ms)",
                      f"muscles + contact {r['base_ms']:.1f} ms", f"{r['ms'] / r['base_ms']:.2f}x",
                      f"<= 0.1%, 3%, 0.5%, < 50%, <= 1x {mark(ok and r['ms'] <= r['base_ms'])}")
