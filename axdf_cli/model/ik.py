"""Inverse kinematics: a skeleton's coordinates fitted to target points, frame by frame.

Points fixed in bones (``bones`` (P,), ``local`` (P, 3)) should follow targets ``Y`` (F, P, 3).
For every frame f the free coordinates x (K of the skeleton's C) minimise

    sum_p w_p |X_p(x) - Y[f, p]|^2  +  sum_k (lambda_k (x_k - x_prev_k))^2

within their ranges: scipy's ``least_squares`` (trust region reflective, which keeps the
bounds), with the analytic Jacobian of :func:`axdf_cli.model.skeleton.point_jacobian`,
warm-started from the previous frame's solution, as OpenSim's InverseKinematicsTool solves
its weighted marker least squares frame after frame (Delp et al. 2007; Seth et al. 2018).
The pull ``lambda`` towards the previous frame (``smooth``; by default
``tolerances.IK_SMOOTH_ROTATION``, 1 mm of residual per degree) settles coordinates the points
barely decide (a hip's rotation about a nearly straight leg: its column of the Jacobian
nearly vanishes; a toe on a 5 cm lever) and costs the well-seen ones little (a 0.4 m lever
moves its end 7 mm per degree: a lag of ~2% of a frame's change).

A speed limit (``max_step``, degrees per frame) narrows each rotation's bounds on every frame
after the first to the previous frame's value ± the step: the fit then lags a source that
turns faster (a kick, a marker that jumps) and catches up as it slows, and the residual
shows what that costs.

The first frame starts from ``q_start`` and fits the ``root`` coordinates alone to the
``root_points`` first (the pelvis placed and turned before the legs move), then everything.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model.skeleton import Skeleton, dof_frames, point_jacobian


@dataclass(frozen=True)
class FitResult:
    q: np.ndarray  # (F, C) coordinates, axdf units
    points: np.ndarray  # (F, P, 3) the fitted points
    error: np.ndarray  # (F, P) |X_p - Y_p|, metres (the targets' units)
    evaluations: np.ndarray  # (F,) residual evaluations per frame
    at_bound: np.ndarray  # (F, C) bool: a free coordinate ended on its range's end


def subskeleton(skel: Skeleton, bones) -> tuple[Skeleton, np.ndarray]:
    """The bones ``bones`` and their ancestors, in order (the coordinates unchanged): what
    moves the points, and no more to pose. Returns it and, per kept bone, its old index."""
    keep = set()
    for b in bones:
        while b >= 0 and b not in keep:
            keep.add(b)
            b = skel.bones[b].parent
    old = np.array(sorted(keep), int)
    new_of = {int(o): i for i, o in enumerate(old)}
    from dataclasses import replace

    kept = tuple(replace(skel.bones[o], parent=new_of[skel.bones[o].parent] if skel.bones[o].parent >= 0 else -1)
                 for o in old)
    return Skeleton(skel.name, kept, skel.coordinates, skel.source), old


def pose_points(skel: Skeleton, q: np.ndarray, bones: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Points fixed in bones, posed: ``q`` (F, C) → (F, P, 3)."""
    from axdf_cli.model.skeleton import forward_kinematics

    world = forward_kinematics(skel, q)[:, bones]
    # x[f, p, i] = R[f, p, i, j] local[p, j] + t[f, p, i]
    return np.einsum("fpij,pj->fpi", world[..., :3, :3], local) + world[..., :3, 3]


class _Problem:
    """One frame's least squares over the free coordinates; caches the last evaluation (scipy
    asks for the residual and the Jacobian at the same x)."""

    def __init__(self, skel, bones, local, sqrt_w, free, smooth):
        self.skel, self.bones, self.local = skel, bones, local
        self.sqrt_w, self.free, self.smooth = sqrt_w, free, smooth
        self.q = skel.rest_coordinates()
        self.target = np.zeros((len(bones), 3))
        self.prev = np.zeros(len(free))
        self.active = np.ones(len(bones), bool)
        self.key = None
        self.count = 0

    def evaluate(self, x):
        key = x.tobytes()
        if key != self.key:
            q = self.q.copy()
            q[self.free] = x
            world, frames = dof_frames(self.skel, q[None])
            pts, jac = point_jacobian(self.skel, frames, world, self.bones, self.local)
            self.key, self.pts, self.jac = key, pts[0], jac[0][:, :, self.free]
            self.count += 1
        return self.pts, self.jac

    def residual(self, x):
        pts, _ = self.evaluate(x)
        w = self.sqrt_w * self.active
        r = (w[:, None] * (pts - self.target)).reshape(-1)
        return np.concatenate([r, self.smooth * (x - self.prev)])

    def jacobian(self, x):
        _, jac = self.evaluate(x)
        w = self.sqrt_w * self.active
        j = (w[:, None, None] * jac).reshape(-1, len(self.free))
        return np.concatenate([j, np.diag(self.smooth)])


def fit_frames(skel: Skeleton, bones, local, weights, targets: np.ndarray, free, q_start: np.ndarray,
               root=(), root_points=(), smooth: float = tol.IK_SMOOTH_ROTATION, max_step: float = np.inf,
               progress=None) -> FitResult:
    """Fit the coordinates ``free`` (K,) indices of ``skel``'s to ``targets`` (F, P, 3), frame
    by frame (see the module doc). Coordinates not free keep their ``q_start`` (C,) values.
    ``root``: coordinates fitted alone first on frame 0, to the points ``root_points``;
    ``smooth``: the pull towards the previous frame, residual metres per degree of a rotation
    (translations: ``tolerances.IK_SMOOTH_TRANSLATION`` per metre); ``max_step``: the most a
    rotation may change from one frame to the next, degrees (translations are not limited): one
    number, or one per free coordinate (K,)."""
    from scipy.optimize import least_squares

    bones_full = np.asarray(bones, int)
    sub, old = subskeleton(skel, bones_full)
    new_of = {int(o): i for i, o in enumerate(old)}
    bones = np.array([new_of[int(b)] for b in bones_full], int)
    local = np.asarray(local, float)
    free = np.asarray(free, int)
    targets = np.asarray(targets, float)
    n_frames = targets.shape[0]
    coords = skel.coordinates
    lo = np.array([coords[c].range[0] if coords[c].range else -np.inf for c in free])
    hi = np.array([coords[c].range[1] if coords[c].range else np.inf for c in free])
    pull = np.array([smooth if coords[c].type == "rotation" else tol.IK_SMOOTH_TRANSLATION for c in free])
    step = np.where([coords[c].type == "rotation" for c in free], np.broadcast_to(max_step, free.shape), np.inf)
    prob = _Problem(sub, bones, local, np.sqrt(np.asarray(weights, float)), free, pull)
    prob.q = np.asarray(q_start, float).copy()
    opts = dict(method="trf", ftol=tol.IK_FTOL, xtol=tol.IK_XTOL, gtol=tol.IK_GTOL, max_nfev=tol.IK_MAX_EVALUATIONS)

    q_out = np.empty((n_frames, len(coords)))
    pts_out = np.empty((n_frames, len(bones), 3))
    evals = np.zeros(n_frames, int)
    at_bound = np.zeros((n_frames, len(coords)), bool)
    x = np.clip(prob.q[free], lo, hi)
    for f in range(n_frames):
        prob.target = targets[f]
        prob.count = 0
        if f == 0 and len(root):
            # the root alone first, to the root's points (nothing pulls it back to the start)
            is_root = np.isin(free, np.asarray(root, int))
            prob.active = np.isin(np.arange(len(bones)), np.asarray(root_points, int))
            sub_free = free[is_root]
            stage = _Problem(sub, bones, local, prob.sqrt_w, sub_free, np.zeros(len(sub_free)))
            stage.q, stage.target, stage.active = prob.q.copy(), prob.target, prob.active
            stage.prev = x[is_root]
            res = least_squares(stage.residual, x[is_root], jac=stage.jacobian, bounds=(lo[is_root], hi[is_root]),
                                **opts)
            x = x.copy()
            x[is_root] = res.x
            prob.q[sub_free] = res.x
            prob.count += stage.count
            prob.active = np.ones(len(bones), bool)
        prob.prev = x.copy()
        lo_f, hi_f = (lo, hi) if f == 0 else (np.maximum(lo, x - step), np.minimum(hi, x + step))
        res = least_squares(prob.residual, x, jac=prob.jacobian, bounds=(lo_f, hi_f), **opts)
        x = res.x
        q = prob.q.copy()
        q[free] = x
        prob.q = q
        q_out[f] = q
        pts_out[f] = prob.evaluate(x)[0]
        evals[f] = prob.count
        width = np.where(np.isfinite(hi - lo), hi - lo, 1.0)
        at_bound[f, free] = (x - lo <= tol.IK_AT_BOUND * width) | (hi - x <= tol.IK_AT_BOUND * width)
        if progress is not None:
            progress(1)
    error = np.linalg.norm(pts_out - targets, axis=2)
    return FitResult(q_out, pts_out, error, evals, at_bound)
