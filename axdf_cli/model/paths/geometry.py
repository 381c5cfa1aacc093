"""Small vector helpers and the outcome codes of the wrap surfaces (:mod:`.wrap`), compiled (numba)."""
from __future__ import annotations

import math

import numpy as np
from numba import njit

#: What wrapping one segment over a surface gives: not wrapped, an end point inside the
#: surface (cannot wrap), wrapped (the path may choose another segment), wrapped because the
#: segment crosses the surface (wins at once).
NO_WRAP, INSIDE, WRAPPED, MANDATORY = 0, 1, 2, 3


@njit(cache=True)
def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def unit(a):
    n = math.sqrt(dot(a, a))
    if n == 0.0:
        return a * 0.0
    return a / n


@njit(cache=True)
def dsign(x):
    return 1 if x >= 0.0 else -1


@njit(cache=True)
def closest_on_line(pt, line_pt, line_dir):
    d = unit(line_dir)
    return line_pt + dot(pt - line_pt, d) * d


@njit(cache=True)
def intersect_lines(p1, p2, p3, p4):
    """Closest points of lines p1p2 and p3p4: (q1, s, q2, t, ok) with s, t fractions of the
    segments (WrapMath::IntersectLines)."""
    v1 = p2 - p1
    m1 = math.sqrt(dot(v1, v1))
    v1 = unit(v1)
    v2 = p4 - p3
    m2 = math.sqrt(dot(v2, v2))
    v2 = unit(v2)
    cp = cross(v1, v2)
    den = dot(cp, cp)
    if abs(den) < 1e-12:
        return p1, np.nan, p3, np.nan, False
    d = p3 - p1
    t = dot(cross(d, v1), cp) / den  # det[d; v1; cp]
    s = dot(cross(d, v2), cp) / den  # det[d; v2; cp]
    return p1 + s * v1, s / m1, p3 + t * v2, t / m2, True


@njit(cache=True)
def rotate(v, axis, angle):
    """v rotated by ``angle`` about the unit ``axis`` (Rodrigues)."""
    c = math.cos(angle)
    s = math.sin(angle)
    return v * c + cross(axis, v) * s + axis * dot(axis, v) * (1.0 - c)
