"""Rotation-minimizing frames by double reflection.

Wang, Jüttler, Zheng, Liu: "Computation of rotation minimizing frames", ACM Transactions on
Graphics 27(1), 2008, Algorithm 1. From a frame (t_i, r_i) at x_i, reflect in the bisector
plane of x_i, x_i+1, then in the plane that maps the reflected tangent onto t_i+1. The
global error is O(h^4) in the sample spacing h.

All functions are batched: leading dimensions (..., ) are frames × muscles.
"""
from __future__ import annotations

import numpy as np

_EPS = 1e-30
STEP_RTOL = 1e-10  # steps shorter than this times the coordinates' magnitude count as none


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # d[...] = sum_c a[..., c] b[..., c]
    return np.einsum("...c,...c->...", a, b)


def reflect_step(x0, t0, r0, x1, t1) -> np.ndarray:
    """One double-reflection step: reference vector at x1 from the frame (t0, r0) at x0.

    x0, t0, r0, x1, t1 : (..., 3) float64 (t unit tangents, r unit and orthogonal to t0)
    returns r1 : (..., 3) unit, orthogonal to t1.
    """
    v1 = x1 - x0
    c1 = _dot(v1, v1)[..., None]
    # A step below rounding noise has no direction: skip that reflection (threshold relative
    # to the coordinates' size, so a bound point that falls on a sample keeps its frame).
    scale = np.maximum(_dot(x0, x0), _dot(x1, x1))[..., None]
    ok1 = c1 > np.maximum(_EPS, STEP_RTOL ** 2 * scale)
    k1 = np.where(ok1, 2.0 / np.where(ok1, c1, 1.0), 0.0)
    r_l = r0 - k1 * _dot(v1, r0)[..., None] * v1
    t_l = t0 - k1 * _dot(v1, t0)[..., None] * v1
    v2 = t1 - t_l
    c2 = _dot(v2, v2)[..., None]
    ok2 = c2 > STEP_RTOL ** 2  # tangents are unit: a change below 1e-10 is rounding noise
    k2 = np.where(ok2, 2.0 / np.where(ok2, c2, 1.0), 0.0)
    r1 = r_l - k2 * _dot(v2, r_l)[..., None] * v2
    # re-orthonormalise against rounding drift (a no-op in exact arithmetic)
    r1 = r1 - _dot(r1, t1)[..., None] * t1
    return r1 / np.maximum(np.linalg.norm(r1, axis=-1, keepdims=True), _EPS)


def propagate(x: np.ndarray, t: np.ndarray, r0: np.ndarray) -> np.ndarray:
    """RMF reference vectors along sampled curves.

    x, t : (B, S, 3) sample positions and unit tangents; r0 : (B, 3) start vector ⟂ t[:, 0]
    returns r : (B, S, 3); the third axis is ``cross(t, r)``.

    Everything that does not depend on r (both reflection planes, t_L) is computed for all
    steps at once; the loop over samples only reflects r twice per step. Reflections keep
    length and angle, so r is made unit and ⟂ t once, at the end.
    """
    v1 = x[:, 1:] - x[:, :-1]  # (B, S-1, 3)
    c1 = _dot(v1, v1)
    scale = np.maximum(_dot(x[:, 1:], x[:, 1:]), _dot(x[:, :-1], x[:, :-1]))
    k1 = np.where(c1 > np.maximum(_EPS, STEP_RTOL ** 2 * scale), 2.0 / np.where(c1 > 0, c1, 1.0), 0.0)
    t_l = t[:, :-1] - (k1 * _dot(v1, t[:, :-1]))[..., None] * v1
    v2 = t[:, 1:] - t_l
    c2 = _dot(v2, v2)
    k2 = np.where(c2 > STEP_RTOL ** 2, 2.0 / np.where(c2 > 0, c2, 1.0), 0.0)
    a1 = k1[..., None] * v1  # r_L = r - (v1 . r) a1
    a2 = k2[..., None] * v2  # r' = r_L - (v2 . r_L) a2
    n = x.shape[1]
    r = np.empty_like(x)
    r[:, 0] = cur = r0
    for i in range(n - 1):
        cur = cur - (v1[:, i] * cur).sum(axis=1, keepdims=True) * a1[:, i]
        cur = cur - (v2[:, i] * cur).sum(axis=1, keepdims=True) * a2[:, i]
        r[:, i + 1] = cur
    r -= _dot(r, t)[..., None] * t
    return r / np.maximum(np.linalg.norm(r, axis=-1, keepdims=True), _EPS)


def perpendicular_unit(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The part of v (..., 3) orthogonal to unit t (..., 3), normalised."""
    p = v - _dot(v, t)[..., None] * t
    return p / np.maximum(np.linalg.norm(p, axis=-1, keepdims=True), _EPS)


def any_perpendicular(t: np.ndarray) -> np.ndarray:
    """A unit vector ⟂ t (..., 3): the first of the X, Y, Z axes within 0.8 of orthogonal
    (|t . axis| < 0.8, one always is), made perpendicular. Free of ties (an argmin over
    |t| would flip between equal components on rounding)."""
    axes = np.eye(3)
    k = np.argmax(np.abs(t) < 0.8, axis=-1)
    return perpendicular_unit(axes[k], t)


def signed_angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Angle (radians, (-pi, pi]) rotating a onto b about unit axis; a, b ⟂ axis: (...,)."""
    return np.arctan2(_dot(np.cross(a, b), axis), _dot(a, b))
