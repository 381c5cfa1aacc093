"""Step 3 of the batch pass (:mod:`axdf_cli.model.batch_kernels` has steps 1 and 2): the bound
control points and the surface of every muscle of a chunk of frames at once.

:func:`shape_pass`, per muscle and frame: the spread twist, the tension law, the
volume-scaled and fixed parts of the bound control points, then the surface
(:mod:`axdf_cli.model.kernels`: tessellation, the exact volume solve, vertices and normals).
Muscles are packed end to end as in step 2 (offsets ``*_off`` (M + 1,)).

Same bytes as the frame-by-frame kernels: every value is formed by the same floating-point
operations in the same order. The steps are laid out for vector instructions: frames run
innermost, LANES at a time, in the bound points; the surface's grids are laid out so that the
volume terms and normals are one long loop each (c-major, ghost columns around), with
unsigned indices where an index is computed (numba's negative-index wraparound keeps loops
scalar) and scratch arrays of fixed shape.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from axdf_cli.model.batch_kernels import LANES
from axdf_cli.model.kernels import quad_volume_terms, solve_scale

_U = np.uint64  # loop indices the compiler can vectorize over (no negative-index wraparound)


class Drive(NamedTuple):
    """What drives each muscle's surface in this chunk, (M, F) each but solve, v0 (M,)."""
    theta: np.ndarray  # the insertion roll on its branch (radians), spread along the axis by lam
    tension: np.ndarray  # effective tension e, clipped to [0, 1]
    scale0: np.ndarray  # the starting scale (the paper's sqrt(l0/l1), or 1)
    solve: np.ndarray  # bool: solve the scale for the volume v0 (``exact``)
    v0: np.ndarray  # the volume to keep


class Binding(NamedTuple):
    """The bound points of every muscle (ΣQ rows, muscle j's from off[j])."""
    off: np.ndarray  # (M + 1,)
    lam: np.ndarray  # (ΣQ,) rest arc fraction
    uvw: np.ndarray  # (ΣQ, 3) offset along the tangent, the reference vector and their cross product
    beta: np.ndarray  # (ΣQ,) belly weight
    bump: np.ndarray  # (ΣQ,) tension bump


class SurfaceBases(NamedTuple):
    """Each muscle's sparse surface bases, rows from u_off[j] and v_off[j]."""
    m_off: np.ndarray  # (M + 1,) net rows (sections + 2) of each muscle's surface
    u_off: np.ndarray  # (M + 1,)
    u_idx: np.ndarray  # (ΣU, 3) along, over the net rows
    u_w: np.ndarray
    v_off: np.ndarray  # (M + 1,)
    v_idx: np.ndarray  # (ΣA, 3) around, over the 8 columns
    v_w: np.ndarray


class ShapeParams(NamedTuple):
    """The tension law's gain, the scale's clip and the volume solve's iterations and tolerance."""
    gain: float
    s_min: float
    s_max: float
    iters: int
    rtol: float


class ShapeOut(NamedTuple):
    """Where :func:`shape_pass` writes (K muscles js, F frames)."""
    vert_off: np.ndarray  # (K + 1,) muscle js[k]'s block (F, V_j, 3) of v, n starts at element 3 F vert_off[k]
    v: np.ndarray  # flat float64: vertices
    n: np.ndarray  # flat float64: normals
    vol: np.ndarray  # (M, F) volume
    s: np.ndarray  # (M, F) scale (before the clip)
    bad: np.ndarray  # (M, F) bool: the volume solve found no root
    cp: np.ndarray  # (F, ΣQ, 3) the bound control points as tessellated (fixed + s scaled, s clipped),
    #                 or (0, 0, 3): not asked for


@njit(cache=True, error_model="numpy")
def _grid(net_a, net_w, u_idx, u_w, v_idx, v_w, ta, tw, ga, gw):
    """The separable tessellation of one frame (along, then around) into the layout the loops
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
        t0, t1, t2, t3 = quad_volume_terms((ax0, ax1, ax2), (wx0, wx1, wx2), (ay0, ay1, ay2), (wy0, wy1, wy2),
                                           (ad0, ad1, ad2), (wd0, wd1, wd2))
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
def shape_pass(js, p, a_off, frames, drive, binding, surface, params, out):
    """The bound control points and surfaces of the muscles ``js`` (K,) at every frame f:

    p, a_off : axis control points (F, ΣN, 3), muscle j's rows from a_off[j] (the surface's
               poles are the axis ends)
    frames   : :class:`~axdf_cli.model.batch_kernels.FrameOut` of step 2: the bound points'
               position, tangent and untwisted reference (q), the unit tangents at the ends
    drive    : :class:`Drive`; binding :class:`Binding`; surface :class:`SurfaceBases`;
               params :class:`ShapeParams`
    out      : :class:`ShapeOut`

    Per bound point (MuscleModel.surface): the twist rotates (R, S) about T by theta lam; the
    offset is u T + v R + w S; tau = sqrt(1 + g e (2 b - 1) beta), h = e b; the part kept is
    C + (1 - beta) off + beta tau h s0 off, the part scaled by s is beta tau (1 - h) off. Then
    the surface, its steps laid out so that each runs as one long loop over the grid (which
    the compiler makes vector instructions): the same operations on the same numbers as
    :mod:`axdf_cli.model.kernels`, so the same bits.
    """
    fr, ends = frames.q, frames.ends
    theta, tension, scale0, solve, v0 = drive
    q_off, lam, uvw, beta, bump = binding
    m_off, u_off, u_idx, u_w, v_off, v_idx, v_w = surface
    gain, s_min, s_max, iters, rtol = params
    vert_off, out_v, out_n, out_vol, out_s, out_bad, out_cp = out
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
