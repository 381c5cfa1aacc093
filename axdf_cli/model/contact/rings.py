"""The contact pass: what every ring of every muscle asks for, and its low-pass.

At evenly spaced points of every sampled ring (:func:`ring_modes`), the push each point asks
for (:func:`point_push`): out of a neighbour it lies within the margin of, by its share of the
distance to leave the neighbour's section (:func:`params.pair_shares`: a deeper muscle gives
way more), faded out where the point and its ring's centre both lie near the neighbour's axis
(two muscles on one line of action have no side to push to); out of a bone along the field's
gradient; and, where the ring is thin against the neighbour, the neighbour's section pulled in
past it (a thin muscle inside a thick one; :func:`add_reactions`). At each pole, the bones'
push as a whole. Per ring, the pushes' low-pass around the ring (the first two Fourier modes:
the ring's shift, tilt of one side and flattening), linear between sampled rings and smoothed
along the muscle (:func:`smooth_rings`). Every step is a continuous function of the frame's
meshes: soft fades and caps, no switching.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from axdf_cli import tolerances as tol
from axdf_cli.model.contact.params import NMODES, PushParams
from axdf_cli.model.contact.query import (bone_query, may_meet, modes, query_in, ring_lists, rows_of, section_angle,
                                          smoothstep)


@njit(cache=True, inline="always")
def within(x, j, jj, mesh, margin, q, gl, gn):
    """Whether point x lies within ``margin`` of neighbour j's surface (j = actm[jj], its
    segment groups gl[jj, :gn[jj]]: :func:`ring_lists`), with j's query in q
    (:func:`query.query_in`)."""
    grid, off, nu, na, cen, coff, box = mesh
    if not may_meet(x, j, box, margin):
        return False
    if not query_in(x, grid, off[j], nu[j], na[j], cen, coff[j], margin, q, gl, jj, gn[jj]):
        return False
    return q[0] < q[1] + margin and q[1] > 0.0


@njit(cache=True, inline="always")
def _give_way(amt, gain, j, mesh, q, g, rec):
    """Record that muscle j's section at the point of query q (:func:`query_in`) is pulled in
    by ``amt`` (m) at the point's angle, asked for ``gain`` times over (tol.CONTACT_RELAX):
    for each of j's two rings there, a record in rec (count in rec[0, 0]): the row, the modes
    of the pull (the Fourier sums of one sample, weighted by its length and the ring's share of
    the segment, times ``gain``), and that weight (:func:`add_reactions` takes their weighted
    mean). g: scratch (NMODES)."""
    grid, off, nu, na, cen, coff = mesh.grid, mesh.off, mesh.nu, mesh.na, mesh.cen, mesh.coff
    th = section_angle(grid, off[j], na[j], cen, coff[j], nu[j], int(q[8]), q[9], q[5], q[6], q[7])
    if not (amt > 0.0 and th == th):
        return
    bu = int(q[8])
    modes(th, g)
    for e in range(2):
        wr = amt * ((1.0 - q[9]) if e == 0 else q[9])
        if wr <= 0.0:
            continue
        n = int(rec[0, 0])
        rec[0, 0] += 1.0
        if n + 1 >= rec.shape[0]:
            continue  # no room: counted, and the pass is run again with more
        rec[n + 1, 0] = coff[j] + bu + e
        for r in range(NMODES):
            br = (1.0 if r == 0 else 2.0) * g[r]
            for c in range(3):
                rec[n + 1, 1 + r * 3 + c] = gain * wr * br * amt * q[5 + c]
        rec[n + 1, 1 + 3 * NMODES] = wr


@njit(cache=True, inline="always")
def point_push(x, ci, i, mesh, fields, share, nmm, nbb, prm, rows):
    """The pushes that point x of muscle i (its ring's centre ci) asks for, against the bone
    fields actb[:nbb] and the neighbours actm[:nmm] (:func:`ring_lists`): in p[4:7], out of
    every bone field by (margin_b - d) along the field's gradient where d < margin_b; in
    p[:3], out of every neighbour j it lies within the margin of, by i's share of the distance to leave j's
    section (a circle of j's radius + margin about j's axis point) along the line from j's axis
    to ci (plus a little of x's radial direction from j's axis, faded out for points nearer j's
    axis than deep1 of j's radius, none below deep0), the push faded out likewise where both x
    and ci lie near j's axis (ci's distance read as tol.CONTACT_DEEP_FADE_CENTRES of itself: two
    muscles on one line of action have no side to push to, and pushing them anyway piles them
    up; a ring that crosses j off its axis has one); p[3]: the signed
    distance to the nearest bone (1e30: none near). Kept apart, the two are smoothed along the
    muscle with different ends (:func:`ring_modes`). Where x's ring is thin against j (its
    radius under thin1 of j's, fully under thin0, times the ring's end fade ci[9]), j gives way
    too: for each of j's two rings at x, a record in rec (count in rec[0, 0]): the row,
    the modes of a push of j's section at x's angle inwards past x by j's share (the Fourier
    sums of one sample, weighted by the push's length and the ring's share of the segment),
    and that weight (:func:`add_reactions` takes their weighted mean). Returns how many
    neighbours pushed.
    Each of the three is asked for relax_m, relax_b, relax_r times over (tol.CONTACT_RELAX).
    prm: :class:`params.PushParams`; rows: :class:`params.Rows` (actb, actm, gl, gn as
    :func:`query.ring_lists` left them; q, g, p, rec)."""
    q, g, p, actb, actm, gl, gn, rec = rows
    margin_m, margin_b, deep0, deep1, sep0, sep1, radial_blend, thin0, thin1, relax_m, relax_b, relax_r = prm
    p[0] = 0.0
    p[1] = 0.0
    p[2] = 0.0
    p[3] = 1e30
    p[4] = 0.0
    p[5] = 0.0
    p[6] = 0.0
    if nbb > 0:
        d = bone_query(x, fields, actb, 0, nbb, margin_b, g)
        p[3] = d
        if d < margin_b:
            # along the gradient as it is, not normalized: length 1 near the surface, shorter
            # where the field's sides meet deep inside, so the push fades where its direction
            # turns (normalized, it flipped there between frames: pops)
            for c in range(3):
                p[4 + c] = relax_b * (margin_b - d) * g[c]
    nm = 0
    for jj in range(nmm):
        j = actm[jj]
        if not within(x, j, jj, mesh, margin_m, q, gl, gn):
            continue
        rho = q[0]
        rr = q[1] + margin_m
        fade = smoothstep((rho / q[1] - deep0) / (deep1 - deep0))  # x near j's axis
        e0 = ci[0] - q[2]
        e1 = ci[1] - q[3]
        e2 = ci[2] - q[4]
        sep = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2) / q[1]  # x's ring centre from j's axis, in j's radii
        if fade <= 0.0 and tol.CONTACT_DEEP_FADE_CENTRES * sep <= deep0:
            continue
        # a thin muscle inside a thick one: the thick one gives way too, its section at x's
        # angle pulled in past x by its share (react: per ring of j, the modes' sums weighted
        # by the push's length, and those lengths: a weighted mean, continuous as samples come
        # and go)
        thin = (1.0 - smoothstep((ci[3] / q[1] - thin0) / (thin1 - thin0))) * ci[9]
        if thin > 0.0 and fade > 0.0:
            # (g: free again once the bones' push is taken)
            _give_way(thin * fade * share[j, i] * (rr - rho), relax_r, j, mesh, q, g, rec)
        # the push: along the line from j's axis to x's ring centre, plus a little of x's radial
        # direction, which turns fast near j's axis (so that part fades there); faded out
        # where the two axes (nearly) meet, whose direction from one to the other turns fast as
        # they move, and where both x and its ring centre lie near j's axis (one line of
        # action: no side to push to), not where a ring crosses j off its axis
        bl = radial_blend * q[1] * fade
        fade = (smoothstep((max(rho / q[1], tol.CONTACT_DEEP_FADE_CENTRES * sep) - deep0) / (deep1 - deep0))
                * smoothstep((sep - sep0) / (sep1 - sep0)))
        if fade <= 0.0:
            continue
        e0 += bl * q[5]
        e1 += bl * q[6]
        e2 += bl * q[7]
        el = np.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if el < 1e-12:
            e0 = q[5]
            e1 = q[6]
            e2 = q[7]
        else:
            e0 /= el
            e1 /= el
            e2 /= el
        # leave the circle of radius rr about the axis point along e: x + s e
        b = rho * (q[5] * e0 + q[6] * e1 + q[7] * e2)
        s = -b + np.sqrt(max(b * b + rr * rr - rho * rho, 0.0))
        w = relax_m * fade * share[i, j] * s
        p[0] += w * e0
        p[1] += w * e1
        p[2] += w * e2
        nm += 1
    return nm


@njit(cache=True, parallel=True)
def ring_modes(mesh, lists, fields, share, prm, cstep, rstep, poles, out, work):
    """One Jacobi pass (module doc, steps 1-2), every muscle from the same state: the pushes at
    ``ns`` = A / ``cstep`` evenly spaced points of every ``rstep``-th ring (and the last inner
    ring), and per such ring their low-pass around the ring, the least-squares fit of the
    :data:`NMODES` modes, which for evenly spaced samples are the discrete Fourier coefficients
    (the modes are orthogonal there): C_0 = mean p, C_k = (2 / ns) sum p b_k, the muscles'
    pushes into coef and the bones' into coefb (smoothed with different ends). coef (rings,
    NMODES, 3); rings between sampled ones: linear between theirs; poles: the bones' push alone,
    mode 0 alone (and the neighbours they lie in give way; ``poles`` False: 0). touched (M,):
    set where a sample was pushed; buried (M,): the share of samples inside a bone. work:
    scratch arrays (:func:`make_work`), one set per muscle, and each muscle's thick neighbours'
    giving way recorded in its own rows of them (:func:`add_reactions` adds them up in
    muscle order): the muscles are independent within a pass and run on numba's threads
    (:func:`_ring_modes_one`), the same bytes for any number of threads
    (:func:`ring_modes_serial`: the same on this thread alone). mesh, lists, fields, prm, out:
    :class:`params.Mesh`, :class:`params.Lists`, :class:`params.Fields`,
    :class:`params.PushParams`, :class:`params.Modes` (coef, coefb, touched, buried)."""
    for i in prange(mesh.nu.shape[0]):
        _ring_modes_one(i, mesh, lists, fields, share, prm, cstep, rstep, poles, out, work)


@njit(cache=True)
def ring_modes_serial(mesh, lists, fields, share, prm, cstep, rstep, poles, out, work):
    """:func:`ring_modes` on this thread alone."""
    for i in range(mesh.nu.shape[0]):
        _ring_modes_one(i, mesh, lists, fields, share, prm, cstep, rstep, poles, out, work)


@njit(cache=True, _nrt=False)
def _ring_modes_one(i, mesh, lists, fields, share, prm, cstep, rstep, poles, out, work):
    """:func:`ring_modes` for muscle i, with its own scratch arrays (row i of each of
    work's). Compiled without numba's reference counting (it allocates nothing): the helpers
    inlined into its loops would otherwise count references to each array they are handed,
    which costs more than the queries' own arithmetic)."""
    grid, off, nu, na, cen, coff, box = mesh
    coef, coefb, touched, buried = out
    rows = rows_of(work, i)
    q, g, p, actb, actm, gl, gn, rec = rows
    b = work.b[i]
    tab = work.tab[i]
    rec[0, 0] = 0.0
    tab_a = -1  # the resolution tab holds the modes of (its columns' angles)
    margin_m = prm[0]
    margin_b = prm[1]
    U = nu[i]
    A = na[i]
    ns = A // cstep
    last = -1
    nb = 0
    nsamp = 0
    u = 1
    while u <= U - 2:
        ci = cen[coff[i] + u]
        r0 = coff[i] + u
        nbb, nmm = ring_lists(ci, i, mesh, fields, lists, margin_b, margin_m, rows)
        for r in range(NMODES):
            for c in range(3):
                coef[r0, r, c] = 0.0
                coefb[r0, r, c] = 0.0
        if nbb == 0 and nmm == 0:
            nsamp += ns  # nothing near: no push (the sums below would add zeros)
            ns_loop = 0
        else:
            ns_loop = ns
        if ns_loop > 0 and tab_a != A:
            for a in range(A):  # the modes at each column of this resolution
                modes(2.0 * np.pi * a / A, b)
                for r in range(NMODES):
                    tab[a, r] = b[r]
            tab_a = A
        for si in range(ns_loop):
            a = si * A // ns
            k = off[i] + u * A + a
            point_push(grid[k], ci, i, mesh, fields, share, nmm, nbb, prm, rows)
            nsamp += 1
            if p[3] < 0.0:
                nb += 1
            if p[0] != 0.0 or p[1] != 0.0 or p[2] != 0.0 or p[4] != 0.0 or p[5] != 0.0 or p[6] != 0.0:
                touched[i] = True
            for r in range(NMODES):
                w = (1.0 if r == 0 else 2.0) / ns
                for c in range(3):
                    coef[r0, r, c] += w * tab[a, r] * p[c]
                    coefb[r0, r, c] += w * tab[a, r] * p[4 + c]
        # rings between the previous sampled ring and this one: linear
        if last > 0:
            for v in range(last + 1, u):
                t = (v - last) / (u - last)
                for r in range(NMODES):
                    for c in range(3):
                        coef[coff[i] + v, r, c] = (1.0 - t) * coef[coff[i] + last, r, c] + t * coef[r0, r, c]
                        coefb[coff[i] + v, r, c] = (1.0 - t) * coefb[coff[i] + last, r, c] + t * coefb[r0, r, c]
        last = u
        if u == U - 2:
            break
        u = min(u + rstep, U - 2)
    # the poles (the tips of the end caps, on the attachments): pushed as a whole (mode 0 only,
    # so the pole's A grid copies stay one point) out of the bones they lie in, by the same
    # rule as a ring's samples: the mesh's tip leaves the bone where the model's attachment
    # point lies inside its mesh (the path, and so the length, stays the model's). Not out of
    # muscles: where attachments crowd (the adductors' origins by the pubis) a pole pushed
    # near a neighbour's axis turned between frames (a 2.4x step on the walk)
    for v in (0, U - 1):
        r0 = coff[i] + v
        for r in range(NMODES):
            for c in range(3):
                coef[r0, r, c] = 0.0
                coefb[r0, r, c] = 0.0
        if not poles:
            continue
        ci = cen[r0]
        nbb, nmm = ring_lists(ci, i, mesh, fields, lists, margin_b, margin_m, rows)
        x = grid[off[i] + v * A]
        if nbb > 0:
            # asked for once (relax_b 1): the pole moves by its own push, which no low-pass
            # spreads, so over-relaxed it would overshoot the bone's surface
            prm1 = PushParams(prm[0], prm[1], prm[2], prm[3], prm[4], prm[5], prm[6], prm[7], prm[8], prm[9], 1.0,
                              prm[11])
            point_push(x, ci, i, mesh, fields, share, 0, nbb, prm1, rows)
            for c in range(3):
                coefb[r0, 0, c] = p[4 + c]
            if p[4] != 0.0 or p[5] != 0.0 or p[6] != 0.0:
                touched[i] = True
        # a pole inside a neighbour: the neighbour gives way (the pole is an attachment, as
        # thin as can be), pulled in past it by its share, faded near its axis as a push is
        for jj in range(nmm):
            j = actm[jj]
            if not within(x, j, jj, mesh, margin_m, q, gl, gn):
                continue
            rr = q[1] + margin_m
            fade = smoothstep((q[0] / q[1] - prm[2]) / (prm[3] - prm[2]))  # (prm[2:4]: deep0, deep1)
            _give_way(fade * share[j, i] * (rr - q[0]), prm[11], j, mesh, q, g, rec)
    buried[i] = nb / max(nsamp, 1)


@njit(cache=True)
def add_reactions(rec, react, coef, nu, coff, touched, floor):
    """The thick muscles' giving way (the records :func:`point_push` left in each muscle's
    rec: rec[i, 0, 0] of them, from row 1: the row, the modes' sums, the weight) added up
    muscle by muscle, in order, into react, then into their rings' modes (the poles stay);
    react is cleared for the next pass."""
    for i in range(rec.shape[0]):
        for n in range(int(rec[i, 0, 0])):
            row = int(rec[i, n + 1, 0])
            for k in range(3 * NMODES):
                react[row, k] -= rec[i, n + 1, 1 + k]
            react[row, 3 * NMODES] += rec[i, n + 1, 1 + 3 * NMODES]
    for m in range(nu.shape[0]):
        for u in range(1, nu[m] - 1):
            row = coff[m] + u
            w = react[row, 3 * NMODES]
            if w <= 0.0:
                continue
            touched[m] = True
            # the pushes' mean weighted by their lengths (times the share of each that falls
            # on this ring), all of it once that weight reaches `floor`: continuous as
            # samples come and go, and as one passes from this ring's segment to the next
            w = max(w, floor)
            for r in range(NMODES):
                for c in range(3):
                    coef[row, r, c] += react[row, r * 3 + c] / (w * NMODES)
    react[:, :] = 0.0


@njit(cache=True)
def smooth_rings(coef, nu, coff, passes, free_ends, tmp):
    """``passes`` rounds of [1 2 1]/4 smoothing of the modes along each muscle (the poles keep
    their own: 0 for the muscles' pushes, the attachments hold; ``free_ends``: the end rings
    are smoothed as if the pole moved with them, so they keep their own push)."""
    for i in range(nu.shape[0]):
        U = nu[i]
        o = coff[i]
        for _ in range(passes):
            for u in range(1, U - 1):
                lo = o + u - 1
                hi = o + u + 1
                if free_ends:
                    lo = max(lo, o + 1)
                    hi = min(hi, o + U - 2)
                for r in range(NMODES):
                    for c in range(3):
                        tmp[u, r, c] = 0.25 * coef[lo, r, c] + 0.5 * coef[o + u, r, c] + 0.25 * coef[hi, r, c]
            for u in range(1, U - 1):
                for r in range(NMODES):
                    for c in range(3):
                        coef[o + u, r, c] = tmp[u, r, c]

