"""Row 9, contact: the gait2392 walk (as imported, packed, the atlas library), the CMU walk,
arm26 and Rajagopal2016's running stride (muscles only) evaluated without any stage, with the
penetration stage's measures alone and with contact: µs per muscle-frame and the ratio, the
shares of vertices inside another muscle or a bone and the deepest penetration before and after
(the product's own measures, stats.csv's), the volume, and the muscle-frames that pop; where
the skeleton has bone meshes, libigl's distance to the meshes themselves against the fields the
product reads them through. Then the shipped packed library's report (axdf pack)."""
from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from benchmarks.common import (ARM_JOB, ARM_MUSCLES, ATLAS_MUSCLES, CMU_GAIT_JOB, GAIT_JOB, GAIT_MUSCLES, ROOT, Table,
                               mark)
from benchmarks.settings import Run

UNIT = True


#: Contact may at most double evaluation, and its targets on the walk.
TARGET_CONTACT_COST = 2.0
TARGET_INSIDE_MUSCLE = 0.02
TARGET_INSIDE_BONE = 0.005
TARGET_DEPTH = 0.003


#: A muscle-frame pops when a vertex steps more than this times its largest no-contact step.
POP_RATIO = 1.5


def contact_pass(plan) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate every frame of ``plan`` (with its stages): wall time (s), the contact measures
    (F, M, 3) (zeros where no stage measured), each muscle's largest vertex step from the
    previous frame of the plan (F, M; row 0 zero) and its volume (F, M)."""
    from axdf_cli.pipeline.evaluate import evaluate_plan

    nf, nm = len(plan.frames), len(plan.models)
    out = np.zeros((nf, nm, 3))
    step = np.zeros((nf, nm))
    vol = np.zeros((nf, nm))
    prev: dict = {}
    t0 = time.perf_counter()
    for chunk, results in evaluate_plan(plan):
        for j, r in results:
            rows = np.arange(nf)[chunk.rows]
            if r.contact is not None:
                out[rows, j] = r.contact
            vol[rows, j] = r.volume
            v = np.concatenate([prev[j][None], r.vertices]) if j in prev else r.vertices
            d = np.linalg.norm(np.diff(v, axis=0), axis=-1).max(axis=-1)
            step[rows[1:] if j not in prev else rows, j] = d
            prev[j] = r.vertices[-1].copy()
    return time.perf_counter() - t0, out, step, vol


def bones_by_libigl(plan) -> tuple[float, float, float, int]:
    """What a bone's mesh says, not its field: every frame of ``plan`` (its stages, contact
    included) evaluated again (apart from :func:`contact_pass`, which is timed), and every vertex within 1 cm of a bone's mesh box
    tested by libigl's signed distance to that mesh (the fast-winding-number sign, as the
    fields are made). Returns (share of the vertices inside a bone by libigl, the same by the
    product's measure (stats.csv's inside_bone, weighted by vertices), the deepest point in a
    bone by libigl (m), frames read)."""
    import igl

    from axdf_cli.pipeline.evaluate import evaluate_plan

    meshes = {i: (np.asarray(v, np.float64), np.asarray(f, np.int64)) for i, (v, f, _) in plan.bone_meshes.items()}
    n_all = n_in = 0
    field = deep = 0.0
    for chunk, results in evaluate_plan(plan):
        results = list(results)
        for fi in range(len(chunk.frames)):
            X = np.concatenate([r.vertices[fi] for _, r in results]).astype(np.float64)
            nv = np.array([len(r.vertices[fi]) for _, r in results], dtype=np.float64)
            field += float(sum(n * r.contact[fi, 1] for n, (_, r) in zip(nv, results) if r.contact is not None))
            sd = np.full(len(X), np.inf)
            inv = np.linalg.inv(chunk.world[fi])
            for b, (bv, bf) in meshes.items():
                y = X @ inv[b, :3, :3].T + inv[b, :3, 3]
                near = np.all((y > bv.min(axis=0) - 0.01) & (y < bv.max(axis=0) + 0.01), axis=1)
                if near.any():
                    d = igl.signed_distance(y[near], bv, bf, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]
                    sd[near] = np.minimum(sd[near], d)
            n_all += len(X)
            n_in += int((sd < 0).sum())
            deep = max(deep, float(-sd.min()))
    return n_in / max(n_all, 1), field / max(n_all, 1), deep, len(plan.frames)


def rajagopal_plan(tmp: Path, stages=None, packed: bool = False):
    """Rajagopal2016 over its running stride (tests/data/rajagopal2016, imported without bone
    meshes into ``tmp``: the contact is muscle against muscle only); ``packed``: its muscles
    packed by ``axdf pack --pose`` over the stride (timed: the row "axdf pack")."""
    from axdf_cli.cli.main import main as axdf_main
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import RefPolicy

    data = ROOT / "tests" / "data" / "rajagopal2016"
    imp = tmp / "rajagopal2016"
    if not imp.is_dir():
        rc = axdf_main(["import", "osim", str(data / "Rajagopal2016.osim"), "--motion", str(data / "run_stride_ik.mot"),
                        "--name", "rajagopal2016", "--no-meshes", "--out", str(imp), "-q"])
        if rc != 0:
            raise RuntimeError(f"axdf import osim Rajagopal2016 failed ({rc})")
    muscles = imp / "muscles"
    if packed:
        muscles = tmp / "rajagopal2016_packed"
        if not muscles.is_dir():
            skel = imp / "skeletons" / "rajagopal2016.yaml"
            t0 = time.perf_counter()
            rc = axdf_main(["pack", str(imp / "muscles"), "--skeleton", str(skel), "--pose",
                            str(imp / "run_stride_ik.yaml"), "--out", str(muscles), "--allow-outside", "-q"])
            PACK_TIMES["Rajagopal2016"] = time.perf_counter() - t0
            if rc != 0:
                raise RuntimeError(f"axdf pack Rajagopal2016 failed ({rc})")
    return plan_run(None, muscle_args=[str(muscles)], pose_arg=str(imp / "run_stride_ik.yaml"),
                    policy=RefPolicy(allow_outside=True), stages=stages)


#: How long ``axdf pack`` took, by model (seconds; filled by :func:`rajagopal_plan`).
PACK_TIMES: dict = {}


def pack_rows(table: "Table") -> None:
    """The shipped packed gait2392 library's report (muscles/gait2392_packed/pack_report.json,
    made by ``make pack``): the rest pose's overlap and volumes before and after packing, and
    the packing times measured here."""
    rep = ROOT / "muscles" / "gait2392_packed" / "pack_report.json"
    if not rep.is_file():
        return
    r = json.loads(rep.read_text())
    b, a = r["before"], r["after"]
    table.section("axdf pack (rest pose; gait2392: muscles/gait2392_packed/pack_report.json)")
    table.add("gait2392 rest: vertices inside another muscle", f"{a['inside_muscle'] * 100:.2f}%",
              f"as imported {b['inside_muscle'] * 100:.2f}%")
    table.add("gait2392 rest: vertices inside a bone", f"{a['inside_bone'] * 100:.2f}%",
              f"as imported {b['inside_bone'] * 100:.2f}%")
    table.add("gait2392 rest: volume kept", f"median {a['volume_ratio_median']:.3f}",
              f"least {a['volume_ratio_min']:.3f}", f"total {a['volume_total'] * 1000:.2f} / {b['volume_total'] * 1000:.2f} L")
    for k, t in PACK_TIMES.items():
        table.add(f"axdf pack {k}", f"{t:.0f} s")


def contact_rows(table: "Table", quick: bool, tmp: Path | None = None) -> None:
    """The shipped gait2392 walk (every frame; every 6th with --quick; with the muscles as
    imported, packed, and the atlas library, whose cost per muscle-frame is set beside the
    others'), its CMU walk, arm26's
    elbow flexion (as imported and packed) and Rajagopal2016's running stride (muscles only:
    imported without bone meshes): evaluation without any stage, with the penetration stage
    alone (--penetration: measures only), and with contact;
    the shares of vertices inside another muscle and inside a bone (mean over muscle-frames),
    the deepest penetration, the volume, and the muscle-frames whose largest vertex step from
    the previous frame exceeds POP_RATIO times the no-contact one (pops)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.stages import ContactStage
    from axdf_cli.specs import load_job

    frames = "18:84:6" if quick else None
    cases = [("gait2392 walk, muscles as imported", lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames,
                                                                         muscle_args=[str(GAIT_MUSCLES)], stages=sw)),
             ("gait2392 walk, packed (axdf pack --pose: the job's muscles)",
              lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames, stages=sw)),
             ("gait2392 walk, the atlas library (muscles/gait2392_atlas: fitted to the Visible Human)",
              lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames, muscle_args=[str(ATLAS_MUSCLES)], stages=sw)),
             ("CMU walk retargeted onto gait2392, packed (not the motion packed over)",
              lambda sw: plan_run(load_job(CMU_GAIT_JOB), frames_arg="0:248:24" if quick else None, stages=sw)),
             ("arm26 elbow flexion, muscles as imported", lambda sw: plan_run(
                 load_job(ARM_JOB), muscle_args=[str(ARM_MUSCLES)], stages=sw)),
             ("arm26 elbow flexion, packed (axdf pack --pose: the job's muscles)",
              lambda sw: plan_run(load_job(ARM_JOB), stages=sw))]
    if tmp is not None:
        cases.append(("Rajagopal2016 run, no bones", lambda sw: rajagopal_plan(tmp, sw)))
        cases.append(("Rajagopal2016 run, no bones, packed", lambda sw: rajagopal_plan(tmp, sw, packed=True)))
    for label, make in cases:
        plans = {k: make(sw) for k, sw in
                 (("none", {"contact": False, "penetration": False}),
                  ("measure", {"contact": False, "penetration": True}),
                  ("contact", {"contact": True, "penetration": True}))}
        t0 = time.perf_counter()
        ContactStage().start(plans["contact"])  # the bone fields (from the disk cache after the first run)
        t_fields = time.perf_counter() - t0
        plan = plans["contact"]
        mf = len(plan.frames) * len(plan.models)
        contact_pass(plans["none"])  # compiled code loaded, caches warm
        contact_pass(dataclasses.replace(plan, frames=plan.frames[:2]))  # contact's too (compiled after an edit)
        t_none, _, step0, vol0 = contact_pass(plans["none"])
        t_meas, before, _, _ = contact_pass(plans["measure"])
        t_con, after, step1, vol1 = contact_pass(plan)
        table.section(f"contact ({label}, {len(plan.frames)} frames x {len(plan.models)} muscles; bone fields "
                      f"{t_fields:.1f} s)")
        us = lambda t: t / mf * 1e6  # noqa: E731
        table.add("evaluate with contact", f"{us(t_con):.0f} µs/mf", f"without {us(t_none):.0f} µs/mf",
                  f"{t_con / t_none:.2f}x", f"<= {TARGET_CONTACT_COST:g}x {mark(t_con / t_none <= TARGET_CONTACT_COST)}")
        table.add("evaluate, measures only (--penetration)", f"{us(t_meas):.0f} µs/mf",
                  f"without {us(t_none):.0f} µs/mf", f"{t_meas / t_none:.2f}x")
        for k, (what, target) in enumerate((("vertices inside another muscle", TARGET_INSIDE_MUSCLE),
                                            ("vertices inside a bone", TARGET_INSIDE_BONE))):
            a, b = after[..., k].mean(), before[..., k].mean()
            table.add(what, f"{a * 100:.2f}%", f"before {b * 100:.2f}%", f"{a / max(b, 1e-12):.3f}x",
                      f"<= {target * 100:g}% {mark(a <= target)}")
        a, b = after[..., 2].max(), before[..., 2].max()
        table.add("deepest penetration", f"{a * 1000:.1f} mm", f"before {b * 1000:.1f} mm",
                  f"{a / max(b, 1e-12):.2f}x", f"<= {TARGET_DEPTH * 1000:g} mm {mark(a <= TARGET_DEPTH)}")
        deep_a, deep_b = after[..., 2], before[..., 2]
        table.add(f"muscle-frames deeper than {TARGET_DEPTH * 1000:g} mm", f"{(deep_a > TARGET_DEPTH).sum()}",
                  f"before {(deep_b > TARGET_DEPTH).sum()} of {deep_a.size}",
                  f"> 5 mm: {(deep_a > 0.005).sum()} (before {(deep_b > 0.005).sum()})",
                  f"p99 {np.percentile(deep_a, 99) * 1000:.1f} mm (before {np.percentile(deep_b, 99) * 1000:.1f})")
        if plan.bone_meshes:
            exact, field, deep, nb = bones_by_libigl(plan)
            table.add("vertices inside a bone by the meshes (libigl)",
                      f"{exact * 100:.3f}%", f"the fields {field * 100:.3f}% ({nb} frames)",
                      f"{exact / max(field, 1e-12):.2f}x", f"<= {TARGET_INSIDE_BONE * 100:g}% "
                      f"{mark(exact <= TARGET_INSIDE_BONE)}")
            table.add("deepest in a bone by the meshes (libigl)", f"{deep * 1000:.1f} mm",
                      f"as measured {a * 1000:.1f} mm (all frames)", "",
                      f"<= {TARGET_DEPTH * 1000:g} mm {mark(deep <= TARGET_DEPTH)}")
        dv = np.abs(vol1 / vol0 - 1.0).max()
        table.add("volume against no contact", f"{dv * 100:.2g}% off", "", "", f"<= 0.5% {mark(dv <= 0.005)}")
        ratio = step1[1:] / np.maximum(step0[1:], 1e-12)
        pops = (ratio > POP_RATIO).mean()
        table.add(f"muscle-frames stepping > {POP_RATIO:g}x their no-contact step", f"{pops * 100:.2f}%",
                  f"worst {ratio.max():.2f}x", f"> {POP_RATIO:g}x + 0.5 mm: "
                  f"{(step1[1:] > POP_RATIO * step0[1:] + 5e-4).mean() * 100:.2f}%", f"none {mark(pops == 0)}")


def rows(table: Table, run: Run) -> list[str]:
    """The contact rows (with Rajagopal2016's, imported into the run's folder) and the pack report's."""
    if not GAIT_JOB.is_file():
        table.section(f"contact: {GAIT_JOB.relative_to(ROOT)} is not here; skipped")
        return []
    contact_rows(table, run.quick, run.tmp)
    pack_rows(table)
    return []
