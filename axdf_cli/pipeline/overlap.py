"""The bulk-overlap policy: when a run's muscles overlap more than contact clears, the warning
that says so, and the ``axdf pack`` command that is the next step (for the terminal; the
manifest's warning names no path)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.pipeline.plan import RunPlan

#: A run whose muscles, after contact, keep more than this share of their vertices inside
#: another muscle (over its frames) overlaps in bulk. Contact moves a surface a few
#: millimetres a pass, continuously in the frame: it clears what motion adds to rest shapes
#: that share space, not rest shapes through each other (an import's generic sections). Such
#: muscles are made to share space once, at rest, by ``axdf pack``; a packed library stays
#: well below this share.
BULK_OVERLAP = 0.05


def overlap_share(plan: RunPlan, inside: np.ndarray) -> float | None:
    """The share of the run's vertices inside another muscle over its frames: inside (F, M),
    stats.csv's inside_muscle, each muscle's share weighted by its vertices. None where
    contact did not run (nothing measured)."""
    if not any(st.name == "contact" for st in plan.stages) or inside.size == 0:
        return None
    n = np.array([m.n_vertices for m in plan.models], dtype=np.float64)
    return float((inside * n).sum() / (n.sum() * inside.shape[0]))


def overlaps_in_bulk(share: float | None) -> bool:
    """Whether muscles keeping ``share`` of their vertices inside another muscle after contact
    (:func:`overlap_share`; None: not measured) overlap in bulk (:data:`BULK_OVERLAP`)."""
    return share is not None and share > BULK_OVERLAP


def bulk_overlap_text(share: float | None, over: str) -> str | None:
    """The warning for muscles that overlap in bulk after contact (:func:`overlaps_in_bulk`;
    ``share`` measured ``over`` "N frame(s)" or the like); None otherwise. Names no path (it
    goes in manifests): :func:`pack_command_line` is the next step, for the terminal."""
    if not overlaps_in_bulk(share):
        return None
    return (f"the muscles overlap in bulk: after contact {share * 100:.1f}% of their vertices lie inside another "
            f"muscle (over {over}; stats.csv's inside_muscle), more than contact clears (it "
            f"resolves what motion adds, a few millimetres a frame); make their rest shapes share space once "
            f"with axdf pack (docs/METHOD.md, Packing)")


def bulk_overlap(plan: RunPlan, inside: np.ndarray) -> str | None:
    """The run's warning when its muscles overlap in bulk after contact (:func:`overlap_share`,
    :func:`bulk_overlap_text`); None otherwise (or where contact did not run). :func:`pack_command`
    is the command for this run, for the terminal."""
    return bulk_overlap_text(overlap_share(plan, inside), f"{inside.shape[0]} frame(s)")


def with_pack_command(plan: RunPlan, warning: str) -> str:
    """The bulk-overlap warning as the terminal shows it: ending with the run's own
    :func:`pack_command` (the manifest's names no path)."""
    return f"{warning}: {pack_command(plan)}"


def pack_command(plan: RunPlan) -> str:
    """The ``axdf pack`` command line for the run's muscles (their folders), skeleton and pose."""
    return pack_command_line([Path(s.source).parent for s in plan.muscles if s.source],
                             plan.pose.skeleton_path or None, plan.pose.source or None)


def pack_command_line(folders, skeleton, pose) -> str:
    """``axdf pack FOLDERS --skeleton SKELETON [--pose POSE] --out FOLDER_packed`` for the
    terminal (paths relative to the current folder where below it, else absolute; placeholders
    where unknown): the next step that a run whose muscles overlap in bulk, or an import, names."""
    def arg(p) -> str:
        p = Path(p).resolve()
        try:
            return p.relative_to(Path.cwd().resolve()).as_posix()
        except ValueError:
            return p.as_posix()

    names = sorted({arg(f) for f in folders}) or ["MUSCLES"]
    sk = arg(skeleton) if skeleton else "SKELETON"
    po = f" --pose {arg(pose)}" if pose else ""
    out = names[0].rstrip("/") + "_packed" if len(names) == 1 and names[0] != "MUSCLES" else "DIR"
    return f"axdf pack {' '.join(names)} --skeleton {sk}{po} --out {out}"
