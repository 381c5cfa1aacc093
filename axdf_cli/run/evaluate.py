"""Evaluating a plan: batched over frames (chunks) and muscles, batch dimension first."""
from __future__ import annotations

import numpy as np

from axdf_cli import rmf
from axdf_cli.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.run.plan import RunPlan
from axdf_cli.skeleton import forward_kinematics

CHUNK_FRAMES = 128  # frames evaluated together: bounds memory for any sequence length
EVAL_BUDGET_BYTES = 128 * 1024 * 1024  # per-muscle chunk memory budget (see chunk_frames)


def twist_references(plan: RunPlan) -> np.ndarray:
    """Unwrapped coarse insertion roll for every selected frame and muscle: (F, M) radians.

    Computed over the pose's whole frame range in order, so the branch (past ±180°) of any
    frame does not depend on which frames are selected."""
    pose = plan.pose
    all_frames = pose.frames
    out = np.empty((len(all_frames), len(plan.models)))
    prev = np.zeros(len(plan.models))
    for s in range(0, len(all_frames), 4 * CHUNK_FRAMES):
        fr = all_frames[s:s + 4 * CHUNK_FRAMES]
        q = sample_coordinates(pose, fr)
        world = forward_kinematics(pose.skeleton, q)
        frames = batched_axis_frames(plan.models, range(len(plan.models)), world, coarse=True, coords=q)
        for j, m in enumerate(plan.models):
            th = np.unwrap(np.concatenate([[prev[j]], m.end_twist(world, r_end=frames[j][3][:, -1], coords=q)]))[1:]
            out[s:s + len(fr), j] = th
            prev[j] = th[-1]
    return out[plan.frames - pose.first]


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
            frames = batched_axis_frames(plan.models, which, world, coords=q)
            for j in which:
                m = plan.models[j]
                yield j, m.evaluate(world, effective_tension(m.spec.tension, act[:, j]), twist_ref[s:s + n, j],
                                    frames=frames.pop(j), coords=q)

        yield slice(s, s + len(fr)), world, results()


def finite_or_rest(res, model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A result's vertices and normals as float32, frames with any non-finite value replaced
    by the rest shape (what is written and rendered): (positions, normals, replaced frame indices)."""
    pos = res.vertices.astype(np.float32)
    nrm = res.normals.astype(np.float32)
    bad = np.nonzero(~(np.isfinite(pos).all(axis=(1, 2)) & np.isfinite(nrm).all(axis=(1, 2))))[0]
    pos[bad] = model.rest_vertices
    nrm[bad] = model.rest_normals
    return pos, nrm, bad
