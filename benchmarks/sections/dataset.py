"""Row 7, data sets: ``axdf dataset build`` of poses/datasets/gait2392_random.yaml (1000
samples, 100 with ``--quick``) at 1 and 2 workers, the scaling ratio, and a sample's split
between evaluation, writing and rendering (``--dataset-samples 0``: not measured)."""
from __future__ import annotations

import shutil
import time
from pathlib import Path

from benchmarks.common import DATASET_FILE, DATASET_SAMPLES, ROOT, Table, mark
from benchmarks.settings import Run

UNIT = False


TARGET_DATASET_SCALING = 1.7  # samples/s with 2 workers over 1 worker, on 2 cores


def time_dataset(n_samples: int, jobs: int, out: Path) -> dict:
    """``axdf dataset build`` of the first ``n_samples`` sequences of DATASET_FILE (one frame,
    one view each; a shard 0/K of its 1000), in process: wall seconds and per-stage seconds."""
    from axdf_cli.dataset import engine
    from axdf_cli.dataset.worker import build_context
    from axdf_cli.specs import RefPolicy

    ctx = build_context(DATASET_FILE, policy=RefPolicy.for_command([DATASET_FILE]))
    shard = (0, max(1, len(ctx.sequences) // n_samples))
    t0 = time.perf_counter()
    res = engine.build(DATASET_FILE, out, jobs=jobs, shard=shard, ctx=ctx, overwrite=True)
    return {"samples": res.built_samples, "wall": time.perf_counter() - t0, "timing": res.timing,
            "renderer": res.gl_renderer}


def dataset_evaluation(n_sequences: int) -> float:
    """Seconds per sample of the evaluation inside a sequence's run (twist references,
    kinematics, ``evaluate``), timed alone on the data set's first sequences."""
    from axdf_cli.dataset import door
    from axdf_cli.dataset.worker import build_context, sequence_pose
    from axdf_cli.pipeline import evaluate_chunks
    from axdf_cli.specs import RefPolicy

    ctx = build_context(DATASET_FILE, policy=RefPolicy.for_command([DATASET_FILE]))
    t = 0.0
    n = 0
    for seq in ctx.sequences[:n_sequences]:
        pose, frames = sequence_pose(ctx, seq)
        plan = door.sequence_plan(pose, frames, ctx.muscles, ctx.models, "ply", Path("unused"), {}, ctx.stages)
        t0 = time.perf_counter()
        for _, _, results in evaluate_chunks(plan):
            for _ in results:
                pass
        t += time.perf_counter() - t0
        n += len(frames)
    return t / max(n, 1)


def dataset_rows(table: "Table", n_samples: int, tmp: Path) -> None:
    """Samples per second at 1 and 2 workers, their ratio, and where a sample's time goes."""
    rel = DATASET_FILE.relative_to(ROOT)
    table.section(f"data sets: axdf dataset build {rel}, {n_samples} samples (92 muscles, 1 frame, one 256x256 "
                  "view, PNG + EXR, PLY meshes), in process")
    one = time_dataset(n_samples, 1, tmp / "dataset-1")
    shutil.rmtree(tmp / "dataset-1", ignore_errors=True)
    two = time_dataset(n_samples, 2, tmp / "dataset-2")
    shutil.rmtree(tmp / "dataset-2", ignore_errors=True)
    r1, r2 = one["samples"] / one["wall"], two["samples"] / two["wall"]
    table.add("dataset, 1 worker", f"{r1:.2f} samples/s", f"{one['wall']:.0f} s for {one['samples']}")
    table.add("dataset, 2 workers (process pool)", f"{r2:.2f} samples/s", f"1 worker {r1:.2f} samples/s",
              f"{r2 / r1:.2f}x", f">= {TARGET_DATASET_SCALING:g}x {mark(r2 / r1 >= TARGET_DATASET_SCALING)}")
    t = {k: v * 1000 / max(one["samples"], 1) for k, v in one["timing"].items()}
    ev = dataset_evaluation(min(20, n_samples)) * 1000
    writing = t["run"] - ev + t["write"]
    table.add("per sample, 1 worker: evaluation / writing / rendering", f"{ev:.0f} / {writing:.0f} / {t['render']:.0f} ms",
              f"of {1000 / r1:.0f} ms; meshes read back {t['read']:.0f} ms")
    table.add("  (writing = the run's meshes, tables, manifest", f"{t['run'] - ev:.0f} ms",
              f"+ labels, PNG, EXR {t['write']:.0f} ms)")
    # CPU seconds (all threads) per sample, summed over workers: on a machine shared with other
    # jobs the wall-clock ratio above depends on their load; this does much less
    c1 = one["timing"]["cpu"] / max(one["samples"], 1) * 1000
    c2 = two["timing"]["cpu"] / max(two["samples"], 1) * 1000
    table.add("CPU per sample: 1 worker / 2 workers", f"{c1:.0f} / {c2:.0f} ms",
              f"2 idle cores: <= {2 * c1 / c2:.2f}x", f"{c2 / c1:.2f}x CPU")


def samples(run: Run) -> int:
    """The data-set rows' samples: --dataset-samples, else DATASET_SAMPLES (100 with --quick)."""
    return run.dataset_samples if run.dataset_samples is not None else (100 if run.quick else DATASET_SAMPLES)


def wanted(run: Run) -> bool:
    """Whether the run measures this section (``--dataset-samples 0``: not; the page keeps the last)."""
    return samples(run) > 0


def rows(table: Table, run: Run) -> list[str]:
    dataset_rows(table, samples(run), run.tmp)
    return []
