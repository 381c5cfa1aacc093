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

Adding a stage: write it (a :class:`~axdf_cli.pipeline.stage.StageBase` with ``name``,
``scope``, ``start`` and ``__call__``; the protocol, and what else it may declare, is
:mod:`axdf_cli.pipeline.stage`'s), add it to :data:`STAGES`. ``axdf run --no-<name>`` comes from the table
(:func:`axdf_cli.cli.run.add_args`); a job key ``<name>: false`` goes in
:mod:`axdf_cli.specs.job` and reaches :func:`build_stages` through ``plan_run(stages=...)``.
The stages a run used (names and each one's ``settings``) are recorded in its manifest's
``settings.stages``, so ``--resume`` refuses a change.

A stage that adds a layer of the body declares its parts and tables (the skin stage,
:mod:`axdf_cli.pipeline.skin_stage`: the part ``skin`` of kind skin and ``skin.csv``); the
sinks write them as they write every part. The skin stage is turned on by the run's inputs
(``--skin FILE``, a job's ``skin:``), not by name: it is in :data:`BY_INPUT`.
"""
from __future__ import annotations

from typing import Mapping

from axdf_cli import runtime
from axdf_cli import tolerances as tol
from axdf_cli.fileio import fieldcache
from axdf_cli.model import contact
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.jiggle_stage import JiggleStage
from axdf_cli.pipeline.skin_stage import SkinStage
from axdf_cli.pipeline.stage import Chunk, RunInputs, Scope, Stage, StageBase


def _contact_model(plan, enabled: bool):
    rest = forward_kinematics(plan.pose.skeleton, plan.pose.skeleton.rest_coordinates()[None])[0]
    return contact.build(plan.muscles, plan.models, rest, plan.contact_meshes, enabled=enabled,
                         field_cache=fieldcache.cached)


class ContactStage(StageBase):
    """Muscles push each other out of the way, bones push muscles (:mod:`axdf_cli.model.contact`).
    Its state is the run's :class:`~axdf_cli.model.contact.ContactModel` (the bones' distance
    fields, the pairs and their shares), built once by :meth:`start`; each frame of a chunk is
    resolved alone. Leaves the measures after contact in ``FrameResult.contact``
    (stats.csv's inside_muscle, inside_bone, depth)."""

    name = "contact"
    scope = Scope.FRAME
    measures = True

    @property
    def settings(self) -> dict:
        return {"iterations": tol.CONTACT_ITERATIONS}

    def start(self, plan):
        return _contact_model(plan, True)

    def __call__(self, state, chunk: Chunk):
        contact.apply(state, chunk.results, chunk.world, threads=runtime.use_threads())
        return state, chunk


class PenetrationStage(StageBase):
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


#: The stages a run may use: name -> stage class, in the order they run within their scope.
#: Each is on unless switched off (``--no-<name>``, a job's ``<name>: false``), or, if named in
#: :data:`OFF_BY_DEFAULT`, off unless switched on (``--<name>``, ``<name>: true``); those in
#: :data:`BY_INPUT` are on exactly when the run's inputs ask (``for_run`` decides).
STAGES: dict[str, type[StageBase]] = {
    "jiggle": JiggleStage,  # TIME: secondary motion of the axis (muscles' `jiggle:`)
    "contact": ContactStage,  # FRAME: muscles push each other, bones push muscles
    "penetration": PenetrationStage,  # FRAME: the contact measures where contact is off
    "skin": SkinStage,  # FRAME, last: the skin worn over the muscles and bones (a run with --skin)
}
#: Stages a run leaves out unless asked for. Contact is on (``--no-contact`` or a job's
#: ``contact: false`` leaves it out); its measures alone (``penetration``) are for runs
#: without it.
OFF_BY_DEFAULT: frozenset[str] = frozenset({"penetration"})
#: Stages the run's inputs turn on, never switched by name (the skin: a run with a skin file).
BY_INPUT: frozenset[str] = frozenset({"skin"})


def switched() -> tuple[str, ...]:
    """The stages switched on and off by name (``--<name>``, a job's ``<name>:``), in order."""
    return tuple(n for n in STAGES if n not in BY_INPUT)


def stage_default(name: str) -> bool:
    """Whether stage ``name`` runs when neither the command line nor the job says."""
    return name not in OFF_BY_DEFAULT


def build_stages(switches: Mapping[str, bool] | None = None, muscles=None, skin=None) -> tuple[Stage, ...]:
    """The run's stages: every registered stage that ``switches`` (name -> on) turns on, or
    leaves at its default (:func:`stage_default`), and that, given the run's ``muscles``
    (specs) and ``skin``, has something to do (its ``for_run``: jiggle only where a muscle has
    ``jiggle``, the skin only with a skin), so a run it would not change neither pays for it
    nor records it."""
    switches = dict(switches or {})
    unknown = sorted(set(switches) - set(switched()))
    if unknown:
        raise ValueError(f"unknown stage(s) {', '.join(unknown)}; known: {', '.join(switched()) or 'none'}")
    inputs = RunInputs(tuple(muscles or ()), skin, switches)
    out = (cls.for_run(inputs) for name, cls in STAGES.items()
           if name in BY_INPUT or switches.get(name, stage_default(name)))
    return tuple(s for s in out if s is not None)


def of_scope(stages, scope: Scope) -> tuple[Stage, ...]:
    return tuple(s for s in stages if Scope(s.scope) is scope)


def stages_record(stages) -> list[dict] | None:
    """What the manifest's ``settings.stages`` says of the stages (None: no stage, and the
    key is left out, so runs without stages keep their manifests)."""
    if not stages:
        return None
    return [{"name": s.name, "scope": Scope(s.scope).value, **dict(s.settings)} for s in stages]
