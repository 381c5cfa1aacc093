"""The stage protocol: what every stage of a run declares and what it acts on (:class:`Chunk`).

The table of the stages and the order a run calls them in is :mod:`axdf_cli.pipeline.stages`.
A stage is a subclass of :class:`StageBase` that sets ``name`` and ``scope`` and writes
``start`` and ``__call__``; everything else it may declare has a default here, so the runner
reads declarations, never probes for them:

- ``for_run(inputs)``: the stage for a run's inputs (:class:`RunInputs`), or None when it has
  nothing to do there (jiggle without a muscle that jiggles, the skin without a skin file);
- ``settings``: a JSON-able mapping of everything that changes its output (the manifest's
  ``settings.stages``; ``--resume`` refuses a change);
- ``sources``: more source files of its numerics than its own module, relative to the
  package (the run's identity hashes them; ``--resume`` refuses a change);
- ``restart(plan, epoch_frame, block)`` (TIME stages): its state for an epoch of the timeline
  after the first, and the frame its warm-up starts at (default: from the pose's first frame);
- ``measures``: it leaves the contact measures (stats.csv's inside_muscle, inside_bone,
  depth) in each result's ``contact``;
- ``warnings(plan)``: what the run says on stderr (and in the manifest) before the first
  frame (a skin worn over muscles it was not fitted to);
- ``parts(plan)``: the meshes it adds to every frame (:class:`axdf_cli.parts.Part`; it sets
  ``chunk.parts[name]``); ``tables``: the tables it adds (:class:`axdf_cli.parts.Table`; it
  sets ``chunk.tables[file]``). The sinks write every declared part and table the same way.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Mapping

import numpy as np

from axdf_cli.model.muscle import FrameResult


class Scope(str, Enum):
    """What a stage needs at once: one muscle (the model itself), time (the frames before,
    per muscle), or a frame (all muscles of it)."""

    MUSCLE = "muscle"
    TIME = "time"
    FRAME = "frame"


@dataclass
class Chunk:
    """All carried muscles of a block of consecutive frames (batch dimension first).

    For a FRAME stage and the sinks, the frames are consecutive *selected* frames and
    ``rows`` their positions in ``plan.frames``. For a TIME stage they are every frame of one
    block of the pose's timeline (selected or not) and ``rows`` their positions in
    ``plan.pose.frames``."""

    rows: slice  # positions of these frames (see above)
    frames: np.ndarray  # (C,) frame numbers
    coords: np.ndarray  # (C, Q) skeleton coordinates
    world: np.ndarray  # (C, B, 4, 4) bone world transforms
    activation: np.ndarray  # (C, M) activation of every muscle (NaN: none given)
    muscles: list[int]  # the muscles carried (all of them whenever a FRAME stage runs)
    axis: dict[int, np.ndarray]  # muscle -> (C, n_j, 3) axis control points, world (after TIME stages)
    results: dict[int, FrameResult] = field(default_factory=dict)  # muscle -> surfaces (after 1b, then FRAME)
    twist: np.ndarray | None = None  # (C, M) unwrapped twist references (radians) of the selected frames
    notes: dict[int, list] = field(default_factory=dict)  # muscle -> step 1a's [(frame index, warning)]
    parts: dict = field(default_factory=dict)  # part name -> axdf_cli.parts.PartFrames: the parts the stages made
    tables: dict = field(default_factory=dict)  # table file -> (C, columns) float64 rows: the tables the stages made


@dataclass(frozen=True)
class RunInputs:
    """What a stage may need to know of a run before it is planned: the muscles (specs), the
    skin it wears (:class:`axdf_cli.specs.skin.Skin`, or None) and the stage switches given
    (name -> on, from the command line and the job)."""

    muscles: tuple = ()
    skin: object = None
    switches: Mapping[str, bool] = field(default_factory=dict)


class StageBase:
    """A stage of the run (module doc). ``start(plan)`` is its state before the pose's first
    frame; ``stage(state, chunk)`` returns the next state and the chunk (changed in place or
    anew)."""

    name: str = ""
    scope: Scope = Scope.FRAME
    settings: Mapping = {}
    sources: tuple[str, ...] = ()
    tables: tuple = ()
    measures: bool = False  # it leaves the contact measures in FrameResult.contact (stats.csv's last three)

    @classmethod
    def for_run(cls, inputs: RunInputs) -> "StageBase | None":
        """The stage for a run with these inputs, or None when it would change nothing."""
        return cls()

    def parts(self, plan) -> tuple:
        """The parts this stage adds to every frame (:class:`axdf_cli.parts.Part`), in order."""
        return ()

    def warnings(self, plan) -> list[str]:
        """What the run warns of before its first frame, because of this stage."""
        return []

    def start(self, plan) -> object:
        raise NotImplementedError

    def restart(self, plan, epoch: int, block: int) -> tuple[object, int]:
        """Its state for an epoch starting at pose frame ``epoch``, and where its walk starts:
        by default, from the pose's first frame."""
        return self.start(plan), int(plan.pose.first)

    def __call__(self, state, chunk: Chunk) -> tuple[object, Chunk]:
        raise NotImplementedError


Stage = StageBase
