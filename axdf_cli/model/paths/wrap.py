"""Wrap surfaces as OpenSim defines them (WrapCylinder, WrapSphere, WrapEllipsoid, WrapTorus),
and the wrapped path of a muscle, compiled (numba) and batched over frames.

Each surface is fixed in a bone, at a transform of its own (``at``, ``orient``): the cylinder
runs along its local Z (radius, length, centred), the sphere and the ellipsoid (semi-axes
a, b, c along X, Y, Z) sit at the origin, the torus lies in the XY plane (inner and outer
radius). A ``quadrant`` (``all``, ``+x``, ``-y`` ...) restricts wrapping to one side of a
local axis. One segment of the path wraps as OpenSim's ``wrapLine`` does it (the same
decision steps; our own implementation, batched over frames):

- cylinder: tangent candidates from each end in the plane normal to the axis, picked by
  quadrant (or the pair closest in direction), slid along the axis onto the plane through
  both ends and the apex; the surface path is the helix between them, length
  sqrt((r theta)^2 + axial^2), the long way round when the quadrant asks for it;
- sphere: tangent points in the plane through both ends and the centre, the great-circle
  arc between them (the far side when the quadrant asks for it);
- ellipsoid: the wrapping plane through both ends and a surface point c1 (``hybrid``:
  the "Frans" point where the path crosses the most parallel principal plane, blended with
  the "fan" average of closest-point directions; ``midpoint``; ``axial``), c1 flipped to
  the active quadrant; tangent points of that plane's ellipse seen from each end; the
  surface path runs over c1's side (the far side when the first try wraps the wrong way);
- torus: the segment wraps when it passes through the hole (``quadrant`` unused), over
  the inner tube, as a cylinder of the tube's radius laid along the segment's closest
  approach to the ring.

- ``mujoco_sphere``, ``mujoco_cylinder``: MuJoCo's spatial-tendon wrapping (``mju_wrap`` in
  MuJoCo's engine_util_misc.c; our own implementation of the same steps): both ends are
  taken into a plane (the sphere: the plane through both ends and the centre; the
  cylinder, which is infinite: the plane normal to its axis), the 2D circle wrap picks the
  tangent pair closer to the side point (``side``, MuJoCo's sidesite) or, without one, the
  shorter of the two; a segment that misses the circle, on the side point's side, is not
  wrapped; a side point inside the surface makes the path wrap *inside* it (one contact
  point, Newton on MuJoCo's equation); the cylinder's tangent heights are interpolated
  linearly along the path and its arc is a helix. ``quadrant`` and ``method`` do not apply.

A segment is not wrapped when its line misses the surface, or when the quadrant says no
(``noWrap``); when an end point lies inside the surface (``insideRadius``), the path
cannot wrap there: the frame is flagged and the straight segment kept.

Which segment and in which order (GeometryPath::applyWrapObjects): the path's active
points in order; for each wrap surface in turn, every segment between the first and last
active points of its ``range`` (1-based path point indices, -1 meaning the ends) is
tried; a segment that crosses the surface wins at once (``mandatoryWrap``), otherwise the
one that lengthens the path least; the two tangent points are inserted. With two or more
surfaces this repeats (at most 8 times) until the length changes by less than 0.5 mm.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

CYLINDER, SPHERE, ELLIPSOID, TORUS, MJ_SPHERE, MJ_CYLINDER = 0, 1, 2, 3, 4, 5
SHAPES = {"cylinder": CYLINDER, "sphere": SPHERE, "ellipsoid": ELLIPSOID, "torus": TORUS,
          "mujoco_sphere": MJ_SPHERE, "mujoco_cylinder": MJ_CYLINDER}
#: Shapes that wrap by MuJoCo's rules (``mju_wrap``) and may have a side point.
MUJOCO_SHAPES = ("mujoco_sphere", "mujoco_cylinder")
HYBRID, MIDPOINT, AXIAL = 0, 1, 2
METHODS = {"hybrid": HYBRID, "midpoint": MIDPOINT, "axial": AXIAL}
QUADRANTS = {"all": (0, 0)}
for _i, _ax in enumerate("xyz"):
    for _name, _sign in ((f"+{_ax}", 1), (_ax, 1), (f"-{_ax}", -1)):
        QUADRANTS[_name] = (_i, _sign)

NO_WRAP, INSIDE, WRAPPED, MANDATORY = 0, 1, 2, 3
#: Segments of the surface path between the tangent points (the arc is kept as a polyline).
ARC_SEGMENTS = 32
#: Wrapping repeats until the path length changes by less than this (m), at most 8 times.
LENGTH_CONVERGED = 0.0005
MAX_PASSES = 8

_MU_BLEND_MIN = 0.7073
_MU_BLEND_MAX = 0.9
_NUM_FAN = 300
_SV_BLEND = 0.3

# ----------------------------------------------------------------------------- small vector helpers


@njit(cache=True)
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _unit(a):
    n = math.sqrt(_dot(a, a))
    if n == 0.0:
        return a * 0.0
    return a / n


@njit(cache=True)
def _dsign(x):
    return 1 if x >= 0.0 else -1


@njit(cache=True)
def _closest_on_line(pt, line_pt, line_dir):
    d = _unit(line_dir)
    return line_pt + _dot(pt - line_pt, d) * d


@njit(cache=True)
def _intersect_lines(p1, p2, p3, p4):
    """Closest points of lines p1p2 and p3p4: (q1, s, q2, t, ok) with s, t fractions of the
    segments (WrapMath::IntersectLines)."""
    v1 = p2 - p1
    m1 = math.sqrt(_dot(v1, v1))
    v1 = _unit(v1)
    v2 = p4 - p3
    m2 = math.sqrt(_dot(v2, v2))
    v2 = _unit(v2)
    cp = _cross(v1, v2)
    den = _dot(cp, cp)
    if abs(den) < 1e-12:
        return p1, np.nan, p3, np.nan, False
    d = p3 - p1
    t = _dot(_cross(d, v1), cp) / den  # det[d; v1; cp]
    s = _dot(_cross(d, v2), cp) / den  # det[d; v2; cp]
    return p1 + s * v1, s / m1, p3 + t * v2, t / m2, True


@njit(cache=True)
def _rotate(v, axis, angle):
    """v rotated by ``angle`` about the unit ``axis`` (Rodrigues)."""
    c = math.cos(angle)
    s = math.sin(angle)
    return v * c + _cross(axis, v) * s + axis * _dot(axis, v) * (1.0 - c)


# ----------------------------------------------------------------------------- cylinder


@njit(cache=True)
def _cylinder(p1, p2, radius, length, wrap_axis, wrap_sign, arc):
    """Wrap segment p1-p2 (cylinder frame) over the cylinder: (code, n arc points, length)."""
    dn = np.array([0.0, 0.0, 1.0])
    p0 = np.array([0.0, 0.0, -1.0])
    r2 = radius * radius
    constrained = wrap_sign != 0
    if p1[0] ** 2 + p1[1] ** 2 < r2 or p2[0] ** 2 + p2[1] ** 2 < r2:
        return INSIDE, 0, 0.0
    code = WRAPPED
    near12, t12, near00, _, _ = _intersect_lines(p1, p2, np.array([0.0, 0.0, -0.5 * length]),
                                                 np.array([0.0, 0.0, 0.5 * length]))
    hit = _dot(near12 - near00, near12 - near00) < r2 and 0.0 < t12 < 1.0
    if not constrained:
        if hit:
            code = MANDATORY
        else:
            return NO_WRAP, 0, 0.0
    p11 = _closest_on_line(p1, p0, dn)
    p22 = _closest_on_line(p2, p0, dn)

    def cands(p, pa):
        vv = p - pa
        dist_p = math.sqrt(_dot(vv, vv))
        vv = _unit(vv)
        sin_t = radius / dist_p
        d = radius * sin_t
        pp = pa + d * vv
        h = math.sqrt(r2 - d * d)
        uu = _cross(dn, vv)
        return pp + h * uu, pp - h * uu, dist_p

    r1a, r1b, d1 = cands(p1, p11)
    r2a, r2b, d2 = cands(p2, p22)
    far_side = False
    long_wrap = False
    if constrained:
        ax = wrap_axis
        sg = wrap_sign
        if _dsign(p1[ax]) == sg or _dsign(p2[ax]) == sg:
            if hit:
                code = MANDATORY
            elif _dsign(p1[ax]) != _dsign(p2[ax]) and _dsign(near12[ax]) != sg:
                code = WRAPPED
            else:
                return NO_WRAP, 0, 0.0
        r1am = r1a - p11
        r1bm = r1b - p11
        r2am = r2a - p22
        r2bm = r2b - p22
        alpha = math.acos(min(1.0, max(-1.0, _dot(r1am, r2bm) / math.sqrt(_dot(r1am, r1am) * _dot(r2bm, r2bm)))))
        beta = math.acos(min(1.0, max(-1.0, _dot(r1bm, r2am) / math.sqrt(_dot(r1bm, r1bm) * _dot(r2am, r2am)))))
        a_on = _dsign(r1a[ax]) == sg
        b_on = _dsign(r1b[ax]) == sg
        if (a_on and b_on) or (not a_on and not b_on and _dsign(r2a[ax]) == sg):
            if a_on and b_on and _dsign(r2a[ax]) != sg:
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
        elif _dsign(r2b[ax]) == sg:
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
        if _dot(sum_r, sum_musc) < 0.0:
            long_wrap = True
    else:
        u1a = _unit(r1a - p11)
        u1b = _unit(r1b - p11)
        u2a = _unit(r2a - p22)
        u2b = _unit(r2b - p22)
        dot1 = _dot(u1a, u2a)
        dot2 = _dot(u1a, u2b)
        dot3 = _dot(u1b, u2a)
        dot4 = _dot(u1b, u2b)
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
    axispt = _closest_on_line(mpt, p0, dn)
    pn = _unit(_cross(_unit(p1 - axispt), _unit(p2 - axispt)))
    vert1 = _unit(_cross(dn, pn))
    vert2 = _unit(_cross(pn, dn))
    apex1 = axispt + radius * vert1
    apex2 = axispt + radius * vert2
    dd1 = _dot(mpt - apex1, mpt - apex1)
    dd2 = _dot(mpt - apex2, mpt - apex2)
    if far_side:
        apex = apex2 if dd1 < dd2 else apex1
    else:
        apex = apex1 if dd1 < dd2 else apex2
    # slide r1, r2 along the axis onto the plane through p1, p2 and the apex
    pn = _unit(_cross(_unit(p1 - apex), _unit(p2 - apex)))
    dpl = -_dot(p1, pn)
    for k in range(2):
        r = r1 if k == 0 else r2_
        a = r - 10.0 * dn
        b = r + 10.0 * dn
        vec = b - a
        dp = _dot(vec, pn)
        if abs(dp) >= 1e-5:
            tt = (-dpl - _dot(pn, a)) / dp
            if -1e-5 <= tt <= 1.0 + 1e-5:
                rp = a + tt * vec
                if k == 0:
                    q = _closest_on_line(rp, p11, p22 - p11)
                    if _dot(q - p22, q - p22) < _dot(p11 - p22, p11 - p22):
                        r1 = rp
                else:
                    q = _closest_on_line(rp, p22, p11 - p22)
                    if _dot(q - p11, q - p11) < _dot(p22 - p11, p22 - p11):
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
    theta = math.atan2(_dot(_cross(uu, vv), dn), _dot(uu, vv))
    sense = 1.0
    if long_wrap:
        theta = 2.0 * math.pi - theta
        sense = -1.0
    n = arc.shape[0] - 1
    for i in range(n + 1):
        f = i / n
        arc[i] = _rotate(r1, dn, sense * f * theta) + dn * (f * axial)
    return code, n + 1, math.sqrt((radius * theta) ** 2 + axial * axial)


# ----------------------------------------------------------------------------- sphere


@njit(cache=True)
def _sphere(p1, p2, radius, wrap_axis, wrap_sign, arc):
    code = WRAPPED
    n1 = math.sqrt(_dot(p1, p1))
    n2 = math.sqrt(_dot(p2, p2))
    if n1 < radius or n2 < radius:
        return INSIDE, 0, 0.0
    ri = p1 - p2
    mp = -p2
    a = _dot(ri, ri)
    b = -2.0 * _dot(mp, ri)
    c = _dot(mp, mp) - radius * radius
    disc = b * b - 4.0 * a * c
    if disc < 0.0:
        return NO_WRAP, 0, 0.0
    l1 = (-b + math.sqrt(disc)) / (2.0 * a)
    l2 = (-b - math.sqrt(disc)) / (2.0 * a)
    if not (0.0 < l1 < 1.0) or not (0.0 < l2 < 1.0) or l1 < l2:
        return NO_WRAP, 0, 0.0
    p1p2 = _unit(p1 - p2)
    hp2 = _cross(p1p2, _unit(p2))
    if math.sqrt(_dot(hp2, hp2)) < 1e-5:
        return NO_WRAP, 0, 0.0  # the line runs through the centre: no plane to wrap in
    nrm = _unit(hp2)

    def tangents(p, dist):
        y = _unit(-p)
        z = _cross(nrm, y)
        ang = math.asin(radius / dist)
        h = dist * math.cos(ang)
        # y rotated by +-ang about nrm (the plane's normal), scaled to the tangent length
        ya = y * math.cos(ang) - z * math.sin(ang)
        yb = y * math.cos(ang) + z * math.sin(ang)
        return p + h * ya, p + h * yb

    r1a, r1b = tangents(p1, n1)
    r2a, r2b = tangents(p2, n2)
    u1a, u1b, u2a, u2b = _unit(r1a), _unit(r1b), _unit(r2a), _unit(r2b)
    j1 = _dot(u1a, u2a)
    j2 = _dot(u1a, u2b)
    j3 = _dot(u1b, u2a)
    j4 = _dot(u1b, u2b)
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
        if _dsign(p1[ax]) == sg or _dsign(p2[ax]) == sg:
            # as OpenSim: tt is a distance along the unit direction (m), compared with 1
            ud = _unit(p2 - p1)
            tt = _dot(-p1, ud)
            mm = p1 + tt * ud
            if _dot(mm, mm) < radius * radius and 0.0 < tt < 1.0:
                code = MANDATORY
            elif _dsign(p1[ax]) != _dsign(p2[ax]) and _dsign(mm[ax]) != sg:
                code = WRAPPED
            else:
                return NO_WRAP, 0, 0.0
        if _dsign(p1[ax]) != sg or _dsign(p2[ax]) != sg:
            wax = np.zeros(3)
            wax[ax] = float(sg)
            sm = _unit(-p1 - p2)
            if _dot(u1a, sm) > _dot(u1b, sm):
                r1, r11 = r1a, r1b
            else:
                r1, r11 = r1b, r1a
            if _dot(u2a, sm) > _dot(u2b, sm):
                r2, r22 = r2a, r2b
            else:
                r2, r22 = r2b, r2a
            sm = _unit((r1 - p1) + (r2 - p2))
            if _dot(sm, wax) < 0.0:
                r1, r2 = r11, r22
            if _dot(r1 + r2, (r1 - p1) + (r2 - p2)) < 0.0:
                far_side = True
    r1n = _unit(r1)
    r2n = _unit(r2)
    angle = math.acos(min(1.0, max(-1.0, _dot(r1n, r2n))))
    if far_side:
        angle = -(2.0 * math.pi - angle)
    axis = _unit(_cross(r1n, r2n))
    n = arc.shape[0] - 1
    for i in range(n + 1):
        arc[i] = _rotate(r1, axis, angle * i / n)
    return code, n + 1, radius * abs(angle)


# ----------------------------------------------------------------------------- ellipsoid


@njit(cache=True)
def _closest_xyz(a0, a1, a2, y0, y1, y2):
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
    x0, x1, x2 = _closest_xyz(a[0], a[1], a[2], y[0], y[1], y[2])
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
    e1 = _unit(_cross(vs, h))
    e2 = _cross(vs, e1)
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
    px = _dot(p - o, e1)
    py = _dot(p - o, e2)
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
    sx = _dot(side_pt - o, e1) - px
    sy = _dot(side_pt - o, e2) - py
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
    mu = -vs4 / _dot(vs, u)
    a0 = mu * u
    ar1 = _unit(r1 - a0)
    ar2 = _unit(r2 - a0)
    phi0 = math.acos(min(1.0, max(-1.0, _dot(ar1, ar2))))
    n = arc.shape[0] - 1
    dphi = -(2.0 * math.pi - phi0) / n if far_side else phi0 / n
    vsz = _unit(_cross(ar1, ar2))
    vsy = _cross(vsz, ar1)
    arc[0] = r1
    arc[n] = r2
    for i in range(1, n):
        phi = i * dphi
        r = ar1 * math.cos(phi) + vsy * math.sin(phi)
        f1 = r / a
        f2 = a0 / a
        aa = _dot(f1, f1)
        bb = 2.0 * _dot(f1, f2)
        cc = _dot(f2, f2) - 1.0
        mu3 = (-bb + math.sqrt(max(bb * bb - 4.0 * aa * cc, 0.0))) / (2.0 * aa)
        arc[i] = a0 + mu3 * r
    length = 0.0
    for i in range(n):
        d = arc[i + 1] - arc[i]
        length += math.sqrt(_dot(d, d))
    return length


@njit(cache=True)
def _ellipsoid(p1, p2, a, wrap_axis, wrap_sign, method, arc):
    p1e = -1.0
    p2e = -1.0
    for i in range(3):
        p1e += (p1[i] / a[i]) ** 2
        p2e += (p2[i] / a[i]) ** 2
    if p1e < -0.0001 or p2e < -0.0001:
        return INSIDE, 0, 0.0
    p1p2 = p1 - p2
    if abs(_dot(_unit(p1), _unit(p2)) - 1.0) < 0.0001:
        return NO_WRAP, 0, 0.0
    f1 = p1p2 / a
    f2 = p2 / a
    aa = _dot(f1, f1)
    bb = 2.0 * _dot(f1, f2)
    cc = _dot(f2, f2) - 1.0
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
    mu = np.abs(_unit(p1p2))
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
                c0, c1_, c2 = _closest_xyz(a[0], a[1], a[2], q0, q1, q2)
                d0, d1, d2 = c0 - q0, c1_ - q1, c2 - q2
                dn_ = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if dn_ > 0.0:
                    s0 += d0 / dn_
                    s1 += d1 / dn_
                    s2 += d2 / dn_
            vsum = _unit(np.array([s0, s1, s2]))
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
        if _dsign(c1[ax]) != wrap_sign:
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
    vs = _unit(_cross(p1p2, p1 - c1))
    vs4 = -_dot(vs, c1)
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
        if _dot(_unit(p1 - t1), _unit(arc[1] - t1)) > 0.0 or _dot(_unit(p2 - t2), _unit(arc[n - 2] - t2)) > 0.0:
            length = _ellipsoid_arc(t1, t2, a, vs, vs4, True, arc)
    return MANDATORY, n, length


# ----------------------------------------------------------------------------- torus


@njit(cache=True)
def _torus(p1, p2, inner, outer, arc):
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
        return np.array([-_dot(q, radial), _dot(q, zax), _dot(q, tang)])

    q1 = to_cyl(p1)
    q2 = to_cyl(p2)
    code, n, length = _cylinder(q1, q2, outer, 1e6, 0, 1, arc)
    if code != INSIDE and n > 0:
        for i in range(n):
            v = arc[i]
            arc[i] = ring - v[0] * radial + v[1] * zax + v[2] * tang
    if code == INSIDE:
        return INSIDE, 0, 0.0
    return code, n, length


# ----------------------------------------------------------------------------- MuJoCo (mju_wrap)

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
def _mujoco(p0, p1, radius, cylinder, side, has_side, arc):
    """Wrap segment p0-p1 (surface frame) by MuJoCo's rules (mju_wrap): (code, arc points,
    surface length). ``side``: the side point in the surface frame (used when has_side)."""
    n0 = math.sqrt(_dot(p0, p0))
    n1 = math.sqrt(_dot(p1, p1))
    if n0 < _MJ_MINVAL or n1 < _MJ_MINVAL:
        return NO_WRAP, 0, 0.0
    ax0 = np.zeros(3)
    ax1 = np.zeros(3)
    if not cylinder:
        ax0 = p0 / n0
        nrm = _cross(p0, p1)
        nn = math.sqrt(_dot(nrm, nrm))
        if nn < _MJ_MINVAL:
            i = 0
            if abs(ax0[1]) > abs(ax0[0]) and abs(ax0[1]) > abs(ax0[2]):
                i = 1
            if abs(ax0[2]) > abs(ax0[0]) and abs(ax0[2]) > abs(ax0[1]):
                i = 2
            tmp = np.ones(3)
            tmp[i] = 0.0
            nrm = _unit(_cross(ax0, tmp))
        else:
            nrm = nrm / nn
        ax1 = _unit(_cross(nrm, ax0))
    else:
        ax0[0] = 1.0
        ax1[1] = 1.0
    e = np.array([_dot(p0, ax0), _dot(p0, ax1), _dot(p1, ax0), _dot(p1, ax1)])
    sd = np.zeros(2)
    inside = False
    if has_side:
        sd[0] = _dot(side, ax0)
        sd[1] = _dot(side, ax1)
        sn = math.sqrt(sd[0] * sd[0] + sd[1] * sd[1])
        if sn < _MJ_MINVAL:
            sd[0], sd[1] = 1.0, 0.0
        else:
            sd /= sn
        sd *= radius
        inside = math.sqrt(_dot(side, side)) < radius
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


# ----------------------------------------------------------------------------- one segment


@njit(cache=True)
def wrap_line(kind, prm, wrap_axis, wrap_sign, method, p1, p2, arc, side, has_side):
    """Wrap one segment (both ends in the surface's frame): (code, arc points, surface length).
    ``side``, ``has_side``: the side point (surface frame) of a MuJoCo shape."""
    if kind == MJ_SPHERE or kind == MJ_CYLINDER:
        return _mujoco(p1, p2, prm[0], kind == MJ_CYLINDER, side, has_side, arc)
    if kind == CYLINDER:
        return _cylinder(p1, p2, prm[0], prm[1], wrap_axis, wrap_sign, arc)
    if kind == SPHERE:
        return _sphere(p1, p2, prm[0], wrap_axis, wrap_sign, arc)
    if kind == ELLIPSOID:
        return _ellipsoid(p1, p2, prm, wrap_axis, wrap_sign, method, arc)
    return _torus(p1, p2, prm[0], prm[1], arc)


# ----------------------------------------------------------------------------- whole paths


@njit(cache=True)
def _xf_point(m, p):
    return np.array([m[0, 0] * p[0] + m[0, 1] * p[1] + m[0, 2] * p[2] + m[0, 3],
                     m[1, 0] * p[0] + m[1, 1] * p[1] + m[1, 2] * p[2] + m[1, 3],
                     m[2, 0] * p[0] + m[2, 1] * p[1] + m[2, 2] * p[2] + m[2, 3]])


@njit(cache=True)
def _inv_point(m, p):
    q = p - m[:3, 3]
    return np.array([m[0, 0] * q[0] + m[1, 0] * q[1] + m[2, 0] * q[2],
                     m[0, 1] * q[0] + m[1, 1] * q[1] + m[2, 1] * q[2],
                     m[0, 2] * q[0] + m[1, 2] * q[1] + m[2, 2] * q[2]])


@njit(cache=True)
def _path_length(n_ent, pos, ent_w, ent_side, arc_len):
    length = 0.0
    for e in range(1, n_ent):
        if ent_w[e] >= 0 and ent_w[e - 1] == ent_w[e] and ent_side[e] == 2:
            length += arc_len[ent_w[e]]
        else:  # |pos[e] - pos[e-1]|, in scalars (no temporary array)
            d0 = pos[e, 0] - pos[e - 1, 0]
            d1 = pos[e, 1] - pos[e - 1, 1]
            d2 = pos[e, 2] - pos[e - 1, 2]
            length += math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return length


@njit(cache=True)
def _drop_surface(w, n_ent, pos, ent_p, ent_w, ent_side):
    """Remove surface ``w``'s entries (its wrap points) from the path's entry arrays, in place,
    keeping the others in order; return the new entry count."""
    e = 0
    while e < n_ent:
        if ent_w[e] == w:
            for g in range(e, n_ent - 1):
                pos[g] = pos[g + 1]
                ent_p[g] = ent_p[g + 1]
                ent_w[g] = ent_w[g + 1]
                ent_side[g] = ent_side[g + 1]
            n_ent -= 1
        else:
            e += 1
    return n_ent


@njit(cache=True)
def wrapped_paths(points, active, wrap_xf, kind, prm, wrap_axis, wrap_sign, method, on, rng, side_pts, has_side,
                  fractions, out_samples, out_length, out_inside, out_points, out_count):
    """Per frame f: the path through the active points (F, P, 3 world; active (F, P)), wrapped
    over the surfaces (world transforms wrap_xf (F, W, 4, 4); kind, prm (W, 3), quadrant axis
    and sign, method, on (W,); rng (W, 2) 0-based point indices; side_pts (F, W, 3) world side
    points, used where has_side (W,)), resampled at arc
    ``fractions`` (K,) into out_samples (F, K, 3); out_length (F,) the path length (wrap arcs
    included); out_inside (F,) the index + 1 of the first surface that an end point of its
    range lies inside (the path cannot wrap there), 0 if none; out_points (F, P + 2 W, 3) and
    out_count (F,): the path's points, tangent points included (OpenSim's current path)."""
    nf, npt = points.shape[0], points.shape[1]
    nw = kind.shape[0]
    cap = npt + 2 * nw
    na = ARC_SEGMENTS + 1
    pos = np.empty((cap, 3))
    ent_p = np.empty(cap, np.int64)
    ent_w = np.empty(cap, np.int64)
    ent_side = np.empty(cap, np.int64)
    arc_loc = np.empty((nw, na, 3))
    arc_len = np.zeros(nw)
    arc = np.empty((na, 3))
    order = np.empty(nw, np.int64)
    result = np.empty(nw, np.int64)
    dense = np.empty((cap + nw * na, 3))
    cum = np.empty(cap + nw * na)
    for f in range(nf):
        n_ent = 0
        for k in range(npt):
            if active[f, k]:
                pos[n_ent] = points[f, k]
                ent_p[n_ent] = k
                ent_w[n_ent] = -1
                ent_side[n_ent] = 0
                n_ent += 1
        for i in range(nw):
            order[i] = i
        inside = 0
        passes = 1 if nw < 2 else MAX_PASSES
        last = np.inf
        for kk in range(passes):
            for i in range(nw):
                w = order[i]
                result[i] = NO_WRAP
                n_ent = _drop_surface(w, n_ent, pos, ent_p, ent_w, ent_side)  # its old wrap points
                if not on[w]:
                    continue
                lo, hi = rng[w, 0], rng[w, 1]
                js = lo
                while js <= hi and not active[f, js]:
                    js += 1
                je = hi
                while je >= lo and not active[f, je]:
                    je -= 1
                if js > hi or je < lo:
                    continue
                start = -1
                end = -1
                for e in range(n_ent):
                    if ent_w[e] < 0 and ent_p[e] == js:
                        start = e
                    if ent_w[e] < 0 and ent_p[e] == je:
                        end = e
                if start < 0 or end < 0:
                    continue
                m = wrap_xf[f, w]
                best = -1
                best_n = 0
                best_len = 0.0
                min_change = np.inf
                for e in range(start, end):
                    if ent_w[e] >= 0 and ent_w[e] == ent_w[e + 1]:
                        continue
                    q1 = _inv_point(m, pos[e])
                    q2 = _inv_point(m, pos[e + 1])
                    sq = _inv_point(m, side_pts[f, w])
                    code, n, ln = wrap_line(kind[w], prm[w], wrap_axis[w], wrap_sign[w], method[w], q1, q2, arc,
                                            sq, has_side[w])
                    result[i] = code
                    if code == INSIDE and (e == start or e + 1 == end) and inside == 0:
                        inside = w + 1
                    if code == MANDATORY:
                        best = e
                        best_n = n
                        best_len = ln
                        arc_loc[w, :n] = arc[:n]
                        break
                    if code == WRAPPED:
                        d1 = q1 - arc[0]
                        d2 = q2 - arc[n - 1]
                        d3 = q2 - q1
                        change = math.sqrt(_dot(d1, d1)) + ln + math.sqrt(_dot(d2, d2)) - math.sqrt(_dot(d3, d3))
                        if change < min_change:
                            min_change = change
                            best = e
                            best_n = n
                            best_len = ln
                            arc_loc[w, :n] = arc[:n]
                if best >= 0 and best_n > 0:
                    for g in range(n_ent - 1, best, -1):
                        pos[g + 2] = pos[g]
                        ent_p[g + 2] = ent_p[g]
                        ent_w[g + 2] = ent_w[g]
                        ent_side[g + 2] = ent_side[g]
                    for side in range(2):
                        g = best + 1 + side
                        pos[g] = _xf_point(m, arc_loc[w, 0] if side == 0 else arc_loc[w, best_n - 1])
                        ent_p[g] = -1
                        ent_w[g] = w
                        ent_side[g] = side + 1
                    for g in range(best_n, na):
                        arc_loc[w, g] = arc_loc[w, best_n - 1]
                    arc_len[w] = best_len
                    n_ent += 2
            length = _path_length(n_ent, pos, ent_w, ent_side, arc_len)
            if abs(length - last) < LENGTH_CONVERGED:
                break
            last = length
            if kk == 0 and nw > 1 and result[0] == NO_WRAP and result[1] == INSIDE:
                order[0] = 1
                order[1] = 0
                n_ent = _drop_surface(0, n_ent, pos, ent_p, ent_w, ent_side)
        out_length[f] = _path_length(n_ent, pos, ent_w, ent_side, arc_len)
        out_inside[f] = inside
        out_count[f] = n_ent
        for e in range(n_ent):
            out_points[f, e] = pos[e]
        # dense polyline (wrap arcs as their points) and its arc length
        nd = 0
        for e in range(n_ent):
            if ent_side[e] == 2 and e > 0 and ent_w[e - 1] == ent_w[e]:
                m = wrap_xf[f, ent_w[e]]
                for g in range(1, na - 1):
                    dense[nd] = _xf_point(m, arc_loc[ent_w[e], g])
                    nd += 1
            dense[nd] = pos[e]
            nd += 1
        cum[0] = 0.0
        for g in range(1, nd):  # (in scalars: no temporary array per point)
            d0 = dense[g, 0] - dense[g - 1, 0]
            d1 = dense[g, 1] - dense[g - 1, 1]
            d2 = dense[g, 2] - dense[g - 1, 2]
            cum[g] = cum[g - 1] + math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        total = cum[nd - 1]
        g = 0
        for k in range(fractions.shape[0]):
            s = fractions[k] * total
            while g < nd - 2 and cum[g + 1] < s:
                g += 1
            span = cum[g + 1] - cum[g]
            u = (s - cum[g]) / span if span > 0.0 else 0.0
            u = min(max(u, 0.0), 1.0)
            for c in range(3):
                out_samples[f, k, c] = dense[g, c] + u * (dense[g + 1, c] - dense[g, c])
