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

from axdf_cli.model import kernels
from axdf_cli.model.batch import LANES, MuscleBatch
from axdf_cli.model.muscle import FrameResult
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.plan import RunPlan
from axdf_cli.pipeline.stages import Chunk, Scope, of_scope

CHUNK_FRAMES = 128  # frames evaluated together: bounds memory for any sequence length
EVAL_BUDGET_BYTES = 40 * 1024 * 1024  # the surfaces of one chunk, every muscle at once (see chunk_frames)
TIME_BLOCK = CHUNK_FRAMES  # frames of the pose's timeline a TIME stage is given at once (always the same blocks)
# blocks of an epoch of the timeline: a TIME stage's state at an epoch's start comes from a
# warm-up walk just before it, not from the pose's first frame (stages.py), so a frame costs
# at most a warm-up and an epoch (4,096 frames) and a whole run repeats a warm-up per epoch
# (the shipped walk's jiggle: 2.1 s, 256 frames at 120 fps: 6%)
TIME_EPOCH_BLOCKS = 32


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
    holds each key) needs only its ends. Runs of whole-frame intervals (a key every frame)
    keep a knot each time the rotations' summed change passes another TWIST_STEP_DEG."""
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
    # Densely keyed motion (a key every frame): consecutive whole intervals merge while the
    # rotations' total movement since the last kept knot stays under TWIST_STEP_DEG (a
    # coordinate is monotone inside each interval, so its summed changes bound how far it
    # moves across several): a step moves at most TWIST_STEP_DEG plus one interval's change.
    # A subdivided interval keeps both of its ends.
    if pose.interpolation != "step":
        total = np.concatenate([[0.0], np.cumsum(change)])
        keep = np.ones(len(knots), dtype=bool)
        keep[1:] = np.floor(total[1:] / TWIST_STEP_DEG) != np.floor(total[:-1] / TWIST_STEP_DEG)
        keep[1:][steps > 1] = keep[:-1][steps > 1] = True
        keep[0] = True
        keep[-1] |= knots[-1] == pose.last  # (the same knots whatever ``upto`` cuts the list at)
        ends = np.flatnonzero(keep)
        pieces = [knots[ends]] + [a + (np.arange(n) * (b - a)) // n
                                  for a, b, n in zip(knots[:-1][steps > 1], knots[1:][steps > 1], steps[steps > 1])]
    else:
        pieces = [knots]
    grid = np.unique(np.concatenate(pieces))
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
    batch, every = batch_of(plan), range(len(plan.models))
    p, _ = batch.axis_points(world, q, every)
    return batch.coarse_roll(world, p, every)


_BATCHES: list = []  # [(models, MuscleBatch)], the most recent last


def batch_of(plan: RunPlan) -> MuscleBatch:
    """The plan's muscle models packed for the compiled passes (:mod:`axdf_cli.model.batch`),
    made once for the same models (a data set's sequences share theirs; a few are kept)."""
    key = tuple(plan.models)
    for models, batch in _BATCHES:
        if len(models) == len(key) and all(a is b for a, b in zip(models, key)):
            return batch
    batch = MuscleBatch(key)
    _BATCHES.append((key, batch))
    del _BATCHES[:-4]
    return batch


def chunk_frames(plan: RunPlan, together: list[int] | None = None) -> int:
    """Frames per evaluation chunk: at most CHUNK_FRAMES, fewer so that the surfaces of the
    muscles made at once (``together``, default all: vertices and normals, 2 float64 arrays
    (F, V, 3) each, and the bound points' frames) stay within EVAL_BUDGET_BYTES; a multiple of
    the compiled pass's LANES when at least that many (its loops over frames run as vector
    instructions LANES frames at a time: 7 frames take 3.5x as long as 8 in the RMF)."""
    together = range(len(plan.models)) if together is None else together
    held = sum(plan.models[j].n_vertices * 3 * 8 * 2 + len(plan.models[j].bind_t) * 3 * 8 * 3 for j in together)
    n = int(np.clip(EVAL_BUDGET_BYTES // max(held, 1), 1, CHUNK_FRAMES))
    return n - n % LANES if n >= LANES else n


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
    frames (empty without TIME stages). Per epoch (:data:`TIME_EPOCH_BLOCKS` blocks) that
    holds one: the stages start (the first epoch: at the pose's first frame; a later one: a
    warm-up before it, from the block of the earliest frame their ``restart`` asks for), then run over its
    blocks in order, all muscles, up to its last such block. Kept states are copies, so a
    stage that changes its state in place cannot change them."""
    stages = of_scope(plan.stages, Scope.TIME)
    if not stages:
        return {}
    first = int(plan.pose.first)
    need = sorted({int(b) for b in np.unique(timeline_block(plan, plan.frames))})
    out = {}
    for e in sorted({b // TIME_EPOCH_BLOCKS for b in need}):
        e0 = e * TIME_EPOCH_BLOCKS
        if e == 0:
            state, walk = tuple(s.start(plan) for s in stages), first
        else:  # a stage without ``restart`` walks from the pose's first frame
            pairs = [s.restart(plan, first + e0 * TIME_BLOCK, TIME_BLOCK) for s in stages]
            state, walk = tuple(p[0] for p in pairs), min(p[1] for p in pairs)
        last = max(b for b in need if b // TIME_EPOCH_BLOCKS == e)
        for b in range(min(e0, (walk - first) // TIME_BLOCK), last + 1):
            if b >= e0 and b in need:  # (a warm-up block belongs to the epoch before)
                out[b] = copy.deepcopy(state)
            if b < last:
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
    batch = batch_of(plan)
    p, notes = batch.axis_points(world, q, muscles)
    return Chunk(rows, frames, q, world, act, muscles, batch.unpack(p, muscles), twist=twist, notes=notes)


# ----------------------------------------------------------------------------- the chunks


def evaluate_plan(plan: RunPlan, prep: Prepass | None = None, rows: slice | None = None,
                  muscles: list[int] | None = None, size: int | None = None
                  ) -> Iterator[tuple[Chunk, Iterator[tuple[int, FrameResult]]]]:
    """The selected frames ``rows`` (positions in ``plan.frames``, default all) of ``muscles``
    (default all; every muscle when a FRAME stage runs), in chunks of at most ``size`` frames:
    yields ``(chunk, results)`` in frame order, where ``results`` yields ``(muscle, FrameResult)``
    in ``chunk.muscles`` order, after every stage. The surfaces of all carried muscles are made
    at once (one compiled pass, :mod:`axdf_cli.model.batch`; chunks sized by
    :func:`chunk_frames`), then the FRAME stages run, then they are handed out. ``prep``:
    :func:`prepare`'s pre-pass (made here when None)."""
    prep = prepare(plan) if prep is None else prep
    rows = slice(0, len(plan.frames)) if rows is None else rows
    time_st, frame_st = of_scope(plan.stages, Scope.TIME), of_scope(plan.stages, Scope.FRAME)
    carried = list(range(len(plan.models))) if frame_st or muscles is None else list(muscles)
    size = size or chunk_frames(plan, carried)
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
    """Step 1b of the chunk's muscles, all at once (:meth:`MuscleBatch.surfaces`), then the
    FRAME ``stages`` (``state``: theirs, kept from chunk to chunk); yields (muscle, result) in
    ``chunk.muscles`` order."""
    batch = batch_of(plan)
    js = list(chunk.muscles)
    tone = np.array([plan.muscles[j].tension for j in js], dtype=np.float64)
    tension = effective_tension(tone, chunk.activation[:, js])  # (C, K)
    fields = batch.surfaces(chunk.world, batch.pack(chunk.axis, len(chunk.frames)), tension, chunk.twist[:, js], js,
                            notes=chunk.notes)
    for j in js:  # a muscle with a line of action reports its length (as OpenSim's path)
        line = plan.models[j].line_length(chunk.world, chunk.coords)
        if line is not None:
            fields[j]["length"] = line
    chunk.results = {j: FrameResult(**f) for j, f in fields.items()}
    for k, stage in enumerate(stages):
        state[k], chunk = stage(state[k], chunk)
    for j in chunk.muscles:
        res = chunk.results.pop(j)
        res.written = written_arrays(res, plan.models[j])
        yield j, res


def evaluate_chunks(plan: RunPlan, chunk: int | None = None, twist_ref: np.ndarray | None = None,
                    muscles: list[int] | None = None, prep: Prepass | None = None):
    """:func:`evaluate_plan` as (frame slice, world (C, B, 4, 4), results): for tests and the bench."""
    if prep is None and twist_ref is not None:
        prep = Prepass(twist_ref, time_states(plan))
    for c, results in evaluate_plan(plan, prep, muscles=muscles, size=chunk):
        yield c.rows, c.world, results


def finite_or_rest(res, model, bounds: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A result's vertices and normals as float32, frames with any non-finite value replaced
    by the rest shape (what is written and rendered): (positions, normals, replaced frame
    indices); ``bounds`` (F, 2, 3), when given, receives each frame's smallest and largest
    written coordinates. :func:`evaluate_plan` makes them for every result after the stages
    (``res.written``); otherwise one compiled pass here (:func:`axdf_cli.model.kernels.written`)."""
    if res.written is None:
        res.written = written_arrays(res, model)
    pos, nrm, bad, box = res.written
    if bounds is not None:
        bounds[...] = box
    return pos, nrm, bad


def written_arrays(res, model) -> tuple:
    """(positions, normals (F, V, 3) float32, replaced frame indices, bounds (F, 2, 3)) of a
    result (:func:`finite_or_rest`)."""
    nf, nv = res.vertices.shape[:2]
    pos = np.empty((nf, nv, 3), np.float32)
    nrm = np.empty((nf, nv, 3), np.float32)
    box = np.empty((nf, 2, 3), np.float32)
    bad = np.empty(nf, np.bool_)
    kernels.written(np.ascontiguousarray(res.vertices, np.float64), np.ascontiguousarray(res.normals, np.float64),
                    model.rest_vertices, model.rest_normals, pos, nrm, box, bad)
    return pos, nrm, np.nonzero(bad)[0], box
