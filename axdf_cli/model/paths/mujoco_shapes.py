"""MuJoCo's spatial-tendon wrapping (``mju_wrap`` in MuJoCo's engine_util_misc.c; our own
implementation of the same steps) of one segment over a sphere or an infinite cylinder, in the
surface's frame: (code, number of arc points, surface length), the arc's points into ``arc``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from axdf_cli.model.paths.geometry import MANDATORY, NO_WRAP, cross, dot, unit

_MJ_MINVAL = 1e-15


@njit(cache=True)
def _mj_intersect(p1x, p1y, p2x, p2y, p3x, p3y, p4x, p4y):
    """Whether 2D segments p1p2 and p3p4 intersect (MuJoCo's is_intersect)."""
    det = (p4y - p3y) * (p2x - p1x) - (p4x - p3x) * (p2y - p1y)
    if abs(det) < _MJ_MINVAL:
        return False
    a = ((p4x - p3x) * (p1y - p3y) - (p4y - p3y) * (p1x - p3x)) / det
    b = ((p2x - p1x) * (p1y - p3y) - (p2y - p1y) * (p1x - p3x)) / det
    return 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0


@njit(cache=True)
def _mj_circle(e, side, has_side, radius, pnt):
    """MuJoCo's 2D circle wrap of the ends e = (x0, y0, x1, y1): tangent points into pnt (4,)
    and the signed arc angle from the first to the second (counter-clockwise positive);
    returns (ok, angle)."""
    sq0 = e[0] * e[0] + e[1] * e[1]
    sq1 = e[2] * e[2] + e[3] * e[3]
    sqr = radius * radius
    if sq0 < sqr or sq1 < sqr or radius < _MJ_MINVAL:
        return False, 0.0
    dx = e[2] - e[0]
    dy = e[3] - e[1]
    dd = dx * dx + dy * dy
    if dd < _MJ_MINVAL:
        return False, 0.0
    a = -(dx * e[0] + dy * e[1]) / dd
    a = min(max(a, 0.0), 1.0)
    tx = a * dx + e[0]
    ty = a * dy + e[1]
    if tx * tx + ty * ty > sqr and (not has_side or side[0] * tx + side[1] * ty >= 0.0):
        return False, 0.0
    s0 = math.sqrt(sq0 - sqr)
    s1 = math.sqrt(sq1 - sqr)
    sol = np.empty((2, 4))
    good = np.empty(2)
    for i in range(2):
        sg = 1.0 if i == 0 else -1.0
        sol[i, 0] = (e[0] * sqr + sg * radius * e[1] * s0) / sq0
        sol[i, 1] = (e[1] * sqr - sg * radius * e[0] * s0) / sq0
        sol[i, 2] = (e[2] * sqr - sg * radius * e[3] * s1) / sq1
        sol[i, 3] = (e[3] * sqr + sg * radius * e[2] * s1) / sq1
        if has_side:
            ux = sol[i, 0] + sol[i, 2]
            uy = sol[i, 1] + sol[i, 3]
            un = math.sqrt(ux * ux + uy * uy)
            if un < _MJ_MINVAL:  # mju_normalize: a vector too short becomes (1, 0)
                ux, uy = 1.0, 0.0
            else:
                ux, uy = ux / un, uy / un
            good[i] = ux * side[0] + uy * side[1]
        else:
            ux = sol[i, 0] - sol[i, 2]
            uy = sol[i, 1] - sol[i, 3]
            good[i] = -(ux * ux + uy * uy)
        if _mj_intersect(e[0], e[1], sol[i, 0], sol[i, 1], e[2], e[3], sol[i, 2], sol[i, 3]):
            good[i] = -10000.0
    i = 0 if good[0] > good[1] else 1
    for k in range(4):
        pnt[k] = sol[i, k]
    if _mj_intersect(e[0], e[1], pnt[0], pnt[1], e[2], e[3], pnt[2], pnt[3]):
        return False, 0.0
    # length_circle: the angle between the points, the long way when the solution says so
    n0 = math.sqrt(pnt[0] * pnt[0] + pnt[1] * pnt[1])
    n1 = math.sqrt(pnt[2] * pnt[2] + pnt[3] * pnt[3])
    c = (pnt[0] * pnt[2] + pnt[1] * pnt[3]) / (n0 * n1)
    ang = math.acos(min(1.0, max(-1.0, c)))
    cross = pnt[1] * pnt[2] - pnt[0] * pnt[3]
    z = -cross  # > 0: the short way is counter-clockwise
    direction = 1.0 if z >= 0.0 else -1.0
    if (cross > 0.0 and i == 1) or (cross < 0.0 and i == 0):
        return True, -direction * (2.0 * math.pi - ang)
    return True, direction * ang


@njit(cache=True)
def _mj_inside(e, radius, pnt):
    """MuJoCo's 2D inside wrap (a side point inside the surface): the one contact point into
    pnt[0:2] = pnt[2:4]; False when the path does not wrap."""
    len0 = math.sqrt(e[0] * e[0] + e[1] * e[1])
    len1 = math.sqrt(e[2] * e[2] + e[3] * e[3])
    dx = e[2] - e[0]
    dy = e[3] - e[1]
    dd = dx * dx + dy * dy
    if len0 <= radius or len1 <= radius or radius < _MJ_MINVAL or len0 < _MJ_MINVAL or len1 < _MJ_MINVAL:
        return False
    if dd > _MJ_MINVAL:
        a = -(dx * e[0] + dy * e[1]) / dd
        if 0.0 < a < 1.0:
            tx = e[0] + a * dx
            ty = e[1] + a * dy
            if math.sqrt(tx * tx + ty * ty) <= radius:
                return False
    px = 0.5 * (e[0] + e[2])
    py = 0.5 * (e[1] + e[3])
    pn = math.sqrt(px * px + py * py)
    if pn < _MJ_MINVAL:
        px, py = 1.0, 0.0
    else:
        px, py = px / pn, py / pn
    pnt[0] = pnt[2] = radius * px
    pnt[1] = pnt[3] = radius * py
    A = radius / len0
    B = radius / len1
    cos_g = (len0 * len0 + len1 * len1 - dd) / (2.0 * len0 * len1)
    if cos_g < -1.0 + _MJ_MINVAL:
        return False
    if cos_g > 1.0 - _MJ_MINVAL:
        return True
    g = math.acos(cos_g)
    z = 1.0 - 1e-7
    f = math.asin(A * z) + math.asin(B * z) - 2.0 * math.asin(z) + g
    if f > 0.0:
        return True
    it = 0
    while it < 20 and abs(f) > 1e-6:
        df = (A / max(_MJ_MINVAL, math.sqrt(1.0 - z * z * A * A)) + B / max(_MJ_MINVAL, math.sqrt(1.0 - z * z * B * B))
              - 2.0 / max(_MJ_MINVAL, math.sqrt(1.0 - z * z)))
        if df > -_MJ_MINVAL:
            return True
        z1 = z - f / df
        if z1 > z:
            return True
        z = z1
        f = math.asin(A * z) + math.asin(B * z) - 2.0 * math.asin(z) + g
        if f > 1e-6:
            return True
        it += 1
    if it >= 20:
        return True
    if e[0] * e[3] - e[1] * e[2] > 0.0:
        vx, vy = e[0] / len0, e[1] / len0
        ang = math.asin(z) - math.asin(A * z)
    else:
        vx, vy = e[2] / len1, e[3] / len1
        ang = math.asin(z) - math.asin(B * z)
    pnt[0] = pnt[2] = radius * (math.cos(ang) * vx - math.sin(ang) * vy)
    pnt[1] = pnt[3] = radius * (math.sin(ang) * vx + math.cos(ang) * vy)
    return True


@njit(cache=True)
def mujoco(p0, p1, radius, cylinder, side, has_side, arc):
    """Wrap segment p0-p1 (surface frame) by MuJoCo's rules (mju_wrap): (code, arc points,
    surface length). ``side``: the side point in the surface frame (used when has_side)."""
    n0 = math.sqrt(dot(p0, p0))
    n1 = math.sqrt(dot(p1, p1))
    if n0 < _MJ_MINVAL or n1 < _MJ_MINVAL:
        return NO_WRAP, 0, 0.0
    ax0 = np.zeros(3)
    ax1 = np.zeros(3)
    if not cylinder:
        ax0 = p0 / n0
        nrm = cross(p0, p1)
        nn = math.sqrt(dot(nrm, nrm))
        if nn < _MJ_MINVAL:
            i = 0
            if abs(ax0[1]) > abs(ax0[0]) and abs(ax0[1]) > abs(ax0[2]):
                i = 1
            if abs(ax0[2]) > abs(ax0[0]) and abs(ax0[2]) > abs(ax0[1]):
                i = 2
            tmp = np.ones(3)
            tmp[i] = 0.0
            nrm = unit(cross(ax0, tmp))
        else:
            nrm = nrm / nn
        ax1 = unit(cross(nrm, ax0))
    else:
        ax0[0] = 1.0
        ax1[1] = 1.0
    e = np.array([dot(p0, ax0), dot(p0, ax1), dot(p1, ax0), dot(p1, ax1)])
    sd = np.zeros(2)
    inside = False
    if has_side:
        sd[0] = dot(side, ax0)
        sd[1] = dot(side, ax1)
        sn = math.sqrt(sd[0] * sd[0] + sd[1] * sd[1])
        if sn < _MJ_MINVAL:
            sd[0], sd[1] = 1.0, 0.0
        else:
            sd /= sn
        sd *= radius
        inside = math.sqrt(dot(side, side)) < radius
    pnt = np.empty(4)
    if inside:
        ok = _mj_inside(e, radius, pnt)
        theta = 0.0
    else:
        ok, theta = _mj_circle(e, sd, has_side, radius, pnt)
    if not ok:
        return NO_WRAP, 0, 0.0
    wlen = radius * abs(theta)
    z0 = 0.0
    z1 = 0.0
    if cylinder:
        l0 = math.sqrt((p0[0] - pnt[0]) ** 2 + (p0[1] - pnt[1]) ** 2)
        l1 = math.sqrt((p1[0] - pnt[2]) ** 2 + (p1[1] - pnt[3]) ** 2)
        tot = l0 + wlen + l1
        z0 = p0[2] + (p1[2] - p0[2]) * l0 / tot if tot > 0.0 else p0[2]
        z1 = p0[2] + (p1[2] - p0[2]) * (l0 + wlen) / tot if tot > 0.0 else p0[2]
    n = arc.shape[0] - 1
    for k in range(n + 1):
        f = k / n
        c = math.cos(theta * f)
        s = math.sin(theta * f)
        x = c * pnt[0] - s * pnt[1]
        y = s * pnt[0] + c * pnt[1]
        arc[k] = x * ax0 + y * ax1
        if cylinder:
            arc[k, 2] = z0 + f * (z1 - z0)
    if cylinder:
        wlen = math.sqrt(wlen * wlen + (z1 - z0) ** 2)
    return MANDATORY, n + 1, wlen
