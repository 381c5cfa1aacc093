"""Stages for the tests of the pipeline's rules (tests/test_stages.py), not for the package.

- :class:`SmoothAxis` (TIME) carries a real state across frames: exponential smoothing of
  every axis control point, s_f = a x_f + (1 - a) s_(f-1), starting at the pose's first frame.
  A frame's axis therefore depends on every frame before it.
- :class:`PushByOthers` (FRAME) really depends on all muscles of a frame: each muscle moves by
  GAIN x the mean of the other muscles' centroids.
- :class:`WarnFirst` (FRAME) adds a warning to the first muscle at every frame.
- :class:`OffsetShell` (FRAME) adds a layer: one part of kind fat, ``shell``, the first
  muscle's surface moved out by SHELL_OFFSET along its normals at every frame (what a fat
  layer's stage would declare and make; no sink knows of it).

:func:`register` puts them in the package's table (``axdf_cli.pipeline.stages.STAGES``), as a
stage engineer's one-line change would; run as a script, this module registers the stages
named in ``AXDF_TEST_STAGES`` and calls ``axdf`` (for tests that kill a real process).
"""
from __future__ import annotations

import numpy as np

from axdf_cli.pipeline.stage import Scope, StageBase

ALPHA = 0.25  # weight of the current frame in the smoothing
SHELL_OFFSET = 0.004  # m: how far the shell lies outside the first muscle
GAIN = 0.05  # share of the others' mean centroid a muscle is moved by


class SmoothAxis(StageBase):
    name = "smooth"
    scope = Scope.TIME
    settings = {"alpha": ALPHA}

    def start(self, plan):
        return {}  # muscle -> (n, 3) the last smoothed axis; empty before the first frame

    def __call__(self, state, chunk):
        state = dict(state)
        for j in chunk.muscles:
            x = chunk.axis[j]  # (C, n, 3)
            out = np.empty_like(x)
            s = state.get(j, x[0])
            for k in range(len(x)):
                s = ALPHA * x[k] + (1.0 - ALPHA) * s
                out[k] = s
            chunk.axis[j] = out
            state[j] = s
        return state, chunk


class PushByOthers(StageBase):
    name = "push"
    scope = Scope.FRAME
    settings = {"gain": GAIN}

    def start(self, plan):
        return None

    def __call__(self, state, chunk):
        js = chunk.muscles
        cent = {j: chunk.results[j].vertices.mean(axis=1) for j in js}  # (C, 3) each
        total = np.sum([cent[j] for j in js], axis=0)
        for j in js:
            others = (total - cent[j]) / max(len(js) - 1, 1)
            r = chunk.results[j]
            r.vertices = r.vertices + GAIN * others[:, None, :]
        return state, chunk


class WarnFirst(StageBase):
    name = "warn"
    scope = Scope.FRAME

    def start(self, plan):
        return None

    def __call__(self, state, chunk):
        j = chunk.muscles[0]
        chunk.results[j].warnings += [(i, "a test stage's warning") for i in range(len(chunk.frames))]
        return state, chunk


class OffsetShell(StageBase):
    name = "shell"
    scope = Scope.FRAME
    settings = {"offset": SHELL_OFFSET}

    def parts(self, plan):
        from axdf_cli.parts import COLORS, Kind, Part

        m = plan.models[0]
        rest = np.asarray(m.rest_vertices, np.float64) + SHELL_OFFSET * np.asarray(m.rest_normals, np.float64)
        return (Part("shell", Kind.FAT, m.faces, rest, np.asarray(m.rest_normals, np.float64), COLORS[Kind.FAT]),)

    def start(self, plan):
        return None

    def __call__(self, state, chunk):
        from axdf_cli.parts import PartFrames

        r = chunk.results[chunk.muscles[0]]
        chunk.parts["shell"] = PartFrames((r.vertices + SHELL_OFFSET * r.normals).astype(np.float32),
                                          r.normals.astype(np.float32))
        return state, chunk


DOUBLES = {s.name: s for s in (SmoothAxis, PushByOthers, WarnFirst, OffsetShell)}


def register(table: dict, names) -> None:
    """Put the named doubles into ``table`` (the STAGES registry), in the order given; the
    product's FRAME stages (contact, penetration) are left out, the real jiggle stays."""
    for k in ("contact", "penetration"):
        table.pop(k, None)
    for n in names:
        table[n] = DOUBLES[n]


if __name__ == "__main__":
    import os
    import sys

    from axdf_cli.cli.main import main
    from axdf_cli.pipeline.stages import STAGES

    register(STAGES, [n for n in os.environ.get("AXDF_TEST_STAGES", "").split(",") if n])
    sys.exit(main(sys.argv[1:]))
