"""The jiggle stage (scope TIME): the secondary motion of :mod:`axdf_cli.model.jiggle`
carried through time, on the axis control points before the surfaces are built (the twist
and the exact-volume solve come after it, as always).

The runner hands a TIME stage consecutive frames of the pose's timeline in order, a block at
a time, from :meth:`JiggleStage.start`'s state (:mod:`axdf_cli.pipeline.stages`,
:func:`axdf_cli.pipeline.evaluate.time_states`). The timeline is cut into epochs of
``TIME_EPOCH_BLOCKS`` blocks. In the first epoch every muscle's oscillators start at the
pose's first frame. For a later epoch each muscle's start as many whole blocks before the
epoch as :func:`axdf_cli.model.jiggle.warmup_frames` asks for its own law (so that how it
started has decayed to ``JIGGLE_WARMUP_EPS``), or at the pose's first frame if that is
nearer or the muscle never forgets (undamped); the frames before a muscle's start pass by
it. A frame therefore costs at most an epoch and a warm-up whichever frame it is, and the
state of every frame is fixed by the pose and the muscle alone: a ``--frames`` subset,
``--resume``, mesh and render workers all see the axis a whole run computes, to the byte.

A muscle's start: on its target, moving at the velocity of its first step (the muscle has
moved at that velocity for ever: a pre-roll at constant velocity,
:func:`axdf_cli.model.jiggle.steady_state`), so a motion already under way has no start-up
transient.

State: for every muscle with ``jiggle``, its start frame and its oscillators' positions and
velocities (n, 3) in the world, its targets and effective tension at the frame the state is
at, plus what the law needs of the muscle (spec, weights, tone). Every muscle's oscillators
are independent and every operation is elementwise per control point, so a muscle moves to
the same bytes whichever muscles share its chunk.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model import jiggle
from axdf_cli.model.pose import effective_tension
from axdf_cli.pipeline.stage import RunInputs, Scope, StageBase


@dataclass
class Oscillators:
    """One muscle's law (spec, weights (n,), tone), the pose frame it starts at, and state:
    positions x and velocities v (n, 3), the targets (n, 3) and effective tension at the
    state's frame (x None: not started)."""

    spec: jiggle.JiggleSpec
    weights: np.ndarray
    tone: float
    begin: int
    x: np.ndarray | None = None
    v: np.ndarray | None = None
    target: np.ndarray | None = None
    tension: float = 0.0


@dataclass
class JiggleState:
    """Every jiggling muscle's :class:`Oscillators`, at pose frame ``frame`` (None: before
    ``first``, the earliest muscle's start); dt the pose's frame time (s)."""

    first: int
    dt: float
    muscles: dict = field(default_factory=dict)  # muscle index -> Oscillators
    frame: int | None = None


class JiggleStage(StageBase):
    """Damped oscillators on the free axis control points of the muscles with ``jiggle``
    (docs/FORMATS.md, "Jiggle"); switched off by ``--no-jiggle`` or a job's ``jiggle: false``."""

    name = "jiggle"
    scope = Scope.TIME

    @property
    def settings(self) -> dict:
        """The bound on what is written (:func:`axdf_cli.model.jiggle.bounded`) and the
        warm-up's precision, recorded in the manifest so that ``--resume`` refuses a change."""
        return {"bound": tol.JIGGLE_BOUND, "knee": tol.JIGGLE_BOUND_KNEE, "warmup_eps": tol.JIGGLE_WARMUP_EPS}

    @classmethod
    def for_run(cls, inputs: RunInputs) -> "JiggleStage | None":
        """The stage where it acts on one of the run's muscles (a run without one leaves it out)."""
        return cls() if any(s.jiggle is not None for s in inputs.muscles) else None

    def start(self, plan) -> JiggleState:
        """The state before the pose's first frame: every muscle starts there."""
        return self._state(plan, None, 1)

    def restart(self, plan, epoch: int, block: int) -> tuple[JiggleState, int]:
        """The state before the warm-up walk that leads to pose frame ``epoch``, and the frame
        that walk starts at (the earliest muscle's start): each muscle starts whole ``block``s
        of frames before it, enough for its warm-up (:func:`axdf_cli.model.jiggle.warmup_frames`),
        never before the pose's first frame."""
        state = self._state(plan, epoch, block)
        return state, state.first

    @staticmethod
    def _state(plan, epoch: int | None, block: int) -> JiggleState:
        first, dt = int(plan.pose.first), 1.0 / float(plan.pose.fps)
        at = first if epoch is None else int(epoch)

        def begin(spec) -> int:
            lead = jiggle.warmup_frames(spec, dt)
            if not lead < at - first:
                return first
            return at - block * int(np.ceil(lead / block))

        muscles = {j: Oscillators(s.jiggle, jiggle.control_weights(s.jiggle.weight, plan.models[j].n_axis),
                                  float(s.tension), max(first, begin(s.jiggle)))
                   for j, s in enumerate(plan.muscles) if s.jiggle is not None}
        return JiggleState(min((o.begin for o in muscles.values()), default=at), dt, muscles)

    def __call__(self, state: JiggleState, chunk):
        """Advance every jiggling muscle of ``chunk`` over its frames (consecutive pose frames
        right after the state's: (C,) frames, axis (C, n, 3) each) and move its axis to
        ``target + weight (x - target)``, that offset softly bounded relative to the axis'
        length at the frame (:func:`axdf_cli.model.jiggle.bounded`). A muscle starts at its
        ``begin`` frame (the first of a chunk) and is left as it is before."""
        frames = np.asarray(chunk.frames, dtype=np.int64)
        start = state.first if state.frame is None else state.frame + 1
        if int(frames[0]) != start or np.any(np.diff(frames) != 1):
            raise ValueError(f"the jiggle stage needs the pose's frames in order from {start}; "
                             f"got {int(frames[0])}..{int(frames[-1])} ({len(frames)} frames)")
        present = [j for j in chunk.muscles if j in state.muscles]
        late = [j for j in present if state.muscles[j].x is None and state.muscles[j].begin < frames[0]]
        if late:
            raise ValueError(f"jiggling muscle {late[0]} starts at frame {state.muscles[late[0]].begin}, "
                             f"before this chunk's first frame {int(frames[0])}")
        fresh = [j for j in present if state.muscles[j].x is None and state.muscles[j].begin == frames[0]]
        running = [j for j in present if state.muscles[j].x is not None]
        moved, after = {}, {}
        for js, new in ((fresh, True), (running, False)):
            if js:
                m, a = self._advance(state, chunk, js, new)
                moved.update(m)
                after.update(a)
        return (replace(state, muscles={**state.muscles, **after}, frame=int(frames[-1])),
                replace(chunk, axis={**chunk.axis, **moved}))

    @staticmethod
    def _advance(state: JiggleState, chunk, js: list, new: bool) -> tuple[dict, dict]:
        """Muscles ``js`` over the chunk, all started before it, or all starting at its first
        frame (``new``: that frame stays on its target); their moved axes and next states."""
        osc = [state.muscles[j] for j in js]
        sizes = [len(o.weights) for o in osc]
        cuts = np.cumsum([0] + sizes)
        targets = np.concatenate([chunk.axis[j] for j in js], axis=1)  # (C, P, 3)
        tone = np.array([o.tone for o in osc])
        tension = effective_tension(tone, chunk.activation[:, js])  # (C, M')
        n = len(chunk.frames)
        if new:  # the steady state of a constant-velocity pre-roll
            skip, prev_t, prev_e = 1, targets[0].copy(), tension[0].copy()
            x, v = jiggle.steady_state(prev_t, targets[1] if n > 1 else None, state.dt)
        else:
            skip = 0
            prev_t = np.concatenate([o.target for o in osc])
            prev_e = np.array([o.tension for o in osc])
            x = np.concatenate([o.x for o in osc])
            v = np.concatenate([o.v for o in osc])
        moved = {j: chunk.axis[j].copy() for j in js}  # (a first frame stays on its target)
        if n > skip:
            tgt, ten = targets[skip:], tension[skip:]
            # a step's stiffness and damping: at the mean effective tension of its two frames
            mid = 0.5 * (np.concatenate([prev_e[None], ten[:-1]]) + ten)  # (S, M')
            phi = np.empty((len(tgt), cuts[-1], 2, 2))
            for k, o in enumerate(osc):
                omega, zeta = jiggle.parameters(o.spec, mid[:, k])
                phi[:, cuts[k]:cuts[k + 1]] = jiggle.step_matrices(omega, zeta, state.dt)[:, None]
            xs, x, v = jiggle.oscillate(x, v, np.concatenate([prev_t[None], tgt]), phi, state.dt)
            w = np.concatenate([o.weights for o in osc])[None, :, None]
            length = np.concatenate([np.repeat(jiggle.axis_length(tgt[:, cuts[k]:cuts[k + 1]])[:, None], m, axis=1)
                                     for k, m in enumerate(sizes)], axis=1)  # (S, P): each point's muscle's
            out = tgt + jiggle.bounded(w * (xs - tgt), length)  # what is written: T + w (x - T), bounded
            for k, j in enumerate(js):
                moved[j][skip:] = out[:, cuts[k]:cuts[k + 1]]
            prev_t, prev_e = tgt[-1], ten[-1]
        after = {j: replace(o, x=x[cuts[k]:cuts[k + 1]].copy(), v=v[cuts[k]:cuts[k + 1]].copy(),
                            target=prev_t[cuts[k]:cuts[k + 1]].copy(), tension=float(prev_e[k]))
                 for k, (j, o) in enumerate(zip(js, osc))}
        return moved, after
