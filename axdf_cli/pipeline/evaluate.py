"""Evaluating a plan: the one path from a plan to surfaces, chunk by chunk, through the stages.

Every evaluation of a run goes through :func:`evaluate_plan`: the mesh pass and ``--strict``'s
check (:mod:`.execute`), the frames sink (:mod:`.frames`) and so a data set's samples. Per
chunk of selected frames (batch dimension first, indexed by muscle): kinematics, step 1a
(axis control points), the TIME stages (over fixed blocks of the pose's timeline, from the
states the pre-pass kept), step 1b (surfaces), the FRAME stages; then the sink takes the
results muscle by muscle (:mod:`.stages` explains the order and the contracts).

:func:`prepare` is the pre-pass made once per run, in the parent, and handed to every
worker: the twist references and the TIME stages' states at the start of each timeline
block that holds selected frames.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from axdf_cli.model import rmf
from axdf_cli.model.muscle import FrameResult
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.plan import RunPlan
from axdf_cli.pipeline.stages import Chunk, Scope, of_scope

CHUNK_FRAMES = 128  # frames evaluated together: bounds memory for any sequence length
EVAL_BUDGET_BYTES = 128 * 1024 * 1024  # per-muscle chunk memory budget (see chunk_frames)
FRAME_BUDGET_BYTES = 256 * 1024 * 1024  # a chunk of every muscle at once (a FRAME stage runs; see chunk_frames)
TIME_BLOCK = CHUNK_FRAMES  # frames of the pose's timeline a TIME stage is given at once (always the same blocks)


TWIST_MIN_STEPS = 64  # the twist reference samples a moving key interval at least this often
TWIST_STEP_DEG = 5.0  # ... and often enough that no rotation coordinate moves more than this per step


def twist_grid(pose, upto: int) -> np.ndarray:
    """The frames (sorted, unique, up to ``upto``) over which the twist reference is
    unwrapped. Fixed by the pose alone, whatever frames are selected.

    Every coordinate curve is monotone between consecutive key frames (linear, step and the
    monotone cubic all are), so the pose moves only between keys and by at most the keys'
    difference. Each interval between consecutive key frames (the pose's first and last
    frame included) is sampled at ``min(length, max(TWIST_MIN_STEPS, change / TWIST_STEP_DEG))``
    evenly spaced whole frames, where change is the largest rotation-coordinate difference
    (degrees) across it; an interval where nothing moves (and ``step`` interpolation, which
    holds each key) needs only its ends. Short intervals are therefore sampled at every frame."""
    knots = {pose.first, pose.last}
    for kf, _ in pose.keys.values():
        knots.update(k for k in kf if pose.first < k < pose.last)
    knots = np.array(sorted(knots), dtype=np.int64)
    knots = knots[:np.searchsorted(knots, upto, side="right") + 1]  # up to the interval holding upto
    if len(knots) < 2:
        return knots[knots <= upto]
    q = sample_coordinates(pose, knots)
    moved = np.abs(np.diff(q, axis=0))  # (K-1, C)
    rot = [i for i, c in enumerate(pose.skeleton.coordinates) if c.type == "rotation"]
    change = moved[:, rot].max(axis=1) if rot else np.zeros(len(knots) - 1)
    length = np.diff(knots)
    steps = np.minimum(length, np.maximum(TWIST_MIN_STEPS, np.ceil(change / TWIST_STEP_DEG))).astype(np.int64)
    steps[(moved.max(axis=1) == 0) | (pose.interpolation == "step")] = 1
    pieces = [a + (np.arange(n) * (b - a)) // n for a, b, n in zip(knots[:-1], knots[1:], steps)]
    grid = np.unique(np.concatenate(pieces + [knots[-1:]]))
    return grid[grid <= upto]


def twist_references(plan: RunPlan) -> np.ndarray:
    """Unwrapped coarse insertion roll for every selected frame and muscle: (F, M) radians.

    The roll is unwrapped in order over :func:`twist_grid` (the pose's key intervals,
    sampled finely enough that it moves well under 180° per step); a selected frame takes the
    branch nearest to the grid's last frame at or before it. The grid depends on the pose
    only, so any ``--frames`` subset gives the same branches, hence the same meshes; the cost
    grows with the keys and motion up to the last selected frame, not with the pose's length."""
    pose, frames, nm = plan.pose, plan.frames, len(plan.models)
    grid = twist_grid(pose, int(frames.max()))
    at = np.searchsorted(grid, frames, side="right") - 1  # the grid frame each selected frame follows
    need, where = np.unique(at, return_inverse=True)
    th_need = np.empty((len(need), nm))
    prev = np.zeros(nm)
    block = 4 * CHUNK_FRAMES
    for s in range(0, int(need[-1]) + 1, block):
        th = np.unwrap(np.concatenate([prev[None], _coarse_roll(plan, grid[s:s + block])]), axis=0)[1:]
        prev = th[-1]
        k = (need >= s) & (need < s + block)
        th_need[k] = th[need[k] - s]
    out = th_need[where]
    off = np.nonzero(grid[at] != frames)[0]
    for s in range(0, len(off), block):
        i = off[s:s + block]
        roll = _coarse_roll(plan, frames[i])
        out[i] = roll + 2.0 * np.pi * np.round((out[i] - roll) / (2.0 * np.pi))
    return out


def _coarse_roll(plan: RunPlan, frames: np.ndarray) -> np.ndarray:
    """Coarse insertion roll (wrapped) of every muscle at ``frames``: (len(frames), M)."""
    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    axes = batched_axis_frames(plan.models, range(len(plan.models)), world, coarse=True, coords=q)
    return np.stack([m.end_twist(world, r_end=axes[j][3][:, -1], coords=q) for j, m in enumerate(plan.models)],
                    axis=1)


def batched_axis_frames(models, indices, world: np.ndarray, coarse: bool = False, coords=None,
                        points: dict | None = None) -> dict:
    """Axis frames (p, x, t, r) of several muscles at once, by muscle index. Muscles with the
    same number of axis samples share one double-reflection recurrence, so its loop over the
    samples runs once per group, not once per muscle (row by row the same arithmetic).
    ``points``: muscle -> (F, n, 3) axis control points already placed (step 1a)."""
    groups: dict[int, list[int]] = {}
    for j in indices:
        m = models[j]
        groups.setdefault(len(m.Bc) if coarse else len(m.ts), []).append(j)
    nf = world.shape[0]
    out = {}
    for js in groups.values():
        ins = [models[j].rmf_inputs(world, coarse, coords, None if points is None else points[j]) for j in js]
        r = rmf.propagate(np.concatenate([i[1] for i in ins]), np.concatenate([i[2] for i in ins]),
                          np.concatenate([i[3] for i in ins]))
        for k, j in enumerate(js):
            p, x, t, _ = ins[k]
            out[j] = (p, x, t, r[k * nf:(k + 1) * nf])
    return out


def chunk_frames(plan: RunPlan, together: list[int] | None = None) -> int:
    """Frames per evaluation chunk: at most CHUNK_FRAMES, fewer for very fine meshes, so that
    one muscle's chunk (about 8 float64 arrays of (F, V, 3)) stays within EVAL_BUDGET_BYTES;
    with ``together`` (the muscles whose results are held at once, for a FRAME stage: 2
    arrays each, plus one muscle's working set), within FRAME_BUDGET_BYTES."""
    v = max(m.n_vertices for m in plan.models)
    if together is None:
        return int(np.clip(EVAL_BUDGET_BYTES // (v * 3 * 8 * 8), 1, CHUNK_FRAMES))
    held = sum(plan.models[j].n_vertices for j in together) * 3 * 8 * 2
    return int(np.clip(FRAME_BUDGET_BYTES // (held + v * 3 * 8 * 8), 1, CHUNK_FRAMES))


# ----------------------------------------------------------------------------- the pre-pass


@dataclass
class Prepass:
    """What a run computes once, before its chunks, for every process that evaluates them."""

    twist: np.ndarray  # (F, M) unwrapped twist references of the selected frames (radians)
    states: dict = field(default_factory=dict)  # timeline block -> the TIME stages' states at its start


def prepare(plan: RunPlan) -> Prepass:
    """The pre-pass: :func:`twist_references`, and with TIME stages their states at the start
    of every timeline block that holds a selected frame (the stages run over every block up
    to the last selected frame; memory: one state per such block, never the frames')."""
    return Prepass(twist_references(plan), time_states(plan))


def timeline_block(plan: RunPlan, frames: np.ndarray) -> np.ndarray:
    """The timeline block (TIME_BLOCK frames from the pose's first) of each frame."""
    return (np.asarray(frames, np.int64) - int(plan.pose.first)) // TIME_BLOCK


def time_states(plan: RunPlan) -> dict:
    """{timeline block: the TIME stages' states at its start} for the blocks holding selected
    frames (empty without TIME stages): the stages run from :meth:`Stage.start` over every
    block before the last such block, all muscles, in order. Kept states are copies, so a
    stage that changes its state in place cannot change them."""
    stages = of_scope(plan.stages, Scope.TIME)
    if not stages:
        return {}
    need = {int(b) for b in np.unique(timeline_block(plan, plan.frames))}
    state = tuple(s.start(plan) for s in stages)
    out = {}
    for b in range(max(need) + 1):
        if b in need:
            out[b] = copy.deepcopy(state)
        if b < max(need):
            state, _ = time_block(plan, stages, state, b)
    return out


def time_block(plan: RunPlan, stages, state: tuple, b: int) -> tuple[tuple, Chunk]:
    """Block ``b`` of the pose's timeline (every frame of it, every muscle): kinematics, step 1a,
    then the TIME ``stages`` from ``state``; returns their next states and the chunk."""
    pose = plan.pose
    lo = b * TIME_BLOCK
    frames = pose.frames[lo:lo + TIME_BLOCK]
    chunk = _chunk(plan, slice(lo, lo + len(frames)), frames, list(range(len(plan.models))))
    out = []
    for stage, st in zip(stages, state):
        st, chunk = stage(st, chunk)
        out.append(st)
    return tuple(out), chunk


def _chunk(plan: RunPlan, rows: slice, frames: np.ndarray, muscles: list[int], twist=None) -> Chunk:
    """Kinematics and step 1a (axis control points) of ``muscles`` at ``frames``."""
    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    act = sample_activation(plan.pose, plan.names, frames)
    axis, notes = {}, {}
    for j in muscles:
        axis[j], notes[j] = plan.models[j].axis_points(world, q)
    return Chunk(rows, frames, q, world, act, muscles, axis, twist=twist, notes=notes)


# ----------------------------------------------------------------------------- the chunks


def evaluate_plan(plan: RunPlan, prep: Prepass | None = None, rows: slice | None = None,
                  muscles: list[int] | None = None, size: int | None = None
                  ) -> Iterator[tuple[Chunk, Iterator[tuple[int, FrameResult]]]]:
    """The selected frames ``rows`` (positions in ``plan.frames``, default all) of ``muscles``
    (default all; every muscle when a FRAME stage runs), in chunks of at most ``size`` frames:
    yields ``(chunk, results)`` in frame order, where ``results`` yields ``(muscle, FrameResult)``
    in ``chunk.muscles`` order, after every stage. Without a FRAME stage the surfaces are made
    as ``results`` is read (a sink handling one muscle at a time holds one muscle's chunk in
    memory); with one, all of them are made, then the FRAME stages run, then they are handed
    out. ``prep``: :func:`prepare`'s pre-pass (made here when None)."""
    prep = prepare(plan) if prep is None else prep
    rows = slice(0, len(plan.frames)) if rows is None else rows
    time_st, frame_st = of_scope(plan.stages, Scope.TIME), of_scope(plan.stages, Scope.FRAME)
    carried = list(range(len(plan.models))) if frame_st or muscles is None else list(muscles)
    size = size or chunk_frames(plan, carried if frame_st else None)
    frame_state = [s.start(plan) for s in frame_st]
    for chunk in (_time_chunks(plan, prep, rows, carried, size, time_st) if time_st else
                  _plain_chunks(plan, prep, rows, carried, size)):
        yield chunk, _surfaces(plan, chunk, frame_st, frame_state)


def _plain_chunks(plan, prep, rows: slice, carried, size: int) -> Iterator[Chunk]:
    for s in range(rows.start, rows.stop, size):
        sl = slice(s, min(s + size, rows.stop))
        yield _chunk(plan, sl, plan.frames[sl], carried, prep.twist[sl])


def _time_chunks(plan, prep, rows: slice, carried, size: int, stages) -> Iterator[Chunk]:
    """The selected rows block by block of the timeline: each block's axis as the TIME stages
    leave it (from the state kept at its start), then its selected frames in chunks."""
    frames = plan.frames[rows]
    blocks = timeline_block(plan, frames)
    for b in np.unique(blocks):
        _, block = time_block(plan, stages, copy.deepcopy(prep.states[int(b)]), int(b))
        k0, k1 = np.searchsorted(blocks, [b, b + 1])
        for s in range(rows.start + int(k0), rows.start + int(k1), size):
            sl = slice(s, min(s + size, rows.start + int(k1)))
            idx = plan.frames[sl] - int(block.frames[0])
            at = {int(i): k for k, i in enumerate(idx)}
            yield Chunk(sl, plan.frames[sl], block.coords[idx], block.world[idx], block.activation[idx], carried,
                        {j: block.axis[j][idx] for j in carried}, twist=prep.twist[sl],
                        notes={j: [(at[i], m) for i, m in block.notes[j] if i in at] for j in carried})


def _surfaces(plan, chunk: Chunk, stages, state: list) -> Iterator[tuple[int, FrameResult]]:
    """Step 1b of the chunk's muscles, then the FRAME ``stages`` (``state``: theirs, kept
    from chunk to chunk); yields (muscle, result) in ``chunk.muscles`` order."""
    frames = batched_axis_frames(plan.models, chunk.muscles, chunk.world, points=chunk.axis)

    def surface(j: int) -> FrameResult:
        m = plan.models[j]
        _, x, t, r = frames.pop(j)
        return m.surface(chunk.world, chunk.axis[j], effective_tension(m.spec.tension, chunk.activation[:, j]),
                         chunk.twist[:, j], frames=(x, t, r), warnings=chunk.notes.get(j, ()))

    if not stages:
        for j in chunk.muscles:
            yield j, surface(j)
        return
    for j in chunk.muscles:
        chunk.results[j] = surface(j)
    for k, stage in enumerate(stages):
        state[k], chunk = stage(state[k], chunk)
    for j in chunk.muscles:
        yield j, chunk.results.pop(j)


def evaluate_chunks(plan: RunPlan, chunk: int | None = None, twist_ref: np.ndarray | None = None,
                    muscles: list[int] | None = None, prep: Prepass | None = None):
    """:func:`evaluate_plan` as (frame slice, world (C, B, 4, 4), results): for tests and the bench."""
    if prep is None and twist_ref is not None:
        prep = Prepass(twist_ref, time_states(plan))
    for c, results in evaluate_plan(plan, prep, muscles=muscles, size=chunk):
        yield c.rows, c.world, results


def finite_or_rest(res, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A result's vertices and normals as float32, frames with any non-finite value replaced
    by the rest shape (what is written and rendered): (positions, normals, replaced frame indices)."""
    pos = res.vertices.astype(np.float32)
    nrm = res.normals.astype(np.float32)
    bad = np.nonzero(~(np.isfinite(pos).all(axis=(1, 2)) & np.isfinite(nrm).all(axis=(1, 2))))[0]
    pos[bad] = model.rest_vertices
    nrm[bad] = model.rest_normals
    return pos, nrm, bad
