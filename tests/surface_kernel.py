"""The muscle surface of one muscle, frame by frame (numba): the compiled form of the surface
steps that ``tests/test_kernel.py`` holds against the numpy formulation in
``tests/reference_surface.py``, and that ``tests/reference_model.py`` uses to form step 1b.

For every frame (:func:`surface_frame`): build the control net [origin pole, sections...,
insertion pole] of the fixed part A and the volume-scaled part W, tessellate both
(separable: along, then around, 3 basis functions each way), accumulate the mesh volume's
cubic over the quads, solve V(s) = V0 (``exact``), form the final grid A + s W, and write
vertices, outward normals and volume, with the kernels the run shares
(:mod:`axdf_cli.model.kernels`). The run itself makes the surface in the batch pass
(:mod:`axdf_cli.model.batch_surface`), which ``tests/test_batch.py`` holds to these bytes.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from axdf_cli.model.kernels import pole_normals, ring_vertices, solve_scale, volume_cubic


@njit(cache=True)
def _fill_net(net_a, net_w, fixed, scaled, pole0, pole1, f):
    """The control net of frame f, fixed part A and scaled part W (m, 8, 3): pole
    rows (A = the axis end, W = 0) around the bound section control points."""
    m = net_a.shape[0]
    for j in range(8):
        for c in range(3):
            net_a[0, j, c] = pole0[f, c]
            net_a[m - 1, j, c] = pole1[f, c]
            net_w[0, j, c] = 0.0
            net_w[m - 1, j, c] = 0.0
    for k in range(m - 2):
        for j in range(8):
            for c in range(3):
                net_a[k + 1, j, c] = fixed[f, 8 * k + j, c]
                net_w[k + 1, j, c] = scaled[f, 8 * k + j, c]


@njit(cache=True)
def _tessellate(net_a, net_w, u_idx, u_w, v_idx, v_w, ta, tw, ga, gw):
    """Separable tessellation of both nets into grids ga, gw (U, A, 3): along
    (T[u, j] = sum_i Bu[u, i] net[i, j]), then around (G[u, a] = sum_k Bv[a, k] T[u, k])."""
    nu = u_idx.shape[0]
    na = v_idx.shape[0]
    for u in range(nu):
        for j in range(8):
            for c in range(3):
                sa = 0.0
                sw = 0.0
                for i in range(3):
                    wgt = u_w[u, i]
                    sa += wgt * net_a[u_idx[u, i], j, c]
                    sw += wgt * net_w[u_idx[u, i], j, c]
                ta[u, j, c] = sa
                tw[u, j, c] = sw
    for u in range(nu):
        for a in range(na):
            for c in range(3):
                sa = 0.0
                sw = 0.0
                for k in range(3):
                    wgt = v_w[a, k]
                    sa += wgt * ta[u, v_idx[a, k], c]
                    sw += wgt * tw[u, v_idx[a, k], c]
                ga[u, a, c] = sa
                gw[u, a, c] = sw


@njit(cache=True)
def surface_frame(fixed, scaled, pole0, pole1, end0, end1, u_idx, u_w, v_idx, v_w, exact, v0, s0, s_min, s_max,
                  iters, rtol, net_a, net_w, ta, tw, ga, gw, out_v, out_n, f):
    """Frame f of one muscle (Q = 8 N bound points, U rows, A columns, m = N + 2):

    fixed, scaled : (F, Q, 3)  bound control points: the part that keeps its size, and the
                    part multiplied by the section scale s
    pole0, pole1  : (F, 3)     axis ends (the pole rows of the net)
    end0, end1    : (F, 3)     outward axis directions at the poles (-T(0), T(1))
    u_idx, u_w    : (U, 3)     along basis (rational), sparse rows over the m net rows
    v_idx, v_w    : (A, 3)     around basis (closed), sparse rows over the 8 columns
    exact, v0     : whether to solve for the scale that gives volume v0
    s0            : frame f's starting scale (the paper's sqrt(l0/l1), or 1)
    scratch       : net_a, net_w (m, 8, 3); ta, tw (U, 8, 3); ga, gw (U, A, 3)
    outputs       : out_v[f], out_n[f] (V, 3) with V = 2 + (U-2) A
    returns       : (volume, scale s, no-solution flag)

    The pipeline: net (1), tessellation (2), volume cubic (3), scale (4, ``exact`` only),
    vertices and ring normals of A + s W (5), pole normals (6).
    """
    nu = u_idx.shape[0]
    na = v_idx.shape[0]
    _fill_net(net_a, net_w, fixed, scaled, pole0, pole1, f)
    _tessellate(net_a, net_w, u_idx, u_w, v_idx, v_w, ta, tw, ga, gw)
    c0, c1, c2, c3 = volume_cubic(ga, gw)
    s = s0
    bad = False
    if exact:
        s, bad = solve_scale(c0, c1, c2, c3, v0, s0, iters, rtol)
    sc = min(max(s, s_min), s_max)
    volume = ((c3 * sc + c2) * sc + c1) * sc + c0
    for u in range(nu):
        for a in range(na):
            for c in range(3):
                ga[u, a, c] += sc * gw[u, a, c]
    ring_vertices(ga, out_v, out_n, f)
    pole_normals(ga, end0, end1, out_n, f)
    return volume, s, bad


@njit(cache=True)
def surface_stage(fixed, scaled, pole0, pole1, end0, end1, u_idx, u_w, v_idx, v_w,
                  exact, v0, s_in, s_min, s_max, iters, rtol,
                  out_v, out_n, out_vol, out_s, out_bad):
    """:func:`surface_frame` over the F frames: fixed, scaled (F, Q, 3); pole0, pole1, end0,
    end1 (F, 3); s_in (F,) starting scales (the paper's sqrt(l0/l1), or 1); exact: solve for
    the scale that keeps volume v0; outputs out_v, out_n (F, V, 3) with V = 2 + (U-2) A;
    out_vol, out_s (F,); out_bad (F,) no solution (the start scale kept)."""
    nf = fixed.shape[0]
    nu = u_idx.shape[0]
    na = v_idx.shape[0]
    m = fixed.shape[1] // 8 + 2
    net_a = np.zeros((m, 8, 3))
    net_w = np.zeros((m, 8, 3))
    ta = np.empty((nu, 8, 3))
    tw = np.empty((nu, 8, 3))
    ga = np.empty((nu, na, 3))
    gw = np.empty((nu, na, 3))
    for f in range(nf):
        vol, s, bad = surface_frame(fixed, scaled, pole0, pole1, end0, end1, u_idx, u_w, v_idx, v_w, exact, v0,
                                    s_in[f], s_min, s_max, iters, rtol, net_a, net_w, ta, tw, ga, gw, out_v, out_n, f)
        out_vol[f] = vol
        out_s[f] = s
        out_bad[f] = bad
