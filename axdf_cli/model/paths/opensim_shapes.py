"""OpenSim's wrap surfaces (WrapCylinder, WrapSphere, WrapEllipsoid, WrapTorus): one segment of
a path wrapped over one surface, in the surface's frame, as OpenSim's ``wrapLine`` does it (the
same decision steps; our own implementation). Each returns (code, number of arc points,
surface length) and writes the surface path's points into ``arc``; :mod:`.wrap` says which
segment wraps and puts the path together.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from axdf_cli.model.paths.geometry import (INSIDE, MANDATORY, NO_WRAP, WRAPPED, closest_on_line, cross, dot, dsign,
                                           intersect_lines, rotate, unit)

#: The ellipsoid's methods of choosing the wrapping plane (WrapEllipsoid's ``method``).
HYBRID, MIDPOINT, AXIAL = 0, 1, 2

# WrapEllipsoid's hybrid method: the blend between the "Frans" point and the "fan" average
# (by how parallel the path is to a principal plane), the fan's rays and the blend near the ends.
_MU_BLEND_MIN = 0.7073
_MU_BLEND_MAX = 0.9
_NUM_FAN = 300
_SV_BLEND = 0.3

# ----------------------------------------------------------------------------- cylinder


@njit(cache=True)
def cylinder(p1, p2, radius, length, wrap_axis, wrap_sign, arc):
    """Wrap segment p1-p2 (cylinder frame) over the cylinder: (code, n arc points, length)."""
    dn = np.array([0.0, 0.0, 1.0])
    p0 = np.array([0.0, 0.0, -1.0])
    r2 = radius * radius
    constrained = wrap_sign != 0
    if p1[0] ** 2 + p1[1] ** 2 < r2 or p2[0] ** 2 + p2[1] ** 2 < r2:
        return INSIDE, 0, 0.0
    code = WRAPPED
    near12, t12, near00, _, _ = intersect_lines(p1, p2, np.array([0.0, 0.0, -0.5 * length]),
                                                 np.array([0.0, 0.0, 0.5 * length]))
    hit = dot(near12 - near00, near12 - near00) < r2 and 0.0 < t12 < 1.0
    if not constrained:
        if hit:
            code = MANDATORY
        else:
            return NO_WRAP, 0, 0.0
    p11 = closest_on_line(p1, p0, dn)
    p22 = closest_on_line(p2, p0, dn)

    def cands(p, pa):
        vv = p - pa
        dist_p = math.sqrt(dot(vv, vv))
        vv = unit(vv)
        sin_t = radius / dist_p
        d = radius * sin_t
        pp = pa + d * vv
        h = math.sqrt(r2 - d * d)
        uu = cross(dn, vv)
        return pp + h * uu, pp - h * uu, dist_p

    r1a, r1b, d1 = cands(p1, p11)
    r2a, r2b, d2 = cands(p2, p22)
    far_side = False
    long_wrap = False
    if constrained:
        ax = wrap_axis
        sg = wrap_sign
        if dsign(p1[ax]) == sg or dsign(p2[ax]) == sg:
            if hit:
                code = MANDATORY
            elif dsign(p1[ax]) != dsign(p2[ax]) and dsign(near12[ax]) != sg:
                code = WRAPPED
            else:
                return NO_WRAP, 0, 0.0
        r1am = r1a - p11
        r1bm = r1b - p11
        r2am = r2a - p22
        r2bm = r2b - p22
        alpha = math.acos(min(1.0, max(-1.0, dot(r1am, r2bm) / math.sqrt(dot(r1am, r1am) * dot(r2bm, r2bm)))))
        beta = math.acos(min(1.0, max(-1.0, dot(r1bm, r2am) / math.sqrt(dot(r1bm, r1bm) * dot(r2am, r2am)))))
        a_on = dsign(r1a[ax]) == sg
        b_on = dsign(r1b[ax]) == sg
        if (a_on and b_on) or (not a_on and not b_on and dsign(r2a[ax]) == sg):
            if a_on and b_on and dsign(r2a[ax]) != sg:
                r1, r2_ = r1a, r2b
                far_side = alpha > beta
            else:
                r1, r2_ = r1b, r2a
                far_side = not (alpha > beta)
        elif a_on and not b_on:
            r1, r2_ = r1a, r2b
            far_side = alpha > beta
        elif not a_on and b_on:
            r1, r2_ = r1b, r2a
            far_side = not (alpha > beta)
        elif dsign(r2b[ax]) == sg:
            r1, r2_ = r1a, r2b
            far_side = alpha > beta
        else:
            far_side = True
            if alpha > beta:
                r1, r2_ = r1a, r2b
            else:
                r1, r2_ = r1b, r2a
        sum_musc = (r1 - p1) + (r2_ - p2)
        sum_r = (r1 - p11) + (r2_ - p22)
        if dot(sum_r, sum_musc) < 0.0:
            long_wrap = True
    else:
        u1a = unit(r1a - p11)
        u1b = unit(r1b - p11)
        u2a = unit(r2a - p22)
        u2b = unit(r2b - p22)
        dot1 = dot(u1a, u2a)
        dot2 = dot(u1a, u2b)
        dot3 = dot(u1b, u2a)
        dot4 = dot(u1b, u2b)
        if dot1 > dot2 and dot1 > dot3 and dot1 > dot4:
            r1, r2_ = r1a, r2a
        elif dot2 > dot3 and dot2 > dot4:
            r1, r2_ = r1a, r2b
        elif dot3 > dot4:
            r1, r2_ = r1b, r2a
        else:
            r1, r2_ = r1b, r2b
    # apex: the cylinder edge in the plane of both ends and the axis point under the path
    t = d1 / (d1 + d2)
    mpt = p1 + t * (p2 - p1)
    axispt = closest_on_line(mpt, p0, dn)
    pn = unit(cross(unit(p1 - axispt), unit(p2 - axispt)))
    vert1 = unit(cross(dn, pn))
    vert2 = unit(cross(pn, dn))
    apex1 = axispt + radius * vert1
    apex2 = axispt + radius * vert2
    dd1 = dot(mpt - apex1, mpt - apex1)
    dd2 = dot(mpt - apex2, mpt - apex2)
    if far_side:
        apex = apex2 if dd1 < dd2 else apex1
    else:
        apex = apex1 if dd1 < dd2 else apex2
    # slide r1, r2 along the axis onto the plane through p1, p2 and the apex
    pn = unit(cross(unit(p1 - apex), unit(p2 - apex)))
    dpl = -dot(p1, pn)
    for k in range(2):
        r = r1 if k == 0 else r2_
        a = r - 10.0 * dn
        b = r + 10.0 * dn
        vec = b - a
        dp = dot(vec, pn)
        if abs(dp) >= 1e-5:
            tt = (-dpl - dot(pn, a)) / dp
            if -1e-5 <= tt <= 1.0 + 1e-5:
                rp = a + tt * vec
                if k == 0:
                    q = closest_on_line(rp, p11, p22 - p11)
                    if dot(q - p22, q - p22) < dot(p11 - p22, p11 - p22):
                        r1 = rp
                else:
                    q = closest_on_line(rp, p22, p11 - p22)
                    if dot(q - p11, q - p11) < dot(p22 - p11, p22 - p11):
                        r2_ = rp
    half = 0.5 * length
    if (r1[2] < -half or r1[2] > half) and (r2_[2] < -half or r2_[2] > half):
        return NO_WRAP, 0, 0.0
    # the helix from r1 to r2
    a1 = np.array([0.0, 0.0, r1[2]])
    a2 = np.array([0.0, 0.0, r2_[2]])
    axial = r2_[2] - r1[2]
    uu = r1 - a1
    vv = r2_ - a2
    theta = math.atan2(dot(cross(uu, vv), dn), dot(uu, vv))
    sense = 1.0
    if long_wrap:
        theta = 2.0 * math.pi - theta
        sense = -1.0
    n = arc.shape[0] - 1
    for i in range(n + 1):
        f = i / n
        arc[i] = rotate(r1, dn, sense * f * theta) + dn * (f * axial)
    return code, n + 1, math.sqrt((radius * theta) ** 2 + axial * axial)


# ----------------------------------------------------------------------------- sphere


@njit(cache=True)
def sphere(p1, p2, radius, wrap_axis, wrap_sign, arc):
    code = WRAPPED
    n1 = math.sqrt(dot(p1, p1))
    n2 = math.sqrt(dot(p2, p2))
    if n1 < radius or n2 < radius:
        return INSIDE, 0, 0.0
    ri = p1 - p2
    mp = -p2
    a = dot(ri, ri)
    b = -2.0 * dot(mp, ri)
    c = dot(mp, mp) - radius * radius
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return NO_WRAP, 0, 0.0
    l1 = (-b + math.sqrt(disc)) / (2.0 * a)
    l2 = (-b - math.sqrt(disc)) / (2.0 * a)
    if not (0.0 < l1 < 1.0) or not (0.0 < l2 < 1.0) or l1 < l2:
        return NO_WRAP, 0, 0.0
    p1p2 = unit(p1 - p2)
    hp2 = cross(p1p2, unit(p2))
    if math.sqrt(dot(hp2, hp2)) < 1e-5:
        return NO_WRAP, 0, 0.0  # the line runs through the centre: no plane to wrap in
    nrm = unit(hp2)

    def tangents(p, dist):
        y = unit(-p)
        z = cross(nrm, y)
        ang = math.asin(radius / dist)
        h = dist * math.cos(ang)
        # y rotated by +-ang about nrm (the plane's normal), scaled to the tangent length
        ya = y * math.cos(ang) - z * math.sin(ang)
        yb = y * math.cos(ang) + z * math.sin(ang)
        return p + h * ya, p + h * yb

    r1a, r1b = tangents(p1, n1)
    r2a, r2b = tangents(p2, n2)
    u1a, u1b, u2a, u2b = unit(r1a), unit(r1b), unit(r2a), unit(r2b)
    j1 = dot(u1a, u2a)
    j2 = dot(u1a, u2b)
    j3 = dot(u1b, u2a)
    j4 = dot(u1b, u2b)
    if j1 > j2 and j1 > j3 and j1 > j4:
        r1, r2, r11, r22 = r1a, r2a, r1b, r2b
    elif j2 > j3 and j2 > j4:
        r1, r2, r11, r22 = r1a, r2b, r1b, r2a
    elif j3 > j4:
        r1, r2, r11, r22 = r1b, r2a, r1a, r2b
    else:
        r1, r2, r11, r22 = r1b, r2b, r1a, r2a
    far_side = False
    if wrap_sign != 0:
        ax = wrap_axis
        sg = wrap_sign
        if dsign(p1[ax]) == sg or dsign(p2[ax]) == sg:
            # as OpenSim: tt is a distance along the unit direction (m), compared with 1
            ud = unit(p2 - p1)
            tt = dot(-p1, ud)
            mm = p1 + tt * ud
            if dot(mm, mm) < radius * radius and 0.0 < tt < 1.0:
                code = MANDATORY
            elif dsign(p1[ax]) != dsign(p2[ax]) and dsign(mm[ax]) != sg:
                code = WRAPPED
            else:
                return NO_WRAP, 0, 0.0
        if dsign(p1[ax]) != sg or dsign(p2[ax]) != sg:
            wax = np.zeros(3)
            wax[ax] = float(sg)
            sm = unit(-p1 - p2)
            if dot(u1a, sm) > dot(u1b, sm):
                r1, r11 = r1a, r1b
            else:
                r1, r11 = r1b, r1a
            if dot(u2a, sm) > dot(u2b, sm):
                r2, r22 = r2a, r2b
            else:
                r2, r22 = r2b, r2a
            sm = unit((r1 - p1) + (r2 - p2))
            if dot(sm, wax) < 0.0:
                r1, r2 = r11, r22
            if dot(r1 + r2, (r1 - p1) + (r2 - p2)) < 0.0:
                far_side = True
    r1n = unit(r1)
    r2n = unit(r2)
    angle = math.acos(min(1.0, max(-1.0, dot(r1n, r2n))))
    if far_side:
        angle = -(2.0 * math.pi - angle)
    axis = unit(cross(r1n, r2n))
    n = arc.shape[0] - 1
    for i in range(n + 1):
        arc[i] = rotate(r1, axis, angle * i / n)
    return code, n + 1, radius * abs(angle)


# ----------------------------------------------------------------------------- ellipsoid


@njit(cache=True)
def closest_xyz(a0, a1, a2, y0, y1, y2):
    """The point of the ellipsoid (semi-axes a0, a1, a2) closest to (y0, y1, y2), inside or
    outside, as a tuple: x_i = a_i^2 y_i / (t + a_i^2) with t the largest root of
    F(t) = sum (a_i y_i / (t + a_i^2))^2 - 1 (t > -min a_i^2). F is convex and decreasing
    there: Newton from a point left of the root (F >= 0; Eberly's start -a_k^2 + a_k |y_k| on
    the shortest axis k) climbs to it monotonically; bisection when y_k = 0 (or so small
    that the start rounds onto the pole -a_k^2). Scalars only
    (no allocation: the fan calls it 300 times per segment)."""
    e0, e1, e2 = a0 * a0, a1 * a1, a2 * a2
    if e0 <= e1 and e0 <= e2:
        ek, ak, yk = e0, a0, y0
    elif e1 <= e2:
        ek, ak, yk = e1, a1, y1
    else:
        ek, ak, yk = e2, a2, y2
    t = -ek + ak * abs(yk)
    newton = False
    if t + ek > 0.0:  # yk != 0 and not so small that t + ek rounds to 0 (bisection then)
        f = (a0 * y0 / (t + e0)) ** 2 + (a1 * y1 / (t + e1)) ** 2 + (a2 * y2 / (t + e2)) ** 2 - 1.0
        newton = f >= 0.0
    if newton:
        for _ in range(64):
            q0 = a0 * y0 / (t + e0)
            q1 = a1 * y1 / (t + e1)
            q2 = a2 * y2 / (t + e2)
            f = q0 * q0 + q1 * q1 + q2 * q2 - 1.0
            df = -2.0 * (q0 * q0 / (t + e0) + q1 * q1 / (t + e1) + q2 * q2 / (t + e2))
            if df == 0.0:
                break
            step = f / df
            t -= step
            if abs(step) <= 1e-15 * max(abs(t), ek):
                break
    else:
        lo = -ek
        hi = math.sqrt((a0 * y0) ** 2 + (a1 * y1) ** 2 + (a2 * y2) ** 2) + 1e-12
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            f = (a0 * y0 / (mid + e0)) ** 2 + (a1 * y1 / (mid + e1)) ** 2 + (a2 * y2 / (mid + e2)) ** 2
            if f > 1.0:
                lo = mid
            else:
                hi = mid
            if hi - lo <= 1e-16 * max(1.0, abs(hi)):
                break
        t = 0.5 * (lo + hi)
    return e0 * y0 / (t + e0), e1 * y1 / (t + e1), e2 * y2 / (t + e2)


@njit(cache=True)
def _ellipsoid_closest(a, y):
    x0, x1, x2 = closest_xyz(a[0], a[1], a[2], y[0], y[1], y[2])
    return np.array([x0, x1, x2])


@njit(cache=True)
def _plane_basis(vs, vs4):
    """A point o of the plane vs . x + vs4 = 0 (closest to the origin) and two unit vectors in it."""
    o = -vs4 * vs
    k = 0
    for i in range(1, 3):
        if abs(vs[i]) < abs(vs[k]):
            k = i
    h = np.zeros(3)
    h[k] = 1.0
    e1 = unit(cross(vs, h))
    e2 = cross(vs, e1)
    return o, e1, e2


@njit(cache=True)
def _ellipse_tangent(a, o, e1, e2, p, side_pt):
    """Tangent point, seen from p, of the ellipse where the plane (o, e1, e2) cuts the
    ellipsoid (semi-axes a), on the side of ``side_pt``. The conic in plane coordinates
    (x, y) is X^T C X = 0 with X = (x, y, 1); the tangent points lie on the polar of p."""
    c = np.zeros((3, 3))
    cols = np.empty((3, 3))  # world = o + x e1 + y e2: columns e1, e2, o
    for i in range(3):
        cols[i, 0] = e1[i]
        cols[i, 1] = e2[i]
        cols[i, 2] = o[i]
    for r in range(3):
        for s in range(3):
            v = 0.0
            for i in range(3):
                v += cols[i, r] * cols[i, s] / (a[i] * a[i])
            c[r, s] = v
    c[2, 2] -= 1.0
    px = dot(p - o, e1)
    py = dot(p - o, e2)
    # polar line l . X = 0
    l0 = c[0, 0] * px + c[0, 1] * py + c[0, 2]
    l1 = c[1, 0] * px + c[1, 1] * py + c[1, 2]
    l2 = c[2, 0] * px + c[2, 1] * py + c[2, 2]
    # a point and direction on the polar line
    den = l0 * l0 + l1 * l1
    if den == 0.0:
        return p, False
    q0 = -l2 * l0 / den
    q1 = -l2 * l1 / den
    d0 = -l1
    d1 = l0
    # (q + s d)^T C (q + s d) = 0
    A = c[0, 0] * d0 * d0 + 2 * c[0, 1] * d0 * d1 + c[1, 1] * d1 * d1
    B = 2.0 * (c[0, 0] * q0 * d0 + c[0, 1] * (q0 * d1 + q1 * d0) + c[1, 1] * q1 * d1 + c[0, 2] * d0 + c[1, 2] * d1)
    C = (c[0, 0] * q0 * q0 + 2 * c[0, 1] * q0 * q1 + c[1, 1] * q1 * q1 + 2 * c[0, 2] * q0 + 2 * c[1, 2] * q1
         + c[2, 2])
    disc = B * B - 4.0 * A * C
    if disc < 0.0 or A == 0.0:
        return p, False
    sq = math.sqrt(disc)
    best = p
    bestv = -1e300
    sx = dot(side_pt - o, e1) - px
    sy = dot(side_pt - o, e2) - py
    sn = math.sqrt(sx * sx + sy * sy)
    if sn > 0.0:
        sx /= sn
        sy /= sn
    for sgn in (-1.0, 1.0):
        s = (-B + sgn * sq) / (2.0 * A)
        x = q0 + s * d0
        y = q1 + s * d1
        # prefer the tangent point on side_pt's side: largest projection on the side direction
        dl = math.sqrt((x - px) ** 2 + (y - py) ** 2)
        v = ((x - px) * sx + (y - py) * sy) / dl if dl > 0.0 else 1.0
        if v > bestv:
            bestv = v
            best = o + x * e1 + y * e2
    return best, True


@njit(cache=True)
def _ellipsoid_arc(r1, r2, a, vs, vs4, far_side, arc):
    """Points of the surface path r1 → r2 in the wrapping plane (WrapEllipsoid's
    CalcDistanceOnEllipsoid: rays from a plane point a0 on the most normal axis)."""
    imax = 0
    for i in range(1, 3):
        if abs(vs[i]) > abs(vs[imax]):
            imax = i
    u = np.zeros(3)
    u[imax] = 1.0
    mu = -vs4 / dot(vs, u)
    a0 = mu * u
    ar1 = unit(r1 - a0)
    ar2 = unit(r2 - a0)
    phi0 = math.acos(min(1.0, max(-1.0, dot(ar1, ar2))))
    n = arc.shape[0] - 1
    dphi = -(2.0 * math.pi - phi0) / n if far_side else phi0 / n
    vsz = unit(cross(ar1, ar2))
    vsy = cross(vsz, ar1)
    arc[0] = r1
    arc[n] = r2
    for i in range(1, n):
        phi = i * dphi
        r = ar1 * math.cos(phi) + vsy * math.sin(phi)
        f1 = r / a
        f2 = a0 / a
        aa = dot(f1, f1)
        bb = 2.0 * dot(f1, f2)
        cc = dot(f2, f2) - 1.0
        mu3 = (-bb + math.sqrt(max(bb * bb - 4.0 * aa * cc, 0.0))) / (2.0 * aa)
        arc[i] = a0 + mu3 * r
    length = 0.0
    for i in range(n):
        d = arc[i + 1] - arc[i]
        length += math.sqrt(dot(d, d))
    return length


@njit(cache=True)
def ellipsoid(p1, p2, a, wrap_axis, wrap_sign, method, arc):
    p1e = -1.0
    p2e = -1.0
    for i in range(3):
        p1e += (p1[i] / a[i]) ** 2
        p2e += (p2[i] / a[i]) ** 2
    if p1e < -0.0001 or p2e < -0.0001:
        return INSIDE, 0, 0.0
    p1p2 = p1 - p2
    if abs(dot(unit(p1), unit(p2)) - 1.0) < 0.0001:
        return NO_WRAP, 0, 0.0
    f1 = p1p2 / a
    f2 = p2 / a
    aa = dot(f1, f1)
    bb = 2.0 * dot(f1, f2)
    cc = dot(f2, f2) - 1.0
    disc = bb * bb - 4.0 * aa * cc
    if disc < 0.0:
        return NO_WRAP, 0, 0.0
    l1 = (-bb + math.sqrt(disc)) / (2.0 * aa)
    l2 = (-bb - math.sqrt(disc)) / (2.0 * aa)
    if not (0.0 < l1 < 1.0) or not (0.0 < l2 < 1.0):
        return NO_WRAP, 0, 0.0
    r1 = p2 + l1 * p1p2
    r2 = p2 + l2 * p1p2
    r1r2 = r2 - r1
    mu = np.abs(unit(p1p2))
    # Frans: where the chord crosses each principal plane, and the closest surface point
    tq = np.empty(3)
    sv3 = np.empty((3, 3))
    c13 = np.empty((3, 3))
    for i in range(3):
        tq[i] = -r1[i] / r1r2[i] if r1r2[i] != 0.0 else np.inf
        sv3[i] = r1 + tq[i] * r1r2 if np.isfinite(tq[i]) else r1
        c13[i] = _ellipsoid_closest(a, sv3[i])
    best = 0
    for i in range(1, 3):
        if mu[i] > mu[best]:
            best = i
    fan_weight = -np.inf
    c1 = np.zeros(3)
    sv = np.zeros(3)
    if method == HYBRID or method == AXIAL:
        mub = mu[best]
        if method == HYBRID and mub > _MU_BLEND_MIN:
            s = 1.0
            if tq[best] < 0.0 or tq[best] > 1.0:
                s = 0.0
            elif tq[best] < _SV_BLEND:
                s = tq[best] / _SV_BLEND
            elif tq[best] > 1.0 - _SV_BLEND:
                s = (1.0 - tq[best]) / _SV_BLEND
            if s < 1.0:
                mub = _MU_BLEND_MIN + s * (mub - _MU_BLEND_MIN)
        if method == AXIAL or mub > _MU_BLEND_MIN:
            c1 = c13[best].copy()
            sv = sv3[best].copy()
        if method == HYBRID and mub < _MU_BLEND_MAX:
            mid = r1 + 0.5 * r1r2
            s0 = 0.0
            s1 = 0.0
            s2 = 0.0
            for i in range(1, _NUM_FAN - 1):
                ft = i / _NUM_FAN
                q0 = r1[0] + ft * r1r2[0]
                q1 = r1[1] + ft * r1r2[1]
                q2 = r1[2] + ft * r1r2[2]
                c0, c1_, c2 = closest_xyz(a[0], a[1], a[2], q0, q1, q2)
                d0, d1, d2 = c0 - q0, c1_ - q1, c2 - q2
                dn_ = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if dn_ > 0.0:
                    s0 += d0 / dn_
                    s1 += d1 / dn_
                    s2 += d2 / dn_
            vsum = unit(np.array([s0, s1, s2]))
            fan_c1 = mid + vsum
            if mub <= _MU_BLEND_MIN:
                c1 = _ellipsoid_closest(a, fan_c1)
                sv = mid
                fan_weight = 1.0
            else:
                tt = (mub - _MU_BLEND_MIN) / (_MU_BLEND_MAX - _MU_BLEND_MIN)
                c1b = _ellipsoid_closest(a, fan_c1)
                c1 = _ellipsoid_closest(a, tt * c1 + (1.0 - tt) * c1b)
                sv = tt * sv + (1.0 - tt) * mid
                fan_weight = 1.0 - tt
        mu[best] = mub
    else:
        sv = r1 + 0.5 * r1r2
        c1 = _ellipsoid_closest(a, sv)
    if wrap_sign != 0:
        ax = wrap_axis
        if dsign(c1[ax]) != wrap_sign:
            orig = c1[ax]
            c1[ax] = -c1[ax]
            if fan_weight == -np.inf:
                fan_weight = 1.0 - (mu[best] - _MU_BLEND_MIN) / (_MU_BLEND_MAX - _MU_BLEND_MIN)
            if fan_weight > 1.0:
                fan_weight = 1.0
            if fan_weight > 0.0:
                bis = 0.5 * (orig + c1[ax])
                c1[ax] = c1[ax] + fan_weight * (bis - c1[ax])
                c1 = _ellipsoid_closest(a, c1)
    vs = unit(cross(p1p2, p1 - c1))
    vs4 = -dot(vs, c1)
    o, e1, e2 = _plane_basis(vs, vs4)
    t1, ok1 = _ellipse_tangent(a, o, e1, e2, p1, c1)
    t2, ok2 = _ellipse_tangent(a, o, e1, e2, p2, c1)
    if not (ok1 and ok2):
        return NO_WRAP, 0, 0.0
    if abs(p1e) < 0.0001:
        t1 = p1.copy()
    if abs(p2e) < 0.0001:
        t2 = p2.copy()
    far = False
    length = _ellipsoid_arc(t1, t2, a, vs, vs4, far, arc)
    n = arc.shape[0]
    if wrap_sign != 0 and n > 2:
        if dot(unit(p1 - t1), unit(arc[1] - t1)) > 0.0 or dot(unit(p2 - t2), unit(arc[n - 2] - t2)) > 0.0:
            length = _ellipsoid_arc(t1, t2, a, vs, vs4, True, arc)
    return MANDATORY, n, length


# ----------------------------------------------------------------------------- torus


@njit(cache=True)
def torus(p1, p2, inner, outer, arc):
    """The segment wraps over the inner side of the tube when it passes through the hole:
    the tube there (radius ``outer``, centred on the ring of radius ``inner``) is treated as
    a cylinder along the tangent of the ring at the segment's closest approach."""
    d = p2 - p1
    if abs(d[2]) < 1e-12:
        return NO_WRAP, 0, 0.0
    tz = -p1[2] / d[2]
    if not (0.0 < tz < 1.0):
        return NO_WRAP, 0, 0.0
    hole = p1 + tz * d
    rho = math.sqrt(hole[0] ** 2 + hole[1] ** 2)
    if rho >= inner:
        return NO_WRAP, 0, 0.0
    ang = math.atan2(hole[1], hole[0]) if rho > 1e-12 else 0.0
    ring = np.array([inner * math.cos(ang), inner * math.sin(ang), 0.0])
    tang = np.array([-math.sin(ang), math.cos(ang), 0.0])
    radial = np.array([math.cos(ang), math.sin(ang), 0.0])
    zax = np.array([0.0, 0.0, 1.0])
    # local cylinder frame: X = -radial (towards the hole), Y = Z, Z = the ring tangent
    def to_cyl(p):
        q = p - ring
        return np.array([-dot(q, radial), dot(q, zax), dot(q, tang)])

    q1 = to_cyl(p1)
    q2 = to_cyl(p2)
    code, n, length = cylinder(q1, q2, outer, 1e6, 0, 1, arc)
    if code != INSIDE and n > 0:
        for i in range(n):
            v = arc[i]
            arc[i] = ring - v[0] * radial + v[1] * zax + v[2] * tang
    if code == INSIDE:
        return INSIDE, 0, 0.0
    return code, n, length
