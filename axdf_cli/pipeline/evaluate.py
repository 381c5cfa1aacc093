"""Evaluating a plan: batched over frames (chunks) and muscles, batch dimension first."""
from __future__ import annotations

import numpy as np

from axdf_cli.model import contact, rmf
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.pipeline.plan import RunPlan
from axdf_cli.model.skeleton import forward_kinematics

CHUNK_FRAMES = 128  # frames evaluated together: bounds memory for any sequence length
EVAL_BUDGET_BYTES = 128 * 1024 * 1024  # per-muscle chunk memory budget (see chunk_frames)


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


def batched_axis_frames(models, indices, world: np.ndarray, coarse: bool = False, coords=None) -> dict:
    """Axis frames (p, x, t, r) of several muscles at once, by muscle index. Muscles with the
    same number of axis samples share one double-reflection recurrence, so its loop over the
    samples runs once per group, not once per muscle (row by row the same arithmetic)."""
    groups: dict[int, list[int]] = {}
    for j in indices:
        m = models[j]
        groups.setdefault(len(m.Bc) if coarse else len(m.ts), []).append(j)
    nf = world.shape[0]
    out = {}
    for js in groups.values():
        ins = [models[j].rmf_inputs(world, coarse, coords) for j in js]
        r = rmf.propagate(np.concatenate([i[1] for i in ins]), np.concatenate([i[2] for i in ins]),
                          np.concatenate([i[3] for i in ins]))
        for k, j in enumerate(js):
            p, x, t, _ = ins[k]
            out[j] = (p, x, t, r[k * nf:(k + 1) * nf])
    return out


def chunk_frames(plan: RunPlan) -> int:
    """Frames per evaluation chunk: at most CHUNK_FRAMES, fewer for very fine meshes, so that
    one muscle's chunk (about 8 float64 arrays of (F, V, 3)) stays within EVAL_BUDGET_BYTES."""
    v = max(m.n_vertices for m in plan.models)
    if plan.contact is not None:  # contact holds every muscle of a chunk at once
        v = sum(m.n_vertices for m in plan.models)
    return int(np.clip(EVAL_BUDGET_BYTES // (v * 3 * 8 * 8), 1, CHUNK_FRAMES))


def evaluate_chunks(plan: RunPlan, chunk: int | None = None, twist_ref: np.ndarray | None = None,
                    muscles: list[int] | None = None):
    """Yield (frame_slice, world (C, B, 4, 4), results) over the selected frames, where
    ``results`` is a lazy iterator of (muscle index, FrameResult): a consumer that handles one
    muscle at a time holds one muscle's chunk in memory, never all of them."""
    if twist_ref is None:
        twist_ref = twist_references(plan)
    chunk = chunk or chunk_frames(plan)
    names = plan.names
    for s in range(0, len(plan.frames), chunk):
        fr = plan.frames[s:s + chunk]
        q = sample_coordinates(plan.pose, fr)
        world = forward_kinematics(plan.pose.skeleton, q)
        act = sample_activation(plan.pose, names, fr)

        def results(world=world, act=act, s=s, n=len(fr), q=q):
            which = list(range(len(plan.models))) if muscles is None else list(muscles)
            if plan.contact is not None:
                # a FRAME stage: every muscle of the chunk, then contact, then the ones asked for
                everyone = list(range(len(plan.models)))
                frames = batched_axis_frames(plan.models, everyone, world, coords=q)
                done = {j: _evaluate(plan, j, world, act, twist_ref[s:s + n, j], frames.pop(j), q) for j in everyone}
                contact.apply(plan.contact, done, world)
                for j in which:
                    yield j, done.pop(j)
                return
            frames = batched_axis_frames(plan.models, which, world, coords=q)
            for j in which:
                yield j, _evaluate(plan, j, world, act, twist_ref[s:s + n, j], frames.pop(j), q)

        yield slice(s, s + len(fr)), world, results()


def _evaluate(plan: RunPlan, j: int, world, act, twist_ref, frames, q):
    m = plan.models[j]
    return m.evaluate(world, effective_tension(m.spec.tension, act[:, j]), twist_ref, frames=frames, coords=q)


def finite_or_rest(res, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A result's vertices and normals as float32, frames with any non-finite value replaced
    by the rest shape (what is written and rendered): (positions, normals, replaced frame indices)."""
    pos = res.vertices.astype(np.float32)
    nrm = res.normals.astype(np.float32)
    bad = np.nonzero(~(np.isfinite(pos).all(axis=(1, 2)) & np.isfinite(nrm).all(axis=(1, 2))))[0]
    pos[bad] = model.rest_vertices
    nrm[bad] = model.rest_normals
    return pos, nrm, bad
