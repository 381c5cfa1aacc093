"""Stages: what a run does to a chunk of frames between the muscle model's two steps, and after.

A run evaluates its selected frames chunk by chunk (:mod:`axdf_cli.pipeline.evaluate`); a
:class:`Chunk` is all carried muscles of a block of consecutive frames, batch dimension first,
indexed by muscle. In order:

1a. **axis** (the model, :meth:`MuscleModel.axis_points`): each muscle's axis control points in
    the world, ``chunk.axis[j]`` (C, n_j, 3), from the bones' world transforms and paths;
2.  **TIME stages** (scope ``time``): across time, on ``chunk.axis``. A TIME stage carries its
    state through consecutive frames in order, from the pose's first frame or from a warm-up
    before an epoch of the timeline (secondary motion: damped oscillators on the axis
    control points);
1b. **surface** (the model, :meth:`MuscleModel.surface`): RMF, binding, twist, tension, volume,
    surface and normals from ``chunk.axis``, into ``chunk.results[j]``;
3.  **FRAME stages** (scope ``frame``): across muscles, on ``chunk.results`` (contact between
    muscles and with bones). The last word on where a surface is;

then the sinks (meshes, packed sequences, tables, frames) consume the results. Stages are
pure functions of ``(state, chunk)``; the object only holds its settings.

What a stage declares decides how a run is split and resumed, never a special case in the
runner (:func:`axdf_cli.pipeline.execute.execute`):

- no stage: each frame is evaluated alone; ``--jobs`` splits the muscles over workers;
- a TIME stage: its chunks are always the same blocks of the pose's timeline
  (:data:`axdf_cli.pipeline.evaluate.TIME_BLOCK` frames from the pose's first, all muscles).
  The timeline is cut into epochs of :data:`~axdf_cli.pipeline.evaluate.TIME_EPOCH_BLOCKS`
  blocks; an epoch's blocks are called in order from ``start(plan)``'s state for the first
  epoch, and for a later one from ``restart(plan, epoch_frame, TIME_BLOCK)``'s, which returns
  the state and the frame its warm-up walk begins at (a stage without ``restart`` is walked
  from the pose's first frame). A pre-pass keeps the states at the blocks'
  starts, so that any ``--frames`` subset, ``--resume``, mesh workers and render workers see
  exactly the axis a whole run computes (same bytes), and a frame costs at most a warm-up and
  an epoch. Contract: the stage acts on ``chunk.axis`` (and its state) only, and for muscle j
  only from muscle j's history and law;
- a FRAME stage: all muscles of a frame are evaluated together (``chunk.muscles`` is every
  muscle), so ``--jobs`` splits the frames, not the muscles; per-muscle packed sequences
  still come out in frame order, byte-identical. Contract: a frame's output depends on that
  frame's chunk rows only (never on which other frames share the chunk).

Adding a stage: write it (a class with ``name``, ``scope``, ``start`` and ``__call__``), add
its factory to :data:`STAGES`. ``axdf run --no-<name>`` comes from the table
(:func:`axdf_cli.cli.run.add_args`); a job key ``<name>: false`` goes in
:mod:`axdf_cli.specs.job` and reaches :func:`build_stages` through ``plan_run(stages=...)``.
The stages a run used (names and each one's ``settings``) are recorded in its manifest's
``settings.stages``, so ``--resume`` refuses a change.

The skin stage (:mod:`axdf_cli.pipeline.skin_stage`, FRAME, last) is not in the table: the
plan adds it when the run has a skin (``--skin FILE``, a job's ``skin:``), since it needs one.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Callable, Mapping, Protocol

import numpy as np

from axdf_cli import runtime
from axdf_cli import tolerances as tol
from axdf_cli.fileio import fieldcache
from axdf_cli.model import contact
from axdf_cli.model.muscle import FrameResult
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.jiggle_stage import JiggleStage


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
    skin: object = None  # the skin stage's SkinFrames (axdf_cli.pipeline.skin_stage), when the run has a skin


class Stage(Protocol):
    """A stage of the run (module doc). ``start(plan)`` is its state before the pose's first
    frame; ``stage(state, chunk)`` returns the next state and the chunk (changed in place or
    anew). ``settings`` (optional): a JSON-able mapping of what changes its output, recorded
    in the manifest."""

    name: str
    scope: Scope

    def start(self, plan) -> object: ...

    def __call__(self, state, chunk: Chunk) -> tuple[object, Chunk]: ...


def _contact_model(plan, enabled: bool):
    rest = forward_kinematics(plan.pose.skeleton, plan.pose.skeleton.rest_coordinates()[None])[0]
    meshes = plan.bone_meshes or getattr(plan, "collision_meshes", None) or {}
    return contact.build(plan.muscles, plan.models, rest, meshes, enabled=enabled, field_cache=fieldcache.cached)


class ContactStage:
    """Muscles push each other out of the way, bones push muscles (:mod:`axdf_cli.model.contact`).
    Its state is the run's :class:`~axdf_cli.model.contact.ContactModel` (the bones' distance
    fields, the pairs and their shares), built once by :meth:`start`; each frame of a chunk is
    resolved alone. Leaves the measures after contact in ``FrameResult.contact``."""

    name = "contact"
    scope = Scope.FRAME
    measures = True  # stats.csv's inside_muscle, inside_bone, depth

    @property
    def settings(self) -> dict:
        return {"iterations": tol.CONTACT_ITERATIONS}

    def start(self, plan):
        return _contact_model(plan, True)

    def __call__(self, state, chunk: Chunk):
        contact.apply(state, chunk.results, chunk.world, threads=runtime.use_threads())
        return state, chunk


class PenetrationStage:
    """The contact measures (stats.csv's inside_muscle, inside_bone, depth) of the meshes as
    they are, where the contact stage did not run (``--no-contact``): changes no vertex."""

    name = "penetration"
    scope = Scope.FRAME
    measures = True

    def start(self, plan):
        return _contact_model(plan, False)

    def __call__(self, state, chunk: Chunk):
        if any(r.contact is None for r in chunk.results.values()):
            contact.apply(state, chunk.results, chunk.world, threads=runtime.use_threads())
        return state, chunk


#: The stages a run may use: name -> factory (no arguments), in the order they run within
#: their scope. Each is on unless switched off (``--no-<name>``, a job's ``<name>: false``),
#: or, if named in :data:`OFF_BY_DEFAULT`, off unless switched on (``--<name>``, ``<name>: true``).
STAGES: dict[str, Callable[[], Stage]] = {
    "jiggle": JiggleStage,  # TIME: secondary motion of the axis (muscles' `jiggle:`)
    "contact": ContactStage,  # FRAME: muscles push each other, bones push muscles
    "penetration": PenetrationStage,  # FRAME: the contact measures where contact is off
}
#: Stages a run leaves out unless asked for. Contact is on (``--no-contact`` or a job's
#: ``contact: false`` leaves it out); its measures alone (``penetration``) are for runs
#: without it.
OFF_BY_DEFAULT: frozenset[str] = frozenset({"penetration"})


def stage_default(name: str) -> bool:
    """Whether stage ``name`` runs when neither the command line nor the job says."""
    return name not in OFF_BY_DEFAULT


def build_stages(switches: Mapping[str, bool] | None = None, muscles=None) -> tuple[Stage, ...]:
    """The run's stages: every registered stage that ``switches`` (name -> on) turns on, or
    leaves at its default (:func:`stage_default`), and, given the run's ``muscles`` (specs), that acts on one of them: a stage may say
    so with ``needed(muscles) -> bool`` (jiggle: a muscle has ``jiggle``), so a run it would
    not change neither pays for it nor records it."""
    switches = switches or {}
    unknown = sorted(set(switches) - set(STAGES))
    if unknown:
        raise ValueError(f"unknown stage(s) {', '.join(unknown)}; known: {', '.join(STAGES) or 'none'}")
    out = (make() for name, make in STAGES.items() if switches.get(name, stage_default(name)))
    return tuple(s for s in out if muscles is None or getattr(s, "needed", None) is None or s.needed(muscles))


def of_scope(stages, scope: Scope) -> tuple[Stage, ...]:
    return tuple(s for s in stages if Scope(s.scope) is scope)


def stages_record(stages) -> list[dict] | None:
    """What the manifest's ``settings.stages`` says of the stages (None: no stage, and the
    key is left out, so runs without stages keep their manifests)."""
    if not stages:
        return None
    return [{"name": s.name, "scope": Scope(s.scope).value, **dict(getattr(s, "settings", None) or {})}
            for s in stages]
