"""Every muscle of a run at once: the models packed end to end for the compiled passes.

A :class:`MuscleBatch` holds what :class:`~axdf_cli.model.muscle.MuscleModel` prepared for
each muscle (basis rows, binding, belly weights, surface bases, rest values) as concatenated
arrays with offsets: muscle j's rows of a packed array ``X`` are ``X[X_off[j]:X_off[j + 1]]``.
Muscles differ in axis control points (n), RMF samples (S), bound points (Q = 8 sections),
Gauss points (G) and resolution (U x A), so each kind of row has its own offsets.

A chunk of F frames of K muscles is then two steps, as the run's stages need them
(:mod:`axdf_cli.pipeline.stages`):

1a. :meth:`MuscleBatch.axis_points`: the axis control points of every muscle, packed
    (F, ΣN, 3) (fixed points compiled in one call; paths through :mod:`axdf_cli.model.paths`);
1b. :meth:`MuscleBatch.surfaces`: from those points (as a TIME stage left them), the RMF, the
    bound points' frames, twist, tension, exact volume, surface and normals of every muscle
    in two compiled calls (:func:`axdf_cli.model.batch_kernels.frames_pass`,
    :func:`axdf_cli.model.batch_surface.shape_pass`), with the roll's arctan2 and branch in
    numpy between them.

The results are the fields of a :class:`~axdf_cli.model.muscle.FrameResult` per muscle, the
vertices and normals views of one buffer (each muscle's block (F, V_j, 3) contiguous). The arithmetic is
:meth:`MuscleModel.surface`'s, operation for operation (``tests/test_batch.py`` holds the two
to the same bytes, or to the stated bound where a numpy kernel's order is not followed).
"""
from __future__ import annotations

import sys

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model import batch_kernels as K
from axdf_cli.model import batch_surface as S
from axdf_cli.model.batch_kernels import LANES  # noqa: F401 (frames per vector: chunk sizes are multiples)
from axdf_cli.model.paths.wrap import Surfaces
from axdf_cli.model.rmf import STEP_RTOL

_RTOL2 = STEP_RTOL ** 2  # (as rmf computes it)
_TWO_PI = 2.0 * np.pi
POOL = 6  # buffers a batch keeps for reuse: the scratch, a chunk's vertices and normals, the previous chunk's (a consumer may still hold its last result) and a spare


class _Pool:
    """Float64 buffers handed out again once nothing refers to them any more (no result of an
    earlier call alive): a chunk's vertices and normals land in memory that is already
    mapped and in the caches, instead of fresh pages the kernel must first fault in and zero."""

    def __init__(self, keep: int = POOL):
        self.keep = keep
        self.free = True  # False: always fresh memory (what the bench compares against)
        self.buffers: list = []

    def take(self, n: int) -> np.ndarray:
        """A flat float64 array of n elements (its contents undefined)."""
        if self.free:
            for b in self.buffers:
                # only this list, the loop variable and getrefcount's argument refer to it
                if len(b) >= n and sys.getrefcount(b) == 3:
                    return b[:n]
        b = np.empty(max(n, 1))
        if self.free:
            self.buffers = (self.buffers + [b])[-self.keep:]
        return b[:n]


def _offsets(sizes) -> np.ndarray:
    return np.concatenate([[0], np.cumsum(np.asarray(list(sizes), dtype=np.int64))]).astype(np.int64)


def _rows(blocks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sparse basis rows (idx (R, 3), w (R, 3)) of every muscle end to end: offsets, idx, w."""
    off = _offsets(len(i) for i, _ in blocks)
    idx = np.ascontiguousarray(np.concatenate([i for i, _ in blocks]), dtype=np.int64)
    w = np.ascontiguousarray(np.concatenate([w for _, w in blocks]), dtype=np.float64)
    return off, idx, w


class MuscleBatch:
    """Muscle models packed for the compiled passes (module doc). Holds arrays only (no
    models), so it pickles small; build it once per run (:func:`axdf_cli.pipeline.evaluate.batch_of`)."""

    def __init__(self, models):
        models = list(models)
        self.n = len(models)
        self.a_off = _offsets(m.n_axis for m in models)
        self.paths = [j for j, m in enumerate(models) if m.path is not None]
        self.fixed = np.array([j for j, m in enumerate(models) if m.path is None], dtype=np.int64)
        nn = int(self.a_off[-1])
        self.bones = np.zeros(nn, dtype=np.int64)
        self.at = np.zeros((nn, 3))
        for j in self.fixed:
            m = models[j]
            self.bones[self.a_off[j]:self.a_off[j + 1]] = m.bones
            self.at[self.a_off[j]:self.a_off[j + 1]] = m.at
        sp = [m.sparse for m in models]
        self.s_off, self.bs_idx, self.bs_w = _rows([s["Bs"] for s in sp])
        _, self.dbs_idx, self.dbs_w = _rows([s["dBs"] for s in sp])
        self.c_off, self.bc_idx, self.bc_w = _rows([s["Bc"] for s in sp])
        _, self.dbc_idx, self.dbc_w = _rows([s["dBc"] for s in sp])
        self.q_off, self.bb_idx, self.bb_w = _rows([s["Bb"] for s in sp])
        _, self.dbb_idx, self.dbb_w = _rows([s["dBb"] for s in sp])
        self.g_off, self.dbg_idx, self.dbg_w = _rows([s["dBg"] for s in sp])
        self.gw = np.concatenate([m.gw for m in models]).astype(np.float64)
        self.bind_j = np.concatenate([m.bind_j for m in models]).astype(np.int64)
        self.lam = np.concatenate([m.lam for m in models]).astype(np.float64)
        self.uvw = np.ascontiguousarray(np.concatenate([m.uvw for m in models]), dtype=np.float64)
        self.beta = np.concatenate([m.beta for m in models]).astype(np.float64)
        self.bump = np.concatenate([m.bump for m in models]).astype(np.float64)
        self.origin = np.array([m.origin_bone for m in models], dtype=np.int64)
        self.insertion = np.array([m.insertion_bone for m in models], dtype=np.int64)
        self.r0_local = np.array([m.r0_local for m in models], dtype=np.float64).reshape(-1, 3)
        self.rend_local = np.array([m.rend_local for m in models], dtype=np.float64).reshape(-1, 3)
        self.l0 = np.array([m.l0 for m in models], dtype=np.float64)
        self.v0 = np.array([getattr(m, "v0", np.nan) for m in models], dtype=np.float64)
        self.solve = np.array([m.volume_mode.value == "exact" for m in models], dtype=np.bool_)  # (VolumeMode)
        self.keep = np.array([m.volume_mode.value == "none" for m in models], dtype=np.bool_)
        self.m_off = _offsets(len(m.spec.sections) + 2 for m in models)
        self.u_off, self.u_idx, self.u_w = _rows([(m.u_idx, m.u_w) for m in models])
        self.v_off, self.v_idx, self.v_w = _rows([(m.v_idx, m.v_w) for m in models])
        self.n_vertices = np.array([m.n_vertices for m in models], dtype=np.int64)
        # the same arrays, grouped as the compiled passes take them
        self.samples = K.Basis(self.s_off, self.bs_idx, self.bs_w, self.dbs_idx, self.dbs_w)
        self.coarse = K.Basis(self.c_off, self.bc_idx, self.bc_w, self.dbc_idx, self.dbc_w)
        self.bound = K.Basis(self.q_off, self.bb_idx, self.bb_w, self.dbb_idx, self.dbb_w)
        self.gauss = K.Quadrature(self.g_off, self.dbg_idx, self.dbg_w, self.gw)
        self.anchors = K.Anchors(self.origin, self.insertion, self.r0_local, self.rend_local)
        self.binding = S.Binding(self.q_off, self.lam, self.uvw, self.beta, self.bump)
        self.bases = S.SurfaceBases(self.m_off, self.u_off, self.u_idx, self.u_w, self.v_off, self.v_idx, self.v_w)
        self._pack_paths(models)
        self.pool = _Pool()

    def _pack_paths(self, models) -> None:
        """The paths' points, wrap surfaces, sample fractions and fits, end to end (muscles
        without a path have none); the moving and conditional points, evaluated per chunk."""
        paths = [m.path if m.path is not None else None for m in models]
        self.p_off = _offsets(0 if pm is None else len(pm.points.bones) for pm in paths)
        self.w_off = _offsets(0 if pm is None else len(pm.kind) for pm in paths)
        self.k_off = _offsets(0 if pm is None else len(pm.fractions) for pm in paths)
        self.fit_off = _offsets(0 if pm is None else pm.fit.size for pm in paths)
        have = [pm for pm in paths if pm is not None]

        def cat(get, shape, dtype):
            parts = [np.asarray(get(pm), dtype=dtype).reshape((-1,) + shape) for pm in have]
            return np.ascontiguousarray(np.concatenate(parts) if parts else np.zeros((0,) + shape, dtype))

        self.pbones = cat(lambda pm: pm.points.bones, (), np.int64)
        self.pat = cat(lambda pm: pm.points.at, (3,), np.float64)
        self.wbones = cat(lambda pm: pm.wrap_bones, (), np.int64)
        self.wlocal = cat(lambda pm: pm.wrap_local, (4, 4), np.float64)
        self.kind = cat(lambda pm: pm.kind, (), np.int64)
        self.prm = cat(lambda pm: pm.prm, (3,), np.float64)
        self.wrap_axis = cat(lambda pm: pm.axis, (), np.int64)
        self.wrap_sign = cat(lambda pm: pm.sign, (), np.int64)
        self.method = cat(lambda pm: pm.method, (), np.int64)
        self.on = cat(lambda pm: pm.on, (), np.bool_)
        self.rng = cat(lambda pm: pm.rng, (2,), np.int64)
        self.side_bones = cat(lambda pm: pm.side_bones, (), np.int64)
        self.side_at = cat(lambda pm: pm.side_at, (4,), np.float64)
        self.has_side = cat(lambda pm: pm.has_side, (), np.bool_)
        self.fractions = cat(lambda pm: pm.fractions, (), np.float64)
        self.fit = cat(lambda pm: pm.fit, (), np.float64)
        self.wrap_names = [[] if pm is None else [w.name for w in pm.spec.wraps] for pm in paths]
        self.wraps = K.Wraps(self.w_off, self.wbones, self.wlocal, self.side_bones, self.side_at)
        self.surfaces_of_paths = Surfaces(self.kind, self.prm, self.wrap_axis, self.wrap_sign, self.method, self.on,
                                          self.rng, self.has_side)
        self.fits = K.Fits(self.k_off, self.fractions, self.fit_off, self.fit)
        # per chunk: (muscle, packed point row, axis, coordinate, function) and (muscle, row, coordinate, lo, hi)
        self.moving = [(j, int(self.p_off[j]) + k, a, c, fn) for j, pm in enumerate(paths) if pm is not None
                       for k, a, c, fn in pm.points.moving]
        self.conditional = [(j, int(self.p_off[j]) + k, c, lo, hi) for j, pm in enumerate(paths) if pm is not None
                            for k, c, lo, hi in pm.points.conditional]

    # -- step 1a ------------------------------------------------------------------------
    def axis_points(self, world: np.ndarray, coords: np.ndarray | None, muscles) -> tuple[np.ndarray, dict]:
        """The axis control points of ``muscles`` (indices) for frames world (F, B, 4, 4) (and
        coordinates (F, C), which paths with moving or conditional points need): packed
        (F, ΣN, 3) (the other muscles' rows undefined) and {muscle: [(frame index, warning)]}
        (a path that could not wrap over a surface)."""
        muscles = list(muscles)
        nf = world.shape[0]
        world = np.ascontiguousarray(world, dtype=np.float64)
        p = np.empty((nf, int(self.a_off[-1]), 3))
        chosen = np.zeros(self.n, dtype=np.bool_)
        chosen[muscles] = True
        K.axis_fixed(self.fixed[chosen[self.fixed]], world, self.bones, self.at, self.a_off, p)
        notes = {j: [] for j in muscles}
        js = np.array([j for j in self.paths if chosen[j]], dtype=np.int64)
        if len(js):
            loc = np.empty((nf, len(self.pbones), 3))
            loc[:] = self.pat
            active = np.ones((nf, len(self.pbones)), dtype=np.bool_)
            if (self.moving or self.conditional) and coords is None:
                raise ValueError("these paths need the skeleton's coordinates per frame")
            for j, row, a, c, fn in self.moving:
                if chosen[j]:
                    loc[:, row, a] = fn(coords[:, c])
            for j, row, c, lo, hi in self.conditional:
                if chosen[j]:
                    active[:, row] = (coords[:, c] >= lo) & (coords[:, c] <= hi)
            inside = np.zeros((self.n, nf), dtype=np.int64)
            K.axis_paths(js, world, K.PathPoints(self.p_off, self.pbones, loc, active), self.wraps,
                         self.surfaces_of_paths, self.fits, self.a_off, p, inside)
            for j in js[inside[js].any(axis=1)]:
                names = self.wrap_names[j]
                notes[int(j)] = [(int(i), f"path cannot wrap over {names[int(inside[j, i]) - 1]!r}: an end point "
                                          "lies inside it; kept the straight segment")
                                 for i in np.nonzero(inside[j])[0]]
        return p, notes

    def pack(self, axis: dict, nf: int) -> np.ndarray:
        """{muscle: (F, n_j, 3)} axis control points → packed (F, ΣN, 3) (the rest undefined)."""
        p = np.empty((nf, int(self.a_off[-1]), 3))
        for j, a in axis.items():
            p[:, self.a_off[j]:self.a_off[j + 1]] = a
        return p

    def unpack(self, p: np.ndarray, muscles) -> dict:
        """Packed (F, ΣN, 3) → {muscle: (F, n_j, 3) view}."""
        return {j: p[:, self.a_off[j]:self.a_off[j + 1]] for j in muscles}

    # -- the roll alone (twist references) ------------------------------------------------
    def coarse_roll(self, world: np.ndarray, p: np.ndarray, muscles) -> np.ndarray:
        """The insertion roll (radians, wrapped to (-pi, pi]) of ``muscles`` on the coarse
        samples (:meth:`MuscleModel.end_twist`), from packed axis points p: (F, K)."""
        js = np.asarray(list(muscles), dtype=np.int64)
        roll = np.zeros((self.n, world.shape[0], 2))
        K.roll_pass(js, p, np.ascontiguousarray(world), self.a_off, self.coarse, self.anchors, _RTOL2, roll)
        return np.arctan2(roll[js, :, 0], roll[js, :, 1]).T

    # -- step 1b ------------------------------------------------------------------------
    def surfaces(self, world: np.ndarray, p: np.ndarray, tension: np.ndarray, twist_reference: np.ndarray | None,
                 muscles, rest_volume: float | None | str = "model", notes: dict | None = None,
                 control_points: np.ndarray | None = None) -> dict:
        """Step 1b of ``muscles`` (indices, K) for F frames: world (F, B, 4, 4); p (F, ΣN, 3)
        packed axis control points; tension (F, K) effective tension of each; twist_reference
        (F, K) unwrapped coarse roll choosing the exact roll's branch, or None (unwrapped within
        the block); rest_volume: the volume ``exact`` keeps ("model": each model's own, None: no
        target, a number: that one); notes: {muscle: step 1a's [(frame index, warning)]};
        control_points: (F, ΣQ, 3) to receive the bound section control points as tessellated
        (fixed + s scaled), or None. Returns {muscle: the fields of its
        :class:`~axdf_cli.model.muscle.FrameResult`} (this room holds arrays only). The vertices
        and normals are views of buffers the batch hands out again once no result of an
        earlier call refers to them (:class:`_Pool`)."""

        js = np.asarray(list(muscles), dtype=np.int64)
        nf, nk, nq = world.shape[0], len(js), int(self.q_off[-1])
        world = np.ascontiguousarray(world, dtype=np.float64)
        p = np.ascontiguousarray(p, dtype=np.float64)
        fr = self.pool.take(3 * nq * 3 * nf).reshape(3, nq, 3, nf)  # frames last (innermost in the passes)
        ends = np.zeros((self.n, nf, 2, 3))
        roll = np.zeros((self.n, nf, 2))
        length = np.zeros((self.n, nf))
        frames = K.FrameOut(fr, ends, roll, length)
        K.frames_pass(js, p, world, self.a_off, self.samples, self.bound, self.bind_j, self.gauss, self.anchors,
                      _RTOL2, frames)
        # the roll on its branch (numpy's arctan2, as MuscleModel._roll)
        theta = np.arctan2(roll[js, :, 0], roll[js, :, 1])  # (K, F)
        if twist_reference is None:
            theta = np.unwrap(theta, axis=1)
        else:
            ref = np.asarray(twist_reference, dtype=np.float64).T
            theta = theta + 2.0 * np.pi * np.round((ref - theta) / _TWO_PI)
        length = length[js]
        e = np.clip(np.asarray(tension, dtype=np.float64).T.reshape(nk, nf), 0.0, 1.0)
        ratio = self.l0[js, None] / np.maximum(length, tol.MIN_AXIS_LENGTH)
        s0 = np.where(self.keep[js, None], 1.0, np.sqrt(ratio))
        full = np.zeros((3, self.n, nf))
        full[0, js], full[1, js], full[2, js] = theta, e, s0
        solve, v0 = self.solve, self.v0
        if not isinstance(rest_volume, str):
            solve = solve & (rest_volume is not None)
            v0 = np.full(self.n, float(rest_volume or 0.0))
        vert_off = _offsets(self.n_vertices[js])
        out_v = self.pool.take(3 * nf * int(vert_off[-1]))
        out_n = self.pool.take(3 * nf * int(vert_off[-1]))
        vol = np.zeros((self.n, nf))
        scale = np.zeros((self.n, nf))
        bad = np.zeros((self.n, nf), dtype=np.bool_)
        S.shape_pass(js, p, self.a_off, frames, S.Drive(full[0], full[1], full[2], solve, v0), self.binding,
                     self.bases, S.ShapeParams(tol.TENSION_GAIN, tol.SCALE_MIN, tol.SCALE_MAX,
                                               tol.VOLUME_SOLVE_ITERS, tol.VOLUME_SOLVE_RTOL),
                     S.ShapeOut(vert_off, out_v, out_n, vol, scale, bad,
                                np.zeros((0, 0, 3)) if control_points is None else control_points))
        twist = np.degrees(theta)
        vol, scale, bad = vol[js], scale[js], bad[js]
        clipped = np.clip(scale, tol.SCALE_MIN, tol.SCALE_MAX)
        short = length < tol.MIN_AXIS_LENGTH
        out_of = (scale < tol.SCALE_MIN) | (scale > tol.SCALE_MAX)
        flagged = bad.any(axis=1) | short.any(axis=1) | out_of.any(axis=1)
        notes = notes or {}
        results = {}
        for k, j in enumerate(js):
            j = int(j)
            a, b = 3 * nf * vert_off[k], 3 * nf * vert_off[k + 1]
            nv = int(self.n_vertices[j])
            warnings = list(notes.get(j, ()))
            if flagged[k]:
                for i in np.nonzero(bad[k])[0]:
                    warnings.append((int(i), "exact volume has no solution; used the paper's scale"))
                for i in np.nonzero(short[k])[0]:
                    warnings.append((int(i), f"axis length {length[k, i]:.3g} m is degenerate"))
                for i in np.nonzero(out_of[k])[0]:
                    warnings.append((int(i), f"section scale {scale[k, i]:.3g} clamped to "
                                             f"[{tol.SCALE_MIN}, {tol.SCALE_MAX}]"))
            results[j] = dict(vertices=out_v[a:b].reshape(nf, nv, 3), normals=out_n[a:b].reshape(nf, nv, 3),
                              length=length[k], volume=vol[k], scale=clipped[k], twist=twist[k], tension=e[k],
                              warnings=warnings)
        return results
