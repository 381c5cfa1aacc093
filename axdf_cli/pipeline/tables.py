"""The run's tables: ``stats.csv`` (a row per frame and muscle) and ``bones.csv`` (a row per
frame and bone), as bytes. Numbers are written to 9 significant digits, ``-0`` as ``0``, so
that the same run writes the same bytes."""
from __future__ import annotations

import numpy as np

from axdf_cli.pipeline.plan import RunPlan

#: stats.csv's numeric columns. The last three (inside_muscle, inside_bone: shares of the
#: muscle's vertices inside another muscle it collides with, inside a bone; depth: its deepest
#: penetration, m) are written when a stage measures them (the contact or penetration stage:
#: ``measures = True``); without, stats.csv has the first six.
STATS_COLUMNS = ("length", "volume", "volume_ratio", "tension", "twist", "scale", "inside_muscle", "inside_bone",
                 "depth")
NSTATS = len(STATS_COLUMNS)
MEASURED_COLUMNS = 3


def stats_csv(plan: RunPlan, stats: np.ndarray, warn_text: list) -> bytes:
    """stats.csv: a row per frame and muscle; numbers to 9 significant digits (-0 written 0).
    One ``%`` per row over plain floats (far cheaper than formatting each number alone)."""
    columns = STATS_COLUMNS if any(st.measures for st in plan.stages) else \
        STATS_COLUMNS[:-MEASURED_COLUMNS]
    stats = stats[..., :len(columns)]
    fmt = "%d,%s" + ",%.9g" * stats.shape[-1] + ",%s\n"
    rows = (stats + 0.0).tolist()  # (+ 0.0: -0 is written 0)
    out = [",".join(("frame", "muscle", *columns, "warning")) + "\n"]
    names = plan.names
    for i, frame in enumerate(plan.frames.tolist()):
        row, warn = rows[i], warn_text[i]
        out += [fmt % (frame, name, *row[j], csv_text(warn[j])) for j, name in enumerate(names)]
    return "".join(out).encode()


def bones_csv(plan: RunPlan, bone_rows: np.ndarray) -> bytes:
    fmt = "%d,%s" + ",%.9g" * bone_rows.shape[-1] + "\n"
    rows = (bone_rows + 0.0).tolist()
    out = ["frame,bone,x,y,z,qw,qx,qy,qz\n"]
    names = [b.name for b in plan.pose.skeleton.bones]
    for i, frame in enumerate(plan.frames.tolist()):
        out += [fmt % (frame, name, *rows[i][b]) for b, name in enumerate(names)]
    return "".join(out).encode()


def csv_text(s: str) -> str:
    if not s:
        return ""
    return '"' + s.replace('"', '""') + '"'
