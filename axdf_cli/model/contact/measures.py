"""Contact's measures: per muscle, the share of its vertices inside another muscle, the share
inside a bone and the deepest penetration (stats.csv's inside_muscle, inside_bone, depth)."""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from axdf_cli.model.contact.query import bone_query, may_meet, query_in, ring_lists, rows_of


@njit(cache=True, inline="always")
def _polygon_distance2(x, grid, a0, b0, A, bl):
    """Squared distance from x to the closed polygon of rings a0 and b0 (first grid rows)
    blended at bl."""
    best = 1e300
    q0 = (1.0 - bl) * grid[a0 + A - 1, 0] + bl * grid[b0 + A - 1, 0]
    q1 = (1.0 - bl) * grid[a0 + A - 1, 1] + bl * grid[b0 + A - 1, 1]
    q2 = (1.0 - bl) * grid[a0 + A - 1, 2] + bl * grid[b0 + A - 1, 2]
    for k in range(A):
        p0 = (1.0 - bl) * grid[a0 + k, 0] + bl * grid[b0 + k, 0]
        p1 = (1.0 - bl) * grid[a0 + k, 1] + bl * grid[b0 + k, 1]
        p2 = (1.0 - bl) * grid[a0 + k, 2] + bl * grid[b0 + k, 2]
        e0 = p0 - q0
        e1 = p1 - q1
        e2 = p2 - q2
        ee = e0 * e0 + e1 * e1 + e2 * e2
        t = 0.0
        if ee > 0.0:
            t = ((x[0] - q0) * e0 + (x[1] - q1) * e1 + (x[2] - q2) * e2) / ee
            t = min(max(t, 0.0), 1.0)
        d0 = q0 + t * e0 - x[0]
        d1 = q1 + t * e1 - x[1]
        d2 = q2 + t * e2 - x[2]
        dd = d0 * d0 + d1 * d1 + d2 * d2
        if dd < best:
            best = dd
        q0 = p0
        q1 = p1
        q2 = p2
    return best


@njit(cache=True, inline="always")
def _section_distance(x, grid, off_j, U, A, bu, bl):
    """Distance from x to the nearest of some of muscle j's surface curves around x: its
    section there (rings bu and bu + 1 blended at bl) and rings bu - 1 to bu + 2 (mesh edges;
    a pole row is its pole). For a point in the middle of a wide, flat section this is how
    deep it lies (to the nearest side), where the radial ray reads it as deep as the section
    is wide; near an attachment, the pole may be nearer than the section."""
    best = _polygon_distance2(x, grid, off_j + bu * A, off_j + (bu + 1) * A, A, bl)
    for u in range(max(bu - 1, 0), min(bu + 3, U)):
        d = _polygon_distance2(x, grid, off_j + u * A, off_j + u * A, A, 0.0)
        if d < best:
            best = d
    return np.sqrt(best)


@njit(cache=True, parallel=True)
def measure(mesh, lists, fields, out, work):
    """Per muscle: [share of points inside another muscle, share inside a bone, deepest
    penetration (m)] over its vertices (pole rows counted once); ring by ring, each against
    what it may meet (:func:`ring_lists`). A point's penetration in a muscle: the nearer of
    two points of that muscle's surface, where the radial ray leaves it (R - rho) and the
    nearest point of its section there (:func:`_section_distance`); in a bone, the depth of
    the bone's field. Muscle by muscle on numba's threads (:func:`_measure_one`), each with
    its own scratch arrays of ``work`` (:func:`query.make_work`). mesh, lists, fields:
    :class:`params.Mesh`, :class:`params.Lists`, :class:`params.Fields`; out (M, 3)."""
    for i in prange(mesh.nu.shape[0]):
        _measure_one(i, mesh, lists, fields, out, work)


@njit(cache=True)
def measure_serial(mesh, lists, fields, out, work):
    """:func:`measure` on this thread alone."""
    for i in range(mesh.nu.shape[0]):
        _measure_one(i, mesh, lists, fields, out, work)


@njit(cache=True, _nrt=False)
def _measure_one(i, mesh, lists, fields, out, work):
    """:func:`measure` for muscle i, with its own scratch arrays (row i of work's; compiled
    without reference counting, as :func:`_ring_modes_one`)."""
    grid, off, nu, na, cen, coff, box = mesh
    rows = rows_of(work, i)
    q, g, actb, actm, gl, gn = rows.q, rows.g, rows.actb, rows.actm, rows.gl, rows.gn
    U = nu[i]
    A = na[i]
    n_in_m = 0
    n_in_b = 0
    deep = 0.0
    n = 0
    for u in range(U):
        ci = cen[coff[i] + u]
        nb, nmm = ring_lists(ci, i, mesh, fields, lists, 0.0, 0.0, rows)
        if nb == 0 and nmm == 0:
            n += A if 0 < u < U - 1 else 1  # nothing near the ring: none of its points is inside
            continue
        for a in range(A if 0 < u < U - 1 else 1):
            k = off[i] + u * A + a
            n += 1
            x = grid[k]
            if nb > 0:
                d = bone_query(x, fields, actb, 0, nb, -1e300, g)
                if d < 0.0:
                    n_in_b += 1
                    if -d > deep:
                        deep = -d
            inside = False
            for jj in range(nmm):
                j = actm[jj]
                if not may_meet(x, j, box, 0.0):
                    continue
                if not query_in(x, grid, off[j], nu[j], na[j], cen, coff[j], 0.0, q, gl, jj, gn[jj]):
                    continue
                if q[0] < q[1]:
                    inside = True
                    if q[1] - q[0] > deep:  # (the depth is at most the radial one)
                        dj = min(q[1] - q[0], _section_distance(x, grid, off[j], nu[j], na[j], int(q[8]), q[9]))
                        if dj > deep:
                            deep = dj
            if inside:
                n_in_m += 1
    out[i, 0] = n_in_m / n
    out[i, 1] = n_in_b / n
    out[i, 2] = deep

