"""The compiled passes of :mod:`axdf_cli.model.batch`: every muscle of a chunk of frames at once.

Three calls per chunk, over muscles packed end to end (concatenated arrays with offsets, batch
dimension first; the offsets ``*_off`` (M + 1,) say where muscle j's rows start and end),
their arrays grouped in the small named tuples below:

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
3. :func:`axdf_cli.model.batch_surface.shape_pass`: the twist, the tension law, the bound
   control points and the surface.

Between 2 and 3 the caller takes numpy's arctan2 (the roll) and the roll's branch, as
:class:`axdf_cli.model.muscle.MuscleModel` does. (:func:`roll_pass`: step 2's roll alone,
on the coarse samples of the twist references.)

Same bytes as the numpy formulation (``tests/reference_model.py``): every quantity is formed
by the same floating-point operations in the same order as numpy forms it (an ``einsum`` dot
of 3-vectors is ``0 + ((a0 b0 + a2 b2) + a1 b1)``, a sum over an axis or a norm starts at 0
and adds in order, a sparse basis row adds its three terms in order, a bone's rotation of a
vector by ``@`` is OpenBLAS's fused ``fma(m2, v2, fma(m0, v0, m1 v1))``), no ``fastmath``;
the one exception is the arc length, which numpy sums by ``@`` (see :func:`frames_pass`).

Written for vector instructions, with the same operations per value: frames run innermost,
LANES at a time; ``error_model="numpy"`` (numba's zero-division check per divide, which no
divisor here needs, keeps loops scalar), unsigned indices where an index is computed
(numba's negative-index wraparound does too), and a scratch array of fixed shape for loops
that write several results (so no overlap check per pair of outputs is needed).
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

from axdf_cli.model.paths import wrap as W

_EPS = 1e-30  # the floor of axdf_cli.model.rmf's norms
_TINY = 1e-300  # the unit tangent's floor (as axdf_cli.model.muscle normalises)
LANES = 8  # frames made at once in the innermost loops (one AVX-512 vector of float64)
_U = np.uint64  # loop indices the compiler can vectorize over (no negative-index wraparound)


class Basis(NamedTuple):
    """Sparse rows of a B-spline basis and of its derivative at the same parameters, every
    muscle's end to end (muscle j's rows from off[j]; column indices local to its control points)."""
    off: np.ndarray  # (M + 1,)
    idx: np.ndarray  # (ΣR, 3) int64
    w: np.ndarray  # (ΣR, 3)
    didx: np.ndarray  # (ΣR, 3) int64: the derivative's
    dw: np.ndarray  # (ΣR, 3)


class Quadrature(NamedTuple):
    """The arc length's Gauss-Legendre points: the derivative's sparse rows there and the weights."""
    off: np.ndarray  # (M + 1,)
    didx: np.ndarray  # (ΣG, 3) int64
    dw: np.ndarray  # (ΣG, 3)
    weight: np.ndarray  # (ΣG,)


class Anchors(NamedTuple):
    """The bones at each muscle's axis ends and the reference vectors in them (M,)."""
    origin: np.ndarray  # origin bone (its start vector of the RMF)
    insertion: np.ndarray  # insertion bone (its reference for the roll)
    r0_local: np.ndarray  # (M, 3) the start vector in the origin bone
    rend_local: np.ndarray  # (M, 3) the insertion's rest reference in its bone


class FrameOut(NamedTuple):
    """Where :func:`frames_pass` writes (F frames)."""
    q: np.ndarray  # (3, ΣQ, 3, F) the bound points' position, unit tangent, untwisted unit reference
    ends: np.ndarray  # (M, F, 2, 3) the unit tangents at t = 0 and 1
    roll: np.ndarray  # (M, F, 2) arctan2's (y, x) of the insertion roll
    length: np.ndarray  # (M, F) the arc length


class PathPoints(NamedTuple):
    """The paths' points, every path muscle's end to end (muscle j's from off[j])."""
    off: np.ndarray  # (M + 1,)
    bones: np.ndarray  # (ΣP,)
    loc: np.ndarray  # (F, ΣP, 3) the locations in the bones (moving points evaluated)
    active: np.ndarray  # (F, ΣP) bool (conditional points)


class Wraps(NamedTuple):
    """Where the wrap surfaces are (ΣW, from off[j]); what they are is a
    :class:`~axdf_cli.model.paths.wrap.Surfaces` of the same rows."""
    off: np.ndarray  # (M + 1,)
    bones: np.ndarray  # (ΣW,)
    local: np.ndarray  # (ΣW, 4, 4) the transforms in the bones
    side_bones: np.ndarray  # (ΣW,) a surface's side point's bone
    side_at: np.ndarray  # (ΣW, 4) the side point in it (homogeneous)


class Fits(NamedTuple):
    """The path samples' arc fractions and the least squares map from samples to control points."""
    k_off: np.ndarray  # (M + 1,)
    fractions: np.ndarray  # (ΣK,)
    fit_off: np.ndarray  # (M + 1,)
    fit: np.ndarray  # flat: muscle j's (n_j, K_j) map, row-major from fit_off[j]


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
def _rows_of(surfaces, w0, w1):
    """Rows w0 .. w1 of a :class:`~axdf_cli.model.paths.wrap.Surfaces`."""
    return W.Surfaces(surfaces.kind[w0:w1], surfaces.prm[w0:w1], surfaces.axis[w0:w1], surfaces.sign[w0:w1],
                      surfaces.method[w0:w1], surfaces.on[w0:w1], surfaces.rng[w0:w1], surfaces.has_side[w0:w1])


@njit(cache=True, error_model="numpy")
def axis_paths(js, world, points, wraps, surfaces, fits, a_off, out, out_inside):
    """Axis control points of path muscles ``js``, as :meth:`PathModel.control_points`:

    world     : (F, B, 4, 4)
    points    : :class:`PathPoints`; wraps :class:`Wraps` and surfaces
                :class:`~axdf_cli.model.paths.wrap.Surfaces` (ΣW rows, ``rng`` as PathModel's)
    fits      : :class:`Fits`
    outputs   : out (F, ΣN, 3) rows a_off[j] ..; out_inside (M, F) the index + 1 of a
                surface the path could not wrap over (an end point inside it), 0 if none

    Points: ``einsum('fpck,fpk->fpc', R, loc) + t`` (``0 + ((r0 l0 + r2 l2) + r1 l1)``), the
    surfaces' transforms ``einsum('fwij,wjk->fwik')`` (in order from 0), their side points
    ``einsum('fwck,wk->fwc')`` (``0 + ((p0 + p2) + (p1 + p3))``), the fit in order.
    """
    p_off, pbones, loc, active = points
    w_off, wbones, wlocal, side_bones, side_at = wraps
    k_off, fractions, fit_off, fit = fits
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
        current = np.zeros((nf, npt + 2 * nw, 3))
        count = np.zeros(nf, dtype=np.int64)
        W.wrapped_paths(pts, act, xf, side, _rows_of(surfaces, w0, w1), fractions[k0:k1],
                        W.PathOut(samples, length, inside, current, count))
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
    """The insertion roll's arctan2 arguments (y, x) (as :func:`axdf_cli.model.rmf.signed_angle`):
    the angle from the propagated r_end to the insertion bone's reference ``rot @ local`` made
    ⟂ t_end (into tgt (3,), scratch)."""
    _start_vector(rot, local, t_end[0], t_end[1], t_end[2], tgt)
    a0, a1, a2 = r_end[0], r_end[1], r_end[2]
    c0 = a1 * tgt[2] - a2 * tgt[1]
    c1 = a2 * tgt[0] - a0 * tgt[2]
    c2 = a0 * tgt[1] - a1 * tgt[0]
    out[0] = _dot(c0, c1, c2, t_end[0], t_end[1], t_end[2])
    out[1] = _dot(a0, a1, a2, tgt[0], tgt[1], tgt[2])


@njit(cache=True, error_model="numpy")
def frames_pass(js, p, world, a_off, samples, bound, bind_j, gauss, anchors, rtol2, out):
    """Step 2 of the module doc for the muscles ``js`` (K,) and every frame of the chunk:

    p          : (F, ΣN, 3)  axis control points (muscle j: rows a_off[j] .. a_off[j+1])
    world      : (F, B, 4, 4) bone transforms (the origin bone's start vector, the insertion roll)
    samples    : :class:`Basis` of the RMF samples
    bound      : :class:`Basis` at the bound points' parameters; bind_j (ΣQ,) the sample each
                 bound point's frame is reflected from
    gauss      : :class:`Quadrature` of the arc length
    anchors    : :class:`Anchors`; rtol2 the reflection's relative tolerance, squared
    out        : :class:`FrameOut`; its length is sum_g weight_g |C'(t_g)|, added in order
                 (numpy's ``@`` is OpenBLAS's dot, whose order changes with the number of
                 frames: this sum may differ from it in the last bit)

    Frames run innermost, LANES at a time, in arrays whose last axis is the frame, so that
    the compiler makes each operation one vector instruction over the frames: every frame
    still gets exactly the scalar sequence of operations (same bits as one frame alone).
    """
    s_off, bs_idx, bs_w, dbs_idx, dbs_w = samples
    q_off, bb_idx, bb_w, dbb_idx, dbb_w = bound
    g_off, dbg_idx, dbg_w, gw = gauss
    origin, insertion, r0_local, rend_local = anchors
    out_q, out_ends, out_roll, out_length = out
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
def roll_pass(js, p, world, a_off, coarse, anchors, rtol2, out_roll):
    """The insertion roll's arctan2 arguments alone (M, F, 2), from the samples of the
    :class:`Basis` ``coarse`` (the twist references'): :func:`frames_pass` without the
    bound points."""
    s_off, bs_idx, bs_w, dbs_idx, dbs_w = coarse
    origin, insertion, r0_local, rend_local = anchors
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
