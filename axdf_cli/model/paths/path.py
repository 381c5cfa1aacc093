"""A muscle path (points + wrap surfaces) → the axis control points of every frame.

How a path whose shape changes (tangent points appear as wrapping engages, conditional
points come and go) becomes a fixed set of axis control points: the wrapped path (a
polyline, wrap arcs included) is sampled at K = 4 n fixed fractions of its current arc
length, and the n control points of the clamped quadratic B-spline are the least-squares
fit to those samples at parameters t = fraction, with the first and last control points
held at the origin and the insertion. The fit is one fixed linear map (n, K), computed
once per muscle, so evaluation is a matrix product per frame; n, the binding (t, u, v, w)
and the mesh topology never change. The samples move continuously with the path (arc
length fractions of a path that deforms continuously), so frames stay continuous as
wrapping engages and lets go: at the moment of contact the wrapped path equals the
straight one.
"""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model import bspline
from axdf_cli.errors import InputError
from axdf_cli.model.paths import wrap as W
from axdf_cli.model.paths.points import PathSpec, PointsModel, default_control_points
from axdf_cli.model.skeleton import bone_of, euler_xyz

#: Samples of the path per axis control point.
SAMPLES_PER_CONTROL_POINT = 4


def fit_matrix(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Fractions (K,) and the linear map M (n, K) from path samples at those fractions to
    the control points of the clamped quadratic B-spline (ends interpolated, interior by
    least squares)."""
    u = np.linspace(0.0, 1.0, k)
    b = bspline.basis_matrix(bspline.clamped_knots(n, 2), 2, u)  # (K, n)
    m = np.zeros((n, k))
    m[0, 0] = 1.0
    m[-1, -1] = 1.0
    # interior: min |B_int P_int - (S - b0 S0 - bn Sn)|
    pinv = np.linalg.pinv(b[:, 1:-1])  # (n-2, K)
    m[1:-1] = pinv
    m[1:-1, 0] -= pinv @ b[:, 0]
    m[1:-1, -1] -= pinv @ b[:, -1]
    return u, m


class PathModel:
    def __init__(self, spec: PathSpec, bone_index: dict[str, int], coord_index: dict[str, int] | None):

        self.spec = spec
        self.points = PointsModel(spec, bone_index, coord_index)
        self.n = spec.control_points or default_control_points(spec)
        self.fractions, self.fit = fit_matrix(self.n, SAMPLES_PER_CONTROL_POINT * self.n)
        nw = len(spec.wraps)
        npt = len(spec.points)
        self.wrap_bones = np.array([bone_of(bone_index, w.bone, w.mark) for w in spec.wraps], dtype=np.int64)
        self.wrap_local = np.zeros((nw, 4, 4))
        self.kind = np.zeros(nw, np.int64)
        self.prm = np.zeros((nw, 3))
        self.axis = np.zeros(nw, np.int64)
        self.sign = np.zeros(nw, np.int64)
        self.method = np.zeros(nw, np.int64)
        self.on = np.zeros(nw, np.bool_)
        self.rng = np.zeros((nw, 2), np.int64)
        self.has_side = np.zeros(nw, np.bool_)
        self.side_bones = np.zeros(nw, np.int64)
        self.side_at = np.zeros((nw, 4))
        self.side_at[:, 3] = 1.0
        for i, w in enumerate(spec.wraps):
            m = np.eye(4)
            m[:3, :3] = euler_xyz(np.asarray(w.orient, dtype=np.float64))
            m[:3, 3] = w.at
            self.wrap_local[i] = m
            self.kind[i] = W.SHAPES[w.shape]
            self.prm[i] = w.size
            self.axis[i], self.sign[i] = W.QUADRANTS[w.quadrant]
            self.method[i] = W.METHODS[w.method]
            self.on[i] = w.active
            lo, hi = w.range
            self.rng[i] = (0 if lo < 1 else lo - 1, npt - 1 if hi < 1 else hi - 1)
            if w.side is not None:
                self.has_side[i] = True
                self.side_bones[i] = bone_of(bone_index, w.side[0], w.mark)
                self.side_at[i, :3] = w.side[1]
        self.surfaces = W.Surfaces(self.kind, self.prm, self.axis, self.sign, self.method, self.on, self.rng,
                                   self.has_side)
        self.origin_bone = int(self.points.bones[0])
        self.insertion_bone = int(self.points.bones[-1])
        if spec.points[0].active is not None or spec.points[-1].active is not None:
            raise InputError(spec.points[0].mark, "the first or last path point is conditional",
                             "origin and insertion are always part of the path (fixed or moving points)")

    @property
    def uses_coordinates(self) -> bool:
        return self.points.uses_coordinates

    def wrap(self, world: np.ndarray, coords: np.ndarray | None) -> W.PathOut:
        """The wrapped path of every frame (:class:`~axdf_cli.model.paths.wrap.PathOut`): its
        samples (F, K, 3), length (F,), the could-not-wrap flags (F,) and its points, tangent
        points included (F, P + 2 W, 3), the first count (F,) of each frame's in use."""
        pts, active = self.points.evaluate(world, coords)
        nf = world.shape[0]
        xf = np.einsum("fwij,wjk->fwik", world[:, self.wrap_bones], self.wrap_local) if len(self.kind) else \
            np.zeros((nf, 0, 4, 4))
        # side[f,w,c] = sum_k world[f,bone(w),c,k] at[w,k]  (zeros where a surface has no side point)
        side = np.einsum("fwck,wk->fwc", world[:, self.side_bones, :3, :], self.side_at) if len(self.kind) else \
            np.zeros((nf, 0, 3))
        out = W.PathOut(np.empty((nf, len(self.fractions), 3)), np.empty(nf), np.zeros(nf, np.int64),
                        np.zeros((nf, pts.shape[1] + 2 * len(self.kind), 3)), np.zeros(nf, np.int64))
        W.wrapped_paths(np.ascontiguousarray(pts), np.ascontiguousarray(active), np.ascontiguousarray(xf),
                        np.ascontiguousarray(side), self.surfaces, self.fractions, out)
        return out

    def wrapped(self, world: np.ndarray, coords: np.ndarray | None):
        """Samples (F, K, 3) of the wrapped path, its length (F,), and per frame the index + 1
        of a surface the path could not wrap over (an end point inside it), 0 if none."""
        out = self.wrap(world, coords)
        return out.samples, out.length, out.inside

    def control_points(self, world: np.ndarray, coords: np.ndarray | None):
        """Axis control points (F, n, 3) and the could-not-wrap flags (F,)."""
        samples, _, inside = self.wrapped(world, coords)
        return np.einsum("nk,fkc->fnc", self.fit, samples), inside

    def shortfall(self, world: np.ndarray, coords: np.ndarray | None) -> np.ndarray:
        """How much shorter the axis is than the wrapped path, as a fraction of the path: (F,)
        ``1 − axis arc length / path length``. The axis is a smooth fit, so it cuts the path's
        corners (a via point where the path turns sharply within less than a knot span);
        more control points follow it closer."""
        samples, length, _ = self.wrapped(world, coords)
        ctrl = np.einsum("nk,fkc->fnc", self.fit, samples)
        knots = bspline.clamped_knots(self.n, 2)
        gt, gw = bspline.gauss_legendre_params(knots, 2, tol.LENGTH_GAUSS_POINTS)
        # d[f, g, c] = sum_n dB[g, n] ctrl[f, n, c]: the axis' derivative at the Gauss points
        d = np.einsum("gn,fnc->fgc", bspline.basis_matrix(knots, 2, gt, 1), ctrl)
        return 1.0 - (np.linalg.norm(d, axis=-1) @ gw) / np.maximum(length, 1e-300)
