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
   sample), the insertion roll's two arguments (arctan2's y and x) and the arc length
   (Gauss-Legendre);
3. :func:`shape_pass`: the spread twist, the tension law, the volume-scaled and fixed parts of
   the bound control points, then the surface of :func:`axdf_cli.model.kernels.surface_frame`
   (tessellation, the exact volume solve, vertices and normals).

Between 2 and 3 the caller takes numpy's arctan2 (the roll) and the roll's branch, as
:class:`axdf_cli.model.muscle.MuscleModel` always did. (:func:`roll_pass`: step 2's roll alone,
on the coarse samples of the twist references.)

Same bytes as the numpy formulation (``tests/reference_model.py``): every quantity is formed
by the same floating-point operations in the same order as numpy forms it (an ``einsum`` dot
of 3-vectors is ``0 + ((a0 b0 + a2 b2) + a1 b1)``, a sum over an axis or a norm starts at 0
and adds in order, a sparse basis row adds its three terms in order, a bone's rotation of a
vector by ``@`` is OpenBLAS's fused ``fma(m2, v2, fma(m0, v0, m1 v1))``), no ``fastmath``;
the one exception is the arc length, which numpy summed by ``@`` (see :func:`frames_pass`).

Written for vector instructions, with the same operations per value: frames run innermost,
LANES at a time, in :func:`frames_pass` and in the bound points of :func:`shape_pass`; the
surface's grids are laid out so that the volume terms and normals are one long loop each
(c-major, ghost columns around); ``error_model="numpy"`` (numba's zero-division check per
divide, which no divisor here needs, keeps loops scalar), unsigned indices where an index
is computed (numba's negative-index wraparound does too), and a scratch array of fixed shape
for loops that write several results (so no overlap check per pair of outputs is needed).
"""
from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from axdf_cli.model.kernels import solve_scale, quad_volume_terms
from axdf_cli.model.paths import wrap as W

_EPS = 1e-30  # as axdf_cli.model.rmf._EPS
_TINY = 1e-300  # the unit tangent's floor (as MuscleModel's _unit)
LANES = 8  # frames made at once in the innermost loops (one AVX-512 vector of float64)
_U = np.uint64  # loop indices the compiler can vectorize over (no negative-index wraparound)


@intrinsic
def _fma(typingctx, a, b, c):
    """a * b + c rounded once (LLVM's ``llvm.fma``: the FMA instruction, or libm's exact fma)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fn = builder.module.declare_intrinsic("llvm.fma", [d], ir.FunctionType(d, [d, d, d]))
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, error_model="numpy")
def _matvec_row(m0, m1, m2, v0, v1, v2):
    """Row (m0, m1, m2) of numpy's ``@`` of a 3x3 matrix and a 3-vector, as its BLAS kernel
    (OpenBLAS dgemv on x86-64) rounds it: fma(m2, v2, fma(m0, v0, m1 v1))."""
    return _fma(m2, v2, _fma(m0, v0, m1 * v1))


@njit(cache=True, error_model="numpy")
def _dot(a0, a1, a2, b0, b1, b2):
    """numpy's ``einsum('...c,...c->...')`` of 3-vectors, operation for operation."""
    return 0.0 + ((a0 * b0 + a2 * b2) + a1 * b1)


@njit(cache=True, error_model="numpy")
def _sumsq(a0, a1, a2):
    """The sum under ``np.linalg.norm(axis=-1)`` (an add.reduce from 0, in order)."""
    return ((0.0 + a0 * a0) + a1 * a1) + a2 * a2


@njit(cache=True, error_model="numpy")
def _floor(x, lo):
    """``np.maximum(x, lo)``: NaN stays NaN."""
    return x if (x >= lo or x != x) else lo


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def axis_paths(js, world, pbones, loc, active, p_off, wbones, wlocal, w_off, kind, prm, wrap_axis, wrap_sign,
               method, on, rng, side_bones, side_at, has_side, fractions, k_off, fit, fit_off, a_off, out, out_inside):
    """Axis control points of path muscles ``js``, as :meth:`PathModel.control_points`:

    world        : (F, B, 4, 4)
    pbones, loc  : (ΣP,) path points' bones, (F, ΣP, 3) their locations in them (moving
                   points already evaluated); active (F, ΣP) bool (conditional points)
    wbones, wlocal : (ΣW,), (ΣW, 4, 4) wrap surfaces' bones and transforms in them; kind,
                   prm (ΣW, 3), wrap_axis, wrap_sign, method, on, rng (ΣW, 2): as PathModel's;
                   side_bones, side_at (ΣW, 4), has_side: a surface's side point in its bone
    fractions    : (ΣK,) arc fractions of the path samples; fit (flat) the (n_j, K_j) least
                   squares map from samples to control points, row-major from fit_off[j]
    outputs      : out (F, ΣN, 3) rows a_off[j] ..; out_inside (M, F) the index + 1 of a
                   surface the path could not wrap over (an end point inside it), 0 if none

    Points: ``einsum('fpck,fpk->fpc', R, loc) + t`` (``0 + ((r0 l0 + r2 l2) + r1 l1)``), the
    surfaces' transforms ``einsum('fwij,wjk->fwik')`` (in order from 0), their side points
    ``einsum('fwck,wk->fwc')`` (``0 + ((p0 + p2) + (p1 + p3))``), the fit in order.
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
        side = np.zeros((nf, nw, 3))
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
                m = world[f, side_bones[w0 + w]]
                sa = side_at[w0 + w]
                for r in range(3):
                    side[f, w, r] = 0.0 + ((m[r, 0] * sa[0] + m[r, 2] * sa[2]) + (m[r, 1] * sa[1] + m[r, 3] * sa[3]))
        samples = np.empty((nf, nk, 3))
        length = np.empty(nf)
        inside = np.zeros(nf, dtype=np.int64)
        points = np.zeros((nf, npt + 2 * nw, 3))
        count = np.zeros(nf, dtype=np.int64)
        W.wrapped_paths(pts, act, xf, kind[w0:w1], prm[w0:w1], wrap_axis[w0:w1], wrap_sign[w0:w1], method[w0:w1],
                        on[w0:w1], rng[w0:w1], side, has_side[w0:w1], fractions[k0:k1], samples, length, inside,
                        points, count)
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def frames_pass(js, p, world, a_off, s_off, bs_idx, bs_w, dbs_idx, dbs_w, q_off, bb_idx, bb_w, dbb_idx, dbb_w,
                bind_j, g_off, dbg_idx, dbg_w, gw, origin, insertion, r0_local, rend_local, rtol2,
                out_q, out_ends, out_roll, out_length):
    """Step 2 of the module doc for the muscles ``js`` (K,) and every frame of the chunk:

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
    outputs    : out_q (3, ΣQ, 3, F) the bound points' position, unit tangent and untwisted
                 unit reference vector (frames last); out_ends (M, F, 2, 3) the
                 unit tangents at t = 0 and 1; out_roll (M, F, 2) arctan2's (y, x) of the
                 insertion roll; out_length (M, F) the arc length sum_g gw_g |C'(t_g)|, added
                 in order (numpy's ``@`` here was OpenBLAS's dot, whose order changes with the
                 number of frames: this sum may differ from it in the last bit)

    Frames run innermost, LANES at a time, in arrays whose last axis is the frame, so that
    the compiler makes each operation one vector instruction over the frames: every frame
    still gets exactly the scalar sequence of operations (same bits as one frame alone).
    """
    nf = p.shape[0]
    smax = 1
    nmax = 1
    for k in range(js.shape[0]):
        j = js[k]
        smax = max(smax, s_off[j + 1] - s_off[j])
        nmax = max(nmax, a_off[j + 1] - a_off[j])
    pt = np.empty((nmax, 3, LANES))  # the block's control points, frames last
    res = np.empty((9, LANES))  # a bound point's results over the block (its shape known to the compiler)
    smp = np.empty((3, smax, 3, LANES))  # the samples x, unit tangents t, reference vectors r (one array:
    # one base pointer, so the compiler checks one overlap per loop, not one per pair of arrays)
    r0 = np.empty(3)
    rj = np.empty(3)
    tj = np.empty(3)
    tgt = np.empty(3)
    for k in range(js.shape[0]):
        j = js[k]
        a0 = a_off[j]
        na = a_off[j + 1] - a0
        ns = s_off[j + 1] - s_off[j]
        sb = s_off[j]
        for f0 in range(0, nf, LANES):
            nb = _U(min(LANES, nf - f0))
            fu = _U(f0)
            for i in range(na):
                for c in range(3):
                    for f in range(nb):
                        pt[i, c, f] = p[fu + f, a0 + i, c]
            # samples and unit tangents (sparse rows, in order from 0; d / max(|d|, 1e-300))
            for s in range(ns):
                r = sb + s
                i0, i1, i2 = bs_idx[r, 0], bs_idx[r, 1], bs_idx[r, 2]
                w0, w1, w2 = bs_w[r, 0], bs_w[r, 1], bs_w[r, 2]
                e0, e1, e2 = dbs_idx[r, 0], dbs_idx[r, 1], dbs_idx[r, 2]
                v0, v1, v2 = dbs_w[r, 0], dbs_w[r, 1], dbs_w[r, 2]
                for c in range(3):
                    for f in range(nb):
                        smp[0, s, c, f] = ((0.0 + w0 * pt[i0, c, f]) + w1 * pt[i1, c, f]) + w2 * pt[i2, c, f]
                for f in range(nb):
                    d0 = ((0.0 + v0 * pt[e0, 0, f]) + v1 * pt[e1, 0, f]) + v2 * pt[e2, 0, f]
                    d1 = ((0.0 + v0 * pt[e0, 1, f]) + v1 * pt[e1, 1, f]) + v2 * pt[e2, 1, f]
                    d2 = ((0.0 + v0 * pt[e0, 2, f]) + v1 * pt[e1, 2, f]) + v2 * pt[e2, 2, f]
                    n = _floor(math.sqrt(_sumsq(d0, d1, d2)), _TINY)
                    smp[1, s, 0, f] = d0 / n
                    smp[1, s, 1, f] = d1 / n
                    smp[1, s, 2, f] = d2 / n
            for f in range(nb):
                _start_vector(world[fu + f, origin[j]], r0_local[j], smp[1, 0, 0, f], smp[1, 0, 1, f], smp[1, 0, 2, f], r0)
                for c in range(3):
                    smp[2, 0, c, f] = r0[c]
            # the double-reflection recurrence (rmf.propagate), every frame of the block at once
            for i in range(ns - 1):
                for f in range(nb):
                    x00 = smp[0, i, 0, f]
                    x01 = smp[0, i, 1, f]
                    x02 = smp[0, i, 2, f]
                    x10 = smp[0, i + 1, 0, f]
                    x11 = smp[0, i + 1, 1, f]
                    x12 = smp[0, i + 1, 2, f]
                    v0 = x10 - x00
                    v1 = x11 - x01
                    v2 = x12 - x02
                    cc1 = _dot(v0, v1, v2, v0, v1, v2)
                    sa = _dot(x10, x11, x12, x10, x11, x12)
                    sq = _dot(x00, x01, x02, x00, x01, x02)
                    k1 = 2.0 / cc1 if (cc1 > _EPS and cc1 > rtol2 * sa and cc1 > rtol2 * sq) else 0.0
                    tt0 = smp[1, i, 0, f]
                    tt1 = smp[1, i, 1, f]
                    tt2 = smp[1, i, 2, f]
                    kd = k1 * _dot(v0, v1, v2, tt0, tt1, tt2)
                    u0 = smp[1, i + 1, 0, f] - (tt0 - kd * v0)
                    u1 = smp[1, i + 1, 1, f] - (tt1 - kd * v1)
                    u2 = smp[1, i + 1, 2, f] - (tt2 - kd * v2)
                    cc2 = _dot(u0, u1, u2, u0, u1, u2)
                    k2 = 2.0 / cc2 if cc2 > rtol2 else 0.0
                    c0 = smp[2, i, 0, f]
                    c1 = smp[2, i, 1, f]
                    c2 = smp[2, i, 2, f]
                    # cur - (v1 . cur) a1 with a1 = k1 v1, then likewise with v2 (sums in order, from 0)
                    sm = ((0.0 + v0 * c0) + v1 * c1) + v2 * c2
                    c0 = c0 - sm * (k1 * v0)
                    c1 = c1 - sm * (k1 * v1)
                    c2 = c2 - sm * (k1 * v2)
                    sm = ((0.0 + u0 * c0) + u1 * c1) + u2 * c2
                    smp[2, i + 1, 0, f] = c0 - sm * (k2 * u0)
                    smp[2, i + 1, 1, f] = c1 - sm * (k2 * u1)
                    smp[2, i + 1, 2, f] = c2 - sm * (k2 * u2)
            e = ns - 1
            for f in range(nb):
                for c in range(3):
                    out_ends[j, fu + f, 0, c] = smp[1, 0, c, f]
                    out_ends[j, fu + f, 1, c] = smp[1, e, c, f]
                    tj[c] = smp[1, e, c, f]
                _finish(smp[2, e, 0, f], smp[2, e, 1, f], smp[2, e, 2, f], tj[0], tj[1], tj[2], rj)
                _roll_args(world[fu + f, insertion[j]], rend_local[j], rj, tj, tgt, out_roll[j, fu + f])
            # the bound points: C(t), its unit tangent, one double-reflection step from sample s
            for q in range(q_off[j], q_off[j + 1]):
                s = bind_j[q]
                i0, i1, i2 = bb_idx[q, 0], bb_idx[q, 1], bb_idx[q, 2]
                w0, w1, w2 = bb_w[q, 0], bb_w[q, 1], bb_w[q, 2]
                e0, e1, e2 = dbb_idx[q, 0], dbb_idx[q, 1], dbb_idx[q, 2]
                v0, v1, v2 = dbb_w[q, 0], dbb_w[q, 1], dbb_w[q, 2]
                for f in range(nb):
                    x10 = ((0.0 + w0 * pt[i0, 0, f]) + w1 * pt[i1, 0, f]) + w2 * pt[i2, 0, f]
                    x11 = ((0.0 + w0 * pt[i0, 1, f]) + w1 * pt[i1, 1, f]) + w2 * pt[i2, 1, f]
                    x12 = ((0.0 + w0 * pt[i0, 2, f]) + w1 * pt[i1, 2, f]) + w2 * pt[i2, 2, f]
                    d0 = ((0.0 + v0 * pt[e0, 0, f]) + v1 * pt[e1, 0, f]) + v2 * pt[e2, 0, f]
                    d1 = ((0.0 + v0 * pt[e0, 1, f]) + v1 * pt[e1, 1, f]) + v2 * pt[e2, 1, f]
                    d2 = ((0.0 + v0 * pt[e0, 2, f]) + v1 * pt[e1, 2, f]) + v2 * pt[e2, 2, f]
                    n = _floor(math.sqrt(_sumsq(d0, d1, d2)), _TINY)
                    t10 = d0 / n
                    t11 = d1 / n
                    t12 = d2 / n
                    # the sample's reference vector made unit and orthogonal (propagate's last step)
                    ts0 = smp[1, s, 0, f]
                    ts1 = smp[1, s, 1, f]
                    ts2 = smp[1, s, 2, f]
                    q0 = smp[2, s, 0, f]
                    q1 = smp[2, s, 1, f]
                    q2 = smp[2, s, 2, f]
                    dd = _dot(q0, q1, q2, ts0, ts1, ts2)
                    q0 = q0 - dd * ts0
                    q1 = q1 - dd * ts1
                    q2 = q2 - dd * ts2
                    n = _floor(math.sqrt(_sumsq(q0, q1, q2)), _EPS)
                    q0 = q0 / n
                    q1 = q1 / n
                    q2 = q2 / n
                    x00 = smp[0, s, 0, f]
                    x01 = smp[0, s, 1, f]
                    x02 = smp[0, s, 2, f]
                    u0 = x10 - x00
                    u1 = x11 - x01
                    u2 = x12 - x02
                    cc1 = _dot(u0, u1, u2, u0, u1, u2)
                    sa = _dot(x00, x01, x02, x00, x01, x02)
                    sq = _dot(x10, x11, x12, x10, x11, x12)
                    k1 = 2.0 / cc1 if (cc1 > _EPS and cc1 > rtol2 * sa and cc1 > rtol2 * sq) else 0.0
                    kr = k1 * _dot(u0, u1, u2, q0, q1, q2)
                    rl0 = q0 - kr * u0
                    rl1 = q1 - kr * u1
                    rl2 = q2 - kr * u2
                    kt = k1 * _dot(u0, u1, u2, ts0, ts1, ts2)
                    z0 = t10 - (ts0 - kt * u0)
                    z1 = t11 - (ts1 - kt * u1)
                    z2 = t12 - (ts2 - kt * u2)
                    cc2 = _dot(z0, z1, z2, z0, z1, z2)
                    k2 = 2.0 / cc2 if cc2 > rtol2 else 0.0
                    kr = k2 * _dot(z0, z1, z2, rl0, rl1, rl2)
                    r10 = rl0 - kr * z0
                    r11 = rl1 - kr * z1
                    r12 = rl2 - kr * z2
                    dd = _dot(r10, r11, r12, t10, t11, t12)
                    r10 = r10 - dd * t10
                    r11 = r11 - dd * t11
                    r12 = r12 - dd * t12
                    n = _floor(math.sqrt(_sumsq(r10, r11, r12)), _EPS)
                    res[0, f] = x10
                    res[1, f] = x11
                    res[2, f] = x12
                    res[3, f] = t10
                    res[4, f] = t11
                    res[5, f] = t12
                    res[6, f] = r10 / n
                    res[7, f] = r11 / n
                    res[8, f] = r12 / n
                for kk in range(9):  # (written apart: stores to one scratch of fixed shape keep the loop above vector code)
                    for f in range(nb):
                        out_q[kk // 3, q, kk % 3, fu + f] = res[kk, f]
            # arc length: the speeds at the Gauss points against their weights, in order
            for f in range(nb):
                out_length[j, fu + f] = 0.0
            for r in range(g_off[j], g_off[j + 1]):
                i0, i1, i2 = dbg_idx[r, 0], dbg_idx[r, 1], dbg_idx[r, 2]
                v0, v1, v2 = dbg_w[r, 0], dbg_w[r, 1], dbg_w[r, 2]
                g = gw[r]
                for f in range(nb):
                    d0 = ((0.0 + v0 * pt[i0, 0, f]) + v1 * pt[i1, 0, f]) + v2 * pt[i2, 0, f]
                    d1 = ((0.0 + v0 * pt[i0, 1, f]) + v1 * pt[i1, 1, f]) + v2 * pt[i2, 1, f]
                    d2 = ((0.0 + v0 * pt[i0, 2, f]) + v1 * pt[i1, 2, f]) + v2 * pt[i2, 2, f]
                    out_length[j, fu + f] += math.sqrt(_sumsq(d0, d1, d2)) * g


@njit(cache=True, error_model="numpy")
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


@njit(cache=True, error_model="numpy")
def _grid(net_a, net_w, u_idx, u_w, v_idx, v_w, ta, tw, ga, gw):
    """:func:`axdf_cli.model.kernels._tessellate` of one frame into the layout the loops
    below run along: nets (m, 24) (rows of 8 points x 3); ta, tw (3, 8, U) along; ga, gw
    (3, A + 2, U): column a + 1 holds around-column a, columns 0 and A + 1 repeat columns
    A - 1 and 0 (so that neighbours around are plain offsets), rows u innermost."""
    nu = u_idx.shape[0]
    na = v_idx.shape[0]
    for u in range(nu):
        i0, i1, i2 = u_idx[u, 0], u_idx[u, 1], u_idx[u, 2]
        w0, w1, w2 = u_w[u, 0], u_w[u, 1], u_w[u, 2]
        for e in range(24):
            ta[e % 3, e // 3, u] = ((0.0 + w0 * net_a[i0, e]) + w1 * net_a[i1, e]) + w2 * net_a[i2, e]
            tw[e % 3, e // 3, u] = ((0.0 + w0 * net_w[i0, e]) + w1 * net_w[i1, e]) + w2 * net_w[i2, e]
    for c in range(3):
        for a in range(na):
            i0, i1, i2 = v_idx[a, 0], v_idx[a, 1], v_idx[a, 2]
            w0, w1, w2 = v_w[a, 0], v_w[a, 1], v_w[a, 2]
            for u in range(nu):
                ga[c, a + 1, u] = ((0.0 + w0 * ta[c, i0, u]) + w1 * ta[c, i1, u]) + w2 * ta[c, i2, u]
                gw[c, a + 1, u] = ((0.0 + w0 * tw[c, i0, u]) + w1 * tw[c, i1, u]) + w2 * tw[c, i2, u]
        for u in range(nu):
            ga[c, 0, u] = ga[c, na, u]
            gw[c, 0, u] = gw[c, na, u]
            ga[c, na + 1, u] = ga[c, 1, u]
            gw[c, na + 1, u] = gw[c, 1, u]


@njit(cache=True, error_model="numpy")
def _volume_terms(ga, gw, terms):
    """Each quad's four contributions to :func:`axdf_cli.model.kernels.volume_cubic`'s sums
    (terms (4, (A + 2) U) at the quad's corner (u, a): flat index (a + 1) U + u), computed over
    the whole grid at once (the rows u = U - 1 and the ghost columns are not quads: unused).
    Indices are unsigned: numba's negative-index wraparound on ``i + U`` would keep the
    compiler from making the loop vector instructions."""
    nu = _U(ga.shape[2])
    n = _U(ga.shape[1] - 1) * nu - _U(1)
    one = _U(1)
    a_ = ga.reshape(3, -1)
    w_ = gw.reshape(3, -1)
    for i in range(nu, n):
        i1 = i + nu  # (u, a + 1)
        i2 = i + one  # (u + 1, a)
        i3 = i1 + one  # (u + 1, a + 1)
        ax0 = a_[0, i1]
        ax1 = a_[1, i1]
        ax2 = a_[2, i1]
        wx0 = w_[0, i1]
        wx1 = w_[1, i1]
        wx2 = w_[2, i1]
        ay0 = a_[0, i2]
        ay1 = a_[1, i2]
        ay2 = a_[2, i2]
        wy0 = w_[0, i2]
        wy1 = w_[1, i2]
        wy2 = w_[2, i2]
        ad0 = a_[0, i] - a_[0, i3]
        ad1 = a_[1, i] - a_[1, i3]
        ad2 = a_[2, i] - a_[2, i3]
        wd0 = w_[0, i] - w_[0, i3]
        wd1 = w_[1, i] - w_[1, i3]
        wd2 = w_[2, i] - w_[2, i3]
        t0, t1, t2, t3 = quad_volume_terms(ax0, ax1, ax2, wx0, wx1, wx2, ay0, ay1, ay2, wy0, wy1, wy2,
                                           ad0, ad1, ad2, wd0, wd1, wd2)
        terms[0, i] = t0
        terms[1, i] = t1
        terms[2, i] = t2
        terms[3, i] = t3


@njit(cache=True, error_model="numpy")
def _ring_normals(ga, nrm):
    """:func:`axdf_cli.model.kernels.ring_vertices`' normals of one frame's grid (3, A + 2, U)
    into nrm (same layout), over the whole grid at once (rows 0 and U - 1 and the ghost
    columns come out meaningless: unused). Unsigned indices, as :func:`_volume_terms`."""
    nu = _U(ga.shape[2])
    n = _U(ga.shape[1] - 1) * nu - _U(1)
    one = _U(1)
    g = ga.reshape(3, -1)
    o = nrm.reshape(3, -1)
    for i in range(nu + one, n):
        ia = i + nu  # around: (u, a + 1) - (u, a - 1)
        ib = i - nu
        ic = i + one  # along: (u + 1, a) - (u - 1, a)
        id_ = i - one
        sv0 = g[0, ia] - g[0, ib]
        sv1 = g[1, ia] - g[1, ib]
        sv2 = g[2, ia] - g[2, ib]
        su0 = g[0, ic] - g[0, id_]
        su1 = g[1, ic] - g[1, id_]
        su2 = g[2, ic] - g[2, id_]
        n0 = sv1 * su2 - sv2 * su1
        n1 = sv2 * su0 - sv0 * su2
        n2 = sv0 * su1 - sv1 * su0
        ln = max(np.sqrt(n0 * n0 + n1 * n1 + n2 * n2), 1e-300)
        o[0, i] = n0 / ln
        o[1, i] = n1 / ln
        o[2, i] = n2 / ln


@njit(cache=True, error_model="numpy")
def _unpack_grid(ga, nrm, bv, bn):
    """The rings' vertices and normals (grids (3, A + 2, U)) into one frame's (V, 3) arrays,
    vertex (u, a) at 1 + (u - 1) A + a (the poles are set apart)."""
    nu = _U(ga.shape[2])
    na = _U(ga.shape[1] - 2)
    one = _U(1)
    for u in range(one, nu - one):
        base = one + (u - one) * na
        for a in range(na):
            for c in range(3):
                bv[base + a, c] = ga[c, a + one, u]
                bn[base + a, c] = nrm[c, a + one, u]


@njit(cache=True, error_model="numpy")
def _pole_normal(ga, row, ring, sign, e0, e1, e2, out):
    """:func:`axdf_cli.model.kernels.pole_normals` of one pole (grid (3, A + 2, U); the pole
    at along-row ``row``, its fan to ``ring``) into out (3,): the fan's area-weighted normal,
    or the outward axis direction e where the fan folds."""
    na = ga.shape[1] - 2
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    for a in range(na):
        x0 = ga[0, a + 2, ring] - ga[0, 1, row]
        x1 = ga[1, a + 2, ring] - ga[1, 1, row]
        x2 = ga[2, a + 2, ring] - ga[2, 1, row]
        y0 = ga[0, a + 1, ring] - ga[0, 1, row]
        y1 = ga[1, a + 1, ring] - ga[1, 1, row]
        y2 = ga[2, a + 1, ring] - ga[2, 1, row]
        f0 += x1 * y2 - x2 * y1
        f1 += x2 * y0 - x0 * y2
        f2 += x0 * y1 - x1 * y0
    ln = max(np.sqrt(f0 * f0 + f1 * f1 + f2 * f2), 1e-300)
    f0 = sign * f0 / ln
    f1 = sign * f1 / ln
    f2 = sign * f2 / ln
    if f0 * e0 + f1 * e1 + f2 * e2 <= 0.5:
        le = max(np.sqrt(e0 * e0 + e1 * e1 + e2 * e2), 1e-300)
        f0 = e0 / le
        f1 = e1 / le
        f2 = e2 / le
    out[0] = f0
    out[1] = f1
    out[2] = f2


@njit(cache=True, error_model="numpy")
def shape_pass(js, p, a_off, fr, ends, theta, tension, scale0, q_off, lam, uvw, beta, bump, gain,
               m_off, u_off, u_idx, u_w, v_off, v_idx, v_w, solve, v0, s_min, s_max, iters, rtol,
               vert_off, out_v, out_n, out_vol, out_s, out_bad, out_cp):
    """Step 3 of the module doc for the muscles ``js`` (K,) and every frame f:

    p, a_off     : axis control points (F, ΣN, 3) (the surface's poles are the axis ends)
    fr           : (3, ΣQ, 3, F) frames_pass's bound points (position, tangent, untwisted R)
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
    C + (1 - beta) off + beta tau h s0 off, the part scaled by s is beta tau (1 - h) off. Then
    the surface of :func:`axdf_cli.model.kernels.surface_frame`, its steps laid out so that
    each runs as one long loop over the grid (which the compiler makes vector instructions):
    the same operations on the same numbers, so the same bits.
    """
    nf = p.shape[0]
    pole = np.empty(3)
    res = np.empty((6, LANES))  # a bound point's fixed and scaled parts over a block (fixed shape: vector code)
    cs = np.empty((2, LANES))
    for k in range(js.shape[0]):
        j = js[k]
        nq = q_off[j + 1] - q_off[j]
        nu = u_off[j + 1] - u_off[j]
        na = v_off[j + 1] - v_off[j]
        nm = m_off[j + 1] - m_off[j]
        nv = 2 + (nu - 2) * na
        last = nv - 1
        # this muscle's scratch (a few allocations per muscle and chunk)
        nets = np.empty((2, LANES, nm, 24))  # the block's control nets: fixed part, scaled part
        ta = np.empty((3, 8, nu))
        tw = np.empty((3, 8, nu))
        ga = np.empty((3, na + 2, nu))
        gw = np.empty((3, na + 2, nu))
        nrm = np.empty((3, na + 2, nu))
        terms = np.empty((4, (na + 2) * nu))
        block_v = out_v[3 * nf * vert_off[k]:3 * nf * vert_off[k + 1]].reshape((nf, nv, 3))
        block_n = out_n[3 * nf * vert_off[k]:3 * nf * vert_off[k + 1]].reshape((nf, nv, 3))
        uj_idx = u_idx[u_off[j]:u_off[j + 1]]
        uj_w = u_w[u_off[j]:u_off[j + 1]]
        vj_idx = v_idx[v_off[j]:v_off[j + 1]]
        vj_w = v_w[v_off[j]:v_off[j + 1]]
        for f0 in range(0, nf, LANES):
            nb = _U(min(LANES, nf - f0))
            fu = _U(f0)
            for qq in range(nq):
                q = q_off[j] + qq
                lq = lam[q]
                for f in range(nb):  # the twist's cos and sin (libm's, one call each)
                    ang = theta[j, fu + f] * lq
                    cs[0, f] = math.cos(ang)
                    cs[1, f] = math.sin(ang)
                u = uvw[q, 0]
                v = uvw[q, 1]
                w = uvw[q, 2]
                b = beta[q]
                bq = bump[q]
                kb = 1.0 - b
                for f in range(nb):
                    e = tension[j, fu + f]
                    t0 = fr[1, q, 0, fu + f]
                    t1 = fr[1, q, 1, fu + f]
                    t2 = fr[1, q, 2, fu + f]
                    r0 = fr[2, q, 0, fu + f]
                    r1 = fr[2, q, 1, fu + f]
                    r2 = fr[2, q, 2, fu + f]
                    # S = T x R (np.cross), then the twist about T
                    x0 = t1 * r2 - t2 * r1
                    x1 = t2 * r0 - t0 * r2
                    x2 = t0 * r1 - t1 * r0
                    ca = cs[0, f]
                    sa = cs[1, f]
                    rr0 = ca * r0 + sa * x0
                    rr1 = ca * r1 + sa * x1
                    rr2 = ca * r2 + sa * x2
                    ss0 = ca * x0 - sa * r0
                    ss1 = ca * x1 - sa * r1
                    ss2 = ca * x2 - sa * r2
                    o0 = (u * t0 + v * rr0) + w * ss0
                    o1 = (u * t1 + v * rr1) + w * ss1
                    o2 = (u * t2 + v * rr2) + w * ss2
                    tau = math.sqrt(1.0 + ((gain * e) * (2.0 * bq - 1.0)) * b)
                    h = e * bq
                    kh = b * ((tau * h) * scale0[j, fu + f])
                    ks = b * (tau * (1.0 - h))
                    res[0, f] = (fr[0, q, 0, fu + f] + kb * o0) + kh * o0
                    res[1, f] = (fr[0, q, 1, fu + f] + kb * o1) + kh * o1
                    res[2, f] = (fr[0, q, 2, fu + f] + kb * o2) + kh * o2
                    res[3, f] = ks * o0
                    res[4, f] = ks * o1
                    res[5, f] = ks * o2
                row = 1 + qq // 8
                col = 3 * (qq % 8)
                for f in range(nb):
                    for c in range(3):
                        nets[0, f, row, col + c] = res[c, f]
                        nets[1, f, row, col + c] = res[3 + c, f]
            for f in range(nb):
                ff = fu + f
                net_a = nets[0, f]
                net_w = nets[1, f]
                for col in range(8):  # the pole rows: the axis ends (fixed), nothing scaled
                    for c in range(3):
                        net_a[0, 3 * col + c] = p[ff, a_off[j], c]
                        net_a[nm - 1, 3 * col + c] = p[ff, a_off[j + 1] - 1, c]
                        net_w[0, 3 * col + c] = 0.0
                        net_w[nm - 1, 3 * col + c] = 0.0
                sf = scale0[j, ff]
                _grid(net_a, net_w, uj_idx, uj_w, vj_idx, vj_w, ta, tw, ga, gw)
                _volume_terms(ga, gw, terms)
                c0 = 0.0
                c1 = 0.0
                c2 = 0.0
                c3 = 0.0
                for u in range(nu - 1):  # the quads' sums in kernels.volume_cubic's order
                    for a in range(na):
                        i = (a + 1) * nu + u
                        c0 += terms[0, i]
                        c1 += terms[1, i]
                        c2 += terms[2, i]
                        c3 += terms[3, i]
                c0 = c0 / 6.0
                c1 = c1 / 6.0
                c2 = c2 / 6.0
                c3 = c3 / 6.0
                s = sf
                bad = False
                if solve[j]:
                    s, bad = solve_scale(c0, c1, c2, c3, v0[j], sf, iters, rtol)
                sc = min(max(s, s_min), s_max)
                out_vol[j, ff] = ((c3 * sc + c2) * sc + c1) * sc + c0
                out_s[j, ff] = s
                out_bad[j, ff] = bad
                g_ = ga.reshape(-1)
                w_ = gw.reshape(-1)
                for i in range(g_.shape[0]):
                    g_[i] += sc * w_[i]
                _ring_normals(ga, nrm)
                bv = block_v[ff]
                bn = block_n[ff]
                for c in range(3):
                    bv[0, c] = ga[c, 1, 0]
                    bv[last, c] = ga[c, 1, nu - 1]
                _unpack_grid(ga, nrm, bv, bn)
                _pole_normal(ga, 0, 1, 1.0, -ends[j, ff, 0, 0], -ends[j, ff, 0, 1], -ends[j, ff, 0, 2], pole)
                for c in range(3):
                    bn[0, c] = pole[c]
                _pole_normal(ga, nu - 1, nu - 2, -1.0, ends[j, ff, 1, 0], ends[j, ff, 1, 1], ends[j, ff, 1, 2], pole)
                for c in range(3):
                    bn[last, c] = pole[c]
                if out_cp.shape[0] > 0:
                    for qq in range(nq):
                        for c in range(3):
                            e3 = 3 * (qq % 8) + c
                            out_cp[ff, q_off[j] + qq, c] = net_a[1 + qq // 8, e3] + sc * net_w[1 + qq // 8, e3]
