"""Point queries against the frame's muscles and bones, shared by the contact passes, the
measures and the packer (:mod:`axdf_cli.model.pack`).

- **Bones**: the smallest signed distance over the bone fields near a point, trilinear between
  grid points, and its gradient by central differences (:func:`bone_query`).
- **Muscles** are queried in axis space: a point x is compared with muscle j at the closest
  point c of j's centre polyline (the rings' centroids between the two poles): its radial
  distance rho from c, perpendicular to the polyline, against j's surface radius R in that
  direction (the ray from c cut with the two neighbouring rings, projected into the plane
  perpendicular to the polyline, linear between them). Inside when rho < R. Where c is a
  pole, x lies past j's end cap (the cone closing the mesh): outside (:func:`query_in`).
- What a ring may meet (:func:`ring_lists`), and which muscles' boxes and which bone fields
  meet (:func:`neighbours`, :func:`field_lists`): testing only those gives the same answers
  as testing all.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from axdf_cli.model.contact.fields import BoneFields
from axdf_cli.model.contact.params import END_FADE, NMODES, QUERY_SIZE, REACTION_RECORDS, SEG_GROUP, SQRT3, Rows, Work

#: No group list: :func:`query_in` scans every group.
_ALL_GROUPS = np.zeros((1, 1), np.int64)


@njit(cache=True, inline="always")
def field_at(values, off, dims, origin, h, x0, x1, x2):
    """Trilinear signed distance at a bone-local point; (distance, inside the grid)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    fx = (x0 - origin[0]) / h
    fy = (x1 - origin[1]) / h
    fz = (x2 - origin[2]) / h
    if not (fx >= 0.0 and fy >= 0.0 and fz >= 0.0 and fx <= nx - 1 and fy <= ny - 1 and fz <= nz - 1):
        return 1e30, False
    ix = min(int(fx), nx - 2)
    iy = min(int(fy), ny - 2)
    iz = min(int(fz), nz - 2)
    tx = fx - ix
    ty = fy - iy
    tz = fz - iz
    b = off + (ix * ny + iy) * nz + iz
    sy = nz
    sx = ny * nz
    c00 = values[b] * (1 - tz) + values[b + 1] * tz
    c01 = values[b + sy] * (1 - tz) + values[b + sy + 1] * tz
    c10 = values[b + sx] * (1 - tz) + values[b + sx + 1] * tz
    c11 = values[b + sx + sy] * (1 - tz) + values[b + sx + sy + 1] * tz
    c0 = c00 * (1 - ty) + c01 * ty
    c1 = c10 * (1 - ty) + c11 * ty
    return c0 * (1 - tx) + c1 * tx, True


@njit(cache=True, inline="always")
def local_field(x, m, fv, off, dims, origin, h):
    """World point x taken into a bone's frame by m (4, 4; world to bone-local) and the
    field's trilinear value there: (distance, inside the grid, the bone-local point)."""
    y0 = m[0, 0] * x[0] + m[0, 1] * x[1] + m[0, 2] * x[2] + m[0, 3]
    y1 = m[1, 0] * x[0] + m[1, 1] * x[1] + m[1, 2] * x[2] + m[1, 3]
    y2 = m[2, 0] * x[0] + m[2, 1] * x[1] + m[2, 2] * x[2] + m[2, 3]
    d, ok = field_at(fv, off, dims, origin, h, y0, y1, y2)
    return d, ok, y0, y1, y2


@njit(cache=True, inline="always")
def bone_query(x, fields, fsel, f0, f1, grad_below, g_out):
    """Smallest signed distance of world point x over the bone fields fsel[f0:f1]
    (:class:`params.Fields`) and, where it is below ``grad_below``, in g_out[:3] its world
    gradient by central differences of the trilinear field over one grid step (continuous,
    unlike the trilinear's own gradient); 1e30 where no field covers x."""
    inv, fb, fo, fh, fd, foff, fv = fields
    best = 1e30
    kb = -1
    l0 = 0.0
    l1 = 0.0
    l2 = 0.0
    for kk in range(f0, f1):
        k = fsel[kk]
        d, ok, y0, y1, y2 = local_field(x, inv[fb[k]], fv, foff[k], fd[k], fo[k], fh[k])
        if ok and d < best:
            best = d
            kb = k
            l0 = y0
            l1 = y1
            l2 = y2
    if kb < 0 or not best < grad_below:
        return best
    h = fh[kb]
    for c in range(3):
        e0 = h if c == 0 else 0.0
        e1 = h if c == 1 else 0.0
        e2 = h if c == 2 else 0.0
        dp, okp = field_at(fv, foff[kb], fd[kb], fo[kb], h, l0 + e0, l1 + e1, l2 + e2)
        dm, okm = field_at(fv, foff[kb], fd[kb], fo[kb], h, l0 - e0, l1 - e1, l2 - e2)
        if not okp:
            dp = best
        if not okm:
            dm = best
        g_out[3 + c] = (dp - dm) / (2.0 * h)
    m = inv[fb[kb]]
    # world gradient = R g, R = the transpose of inv's rotation
    for c in range(3):
        g_out[c] = m[0, c] * g_out[3] + m[1, c] * g_out[4] + m[2, c] * g_out[5]
    return best


@njit(cache=True)
def centres(grid, off, nu, na, cen, coff):
    """Ring centroids of every muscle (pole rows: the pole) in cen[:, :3], in cen[:, 3] each
    ring's largest distance from its centroid, and in cen[:, 4:8] of every SEG_GROUP-th ring
    the bounding sphere (centre, radius) of the centres from it to SEG_GROUP rings on, in
    cen[:, 8] the largest of those rings' radii, and in cen[:, 9] each ring's end fade (0 at
    the poles, 1 from :data:`END_FADE` of the rings on; cen: (rings, :data:`CEN_COLUMNS`))."""
    for m in range(nu.shape[0]):
        centres_one(m, grid, off, nu, na, cen, coff)


@njit(cache=True)
def centres_one(m, grid, off, nu, na, cen, coff):
    """:func:`centres` for muscle m."""
    U = nu[m]
    A = na[m]
    for u in range(U):
        for c in range(3):
            s = 0.0
            for a in range(A):
                s += grid[off[m] + u * A + a, c]
            cen[coff[m] + u, c] = s / A
        r = 0.0
        for a in range(A):
            k = off[m] + u * A + a
            q = ((grid[k, 0] - cen[coff[m] + u, 0]) ** 2 + (grid[k, 1] - cen[coff[m] + u, 1]) ** 2
                 + (grid[k, 2] - cen[coff[m] + u, 2]) ** 2)
            if q > r:
                r = q
        cen[coff[m] + u, 3] = np.sqrt(r)
        cen[coff[m] + u, 9] = smoothstep(min(u, U - 1 - u) / (END_FADE * (U - 1)))
    # each ring's plane normal (Newell's, over its polygon), along the centre line
    for u in range(U):
        r = coff[m] + u
        n0 = 0.0
        n1 = 0.0
        n2 = 0.0
        for a in range(A):
            p = off[m] + u * A + a
            q = off[m] + u * A + (a + 1) % A
            n0 += (grid[p, 1] - grid[q, 1]) * (grid[p, 2] + grid[q, 2])
            n1 += (grid[p, 2] - grid[q, 2]) * (grid[p, 0] + grid[q, 0])
            n2 += (grid[p, 0] - grid[q, 0]) * (grid[p, 1] + grid[q, 1])
        nl = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        ra = coff[m] + max(u - 1, 0)
        rb = coff[m] + min(u + 1, U - 1)
        d0 = cen[rb, 0] - cen[ra, 0]
        d1 = cen[rb, 1] - cen[ra, 1]
        d2 = cen[rb, 2] - cen[ra, 2]
        if nl <= 1e-12 * cen[r, 3] * cen[r, 3] or nl == 0.0:
            n0, n1, n2, nl = 0.0, 0.0, 0.0, 1.0  # a pole, or no area: the centre line's own
        elif n0 * d0 + n1 * d1 + n2 * d2 < 0.0:
            nl = -nl
        cen[r, 10] = n0 / nl
        cen[r, 11] = n1 / nl
        cen[r, 12] = n2 / nl
    # bounding spheres of the centre segments in groups of SEG_GROUP (cen[first, 4:8])
    for g in range((U - 2) // SEG_GROUP + 1):
        r0 = coff[m] + g * SEG_GROUP
        r1 = coff[m] + min(g * SEG_GROUP + SEG_GROUP, U - 1)
        for c in range(3):
            cen[r0, 4 + c] = 0.5 * (cen[r0, c] + cen[r1, c])
        r = 0.0
        for k in range(r0, r1 + 1):
            q = (cen[k, 0] - cen[r0, 4]) ** 2 + (cen[k, 1] - cen[r0, 5]) ** 2 + (cen[k, 2] - cen[r0, 6]) ** 2
            if q > r:
                r = q
        cen[r0, 7] = np.sqrt(r)
        big = 0.0
        for k in range(r0, r1 + 1):
            if cen[k, 3] > big:
                big = cen[k, 3]
        cen[r0, 8] = big


@njit(cache=True, parallel=True)
def centres_and_boxes(mesh):
    """:func:`centres` and :func:`boxes` of a :class:`params.Mesh`, muscle by muscle on
    numba's threads (the same values)."""
    grid, off, nu, na, cen, coff, box = mesh
    for m in prange(nu.shape[0]):
        centres_one(m, grid, off, nu, na, cen, coff)
        box_one(m, grid, off, box)


@njit(cache=True)
def centres_and_boxes_serial(mesh):
    """:func:`centres_and_boxes` on this thread alone."""
    grid, off, nu, na, cen, coff, box = mesh
    for m in range(nu.shape[0]):
        centres_one(m, grid, off, nu, na, cen, coff)
        box_one(m, grid, off, box)


@njit(cache=True)
def boxes(grid, off, box):
    """Every muscle's bounding box (M, 6): lo, hi."""
    for m in range(off.shape[0] - 1):
        box_one(m, grid, off, box)


@njit(cache=True)
def box_one(m, grid, off, box):
    """:func:`boxes` for muscle m."""
    for c in range(3):
        box[m, c] = 1e300
        box[m, 3 + c] = -1e300
    for k in range(off[m], off[m + 1]):
        for c in range(3):
            v = grid[k, c]
            if v < box[m, c]:
                box[m, c] = v
            if v > box[m, 3 + c]:
                box[m, 3 + c] = v


@njit(cache=True, inline="always")
def ring_radius(grid, base, A, cx0, cx1, cx2, a0, a1, a2, b0, b1, b2):
    """Radius of a ring (A points from ``base``) along (a0, a1, a2) from the centre (cx0, cx1,
    cx2), in the plane of that direction and (b0, b1, b2): the ray cut with the ring's polygon
    projected into that plane (0 when it misses)."""
    best = 0.0
    px0 = 0.0
    py0 = 0.0
    for k in range(A + 1):
        i = base + (k % A)
        dx = grid[i, 0] - cx0
        dy = grid[i, 1] - cx1
        dz = grid[i, 2] - cx2
        px = dx * a0 + dy * a1 + dz * a2
        py = dx * b0 + dy * b1 + dz * b2
        if k > 0 and ((py0 <= 0.0 < py) or (py <= 0.0 < py0)):
            xh = px0 + (px - px0) * py0 / (py0 - py)
            if xh > best:
                best = xh
        px0 = px
        py0 = py
    return best


@njit(cache=True, inline="always")
def centre_tangent(cen, coff_j, U, u):
    """Unit axis direction of a muscle at ring u: the ring's plane normal (cen[:, 10:13]); at
    the poles and rings with no area, the centre polyline's tangent (central difference;
    one-sided at the poles)."""
    r = coff_j + u
    if cen[r, 10] != 0.0 or cen[r, 11] != 0.0 or cen[r, 12] != 0.0:
        return cen[r, 10], cen[r, 11], cen[r, 12]
    a = coff_j + max(u - 1, 0)
    b = coff_j + min(u + 1, U - 1)
    d0 = cen[b, 0] - cen[a, 0]
    d1 = cen[b, 1] - cen[a, 1]
    d2 = cen[b, 2] - cen[a, 2]
    dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dl == 0.0:
        return 0.0, 0.0, 0.0
    return d0 / dl, d1 / dl, d2 / dl


@njit(cache=True, inline="always")
def scan_segments(x, cen, coff_j, U, u0, u1, best, bu, bl):
    """The nearest of centre segments u0..u1-1 to x if nearer than ``best`` (squared distance):
    (best, segment, parameter), the parameter clamped to [0, 1]: beyond the first or last
    segment's end, the nearest point is the pole (the end cap's apex, :func:`muscle_query`)."""
    for u in range(u0, u1):
        a0 = cen[coff_j + u, 0]
        a1 = cen[coff_j + u, 1]
        a2 = cen[coff_j + u, 2]
        d0 = cen[coff_j + u + 1, 0] - a0
        d1 = cen[coff_j + u + 1, 1] - a1
        d2 = cen[coff_j + u + 1, 2] - a2
        ll = d0 * d0 + d1 * d1 + d2 * d2
        lam = 0.0
        if ll > 0.0:
            lam = ((x[0] - a0) * d0 + (x[1] - a1) * d1 + (x[2] - a2) * d2) / ll
        lam = min(max(lam, 0.0), 1.0)
        e0 = x[0] - (a0 + lam * d0)
        e1 = x[1] - (a1 + lam * d1)
        e2 = x[2] - (a2 + lam * d2)
        q = e0 * e0 + e1 * e1 + e2 * e2
        if q < best:
            best = q
            bu = u
            bl = lam
    return best, bu, bl


@njit(cache=True, inline="always")
def muscle_query(x, grid, off_j, U, A, cen, coff_j, reach, out):
    """:func:`query_in` over all of muscle j's segment groups."""
    return query_in(x, grid, off_j, U, A, cen, coff_j, reach, out, _ALL_GROUPS, 0, -1)


@njit(cache=True, inline="always")
def query_in(x, grid, off_j, U, A, cen, coff_j, reach, out, gl, row, cnt):
    """Axis-space query of point x against muscle j. out (:data:`QUERY_SIZE`) = [rho, R, cx,
    cy, cz, rx, ry, rz, segment, parameter]: radial distance, surface radius, axis point, unit
    radial direction, and the axis point's centre segment and its parameter there. Returns False when x
    lies beyond j's ends, or when rho exceeds the two rings' largest radius (cen[:, 3]) plus
    ``reach`` (then rho > R + reach: the rings' radii are not read).
    Beyond an end: where the nearest point of the whole centre polyline (poles included) is a
    pole, x lies past the plane through the pole across the end segment, outside the end cap
    (the cone from the pole to ring 1 or U - 2 that closes the mesh), whose radius is 0 at the
    pole: False (not read against an endless continuation of ring 1).
    The nearest centre segment: the groups of :data:`SEG_GROUP` segments are scanned nearest
    bounding sphere first (cen[:, 4:8]), the others only where their sphere may hold a nearer
    point (the same segment as a scan of all, in fewer steps).
    Farther than the two rings' largest radius plus ``reach`` from the nearest centre point:
    False (every point of the tube lies within the larger of its two rings' radii of the
    segment between their centres). So where no group's bounding sphere comes within its
    largest ring radius (cen[first, 8]) plus ``reach`` of x, no segment is scanned.
    Only the groups gl[row, :cnt] are scanned (all where cnt < 0): those that may hold the
    nearest segment of any point near x (:func:`_ring_groups`), so the answer is the same."""
    ng = (U - 2) // SEG_GROUP + 1 if cnt < 0 else cnt
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        r = coff_j + g * SEG_GROUP
        lim = cen[r, 7] + cen[r, 8] + reach
        if (x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2 <= lim * lim:
            break
    else:
        return False  # no centre segment within its rings' radius plus reach
    gb = 0
    lb_best = 1e300
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        r = coff_j + g * SEG_GROUP
        e = np.sqrt((x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2) - cen[r, 7]
        if e < lb_best:
            lb_best = e
            gb = g
    best, bu, bl = scan_segments(x, cen, coff_j, U, gb * SEG_GROUP, min(gb * SEG_GROUP + SEG_GROUP, U - 1),
                                  1e300, -1, 0.0)
    for k in range(ng):
        g = k if cnt < 0 else gl[row, k]
        if g == gb:
            continue
        r = coff_j + g * SEG_GROUP
        e = np.sqrt((x[0] - cen[r, 4]) ** 2 + (x[1] - cen[r, 5]) ** 2 + (x[2] - cen[r, 6]) ** 2) - cen[r, 7]
        if e > 0.0 and e * e >= best:
            continue
        best, bu, bl = scan_segments(x, cen, coff_j, U, g * SEG_GROUP, min(g * SEG_GROUP + SEG_GROUP, U - 1),
                                      best, bu, bl)
    if bu < 0:
        return False
    if best > (max(cen[coff_j + bu, 3], cen[coff_j + bu + 1, 3]) + reach) ** 2:
        return False  # farther from the centre line than its rings' largest radius: outside
    # the segment whose ring planes hold x between them, from the nearest one, and x's place
    # between them: a packed section whose centre leaves the line of action stands oblique to
    # the line of the centres, and the nearest centre is not in x's section
    sa = 0.0
    sb = 0.0
    ta0 = ta1 = ta2 = tb0 = tb1 = tb2 = 0.0
    settled = False
    for _ in range(U):
        ta0, ta1, ta2 = centre_tangent(cen, coff_j, U, bu)
        tb0, tb1, tb2 = centre_tangent(cen, coff_j, U, bu + 1)
        p0 = coff_j + bu
        sa = (x[0] - cen[p0, 0]) * ta0 + (x[1] - cen[p0, 1]) * ta1 + (x[2] - cen[p0, 2]) * ta2
        sb = (x[0] - cen[p0 + 1, 0]) * tb0 + (x[1] - cen[p0 + 1, 1]) * tb1 + (x[2] - cen[p0 + 1, 2]) * tb2
        if sa < 0.0 and bu > 0:
            bu -= 1
        elif sb > 0.0 and bu < U - 2:
            bu += 1
        else:
            settled = True
            break
    if not settled:
        # where ring planes cross (a squeezed section), the walk may go back and forth and
        # stop after U steps, one segment past the one it read: the directions of this one
        ta0, ta1, ta2 = centre_tangent(cen, coff_j, U, bu)
        tb0, tb1, tb2 = centre_tangent(cen, coff_j, U, bu + 1)
    if sa < 0.0:
        bl = 0.0
    elif sb > 0.0:
        bl = 1.0
    else:
        bl = sa / (sa - sb) if sa - sb > 0.0 else 0.5
    if (bu == 0 and bl <= 0.0) or (bu == U - 2 and bl >= 1.0):
        return False  # beyond an end: outside the end cap
    p0 = coff_j + bu
    p1 = p0 + 1
    cx0 = (1.0 - bl) * cen[p0, 0] + bl * cen[p1, 0]
    cx1 = (1.0 - bl) * cen[p0, 1] + bl * cen[p1, 1]
    cx2 = (1.0 - bl) * cen[p0, 2] + bl * cen[p1, 2]
    # the axis direction blends the two rings' directions (read above) along the segment: the
    # same at a shared ring from either segment, so the query is continuous where it changes
    t0 = (1.0 - bl) * ta0 + bl * tb0
    t1 = (1.0 - bl) * ta1 + bl * tb1
    t2 = (1.0 - bl) * ta2 + bl * tb2
    tl = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if tl == 0.0:
        return False
    t0 /= tl
    t1 /= tl
    t2 /= tl
    dt = (x[0] - cx0) * t0 + (x[1] - cx1) * t1 + (x[2] - cx2) * t2
    r0 = x[0] - cx0 - dt * t0
    r1 = x[1] - cx1 - dt * t1
    r2 = x[2] - cx2 - dt * t2
    rho = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if rho > max(cen[p0, 3], cen[p1, 3]) + reach:
        return False  # R <= the rings' largest radius (projected across the axis, no longer)
    if rho < 1e-12:
        # on the axis: any perpendicular
        r0 = t1 - t2
        r1 = t2 - t0
        r2 = t0 - t1
        rl = np.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if rl < 1e-12:
            r0 = -t1
            r1 = t0
            r2 = 0.0
            rl = np.sqrt(r0 * r0 + r1 * r1)
    else:
        rl = rho
    r0 /= rl
    r1 /= rl
    r2 /= rl
    b0 = t1 * r2 - t2 * r1
    b1 = t2 * r0 - t0 * r2
    b2 = t0 * r1 - t1 * r0
    ra = ring_radius(grid, off_j + bu * A, A, cen[p0, 0], cen[p0, 1], cen[p0, 2], r0, r1, r2, b0, b1, b2)
    rb = ring_radius(grid, off_j + (bu + 1) * A, A, cen[p1, 0], cen[p1, 1], cen[p1, 2], r0, r1, r2, b0, b1, b2)
    out[0] = rho
    out[1] = (1.0 - bl) * ra + bl * rb
    out[2] = cx0
    out[3] = cx1
    out[4] = cx2
    out[5] = r0
    out[6] = r1
    out[7] = r2
    out[8] = bu
    out[9] = bl
    return True


@njit(cache=True, inline="always")
def may_meet(x, j, box, margin):
    """Whether point x lies in muscle j's box grown by ``margin`` (before :func:`muscle_query`)."""
    return not (x[0] < box[j, 0] - margin or x[1] < box[j, 1] - margin or x[2] < box[j, 2] - margin
                or x[0] > box[j, 3] + margin or x[1] > box[j, 4] + margin or x[2] > box[j, 5] + margin)


@njit(cache=True, inline="always")
def smoothstep(x):
    """0 below 0, 1 above 1, 3x^2 - 2x^3 between: a continuous switch with continuous slope."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True)
def modes(theta, b):
    b[0] = 1.0
    b[1] = np.cos(theta)
    b[2] = np.sin(theta)
    b[3] = np.cos(2.0 * theta)
    b[4] = np.sin(2.0 * theta)


@njit(cache=True, inline="always")
def section_angle(grid, off_j, A, cen, coff_j, U, bu, bl, r0, r1, r2):
    """The angle, in muscle j's column angle (2 pi a / A for column a), of the unit direction
    (r0, r1, r2) perpendicular to j's centre line at parameter bl of segment bu: measured from
    the direction to column 0 towards column A / 4, both blended between the segment's two
    rings. NaN where those are degenerate (both rings at a pole)."""
    ka = off_j + bu * A
    kb = off_j + (bu + 1) * A
    ca = coff_j + bu
    cb = ca + 1
    qa = A // 4
    x0 = (1.0 - bl) * (grid[ka, 0] - cen[ca, 0]) + bl * (grid[kb, 0] - cen[cb, 0])
    x1 = (1.0 - bl) * (grid[ka, 1] - cen[ca, 1]) + bl * (grid[kb, 1] - cen[cb, 1])
    x2 = (1.0 - bl) * (grid[ka, 2] - cen[ca, 2]) + bl * (grid[kb, 2] - cen[cb, 2])
    y0 = (1.0 - bl) * (grid[ka + qa, 0] - cen[ca, 0]) + bl * (grid[kb + qa, 0] - cen[cb, 0])
    y1 = (1.0 - bl) * (grid[ka + qa, 1] - cen[ca, 1]) + bl * (grid[kb + qa, 1] - cen[cb, 1])
    y2 = (1.0 - bl) * (grid[ka + qa, 2] - cen[ca, 2]) + bl * (grid[kb + qa, 2] - cen[cb, 2])
    # e1 along column 0, e2: column A / 4 made perpendicular to it
    xl = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if xl < 1e-9:
        return np.nan
    x0 /= xl
    x1 /= xl
    x2 /= xl
    d = y0 * x0 + y1 * x1 + y2 * x2
    y0 -= d * x0
    y1 -= d * x1
    y2 -= d * x2
    yl = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    if yl < 1e-9:
        return np.nan
    return np.arctan2((r0 * y0 + r1 * y1 + r2 * y2) / yl, r0 * x0 + r1 * x1 + r2 * x2)


@njit(cache=True)
def ring_lists(ci, i, mesh, fields, lists, reach_b, reach_m, rows):
    """What a ring of muscle i (centre ci[:3], every point within ri = ci[3] of it) may meet:
    into actb the bone fields of fl[fl_off[i]:fl_off[i + 1]] but those whose grid it misses or
    whose value at the centre exceeds sqrt(3) ri + reach_b (the trilinear field changes by at
    most sqrt(3) per metre: its grid values are exact distances, so each axis' difference
    quotient is at most 1), into actm the neighbours nbr[nbr_off[i]:nbr_off[i + 1]] whose box,
    grown by reach_m, its sphere meets, and, of those, whose centre line it may come within
    their radius of, with into gl, gn the segment groups to scan for each
    (:func:`_ring_groups`). Returns (how many fields, how many neighbours): testing only those
    gives the same answers as testing all. mesh, fields, lists: :class:`params.Mesh`,
    :class:`params.Fields`, :class:`params.Lists`; actb, actm, gl, gn: those of ``rows``
    (:class:`params.Rows`)."""
    cen, coff, nu, box = mesh.cen, mesh.coff, mesh.nu, mesh.box
    inv, fb, fo, fh, fd, foff, fv = fields
    nbr_off, nbr, fl_off, fl = lists
    actb, actm, gl, gn = rows.actb, rows.actm, rows.gl, rows.gn
    ri = ci[3]
    nb = 0
    for kk in range(fl_off[i], fl_off[i + 1]):
        k = fl[kk]
        d, ok, y0, y1, y2 = local_field(ci, inv[fb[k]], fv, foff[k], fd[k], fo[k], fh[k])
        if ok:
            if d > SQRT3 * ri + reach_b:
                continue
        else:
            # outside the grid: skip when the ring's sphere misses the grid's box (no point
            # outside a field's grid is inside or near its bone)
            e = 0.0
            yy = (y0, y1, y2)
            for c in range(3):
                lo = fo[k, c]
                hi = fo[k, c] + fh[k] * (fd[k, c] - 1)
                if yy[c] < lo:
                    e += (lo - yy[c]) ** 2
                elif yy[c] > hi:
                    e += (yy[c] - hi) ** 2
            if e > ri * ri:
                continue
        actb[nb] = k
        nb += 1
    nmm = 0
    for jj in range(nbr_off[i], nbr_off[i + 1]):
        j = nbr[jj]
        if may_meet(ci, j, box, ri + reach_m):
            actm[nmm] = j
            nmm += 1
    return nb, _ring_groups(ci, reach_m, cen, coff, nu, actm, nmm, gl, gn)


@njit(cache=True, inline="always")
def _near_segment(ci, reach, cen, coff_j, U, g):
    """Whether a segment of group g of muscle j comes within its two rings' larger radius plus
    ``reach`` of point ci[:3]."""
    for u in range(g * SEG_GROUP, min(g * SEG_GROUP + SEG_GROUP, U - 1)):
        q, _, _ = scan_segments(ci, cen, coff_j, U, u, u + 1, 1e300, -1, 0.0)
        lim = reach + max(cen[coff_j + u, 3], cen[coff_j + u + 1, 3])
        if q <= lim * lim:
            return True
    return False


@njit(cache=True)
def _ring_groups(ci, reach, cen, coff, nu, actm, nmm, gl, gn):
    """For a ring (every point within ci[3] of ci[:3]) and each of its neighbours actm[:nmm],
    into gl[jj, :gn[jj]] the groups of :data:`SEG_GROUP` centre segments (bounding spheres
    cen[first, 4:8]) that may hold the nearest centre segment of one of the ring's points:
    those whose least distance from the ring's sphere is at most the largest distance from it
    of the nearest group. Any other group is farther from every point of the ring than that
    group is, so :func:`query_in` over these finds the same nearest segment as over all. A
    neighbour none of whose candidate groups has a segment within its two rings' larger radius
    plus ``reach`` of the sphere is dropped (for every point of the ring, its nearest segment
    is then farther than that from it: :func:`query_in` is False); actm and gl are
    compacted. Returns how many neighbours remain."""
    ri = ci[3]
    n = 0
    for jj in range(nmm):
        j = actm[jj]
        ng = (nu[j] - 2) // SEG_GROUP + 1
        ub = 1e300
        for g in range(ng):
            r = coff[j] + g * SEG_GROUP
            d = np.sqrt((ci[0] - cen[r, 4]) ** 2 + (ci[1] - cen[r, 5]) ** 2 + (ci[2] - cen[r, 6]) ** 2)
            if d + cen[r, 7] + ri < ub:
                ub = d + cen[r, 7] + ri
        k = 0
        near = False
        for g in range(ng):
            r = coff[j] + g * SEG_GROUP
            d = np.sqrt((ci[0] - cen[r, 4]) ** 2 + (ci[1] - cen[r, 5]) ** 2 + (ci[2] - cen[r, 6]) ** 2)
            if d - cen[r, 7] - ri <= ub:
                gl[n, k] = g
                k += 1
                if not near and d <= ri + reach + cen[r, 7] + cen[r, 8]:
                    near = _near_segment(ci, ri + reach, cen, coff[j], nu[j], g)
        if near:
            actm[n] = j
            gn[n] = k
            n += 1
    return n


def field_lists(box: np.ndarray, fields: BoneFields, world_inv: np.ndarray, reach: float):
    """Which bone fields each muscle can meet: those whose grid's world box meets the muscle's
    box (M, 6) grown by ``reach`` (m), as CSR rows (offsets (M + 1,), field indices)."""
    K = len(fields.bones)
    if K == 0:
        return np.zeros(len(box) + 1, np.int64), np.zeros(0, np.int64)
    world = np.linalg.inv(world_inv[fields.bones])  # (K, 4, 4) bone-local to world
    corner = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, 8).T  # (8, 3)
    ext = fields.h[:, None] * (fields.dims - 1)  # (K, 3)
    local = fields.origin[:, None, :] + corner[None] * ext[:, None, :]  # (K, 8, 3)
    # w[k,p,c] = sum_d R[k,c,d] local[k,p,d] + t[k,c]
    w = np.einsum("kcd,kpd->kpc", world[:, :3, :3], local) + world[:, None, :3, 3]
    fbox = np.concatenate([w.min(axis=1), w.max(axis=1)], axis=1)  # (K, 6)
    meet = np.all(box[:, None, :3] - reach <= fbox[None, :, 3:], axis=-1) & np.all(
        fbox[None, :, :3] <= box[:, None, 3:] + reach, axis=-1)
    idx = np.nonzero(meet)
    return np.concatenate([[0], np.cumsum(np.bincount(idx[0], minlength=len(box)))]).astype(np.int64), \
        idx[1].astype(np.int64)


def neighbours(box: np.ndarray, allow: np.ndarray, margin: float):
    """Allowed pairs whose boxes (M, 6) meet within ``margin``, as CSR rows (offsets, indices)."""
    M = len(box)
    nbr_off = np.zeros(M + 1, np.int64)
    nbr = np.empty(M * M, np.int64)
    n = _box_pairs(box, allow, margin, nbr_off, nbr)
    return nbr_off, nbr[:n]


@njit(cache=True)
def _box_pairs(box, allow, margin, nbr_off, nbr):
    """:func:`neighbours`' rows, in order; returns how many pairs."""
    n = 0
    for i in range(box.shape[0]):
        for j in range(box.shape[0]):
            if not allow[i, j]:
                continue
            meet = True
            for c in range(3):
                if not (box[i, c] <= box[j, 3 + c] + margin and box[j, c] <= box[i, 3 + c] + margin):
                    meet = False
                    break
            if meet:
                nbr[n] = j
                n += 1
        nbr_off[i + 1] = n
    return n


def make_work(nu: np.ndarray, na: np.ndarray, fields: BoneFields, records: int | None = None) -> Work:
    """Scratch arrays for :func:`rings.ring_modes` and :func:`measures.measure`, one of each per
    muscle (:class:`params.Work`; allocated here: the per-muscle kernels are compiled without
    reference counting): rec holds :func:`rings.point_push`'s pulls on thick neighbours (a
    count in [0, 0], then up to ``records`` records, :data:`params.REACTION_RECORDS` unless
    given), react is zeros (it accumulates)."""
    M = max(len(nu), 1)
    records = REACTION_RECORDS if records is None else records
    ng = (int(nu.max()) - 2) // SEG_GROUP + 1
    return Work(np.empty((M, QUERY_SIZE)), np.empty((M, 6)), np.empty((M, 7)), np.empty((M, NMODES)),
                np.empty((M, max(len(fields.bones), 1)), np.int64), np.empty((M, M), np.int64),
                np.empty((M, M, ng), np.int64), np.empty((M, M), np.int64),
                np.empty((M, records + 1, 3 * NMODES + 2)), np.empty((M, int(na.max()), NMODES)),
                np.zeros((int(nu.sum()), 3 * NMODES + 1)))


@njit(cache=True, inline="always")
def rows_of(work, i):
    """Muscle i's rows of ``work`` (:class:`params.Rows`)."""
    return Rows(work.q[i], work.g[i], work.p[i], work.actb[i], work.actm[i], work.gl[i], work.gn[i], work.rec[i])

