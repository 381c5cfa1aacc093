"""The numpy formulation of the surface stage: the reference the compiled kernel
(``surface_kernel.py``, on :mod:`axdf_cli.model.kernels`) is tested against. Dense Kronecker tessellation, component-major
grids, whole-array cross products: slow, but written independently of the kernel's loops."""
from __future__ import annotations

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model.muscle import OCT


def _planar(g: np.ndarray) -> np.ndarray:
    """(F, U, A, 3) grid → component-major (3, F, U, A + 1) with the first column repeated."""
    c = np.moveaxis(g, -1, 0)
    return np.concatenate([c, c[..., :1]], axis=-1)


def _corners(g):
    """Views of the quad corners p00, p01, p10, p11 of a planar wrapped grid (3, F, U, A+1)."""
    return g[:, :, :-1, :-1], g[:, :, :-1, 1:], g[:, :, 1:, :-1], g[:, :, 1:, 1:]


def _cross(a, b):
    """Component-wise cross product of (3, ...) arrays (much faster than np.cross here)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _dot_sum(a, b) -> np.ndarray:
    """sum over the grid of a . b for (3, F, U, A) arrays → (F,)."""
    return (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).sum(axis=(1, 2))


def planar_volume(g: np.ndarray) -> np.ndarray:
    """Enclosed volume of a planar wrapped grid (3, F, U, A+1) → (F,) (divergence theorem).

    Each quad is the triangles (p00, p01, p10) and (p10, p01, p11), whose signed tetrahedra
    add up to p01 . (p10 x (p00 - p11)) / 6: one cross product per quad."""
    p00, p01, p10, p11 = _corners(g)
    return _dot_sum(p01, _cross(p10, p00 - p11)) / 6.0


def planar_volume_cubic(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Coefficients (F, 4) of V(s) = c0 + c1 s + c2 s^2 + c3 s^3 for the grid a + s w.

    V is the trilinear form p01 . (p10 x d) / 6 (d = p00 - p11) summed over quads; with
    each argument affine in s it expands into four sums."""
    a00, a01, a10, a11 = _corners(a)
    w00, w01, w10, w11 = _corners(w)
    ad, wd = a00 - a11, w00 - w11
    p = _cross(a10, ad)
    q = _cross(w10, wd)
    r = _cross(w10, ad) + _cross(a10, wd)
    return np.stack([_dot_sum(a01, p), _dot_sum(w01, p) + _dot_sum(a01, r),
                     _dot_sum(a01, q) + _dot_sum(w01, r), _dot_sum(w01, q)], axis=1) / 6.0


def planar_normals(g: np.ndarray, ends: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Outward unit vertex normals (3, F, U, A) of a planar wrapped grid (3, F, U, A+1).

    Ring vertices: the cross product of the central differences around and along
    (S_v x S_u points outwards). Pole vertices: the axis direction out of the muscle,
    ``ends = (-T(0), T(1))`` each (3, F), when given (a pointed end's apex faces along the
    axis; the fan of a strongly curved end can tilt past it), else the sum of their fan
    triangles' normals."""
    c = g[..., :-1]  # (3, F, U, A)
    sv = np.roll(c[:, :, 1:-1], -1, axis=3) - np.roll(c[:, :, 1:-1], 1, axis=3)
    su = c[:, :, 2:] - c[:, :, :-2]
    n = np.empty_like(c)
    n[:, :, 1:-1] = _cross(sv, su)
    for k, (row, nxt) in enumerate(((0, 1), (-1, -2))):
        ring = c[:, :, nxt]  # (3, F, A)
        pole = c[:, :, row, :1]
        fan = _cross(np.roll(ring, -1, axis=2) - pole, ring - pole).sum(axis=2)  # (3, F)
        fan = fan if row == 0 else -fan
        if ends is not None:  # a fan tilted more than 60 degrees off the axis: use the axis
            fan = fan / np.maximum(np.sqrt((fan * fan).sum(axis=0)), 1e-300)
            fan = np.where((fan * ends[k]).sum(axis=0) > 0.5, fan, ends[k])
        n[:, :, row] = fan[..., None]
    return n / np.maximum(np.sqrt(n[0] ** 2 + n[1] ** 2 + n[2] ** 2), 1e-300)


def planar_to_vertices(g: np.ndarray) -> np.ndarray:
    """(3, F, U, A[+1]) grid → (3, F, V) vertices (poles once, rings in order)."""
    c, f, u = g.shape[:3]
    a = g.shape[3]
    return np.concatenate([g[:, :, 0, :1], g[:, :, 1:-1, :].reshape(c, f, (u - 2) * a), g[:, :, -1, :1]], axis=2)


def grid_volume(g: np.ndarray) -> np.ndarray:
    """Enclosed volume of a grid surface (F, U, A, 3) → (F,)."""
    return planar_volume(_planar(g))


def grid_volume_cubic(a: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Coefficients (F, 4) of V(s) for the grid a + s w, both (F, U, A, 3)."""
    return planar_volume_cubic(_planar(a), _planar(w))


def grid_normals(g: np.ndarray) -> np.ndarray:
    """Area-weighted outward unit vertex normals of the grid (F, U, A, 3)."""
    return np.moveaxis(planar_normals(_planar(g)), 0, -1)


def _solve_cubic(coef: np.ndarray, v0: float, s0: np.ndarray):
    """Solve c0 + c1 s + c2 s^2 + c3 s^3 = v0 for s > 0 near s0 by safeguarded Newton: (F,), bad (F,)."""
    c0, c1, c2, c3 = coef.T
    s = s0.copy()
    for _ in range(tol.VOLUME_SOLVE_ITERS):
        f = ((c3 * s + c2) * s + c1) * s + c0 - v0
        df = (3.0 * c3 * s + 2.0 * c2) * s + c1
        ok = df > 0
        step = np.where(ok, f / np.where(ok, df, 1.0), 0.0)
        s_new = np.where(s - step > 0, s - step, 0.5 * s)
        if np.all(np.abs(s_new - s) <= tol.VOLUME_SOLVE_RTOL * np.abs(s)):
            s = s_new
            break
        s = s_new
    f = ((c3 * s + c2) * s + c1) * s + c0 - v0
    bad = ~(np.abs(f) <= 1e-6 * abs(v0)) | ~np.isfinite(s)
    s = np.where(bad, s0, s)
    return s, bad


def reference_surface(model, fixed, scaled, p, t, s0, v0):
    """What :func:`surface_kernel.surface_stage` computes, in numpy, from the bound
    control points fixed, scaled (F, Q, 3), the axis points p (F, n, 3; its ends are the poles),
    the unit tangents t (F, S, 3; its first and last give the pole normals' fallback), the
    start scales s0 (F,) and the volume v0 to keep (None: keep s0): (vertices, normals,
    volume, s, bad)."""
    nf = fixed.shape[0]
    m = len(model.spec.sections) + 2
    bv = np.concatenate([model.Bv, model.Bv[:1]])  # wrapped: column A repeats column 0
    # K[(m,j),(u,a)] = Bu[u,m] Bv[a,j]
    k = np.einsum("um,aj->mjua", model.Bu, bv).reshape(m * OCT, model.U * (model.A + 1))

    def tess(bound, poles):
        net = np.zeros((3, nf, m * OCT))
        net[:, :, OCT:-OCT] = np.moveaxis(bound, -1, 0)
        if poles:
            net[:, :, :OCT] = np.moveaxis(p[:, 0], -1, 0)[:, :, None]
            net[:, :, -OCT:] = np.moveaxis(p[:, -1], -1, 0)[:, :, None]
        return (net.reshape(3 * nf, m * OCT) @ k).reshape(3, nf, model.U, model.A + 1)

    a_grid, w_grid = tess(fixed, True), tess(scaled, False)
    coef = planar_volume_cubic(a_grid, w_grid)
    s, bad = (_solve_cubic(coef, v0, s0) if v0 is not None else (s0.copy(), np.zeros(nf, bool)))
    sc = np.clip(s, tol.SCALE_MIN, tol.SCALE_MAX)
    grid = a_grid + sc[None, :, None, None] * w_grid
    ends = (-np.moveaxis(t[:, 0], -1, 0), np.moveaxis(t[:, -1], -1, 0))
    verts = np.moveaxis(planar_to_vertices(grid[..., :-1]), 0, -1)
    norms = np.moveaxis(planar_to_vertices(planar_normals(grid, ends)), 0, -1)
    return verts, norms, planar_volume(grid), s, bad
