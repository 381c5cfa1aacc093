"""The compiled passes of :mod:`axdf_cli.model.batch`: every muscle of a chunk of frames at once.

Three calls per chunk, over muscles packed end to end (concatenated arrays with offsets, batch
dimension first; the offsets ``*_off`` (M + 1,) say where muscle j's rows start and end):

1. :func:`axis_fixed`, :func:`axis_paths`: the axis control points of the muscles fixed in
   bones, and of the muscles with a path (its points placed, wrapped over its surfaces by
   :func:`axdf_cli.model.paths.wrap.wrapped_paths`, sampled and fitted as
   :class:`~axdf_cli.model.paths.path.PathModel` does);
2. :func:`frames_pass`: per muscle and frame, the axis samples and unit tangents, the
   rotation-minimizing frame by double reflection (Wang, Jüttler, Zheng, Liu: "Computation
   of rotation minimizing frames", ACM TOG 27(1), 2008, Algorithm 1), the bound points'
   positions, tangents and untwisted reference vectors (one more reflection from the nearest
   sample), the insertion roll's two arguments (arctan2's y and x) and the speeds at the
   Gauss-Legendre points of the arc length;
3. :func:`shape_pass`: the spread twist, the tension law, the volume-scaled and fixed parts of
   the bound control points, then the surface of :func:`axdf_cli.model.kernels.surface_frame`
   (tessellation, the exact volume solve, vertices and normals).

Between 2 and 3 the caller takes arctan2 (the roll), its branch and the arc length's
quadrature sum in numpy, as :class:`axdf_cli.model.muscle.MuscleModel` always did.

Same bytes as the numpy formulation (``tests/reference_model.py``): every quantity is formed
by the same floating-point operations in the same order as numpy forms it (an ``einsum`` dot
of 3-vectors is ``0 + ((a0 b0 + a2 b2) + a1 b1)``, a sum over an axis or a norm starts at 0
and adds in order, a sparse basis row adds its three terms in order, a bone's rotation of a
vector by ``@`` is OpenBLAS's fused ``fma(m2, v2, fma(m0, v0, m1 v1))``), no ``fastmath``.
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from axdf_cli.model.kernels import surface_frame
from axdf_cli.model.paths import wrap as W

_EPS = 1e-30  # as axdf_cli.model.rmf._EPS
_TINY = 1e-300  # the unit tangent's floor (as MuscleModel's _unit)


@intrinsic
def _fma(typingctx, a, b, c):
    """a * b + c rounded once (LLVM's ``llvm.fma``: the FMA instruction, or libm's exact fma)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, inline="always")
def _matvec_row(m0, m1, m2, v0, v1, v2):
    """Row (m0, m1, m2) of numpy's ``@`` of a 3x3 matrix and a 3-vector, as its BLAS kernel
    (OpenBLAS dgemv on x86-64) rounds it: fma(m2, v2, fma(m0, v0, m1 v1))."""
    return _fma(m2, v2, _fma(m0, v0, m1 * v1))


@njit(cache=True, inline="always")
def _dot(a0, a1, a2, b0, b1, b2):
    """numpy's ``einsum('...c,...c->...')`` of 3-vectors, operation for operation."""
    return 0.0 + ((a0 * b0 + a2 * b2) + a1 * b1)


@njit(cache=True, inline="always")
def _sumsq(a0, a1, a2):
    """The sum under ``np.linalg.norm(axis=-1)`` (an add.reduce from 0, in order)."""
    return ((0.0 + a0 * a0) + a1 * a1) + a2 * a2


@njit(cache=True, inline="always")
def _floor(x, lo):
    """``np.maximum(x, lo)``: NaN stays NaN."""
    return x if (x >= lo or x != x) else lo


@njit(cache=True)
def axis_fixed(js, world, bones, at, a_off, out):
    """Axis control points of muscles fixed in bones: out[f, i] = M[f, bone_i, :3, :3] at_i +
    M[f, bone_i, :3, 3] for the rows i of muscles ``js`` (numpy's ``einsum('fick,ik->fic')``
    then ``+``). world (F, B, 4, 4); bones (ΣN,) int64; at (ΣN, 3); out (F, ΣN, 3)."""
    nf = world.shape[0]
    for k in range(js.shape[0]):
        j = js[k]
        for i in range(a_off[j], a_off[j + 1]):
            b = bones[i]
            for f in range(nf):
                for c in range(3):
                    m = world[f, b]
                    out[f, i, c] = (0.0 + ((m[c, 0] * at[i, 0] + m[c, 2] * at[i, 2]) + m[c, 1] * at[i, 1])) + m[c, 3]


@njit(cache=True)
def axis_paths(js, world, pbones, loc, active, p_off, wbones, wlocal, w_off, kind, prm, wrap_axis, wrap_sign,
               method, on, rng, fractions, k_off, fit, fit_off, a_off, out, out_inside):
    """Axis control points of path muscles ``js``, as :meth:`PathModel.control_points`:

    world        : (F, B, 4, 4)
    pbones, loc  : (ΣP,) path points' bones, (F, ΣP, 3) their locations in them (moving
                   points already evaluated); active (F, ΣP) bool (conditional points)
    wbones, wlocal : (ΣW,), (ΣW, 4, 4) wrap surfaces' bones and transforms in them; kind,
                   prm (ΣW, 3), wrap_axis, wrap_sign, method, on, rng (ΣW, 2): as PathModel's
    fractions    : (ΣK,) arc fractions of the path samples; fit (flat) the (n_j, K_j) least
                   squares map from samples to control points, row-major from fit_off[j]
    outputs      : out (F, ΣN, 3) rows a_off[j] ..; out_inside (M, F) the index + 1 of a
                   surface the path could not wrap over (an end point inside it), 0 if none

    Points: ``einsum('fpck,fpk->fpc', R, loc) + t`` (``0 + ((r0 l0 + r2 l2) + r1 l1)``), the
    surfaces' transforms ``einsum('fwij,wjk->fwik')`` (in order from 0), the fit in order.
    """
    nf = world.shape[0]
    for kk in range(js.shape[0]):
        j = js[kk]
        p0, p1 = p_off[j], p_off[j + 1]
        w0, w1 = w_off[j], w_off[j + 1]
        k0, k1 = k_off[j], k_off[j + 1]
        npt, nw, nk = p1 - p0, w1 - w0, k1 - k0
        pts = np.empty((nf, npt, 3))
        act = np.empty((nf, npt), dtype=np.bool_)
        xf = np.zeros((nf, nw, 4, 4))
        for f in range(nf):
            for i in range(npt):
                m = world[f, pbones[p0 + i]]
                l0 = loc[f, p0 + i, 0]
                l1 = loc[f, p0 + i, 1]
                l2 = loc[f, p0 + i, 2]
                for c in range(3):
                    pts[f, i, c] = (0.0 + ((m[c, 0] * l0 + m[c, 2] * l2) + m[c, 1] * l1)) + m[c, 3]
                act[f, i] = active[f, p0 + i]
            for w in range(nw):
                m = world[f, wbones[w0 + w]]
                b = wlocal[w0 + w]
                for r in range(4):
                    for c in range(4):
                        acc = 0.0
                        for q in range(4):
                            acc += m[r, q] * b[q, c]
                        xf[f, w, r, c] = 0.0 + acc
        samples = np.empty((nf, nk, 3))
        length = np.empty(nf)
        inside = np.zeros(nf, dtype=np.int64)
        points = np.zeros((nf, npt + 2 * nw, 3))
        count = np.zeros(nf, dtype=np.int64)
        W.wrapped_paths(pts, act, xf, kind[w0:w1], prm[w0:w1], wrap_axis[w0:w1], wrap_sign[w0:w1], method[w0:w1],
                        on[w0:w1], rng[w0:w1], fractions[k0:k1], samples, length, inside, points, count)
        n = a_off[j + 1] - a_off[j]
        for f in range(nf):
            out_inside[j, f] = inside[f]
            for i in range(n):
                row = fit_off[j] + i * nk
                for c in range(3):
                    acc = 0.0
                    for k in range(nk):
                        acc += fit[row + k] * samples[f, k, c]
                    out[f, a_off[j] + i, c] = acc


@njit(cache=True)
def _samples(p, a0, idx, w, didx, dw, s0, ns, xs, ts):
    """Axis samples xs (ns, 3) and unit tangents ts from control points p[a0 + i] (sparse
    basis rows idx, w and didx, dw from row s0): numpy's sparse ``einsum('sk,fskc->fsc')``, then
    ``d / np.maximum(np.linalg.norm(d), 1e-300)``."""
    for s in range(ns):
        r = s0 + s
        d0 = 0.0
        d1 = 0.0
        d2 = 0.0
        for c in range(3):
            x = 0.0
            d = 0.0
            for k in range(3):
                x += w[r, k] * p[a0 + idx[r, k], c]
                d += dw[r, k] * p[a0 + didx[r, k], c]
            xs[s, c] = x
            if c == 0:
                d0 = d
            elif c == 1:
                d1 = d
            else:
                d2 = d
        n = _floor(math.sqrt(_sumsq(d0, d1, d2)), _TINY)
        ts[s, 0] = d0 / n
        ts[s, 1] = d1 / n
        ts[s, 2] = d2 / n


@njit(cache=True)
def _start_vector(rot, local, t0, t1, t2, out):
    """:func:`axdf_cli.model.rmf.perpendicular_unit` of ``rot @ local`` against the unit t:
    out (3,)."""
    v0 = _matvec_row(rot[0, 0], rot[0, 1], rot[0, 2], local[0], local[1], local[2])
    v1 = _matvec_row(rot[1, 0], rot[1, 1], rot[1, 2], local[0], local[1], local[2])
    v2 = _matvec_row(rot[2, 0], rot[2, 1], rot[2, 2], local[0], local[1], local[2])
    d = _dot(v0, v1, v2, t0, t1, t2)
    p0 = v0 - d * t0
    p1 = v1 - d * t1
    p2 = v2 - d * t2
    n = _floor(math.sqrt(_sumsq(p0, p1, p2)), _EPS)
    out[0] = p0 / n
    out[1] = p1 / n
    out[2] = p2 / n


@njit(cache=True)
def _propagate(xs, ts, ns, r0, rs, rtol2):
    """The double-reflection recurrence of :func:`axdf_cli.model.rmf.propagate` over samples
    xs, ts (ns, 3) from r0 (3,): the unnormalised reference vectors rs (ns, 3) (the caller
    makes the ones it needs unit and orthogonal to t, as propagate does for all)."""
    c0 = r0[0]
    c1 = r0[1]
    c2 = r0[2]
    rs[0, 0] = c0
    rs[0, 1] = c1
    rs[0, 2] = c2
    for i in range(ns - 1):
        x00 = xs[i, 0]
        x01 = xs[i, 1]
        x02 = xs[i, 2]
        x10 = xs[i + 1, 0]
        x11 = xs[i + 1, 1]
        x12 = xs[i + 1, 2]
        v0 = x10 - x00
        v1 = x11 - x01
        v2 = x12 - x02
        cc1 = _dot(v0, v1, v2, v0, v1, v2)
        sa = _dot(x10, x11, x12, x10, x11, x12)
        sb = _dot(x00, x01, x02, x00, x01, x02)
        k1 = 0.0
        if cc1 > _EPS and cc1 > rtol2 * sa and cc1 > rtol2 * sb:
            k1 = 2.0 / cc1
        tt0 = ts[i, 0]
        tt1 = ts[i, 1]
        tt2 = ts[i, 2]
        kd = k1 * _dot(v0, v1, v2, tt0, tt1, tt2)
        l0 = tt0 - kd * v0
        l1 = tt1 - kd * v1
        l2 = tt2 - kd * v2
        u0 = ts[i + 1, 0] - l0
        u1 = ts[i + 1, 1] - l1
        u2 = ts[i + 1, 2] - l2
        cc2 = _dot(u0, u1, u2, u0, u1, u2)
        k2 = 2.0 / cc2 if cc2 > rtol2 else 0.0
        # cur - (v1 . cur) a1 with a1 = k1 v1, then likewise with v2 (sums in order, from 0)
        a0 = k1 * v0
        a1 = k1 * v1
        a2 = k1 * v2
        s = ((0.0 + v0 * c0) + v1 * c1) + v2 * c2
        c0 = c0 - s * a0
        c1 = c1 - s * a1
        c2 = c2 - s * a2
        a0 = k2 * u0
        a1 = k2 * u1
        a2 = k2 * u2
        s = ((0.0 + u0 * c0) + u1 * c1) + u2 * c2
        c0 = c0 - s * a0
        c1 = c1 - s * a1
        c2 = c2 - s * a2
        rs[i + 1, 0] = c0
        rs[i + 1, 1] = c1
        rs[i + 1, 2] = c2


@njit(cache=True)
def _finish(r0, r1, r2, t0, t1, t2, out):
    """propagate's last step for one sample: r - (r . t) t, made unit: out (3,)."""
    d = _dot(r0, r1, r2, t0, t1, t2)
    p0 = r0 - d * t0
    p1 = r1 - d * t1
    p2 = r2 - d * t2
    n = _floor(math.sqrt(_sumsq(p0, p1, p2)), _EPS)
    out[0] = p0 / n
    out[1] = p1 / n
    out[2] = p2 / n


@njit(cache=True)
def _roll_args(rot, local, r_end, t_end, tgt, out):
    """The insertion roll's arctan2 arguments (y, x) (:meth:`MuscleModel._roll`): the angle from
    the propagated r_end to the insertion bone's reference ``rot @ local`` made ⟂ t_end
    (into tgt (3,), scratch)."""
    _start_vector(rot, local, t_end[0], t_end[1], t_end[2], tgt)
    a0, a1, a2 = r_end[0], r_end[1], r_end[2]
    c0 = a1 * tgt[2] - a2 * tgt[1]
    c1 = a2 * tgt[0] - a0 * tgt[2]
    c2 = a0 * tgt[1] - a1 * tgt[0]
    out[0] = _dot(c0, c1, c2, t_end[0], t_end[1], t_end[2])
    out[1] = _dot(a0, a1, a2, tgt[0], tgt[1], tgt[2])


@njit(cache=True)
def frames_pass(js, p, world, a_off, s_off, bs_idx, bs_w, dbs_idx, dbs_w, q_off, bb_idx, bb_w, dbb_idx, dbb_w,
                bind_j, g_off, dbg_idx, dbg_w, gw, origin, insertion, r0_local, rend_local, rtol2,
                out_c, out_t, out_r, out_ends, out_roll, out_length):
    """Step 2 of the module doc for the muscles ``js`` (K,) and every frame f of the chunk:

    p          : (F, ΣN, 3)  axis control points (muscle j: rows a_off[j] .. a_off[j+1])
    world      : (F, B, 4, 4) bone transforms (the origin bone's start vector, the insertion roll)
    bs_*, dbs_*: (ΣS, 3)     sparse basis rows of the RMF samples and their derivative (local
                             control point indices)
    bb_*, dbb_*: (ΣQ, 3)     the same at the bound points' parameters; bind_j (ΣQ,) the sample
                             each bound point's frame is reflected from
    dbg_*, gw  : (ΣG, 3), (ΣG,) the derivative at the arc length's Gauss-Legendre points and
                             their weights
    origin, insertion : (M,) bones; r0_local, rend_local (M, 3) the start vector in the
                             origin bone and the insertion's rest reference in its bone
    outputs    : out_c, out_t, out_r (F, ΣQ, 3) bound points' position, unit tangent and
                 untwisted unit reference vector; out_ends (M, F, 2, 3) the unit tangents at
                 t = 0 and 1; out_roll (M, F, 2) arctan2's (y, x) of the insertion roll;
                 out_length (M, F) the arc length sum_g gw_g |C'(t_g)|, added in order (numpy's
                 ``@`` here is OpenBLAS's dot, whose order follows the data's alignment: this
                 sum may differ from it in the last bit)
    """
    nf = p.shape[0]
    smax = 1
    for k in range(js.shape[0]):
        j = js[k]
        smax = max(smax, s_off[j + 1] - s_off[j])
    xs = np.empty((smax, 3))
    ts = np.empty((smax, 3))
    rs = np.empty((smax, 3))
    r0 = np.empty(3)
    rj = np.empty(3)
    for k in range(js.shape[0]):
        j = js[k]
        a0 = a_off[j]
        ns = s_off[j + 1] - s_off[j]
        ng = g_off[j + 1] - g_off[j]
        for f in range(nf):
            pf = p[f]
            _samples(pf, a0, bs_idx, bs_w, dbs_idx, dbs_w, s_off[j], ns, xs, ts)
            _start_vector(world[f, origin[j]], r0_local[j], ts[0, 0], ts[0, 1], ts[0, 2], r0)
            _propagate(xs, ts, ns, r0, rs, rtol2)
            for c in range(3):
                out_ends[j, f, 0, c] = ts[0, c]
                out_ends[j, f, 1, c] = ts[ns - 1, c]
            _finish(rs[ns - 1, 0], rs[ns - 1, 1], rs[ns - 1, 2], ts[ns - 1, 0], ts[ns - 1, 1], ts[ns - 1, 2], rj)
            _roll_args(world[f, insertion[j]], rend_local[j], rj, ts[ns - 1], r0, out_roll[j, f])
            for q in range(q_off[j], q_off[j + 1]):
                # the bound point: C(t) and its unit tangent (sparse rows, as _samples)
                x10 = 0.0
                x11 = 0.0
                x12 = 0.0
                d0 = 0.0
                d1 = 0.0
                d2 = 0.0
                for kk in range(3):
                    wv = bb_w[q, kk]
                    i = a0 + bb_idx[q, kk]
                    x10 += wv * pf[i, 0]
                    x11 += wv * pf[i, 1]
                    x12 += wv * pf[i, 2]
                for kk in range(3):
                    wv = dbb_w[q, kk]
                    i = a0 + dbb_idx[q, kk]
                    d0 += wv * pf[i, 0]
                    d1 += wv * pf[i, 1]
                    d2 += wv * pf[i, 2]
                n = _floor(math.sqrt(_sumsq(d0, d1, d2)), _TINY)
                t10 = d0 / n
                t11 = d1 / n
                t12 = d2 / n
                # one double-reflection step from sample s (rmf.reflect_step)
                s = bind_j[q]
                _finish(rs[s, 0], rs[s, 1], rs[s, 2], ts[s, 0], ts[s, 1], ts[s, 2], rj)
                x00 = xs[s, 0]
                x01 = xs[s, 1]
                x02 = xs[s, 2]
                v0 = x10 - x00
                v1 = x11 - x01
                v2 = x12 - x02
                cc1 = _dot(v0, v1, v2, v0, v1, v2)
                sa = _dot(x00, x01, x02, x00, x01, x02)
                sb = _dot(x10, x11, x12, x10, x11, x12)
                k1 = 0.0
                if cc1 > _EPS and cc1 > rtol2 * sa and cc1 > rtol2 * sb:
                    k1 = 2.0 / cc1
                kr = k1 * _dot(v0, v1, v2, rj[0], rj[1], rj[2])
                rl0 = rj[0] - kr * v0
                rl1 = rj[1] - kr * v1
                rl2 = rj[2] - kr * v2
                kt = k1 * _dot(v0, v1, v2, ts[s, 0], ts[s, 1], ts[s, 2])
                u0 = t10 - (ts[s, 0] - kt * v0)
                u1 = t11 - (ts[s, 1] - kt * v1)
                u2 = t12 - (ts[s, 2] - kt * v2)
                cc2 = _dot(u0, u1, u2, u0, u1, u2)
                k2 = 2.0 / cc2 if cc2 > rtol2 else 0.0
                kr = k2 * _dot(u0, u1, u2, rl0, rl1, rl2)
                r10 = rl0 - kr * u0
                r11 = rl1 - kr * u1
                r12 = rl2 - kr * u2
                dd = _dot(r10, r11, r12, t10, t11, t12)
                r10 = r10 - dd * t10
                r11 = r11 - dd * t11
                r12 = r12 - dd * t12
                n = _floor(math.sqrt(_sumsq(r10, r11, r12)), _EPS)
                out_c[f, q, 0] = x10
                out_c[f, q, 1] = x11
                out_c[f, q, 2] = x12
                out_t[f, q, 0] = t10
                out_t[f, q, 1] = t11
                out_t[f, q, 2] = t12
                out_r[f, q, 0] = r10 / n
                out_r[f, q, 1] = r11 / n
                out_r[f, q, 2] = r12 / n
            acc = 0.0
            for g in range(ng):
                r = g_off[j] + g
                d0 = 0.0
                d1 = 0.0
                d2 = 0.0
                for kk in range(3):
                    wv = dbg_w[r, kk]
                    i = a0 + dbg_idx[r, kk]
                    d0 += wv * pf[i, 0]
                    d1 += wv * pf[i, 1]
                    d2 += wv * pf[i, 2]
                acc += math.sqrt(_sumsq(d0, d1, d2)) * gw[r]
            out_length[j, f] = acc


@njit(cache=True)
def roll_pass(js, p, world, a_off, s_off, bs_idx, bs_w, dbs_idx, dbs_w, origin, insertion, r0_local, rend_local,
              rtol2, out_roll):
    """The insertion roll's arctan2 arguments alone (M, F, 2), from the samples of the given
    basis rows (the coarse ones of the twist references): :func:`frames_pass` without the
    bound points."""
    nf = p.shape[0]
    smax = 1
    for k in range(js.shape[0]):
        j = js[k]
        smax = max(smax, s_off[j + 1] - s_off[j])
    xs = np.empty((smax, 3))
    ts = np.empty((smax, 3))
    rs = np.empty((smax, 3))
    r0 = np.empty(3)
    rj = np.empty(3)
    for k in range(js.shape[0]):
        j = js[k]
        ns = s_off[j + 1] - s_off[j]
        for f in range(nf):
            _samples(p[f], a_off[j], bs_idx, bs_w, dbs_idx, dbs_w, s_off[j], ns, xs, ts)
            _start_vector(world[f, origin[j]], r0_local[j], ts[0, 0], ts[0, 1], ts[0, 2], r0)
            _propagate(xs, ts, ns, r0, rs, rtol2)
            _finish(rs[ns - 1, 0], rs[ns - 1, 1], rs[ns - 1, 2], ts[ns - 1, 0], ts[ns - 1, 1], ts[ns - 1, 2], rj)
            _roll_args(world[f, insertion[j]], rend_local[j], rj, ts[ns - 1], r0, out_roll[j, f])


@njit(cache=True)
def shape_pass(js, p, a_off, cb, tb, rb, ends, theta, tension, scale0, q_off, lam, uvw, beta, bump, gain,
               m_off, u_off, u_idx, u_w, v_off, v_idx, v_w, solve, v0, s_min, s_max, iters, rtol,
               vert_off, out_v, out_n, out_vol, out_s, out_bad, out_cp):
    """Step 3 of the module doc for the muscles ``js`` (K,) and every frame f:

    p, a_off     : axis control points (F, ΣN, 3) (the surface's poles are the axis ends)
    cb, tb, rb   : (F, ΣQ, 3) frames_pass's bound points (position, tangent, untwisted R)
    ends         : (M, F, 2, 3) unit tangents at the axis ends
    theta        : (M, F) the insertion roll on its branch (radians), spread by ``lam``
    tension      : (M, F) effective tension e, clipped to [0, 1]
    scale0       : (M, F) the starting scale (the paper's sqrt(l0/l1), or 1)
    lam, beta, bump : (ΣQ,) rest arc fraction, belly weight, tension bump; uvw (ΣQ, 3)
    gain         : the tension law's g
    m_off        : (M + 1,) net rows (sections + 2) of each muscle's surface
    u_*, v_*     : sparse surface bases (ΣU, 3), (ΣA, 3) from u_off, v_off
    solve, v0    : (M,) whether to solve the scale for volume v0 (``exact``)
    vert_off     : (K + 1,) muscle js[k]'s block of out_v, out_n: (F, V_j, 3) starting at
                   element 3 F vert_off[k]
    outputs      : out_v, out_n (flat float64); out_vol, out_s (M, F); out_bad (M, F);
                   out_cp (F, ΣQ, 3) the bound control points as tessellated, fixed + s scaled
                   (s clipped), when it has frames (else (0, 0, 3): not asked for)

    Per bound point (MuscleModel.surface): the twist rotates (R, S) about T by theta lam; the
    offset is u T + v R + w S; tau = sqrt(1 + g e (2 b - 1) beta), h = e b; the part kept is
    C + (1 - beta) off + beta tau h s0 off, the part scaled by s is beta tau (1 - h) off.
    """
    nf = p.shape[0]
    for k in range(js.shape[0]):
        j = js[k]
        nq = q_off[j + 1] - q_off[j]
        nu = u_off[j + 1] - u_off[j]
        na = v_off[j + 1] - v_off[j]
        nm = m_off[j + 1] - m_off[j]
        nv = 2 + (nu - 2) * na
        # this muscle's inputs and scratch (a few allocations per muscle and chunk)
        fixed = np.empty((nf, nq, 3))
        scaled = np.empty((nf, nq, 3))
        poles = np.empty((4, nf, 3))  # pole0, pole1, end0 = -T(0), end1 = T(1)
        net_a = np.zeros((nm, 8, 3))
        net_w = np.zeros((nm, 8, 3))
        ta = np.empty((nu, 8, 3))
        tw = np.empty((nu, 8, 3))
        ga = np.empty((nu, na, 3))
        gw = np.empty((nu, na, 3))
        block_v = out_v[3 * nf * vert_off[k]:3 * nf * vert_off[k + 1]].reshape((nf, nv, 3))
        block_n = out_n[3 * nf * vert_off[k]:3 * nf * vert_off[k + 1]].reshape((nf, nv, 3))
        uj_idx = u_idx[u_off[j]:u_off[j + 1]]
        uj_w = u_w[u_off[j]:u_off[j + 1]]
        vj_idx = v_idx[v_off[j]:v_off[j + 1]]
        vj_w = v_w[v_off[j]:v_off[j + 1]]
        for f in range(nf):
            th = theta[j, f]
            e = tension[j, f]
            sf = scale0[j, f]
            ge = gain * e
            for qq in range(nq):
                q = q_off[j] + qq
                t0 = tb[f, q, 0]
                t1 = tb[f, q, 1]
                t2 = tb[f, q, 2]
                r0 = rb[f, q, 0]
                r1 = rb[f, q, 1]
                r2 = rb[f, q, 2]
                # S = T x R (np.cross), then the twist about T
                x0 = t1 * r2 - t2 * r1
                x1 = t2 * r0 - t0 * r2
                x2 = t0 * r1 - t1 * r0
                ang = th * lam[q]
                ca = math.cos(ang)
                sa = math.sin(ang)
                rr0 = ca * r0 + sa * x0
                rr1 = ca * r1 + sa * x1
                rr2 = ca * r2 + sa * x2
                ss0 = ca * x0 - sa * r0
                ss1 = ca * x1 - sa * r1
                ss2 = ca * x2 - sa * r2
                u = uvw[q, 0]
                v = uvw[q, 1]
                w = uvw[q, 2]
                o0 = (u * t0 + v * rr0) + w * ss0
                o1 = (u * t1 + v * rr1) + w * ss1
                o2 = (u * t2 + v * rr2) + w * ss2
                b = beta[q]
                tau = math.sqrt(1.0 + (ge * (2.0 * bump[q] - 1.0)) * b)
                h = e * bump[q]
                kh = b * ((tau * h) * sf)
                kb = 1.0 - b
                ks = b * (tau * (1.0 - h))
                fixed[f, qq, 0] = (cb[f, q, 0] + kb * o0) + kh * o0
                fixed[f, qq, 1] = (cb[f, q, 1] + kb * o1) + kh * o1
                fixed[f, qq, 2] = (cb[f, q, 2] + kb * o2) + kh * o2
                scaled[f, qq, 0] = ks * o0
                scaled[f, qq, 1] = ks * o1
                scaled[f, qq, 2] = ks * o2
            for c in range(3):
                poles[0, f, c] = p[f, a_off[j], c]
                poles[1, f, c] = p[f, a_off[j + 1] - 1, c]
                poles[2, f, c] = -ends[j, f, 0, c]
                poles[3, f, c] = ends[j, f, 1, c]
            vol, s, bad = surface_frame(fixed, scaled, poles[0], poles[1], poles[2], poles[3], uj_idx, uj_w, vj_idx,
                                        vj_w, solve[j], v0[j], sf, s_min, s_max, iters, rtol, net_a, net_w, ta, tw,
                                        ga, gw, block_v, block_n, f)
            out_vol[j, f] = vol
            out_s[j, f] = s
            out_bad[j, f] = bad
            if out_cp.shape[0] > 0:
                sc = min(max(s, s_min), s_max)
                for qq in range(nq):
                    for c in range(3):
                        out_cp[f, q_off[j] + qq, c] = fixed[f, qq, c] + sc * scaled[f, qq, c]
