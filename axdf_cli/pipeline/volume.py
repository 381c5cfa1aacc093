"""The run's volume promise, checked: a muscle whose volume is kept exactly (``volume:
exact``) and that leaves :data:`~axdf_cli.tolerances.VOLUME_EXACT_PROMISE` of its rest volume
at some frame is named, with those frames, in the run's warnings (stderr and the manifest), not
only in the last summary line's worst figure."""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model.pose import frame_spans


def volume_breaches(names, modes, frames, ratio: np.ndarray) -> list[str]:
    """A line for each muscle kept at ``exact`` volume whose volume ratio (F, M) leaves 1 by
    more than the promise at some frame: its name, the worst error and the frames (``frames``
    (F,), the run's frame numbers). ``modes``: each muscle's volume mode's value (M,)."""
    out = []
    err = np.abs(np.asarray(ratio, dtype=np.float64) - 1.0)
    for j, (name, mode) in enumerate(zip(names, modes)):
        if mode != "exact":
            continue
        bad = np.nonzero(~(err[:, j] <= tol.VOLUME_EXACT_PROMISE))[0]  # (NaN counts as off)
        if bad.size:
            worst = np.nanmax(err[bad, j]) if np.isfinite(err[bad, j]).any() else float("nan")
            out.append(f"{name}: volume off by up to {worst * 100:.1f}% (kept within "
                       f"{tol.VOLUME_EXACT_PROMISE * 100:g}%) at {bad.size} frame(s): "
                       f"{frame_spans(np.asarray(frames)[bad])}")
    return out
