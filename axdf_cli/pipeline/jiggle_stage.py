"""The jiggle stage (scope TIME): the secondary motion of :mod:`axdf_cli.model.jiggle`
carried through time, on the axis control points before the surfaces are built (the
exact-volume solve comes after it, as always).

State: for every carried muscle with ``jiggle``, its oscillators' positions and velocities
(n_j, 3) in the world, with the kinematic targets and effective tension of the frame the
state is at. It starts at rest on the pose's first frame (the muscle has held that pose for
ever: a settled pre-roll). A chunk holds the *selected* frames only; the oscillators advance
over every pose frame up to the chunk's last one (the targets of frames that are not
selected are computed here, a block at a time, so memory stays bounded), so a ``--frames``
subset gives the bytes of the same frames of a full run. A chunk that starts at or before
the state's frame restarts from the first frame.

Every muscle's oscillators are independent, and every operation is elementwise per control
point, so a muscle moves to the same bytes whichever muscles share its chunk (``--jobs``
splits muscles).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from axdf_cli.model import jiggle
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.stages import Chunk, Scope

#: Pose frames advanced per block when the targets of frames that are not selected must be
#: computed here (--frames subsets, render blocks): bounds memory for any pose length.
BLOCK_FRAMES = 128


@dataclass
class JiggleState:
    """Where the oscillators are: at pose frame ``frame`` (None: before the first chunk);
    per muscle, positions x and velocities v (n, 3), the targets (n, 3) and effective tension
    at that frame."""

    frame: int | None = None
    x: dict = field(default_factory=dict)
    v: dict = field(default_factory=dict)
    target: dict = field(default_factory=dict)
    tension: dict = field(default_factory=dict)


class JiggleStage:
    """Damped oscillators on the free axis control points of the muscles with ``jiggle``."""

    name = "jiggle"
    scope = Scope.TIME

    def __init__(self, plan):
        self.plan = plan
        self.specs = {j: s.jiggle for j, s in enumerate(plan.muscles) if s.jiggle is not None}
        self.weights = {j: jiggle.control_weights(spec.weight, plan.models[j].n_axis) for j, spec in self.specs.items()}
        self.dt = 1.0 / float(plan.pose.fps)

    def start(self, plan) -> JiggleState:
        return JiggleState()

    def __call__(self, state: JiggleState, chunk: Chunk) -> tuple[JiggleState, Chunk]:
        js = [j for j in chunk.muscles if j in self.specs]
        if not js:
            return state, chunk
        frames = np.asarray(chunk.frames, dtype=np.int64)
        if state.frame is None or frames[0] <= state.frame or any(j not in state.x for j in js):
            state = self._at_rest(js, chunk)
        pos = {int(f): i for i, f in enumerate(frames)}
        sizes = [len(self.weights[j]) for j in js]
        cuts = np.cumsum([0] + sizes)
        w = np.concatenate([self.weights[j] for j in js])[None, :, None]  # (1, P, 1)
        x = np.concatenate([state.x[j] for j in js])
        v = np.concatenate([state.v[j] for j in js])
        prev_t = np.concatenate([state.target[j] for j in js])
        prev_e = np.array([state.tension[j] for j in js])
        moved = {j: np.array(chunk.axis[j], dtype=np.float64, copy=True) for j in js}
        frame = state.frame
        while frame < frames[-1]:
            block = np.arange(frame + 1, min(frame + BLOCK_FRAMES, int(frames[-1])) + 1, dtype=np.int64)
            targets, tension = self._block_targets(js, block, pos, chunk)  # (b, P, 3), (b, M')
            # a step's stiffness and damping: at the mean tension of its two frames
            mid = 0.5 * (np.concatenate([prev_e[None], tension[:-1]]) + tension)  # (b, M')
            phi = np.empty((len(block), cuts[-1], 2, 2))
            for k, j in enumerate(js):
                omega, zeta = jiggle.parameters(self.specs[j], mid[:, k])
                phi[:, cuts[k]:cuts[k + 1]] = jiggle.step_matrices(omega, zeta, self.dt)[:, None]
            xs, x, v = jiggle.oscillate(x, v, np.concatenate([prev_t[None], targets]), phi, self.dt)
            # a target that is not finite (a degenerate pose) leaves the oscillator at rest
            # on the next finite one, instead of poisoning every later frame
            bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
            if bad.any():
                x[bad], v[bad] = targets[-1, bad], 0.0
            out = targets + w * (xs - targets)  # what is written: T + w (x - T)
            for i, f in enumerate(block):
                row = pos.get(int(f))
                if row is not None:
                    for k, j in enumerate(js):
                        moved[j][row] = out[i, cuts[k]:cuts[k + 1]]
            prev_t, prev_e, frame = targets[-1], tension[-1], int(block[-1])
        state = JiggleState(frame, {j: x[cuts[k]:cuts[k + 1]] for k, j in enumerate(js)},
                            {j: v[cuts[k]:cuts[k + 1]] for k, j in enumerate(js)},
                            {j: prev_t[cuts[k]:cuts[k + 1]] for k, j in enumerate(js)},
                            {j: float(prev_e[k]) for k, j in enumerate(js)})
        return state, replace(chunk, axis={**chunk.axis, **moved})

    # -- the kinematic targets ------------------------------------------------------------
    def _at_rest(self, js: list[int], chunk: Chunk) -> JiggleState:
        """Every oscillator at rest on its target at the pose's first frame."""
        first = int(self.plan.pose.first)
        if int(chunk.frames[0]) == first:
            targets = {j: chunk.axis[j][0] for j in js}
            act = chunk.activation[:1]
        else:
            targets = {j: p[0] for j, p in self._targets(js, np.array([first])).items()}
            act = sample_activation(self.plan.pose, self.plan.names, np.array([first]))
        tension = self._tension(js, act)[0]
        return JiggleState(first, {j: np.array(targets[j], dtype=np.float64) for j in js},
                           {j: np.zeros(np.shape(targets[j])) for j in js},
                           {j: np.array(targets[j], dtype=np.float64) for j in js},
                           {j: float(tension[k]) for k, j in enumerate(js)})

    def _block_targets(self, js, block, pos, chunk: Chunk):
        """Targets (b, P, 3) and effective tensions (b, M') of the pose frames ``block``: the
        chunk's axis and activation where selected, computed for the others."""
        rows = np.array([pos.get(int(f), -1) for f in block], dtype=np.int64)
        have = rows >= 0
        targets = np.empty((len(block), sum(len(self.weights[j]) for j in js), 3))
        tension = np.empty((len(block), len(js)))
        if have.any():
            r = rows[have]
            targets[have] = np.concatenate([chunk.axis[j][r] for j in js], axis=1)
            tension[have] = self._tension(js, chunk.activation[r])
        if not have.all():
            need = block[~have]
            computed = self._targets(js, need)
            targets[~have] = np.concatenate([computed[j] for j in js], axis=1)
            tension[~have] = self._tension(js, sample_activation(self.plan.pose, self.plan.names, need))
        return targets, tension

    def _targets(self, js, frames: np.ndarray) -> dict:
        """Axis control points where the bones put them, at ``frames``: muscle -> (F, n, 3)."""
        q = sample_coordinates(self.plan.pose, frames)
        world = forward_kinematics(self.plan.pose.skeleton, q)
        return {j: self.plan.models[j].axis_points(world, q) for j in js}

    def _tension(self, js, activation: np.ndarray) -> np.ndarray:
        """Effective tension (F, M') of muscles ``js`` from every muscle's activation (F, M)."""
        tone = np.array([self.plan.muscles[j].tension for j in js])
        return effective_tension(tone, activation[:, js])


def time_stages(plan) -> list:
    """The plan's TIME stages: jiggle when it is on and a muscle has ``jiggle``."""
    if plan.jiggle and any(s.jiggle is not None for s in plan.muscles):
        return [JiggleStage(plan)]
    return []
