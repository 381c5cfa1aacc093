"""Stages of a run (issue 18): what acts on a chunk of frames between the axis and the
sinks. The interface the stage engineers build against; the pipeline branch owns this
module (on merge, take its version: this one holds only the interface jiggle needs).

A stage is a pure, batch-first function over a whole chunk, ``(state, chunk) -> (state,
chunk)``; its ``scope`` says what it needs: ``TIME`` acts on the axis control points before
the surfaces are built and carries state from frame to frame (the runner runs it from the
pose's first frame through the frames in order); ``FRAME`` acts on all muscles' surfaces of
a frame, after them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Protocol

import numpy as np


class Scope(str, Enum):
    MUSCLE = "muscle"
    TIME = "time"
    FRAME = "frame"


@dataclass
class Chunk:
    """All carried muscles of a block of consecutive selected frames."""

    rows: slice  # positions of these frames in plan.frames
    frames: np.ndarray  # (C,) frame numbers
    coords: np.ndarray  # (C, Q) skeleton coordinates
    world: np.ndarray  # (C, B, 4, 4) bone world transforms
    activation: np.ndarray  # (C, M) activation of every muscle (NaN: no curve)
    muscles: list[int]  # the muscles carried
    axis: dict[int, np.ndarray]  # muscle -> (C, n_j, 3) axis control points, world (after TIME stages)
    results: dict = field(default_factory=dict)  # muscle -> FrameResult (after the surfaces)


class Stage(Protocol):
    name: str
    scope: Scope

    def start(self, plan) -> object:
        """The state before the first frame of the pose."""

    def __call__(self, state, chunk: Chunk) -> tuple[object, Chunk]:
        """Advance over ``chunk``: the new state and the chunk the next stage sees."""
