"""B-spline basis matrices: clamped (open uniform) and closed (periodic uniform).

Basis functions follow the Cox-de Boor recurrence and its derivative formula (The NURBS
Book, Piegl & Tiller, eqs. 2.5 and 2.9), evaluated for many parameters at once. A curve is
then a matrix product: ``C(t) = B(t) @ P`` with ``B`` of shape (S, n) and ``P`` (n, 3),
so basis matrices are computed once per muscle and reused for every frame.
"""
from __future__ import annotations

import numpy as np


def clamped_knots(n_ctrl: int, degree: int = 2) -> np.ndarray:
    """Open uniform knot vector on [0, 1]: (n_ctrl + degree + 1,) float64."""
    if n_ctrl <= degree:
        raise ValueError(f"a degree-{degree} B-spline needs more than {degree} control points, got {n_ctrl}")
    inner = np.linspace(0.0, 1.0, n_ctrl - degree + 1)
    return np.concatenate([np.zeros(degree), inner, np.ones(degree)])


def _basis0(knots: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Degree-0 basis (S, m) where m = len(knots) - 1; t = knots[-1] belongs to the last span."""
    lo, hi = knots[:-1], knots[1:]
    n0 = ((lo[None, :] <= t[:, None]) & (t[:, None] < hi[None, :])).astype(np.float64)
    last = np.nonzero(hi > lo)[0][-1]  # last non-empty span
    at_end = t >= knots[-1]
    n0[at_end, :] = 0.0
    n0[at_end, last] = 1.0
    return n0


def _safe_div(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    out = np.zeros(np.broadcast(num, den).shape)
    np.divide(num, den, out=out, where=den != 0)
    return out


def _basis(knots: np.ndarray, k: int, t: np.ndarray) -> np.ndarray:
    """Degree-k basis functions at t: (S, len(knots) - 1 - k)."""
    n = _basis0(knots, t)
    m = len(knots) - 1
    for d in range(1, k + 1):
        i = np.arange(m - d)
        left = _safe_div(t[:, None] - knots[i], knots[i + d] - knots[i])
        right = _safe_div(knots[i + d + 1] - t[:, None], knots[i + d + 1] - knots[i + 1])
        n = left * n[:, :-1] + right * n[:, 1:]
    return n


def _dbasis(knots: np.ndarray, k: int, t: np.ndarray, deriv: int) -> np.ndarray:
    if deriv == 0:
        return _basis(knots, k, t)
    lower = _dbasis(knots, k - 1, t, deriv - 1)  # (S, m - k + 1)
    m = len(knots) - 1
    i = np.arange(m - k)
    a = _safe_div(np.full(len(i), float(k)), knots[i + k] - knots[i])
    b = _safe_div(np.full(len(i), float(k)), knots[i + k + 1] - knots[i + 1])
    return a * lower[:, :-1] - b * lower[:, 1:]


def basis_matrix(knots: np.ndarray, degree: int, t, deriv: int = 0) -> np.ndarray:
    """``deriv``-th derivative of every basis function at parameters ``t``: (S, n_ctrl)."""
    t = np.clip(np.atleast_1d(np.asarray(t, dtype=np.float64)), knots[degree], knots[-degree - 1])
    if deriv > degree:
        return np.zeros((len(t), len(knots) - degree - 1))
    return _dbasis(np.asarray(knots, dtype=np.float64), degree, t, deriv)


def periodic_quadratic_basis(n_ctrl: int, v) -> np.ndarray:
    """Closed uniform quadratic B-spline basis at v in [0, 1): (S, n_ctrl).

    Segment j = floor(n v) blends control points j, j+1, j+2 (mod n) with
    ((1-s)^2, 1 + 2s - 2s^2, s^2) / 2, s the local parameter: at v = j/n the curve is the
    midpoint of P_j and P_j+1.
    """
    v = np.mod(np.atleast_1d(np.asarray(v, dtype=np.float64)), 1.0)
    x = v * n_ctrl
    j = np.floor(x).astype(np.int64) % n_ctrl
    s = x - np.floor(x)
    out = np.zeros((len(v), n_ctrl))
    rows = np.arange(len(v))
    np.add.at(out, (rows, j), 0.5 * (1.0 - s) ** 2)
    np.add.at(out, (rows, (j + 1) % n_ctrl), 0.5 + s - s * s)
    np.add.at(out, (rows, (j + 2) % n_ctrl), 0.5 * s * s)
    return out


def rational(basis: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """NURBS basis ``R_i = w_i N_i / sum_j w_j N_j`` from a plain basis (S, n) and weights (n,)."""
    wb = basis * weights[None, :]
    return wb / wb.sum(axis=1, keepdims=True)


def gauss_legendre_params(knots: np.ndarray, degree: int, n_points: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature nodes and weights over [0, 1], n_points per non-empty knot span: (Q,), (Q,)."""
    x, w = np.polynomial.legendre.leggauss(n_points)
    spans = np.unique(knots[degree:-degree])
    a, b = spans[:-1], spans[1:]
    half = (b - a)[:, None] / 2.0
    t = (a[:, None] + half * (x[None, :] + 1.0)).ravel()
    weights = (half * w[None, :]).ravel()
    return t, weights
