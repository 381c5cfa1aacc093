"""Wrap surfaces as OpenSim defines them (WrapCylinder, WrapSphere, WrapEllipsoid, WrapTorus)
and as MuJoCo does, and the wrapped path of a muscle, compiled (numba) and batched over frames.
One segment over one surface is :mod:`.opensim_shapes` or :mod:`.mujoco_shapes`
(:func:`wrap_line` picks by kind); this module puts the whole path together
(:func:`wrapped_paths`).

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
active points of its ``range`` (1-based path point indices, -1 meaning the ends) is a
candidate; a segment that crosses the surface wins at once (``mandatoryWrap``), otherwise the
one that lengthens the path least; the two tangent points are inserted. With two or more
surfaces this repeats (at most 8 times) until the length changes by less than 0.5 mm.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from axdf_cli.model.paths.geometry import INSIDE, MANDATORY, NO_WRAP, WRAPPED, dot
from axdf_cli.model.paths.mujoco_shapes import mujoco
from axdf_cli.model.paths.opensim_shapes import AXIAL, HYBRID, MIDPOINT, cylinder, ellipsoid, sphere, torus

CYLINDER, SPHERE, ELLIPSOID, TORUS, MJ_SPHERE, MJ_CYLINDER = 0, 1, 2, 3, 4, 5
SHAPES = {"cylinder": CYLINDER, "sphere": SPHERE, "ellipsoid": ELLIPSOID, "torus": TORUS,
          "mujoco_sphere": MJ_SPHERE, "mujoco_cylinder": MJ_CYLINDER}
#: Shapes that wrap by MuJoCo's rules (``mju_wrap``) and may have a side point.
MUJOCO_SHAPES = ("mujoco_sphere", "mujoco_cylinder")
METHODS = {"hybrid": HYBRID, "midpoint": MIDPOINT, "axial": AXIAL}
QUADRANTS = {"all": (0, 0)}
for _i, _ax in enumerate("xyz"):
    for _name, _sign in ((f"+{_ax}", 1), (_ax, 1), (f"-{_ax}", -1)):
        QUADRANTS[_name] = (_i, _sign)

#: Segments of the surface path between the tangent points (the arc is kept as a polyline).
ARC_SEGMENTS = 32
#: Wrapping repeats until the path length changes by less than this (m), at most 8 times.
LENGTH_CONVERGED = 0.0005
MAX_PASSES = 8

__all__ = ["ARC_SEGMENTS", "CYLINDER", "ELLIPSOID", "INSIDE", "LENGTH_CONVERGED", "MANDATORY", "MAX_PASSES",
           "METHODS", "MJ_CYLINDER", "MJ_SPHERE", "MUJOCO_SHAPES", "NO_WRAP", "PathOut", "QUADRANTS", "SHAPES",
           "SPHERE", "Surfaces", "TORUS", "WRAPPED", "wrap_line", "wrapped_paths"]


class Surfaces(NamedTuple):
    """A path's wrap surfaces, in order (W,): what each is, in its own frame."""
    kind: np.ndarray  # int64: CYLINDER, SPHERE, ... (:data:`SHAPES`)
    prm: np.ndarray  # (W, 3): radius, length / semi-axes / inner and outer radius
    axis: np.ndarray  # int64: the quadrant's axis (:data:`QUADRANTS`)
    sign: np.ndarray  # int64: the quadrant's side, 0 for all
    method: np.ndarray  # int64: the ellipsoid's method (:data:`METHODS`)
    on: np.ndarray  # bool: active
    rng: np.ndarray  # (W, 2) int64: the 0-based path point indices it may wrap between
    has_side: np.ndarray  # bool: has a side point (MuJoCo shapes)


class PathOut(NamedTuple):
    """Where :func:`wrapped_paths` writes (F frames, K samples, P points, W surfaces)."""
    samples: np.ndarray  # (F, K, 3) the path at the arc fractions
    length: np.ndarray  # (F,) the path length, wrap arcs included
    inside: np.ndarray  # (F,) int64: the index + 1 of the first surface an end point of its range
    #                     lies inside (the path cannot wrap there), 0 if none
    points: np.ndarray  # (F, P + 2 W, 3) the path's points, tangent points included (OpenSim's current path)
    count: np.ndarray  # (F,) int64: how many of them


# ----------------------------------------------------------------------------- one segment


@njit(cache=True)
def wrap_line(kind, prm, wrap_axis, wrap_sign, method, p1, p2, arc, side, has_side):
    """Wrap one segment (both ends in the surface's frame): (code, arc points, surface length).
    ``side``, ``has_side``: the side point (surface frame) of a MuJoCo shape."""
    if kind == MJ_SPHERE or kind == MJ_CYLINDER:
        return mujoco(p1, p2, prm[0], kind == MJ_CYLINDER, side, has_side, arc)
    if kind == CYLINDER:
        return cylinder(p1, p2, prm[0], prm[1], wrap_axis, wrap_sign, arc)
    if kind == SPHERE:
        return sphere(p1, p2, prm[0], wrap_axis, wrap_sign, arc)
    if kind == ELLIPSOID:
        return ellipsoid(p1, p2, prm, wrap_axis, wrap_sign, method, arc)
    return torus(p1, p2, prm[0], prm[1], arc)


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
def wrapped_paths(points, active, wrap_xf, side_pts, surfaces, fractions, out):
    """Per frame f: the path through the active points (F, P, 3 world; active (F, P)), wrapped
    over the :class:`Surfaces` (world transforms wrap_xf (F, W, 4, 4); side_pts (F, W, 3) world
    side points, used where surfaces.has_side), resampled at arc ``fractions`` (K,); the
    results into ``out``, a :class:`PathOut`."""
    kind, prm, wrap_axis, wrap_sign, method, on, rng, has_side = surfaces
    out_samples, out_length, out_inside, out_points, out_count = out
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
                        change = math.sqrt(dot(d1, d1)) + ln + math.sqrt(dot(d2, d2)) - math.sqrt(dot(d3, d3))
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
