"""Contact's volume and output: every muscle's rings moved by their modes, the volume solved
exactly again (every point moves along its no-contact radial offset by sigma, the root of the
mesh volume's cubic V(sigma) = V, as in :func:`axdf_cli.model.batch_surface.shape_pass`), and the
grids' conversion from and to the surface stage's vertices and normals."""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from axdf_cli import tolerances as tol
from axdf_cli.model import kernels
from axdf_cli.model.contact.params import NMODES
from axdf_cli.model.contact.query import modes


@njit(cache=True, parallel=True)
def apply_and_solve(grid, rad, coef, off, nu, na, coff, active, target, max_step, ga, sigma):
    """Move every ring of an active muscle by its modes (the displacement's length soft-capped
    at max_step: max_step tanh(|D| / max_step)), then solve the volume exactly again (module
    doc, step 3): grid <- grid + D + sigma rad with V = target (rad: the no-contact shape's
    offsets from its ring centres, so the section grows about its centre). Muscle by muscle
    on numba's threads (:func:`_apply_one`; :func:`apply_and_solve_serial` on this thread
    alone); ga: (M, U, A, 3) scratch."""
    for m in prange(nu.shape[0]):
        if active[m]:
            _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga[m], sigma)


@njit(cache=True)
def apply_and_solve_serial(grid, rad, coef, off, nu, na, coff, active, target, max_step, ga, sigma):
    """:func:`apply_and_solve` on this thread alone."""
    for m in range(nu.shape[0]):
        if active[m]:
            _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga[m], sigma)


@njit(cache=True)
def _apply_one(m, grid, rad, coef, off, nu, na, coff, target, max_step, ga, sigma):
    """:func:`apply_and_solve` for muscle m (ga: its (U, A, 3) scratch)."""
    b = np.empty(NMODES)
    U = nu[m]
    A = na[m]
    o = off[m]
    for a in range(A):
        modes(2.0 * np.pi * a / A, b)
        for u in range(U):
            k = o + u * A + a
            d0 = 0.0
            d1 = 0.0
            d2 = 0.0
            for r in range(NMODES):
                d0 += b[r] * coef[coff[m] + u, r, 0]
                d1 += b[r] * coef[coff[m] + u, r, 1]
                d2 += b[r] * coef[coff[m] + u, r, 2]
            dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            f = 1.0 if dl < 1e-12 else max_step * np.tanh(dl / max_step) / dl
            grid[k, 0] += f * d0
            grid[k, 1] += f * d1
            grid[k, 2] += f * d2
            for c in range(3):
                ga[u, a, c] = grid[k, c]
    c0, c1, c2, c3 = kernels.volume_cubic(ga[:U, :A], rad[o:o + U * A].reshape(U, A, 3))
    s = solve_offset(c0, c1, c2, c3, target[m])
    sigma[m] += s
    for k in range(o, o + U * A):
        for c in range(3):
            grid[k, c] += s * rad[k, c]


@njit(cache=True)
def solve_offset(c0, c1, c2, c3, v0):
    """The root sigma nearest 0 of the cubic c0 + c1 s + c2 s^2 + c3 s^3 = v0 (the volume along
    the free points' radial offsets, increasing near 0): Newton from 0, safeguarded by
    bisection on a bracket grown from 0. 0 when there is none (the volume is then kept as is)."""
    f0 = c0 - v0
    if f0 == 0.0:
        return 0.0
    step = 0.05 if f0 < 0.0 else -0.05
    lo = 0.0
    hi = step
    fhi = ((c3 * hi + c2) * hi + c1) * hi + c0 - v0
    n = 0
    while fhi * f0 > 0.0 and n < 60:
        lo = hi
        hi *= 2.0
        fhi = ((c3 * hi + c2) * hi + c1) * hi + c0 - v0
        n += 1
    if fhi * f0 > 0.0:
        return 0.0
    a = min(lo, hi)
    b = max(lo, hi)
    fa = ((c3 * a + c2) * a + c1) * a + c0 - v0
    s = 0.5 * (a + b)
    for _ in range(100):
        fs = ((c3 * s + c2) * s + c1) * s + c0 - v0
        if abs(fs) <= tol.VOLUME_SOLVE_RTOL * abs(v0):
            break
        if (fs < 0.0) == (fa < 0.0):
            a = s
            fa = fs
        else:
            b = s
        df = (3.0 * c3 * s + 2.0 * c2) * s + c1
        sn = s - fs / df if df != 0.0 else 0.5 * (a + b)
        s = sn if a < sn < b else 0.5 * (a + b)
    return s


def vertices_to_grid(v: np.ndarray, U: int, A: int) -> np.ndarray:
    """(V, 3) vertices with collapsed poles → (U * A, 3) float64 grid rows (poles repeated;
    :func:`to_grid` for one muscle)."""
    grid = np.empty((U * A, 3))
    to_grid(np.ascontiguousarray(v, dtype=np.float64), np.array([0, len(v)], np.int64), np.array([0, U * A], np.int64),
             np.array([U], np.int64), np.array([A], np.int64), grid)
    return grid


@njit(cache=True)
def to_grid(verts, vo, off, nu, na, grid):
    """Every muscle's vertices (concatenated; muscle m's from vo[m], poles collapsed) into its
    grid rows from off[m] (:func:`vertices_to_grid`)."""
    for m in range(nu.shape[0]):
        U = nu[m]
        A = na[m]
        v0 = vo[m]
        for a in range(A):
            for c in range(3):
                grid[off[m] + a, c] = verts[v0, c]
                grid[off[m] + (U - 1) * A + a, c] = verts[vo[m + 1] - 1, c]
        for k in range((U - 2) * A):
            for c in range(3):
                grid[off[m] + A + k, c] = verts[v0 + 1 + k, c]


@njit(cache=True)
def grid_volumes(grid, off, nu, na, out):
    """out[m]: the mesh volume of muscle m's grid (:func:`grid_volume`)."""
    for m in range(nu.shape[0]):
        U = nu[m]
        A = na[m]
        ga = grid[off[m]:off[m + 1]].reshape(U, A, 3)
        out[m] = kernels.volume_cubic(ga, np.zeros_like(ga))[0]


def grid_volume(g: np.ndarray, U: int, A: int) -> float:
    """The mesh volume of one muscle's (U * A, 3) grid (:func:`grid_volumes` for one)."""
    out = np.empty(1)
    grid_volumes(np.ascontiguousarray(g, dtype=np.float64).reshape(U * A, 3), np.array([0, U * A], np.int64),
                  np.array([U], np.int64), np.array([A], np.int64), out)
    return float(out[0])


@njit(cache=True)
def normals(grid, off, nu, na, m, out_v, out_n):
    """Vertices and normals of muscle m's grid, as the surface stage writes them."""
    U = nu[m]
    A = na[m]
    o = off[m]
    ga = np.empty((U, A, 3))
    for u in range(U):
        for a in range(A):
            for c in range(3):
                ga[u, a, c] = grid[o + u * A + a, c]
    e0 = np.empty((1, 3))
    e1 = np.empty((1, 3))
    for c in range(3):
        s0 = 0.0
        s1 = 0.0
        for a in range(A):
            s0 += ga[1, a, c]
            s1 += ga[U - 2, a, c]
        e0[0, c] = ga[0, 0, c] - s0 / A
        e1[0, c] = ga[U - 1, 0, c] - s1 / A
    # unit outward directions at the poles, as the surface stage's (-T(0), T(1)): the fan's
    # normal is kept where it is within 60 degrees of them (unnormalized, a few mm long, they
    # replaced every pole's fan normal)
    for e in (e0, e1):
        el = np.sqrt(e[0, 0] ** 2 + e[0, 1] ** 2 + e[0, 2] ** 2)
        if el > 0.0:
            for c in range(3):
                e[0, c] /= el
    kernels.ring_vertices(ga, out_v, out_n, 0)
    kernels.pole_normals(ga, e0, e1, out_n, 0)


@njit(cache=True)
def _normals_into(grid, off, nu, na, m, vo, out_v, out_n):
    """:func:`normals` of muscle m into rows vo[m]:vo[m + 1] of out_v, out_n (V, 3)."""
    nv = vo[m + 1] - vo[m]
    v = np.empty((1, nv, 3))
    n = np.empty((1, nv, 3))
    normals(grid, off, nu, na, m, v, n)
    for k in range(nv):
        for c in range(3):
            out_v[vo[m] + k, c] = v[0, k, c]
            out_n[vo[m] + k, c] = n[0, k, c]


@njit(cache=True, parallel=True)
def normals_all(grid, off, nu, na, touched, vo, out_v, out_n):
    """:func:`_normals_into` for every touched muscle, muscle by muscle on numba's threads."""
    for m in prange(nu.shape[0]):
        if touched[m]:
            _normals_into(grid, off, nu, na, m, vo, out_v, out_n)


@njit(cache=True)
def normals_all_serial(grid, off, nu, na, touched, vo, out_v, out_n):
    """:func:`normals_all` on this thread alone."""
    for m in range(nu.shape[0]):
        if touched[m]:
            _normals_into(grid, off, nu, na, m, vo, out_v, out_n)

