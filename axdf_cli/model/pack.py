"""Packing: the rest shapes of a body's muscles made to share space.

Imported muscles overlap in bulk, not at their skins: OpenSim's lines of action with volumes
from the force a muscle makes put several muscles on nearly one line. No push made frame by
frame separates that without popping. So the overlap is resolved once, at the rest pose, and
written into the muscle files as section outlines (``outline:``, 8 control points each, which
may leave the line of action and take any shape); the frame's contact stage then only meets
what motion adds.

The method: a weighted partition of space, then a fit.

1. **Territories.** Every muscle i has an envelope, its rest shape scaled by s_i about its
   axis: the points whose axis-space radial fraction q_i(x) = rho_i / R_i (the distance from
   i's centre line over i's surface radius in that direction, :func:`query.muscle_query`)
   is below s_i. A point belongs to the muscle of least q_i / s_i whose envelope holds it,
   and to none inside a bone (its signed distance field, :mod:`axdf_cli.model.contact`). The
   territories never overlap, by construction; where two envelopes overlap the boundary lies
   where their fractions agree (halfway between two equal muscles on parallel lines).
2. **Rings.** Each ring of a muscle's rest mesh is cut with its territory on a 2-D grid in the
   ring's plane (the largest connected piece, so the territory may leave the line of action),
   and every vertex of the ring is given a target: the territory's boundary, seen from the
   piece's centroid in the vertex's own direction, less the margin.
3. **Fit.** The sections' control points (2 unknowns each, in their rest planes) are fitted to
   the targets by least squares through the surface's own basis (the rest surface is linear in
   them), a little pulled towards where they were.
4. **Volume.** s_i is grown until the packed rest mesh has the muscle's volume again (it
   loses what it shared), and steps 1-3 repeat. A muscle boxed in by bone and neighbours may
   not reach it within tol.PACK_SCALE_MAX; its volume is then what it could take (reported).
5. **Polish.** The round kept leaves what the fit could not follow: smooth sections cut a
   little across territory boundaries. The frame's own contact stage (:func:`contact.resolve_frame`, volume kept,
   the poles where they are: packing fits sections, not attachments) is run at the rest pose
   with many passes, and the sections are fitted to the rings it gives,
   without the smoothing of step 3 (contact's displacements are smooth along the muscle
   already); tol.PACK_POLISH_ROUNDS times. Each round is scored like the others, and the best
   of all is written.

Everything is deterministic: the same muscles give the same outlines, bytes included.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from axdf_cli import tolerances as tol
from axdf_cli.model import bspline, contact
from axdf_cli.model.contact import query
from axdf_cli.model.contact.params import NMODES, QUERY_SIZE, SEG_GROUP, Lists, Mesh, Rows
from axdf_cli.model.muscle import OCT, MuscleModel, MuscleSpec, Section


class RingCut(NamedTuple):
    """How a ring is cut with its territory (module doc, step 2): on a ``pixels`` x ``pixels``
    grid over the ring's radius times ``grow`` (plus 2 mm), outside the bones by
    ``bone_margin``, the targets ``margin`` inside the territory's edge."""

    pixels: int
    grow: float
    bone_margin: float
    margin: float


# ----------------------------------------------------------------------------- territories


@njit(cache=True)
def _frac(x, j, mesh, reach, q):
    """q_j(x) = rho / R of point x against muscle j's rest shape, 1e30 where it cannot hold x."""
    grid, off, nu, na, cen, coff, box = mesh
    if not query.may_meet(x, j, box, reach):
        return 1e30
    if not query.muscle_query(x, grid, off[j], nu[j], na[j], cen, coff[j], reach, q):
        return 1e30
    if q[1] <= 1e-9:
        return 1e30
    return q[0] / q[1]


@njit(cache=True)
def _owned(x, i, s, mesh, reach, fields, nmm, nb, bone_margin, rows):
    """Whether point x lies in muscle i's territory (module doc, step 1), against the bone
    fields rows.actb[:nb] and the neighbours rows.actm[:nmm] (:func:`query.ring_lists`)."""
    q, g, actb, actm = rows.q, rows.g, rows.actb, rows.actm
    qi = _frac(x, i, mesh, reach[i], q) / s[i]
    if not qi < 1.0:
        return False
    if nb > 0:
        d = query.bone_query(x, fields, actb, 0, nb, -1e300, g)
        if d < bone_margin:
            return False
    for jj in range(nmm):
        j = actm[jj]
        qj = _frac(x, j, mesh, reach[j], q) / s[j]
        if qj < qi or (qj == qi and j < i):
            return False
    return True


@njit(cache=True)
def _largest_piece(mask, K, lab, stack):
    """Keep in ``mask`` (K*K) only its largest 4-connected piece; returns its size."""
    for k in range(K * K):
        lab[k] = 0
    best = 0
    best_lab = 0
    n_lab = 0
    for k0 in range(K * K):
        if not mask[k0] or lab[k0] != 0:
            continue
        n_lab += 1
        lab[k0] = n_lab
        top = 0
        stack[top] = k0
        top += 1
        size = 0
        while top > 0:
            top -= 1
            k = stack[top]
            size += 1
            ix = k // K
            iy = k % K
            for d in range(4):
                jx = ix + (1 if d == 0 else (-1 if d == 1 else 0))
                jy = iy + (1 if d == 2 else (-1 if d == 3 else 0))
                if jx < 0 or jy < 0 or jx >= K or jy >= K:
                    continue
                kk = jx * K + jy
                if mask[kk] and lab[kk] == 0:
                    lab[kk] = n_lab
                    stack[top] = kk
                    top += 1
        if size > best:
            best = size
            best_lab = n_lab
    for k in range(K * K):
        mask[k] = best > 0 and lab[k] == best_lab
    return best


@njit(cache=True)
def _query_scratch(nu, nfields):
    """Scratch arrays for contact's queries of one point or ring (:class:`params.Rows`;
    :func:`query.ring_lists`, :func:`_owned`)."""
    M = nu.shape[0]
    ngmax = (nu.max() - 2) // SEG_GROUP + 1
    return Rows(np.empty(QUERY_SIZE), np.empty(6), np.empty(7), np.empty(max(nfields, 1), np.int64),
                np.empty(max(M, 1), np.int64), np.empty((max(M, 1), ngmax), np.int64), np.empty(max(M, 1), np.int64),
                np.empty((1, 3 * NMODES + 2)))


@njit(cache=True, parallel=True)
def _ring_targets(s, mesh, reach, lists, fields, cut, rows, targets, origins, full):
    """Targets of every ring vertex (module doc, step 2). mesh, lists, fields:
    :class:`params.Mesh`, :class:`params.Lists`, :class:`params.Fields`; cut: :class:`RingCut`;
    rows (R, 2): (muscle, ring) pairs of the rings to cut (the pole rows are not); targets,
    origins: like grid (each vertex's target and the ray origin it was found from); full (R,):
    whether the ring's territory is its whole envelope (nothing claims any of it)."""
    for r in prange(rows.shape[0]):
        _ring_targets_one(r, s, mesh, reach, lists, fields, cut, rows, targets, origins, full)


@njit(cache=True)
def _ring_targets_serial(s, mesh, reach, lists, fields, cut, rows, targets, origins, full):
    """:func:`_ring_targets` on this thread alone."""
    for r in range(rows.shape[0]):
        _ring_targets_one(r, s, mesh, reach, lists, fields, cut, rows, targets, origins, full)


@njit(cache=True)
def _ring_targets_one(r, s, mesh, reach, lists, fields, cut, rows, targets, origins, full):
    """:func:`_ring_targets` for row r of ``rows``."""
    grid, off, nu, na, cen, coff, box = mesh
    K, grow, bone_margin, margin = cut
    i = rows[r, 0]
    u = rows[r, 1]
    U = nu[i]
    A = na[i]
    sc = _query_scratch(nu, fields.fb.shape[0])
    q = sc.q
    mask = np.zeros(K * K, np.bool_)
    lab = np.zeros(K * K, np.int64)
    stack = np.zeros(K * K, np.int64)
    dist = np.zeros(K * K, np.int64)
    ci = cen[coff[i] + u].copy()
    t0, t1, t2 = query.centre_tangent(cen, coff[i], U, u)
    # e1: towards the ring's first vertex, across the tangent; e2 = t x e1
    base = off[i] + u * A
    d0 = grid[base, 0] - ci[0]
    d1 = grid[base, 1] - ci[1]
    d2 = grid[base, 2] - ci[2]
    dt = d0 * t0 + d1 * t1 + d2 * t2
    d0 -= dt * t0
    d1 -= dt * t1
    d2 -= dt * t2
    dl = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    if dl < 1e-12 or (t0 == 0.0 and t1 == 0.0 and t2 == 0.0):
        for a in range(A):
            for c in range(3):
                targets[base + a, c] = grid[base + a, c]
                origins[base + a, c] = ci[c]
        full[r] = False
        return
    e10 = d0 / dl
    e11 = d1 / dl
    e12 = d2 / dl
    e20 = t1 * e12 - t2 * e11
    e21 = t2 * e10 - t0 * e12
    e22 = t0 * e11 - t1 * e10
    L = grow * s[i] * ci[3] + 0.002
    h = 2.0 * L / K
    ci[3] = L * 1.4143
    nb, nmm = query.ring_lists(ci, i, mesh, fields, lists, 0.0, reach.max(), sc)
    x = np.empty(3)
    n_env = 0
    for ix in range(K):
        for iy in range(K):
            a_ = -L + (ix + 0.5) * h
            b_ = -L + (iy + 0.5) * h
            x[0] = ci[0] + a_ * e10 + b_ * e20
            x[1] = ci[1] + a_ * e11 + b_ * e21
            x[2] = ci[2] + a_ * e12 + b_ * e22
            if _frac(x, i, mesh, reach[i], q) < s[i]:
                n_env += 1
            mask[ix * K + iy] = _owned(x, i, s, mesh, reach, fields, nmm, nb, bone_margin, sc)
    n = _largest_piece(mask, K, lab, stack)
    full[r] = n == n_env
    if n == 0:
        for a in range(A):
            for c in range(3):
                targets[base + a, c] = ci[c]
                origins[base + a, c] = ci[c]
        return
    # the rays' origin: the piece's deepest point (its largest distance from outside)
    kd = _deepest(mask, K, dist)
    ca = -L + (kd // K + 0.5) * h
    cb = -L + (kd % K + 0.5) * h
    for a in range(A):
        k = base + a
        v0 = grid[k, 0] - ci[0]
        v1 = grid[k, 1] - ci[1]
        v2 = grid[k, 2] - ci[2]
        pa = v0 * e10 + v1 * e11 + v2 * e12
        pb = v0 * e20 + v1 * e21 + v2 * e22
        pt = v0 * t0 + v1 * t1 + v2 * t2
        th = np.arctan2(pb, pa)
        ct = np.cos(th)
        st = np.sin(th)
        # march from the origin to the piece's edge (a star-shaped part of the piece)
        step = 0.25 * h
        rr = 0.0
        rho = 0.0
        while rho < 3.0 * L:
            jx = int(np.floor((ca + rho * ct + L) / h))
            jy = int(np.floor((cb + rho * st + L) / h))
            if not (0 <= jx < K and 0 <= jy < K and mask[jx * K + jy]):
                break
            rr = rho
            rho += step
        rr = max(rr + 0.5 * step - margin, 0.0)
        for c in range(3):
            e1c = e10 if c == 0 else (e11 if c == 1 else e12)
            e2c = e20 if c == 0 else (e21 if c == 1 else e22)
            tc = t0 if c == 0 else (t1 if c == 1 else t2)
            origins[k, c] = ci[c] + ca * e1c + cb * e2c + pt * tc
            targets[k, c] = origins[k, c] + rr * (ct * e1c + st * e2c)



@njit(cache=True)
def _deepest(mask, K, dist):
    """The pixel of ``mask`` (K*K) farthest from any pixel outside it (3-4 chamfer distance,
    the grid's edge counted as outside); the first of equals."""
    big = 1 << 40
    for k in range(K * K):
        dist[k] = big if mask[k] else 0
    for ix in range(K):
        for iy in range(K):
            k = ix * K + iy
            if dist[k] == 0:
                continue
            best = dist[k]
            if ix == 0 or iy == 0 or iy == K - 1:
                best = 3
            else:
                best = min(best, dist[k - K] + 3, dist[k - 1] + 3, dist[k - K - 1] + 4, dist[k - K + 1] + 4)
            dist[k] = best
    for ix in range(K - 1, -1, -1):
        for iy in range(K - 1, -1, -1):
            k = ix * K + iy
            if dist[k] == 0:
                continue
            best = dist[k]
            if ix == K - 1 or iy == 0 or iy == K - 1:
                best = 3
            else:
                best = min(best, dist[k + K] + 3, dist[k + 1] + 3, dist[k + K + 1] + 4, dist[k + K - 1] + 4)
            dist[k] = best
    kb = 0
    for k in range(K * K):
        if dist[k] > dist[kb]:
            kb = k
    return kb


@njit(cache=True, parallel=True)
def _owned_all(pts, owner, s, mesh, reach, lists, fields, bone_margin, out):
    """Whether each point pts[p] lies in the territory of muscle owner[p] (module doc, step 1)."""
    for p in prange(pts.shape[0]):
        _owned_all_one(p, pts, owner, s, mesh, reach, lists, fields, bone_margin, out)


@njit(cache=True)
def _owned_all_serial(pts, owner, s, mesh, reach, lists, fields, bone_margin, out):
    """:func:`_owned_all` on this thread alone."""
    for p in range(pts.shape[0]):
        _owned_all_one(p, pts, owner, s, mesh, reach, lists, fields, bone_margin, out)


@njit(cache=True)
def _owned_all_one(p, pts, owner, s, mesh, reach, lists, fields, bone_margin, out):
    """:func:`_owned_all` for point p."""
    i = owner[p]
    sc = _query_scratch(mesh.nu, fields.fb.shape[0])
    ci = np.empty(8)
    for c in range(3):
        ci[c] = pts[p, c]
    ci[3] = 0.0
    nb, nmm = query.ring_lists(ci, i, mesh, fields, lists, 0.0, reach.max(), sc)
    out[p] = _owned(pts[p], i, s, mesh, reach, fields, nmm, nb, bone_margin, sc)


@njit(cache=True, parallel=True)
def _inside_of(mesh, nbr_off, nbr, out):
    """For every vertex of every muscle (grid rows), the first neighbour whose mesh holds it
    (axis-space query), or -1."""
    M = mesh.nu.shape[0]
    for i in prange(M):
        _inside_of_one(i, mesh, nbr_off, nbr, out)


@njit(cache=True)
def _inside_of_serial(mesh, nbr_off, nbr, out):
    """:func:`_inside_of` on this thread alone."""
    M = mesh.nu.shape[0]
    for i in range(M):
        _inside_of_one(i, mesh, nbr_off, nbr, out)


@njit(cache=True)
def _inside_of_one(i, mesh, nbr_off, nbr, out):
    """:func:`_inside_of` for muscle i."""
    grid, off, nu, na, cen, coff, box = mesh
    q = np.empty(QUERY_SIZE)
    for k in range(off[i], off[i + 1]):
        out[k] = -1
        x = grid[k]
        for jj in range(nbr_off[i], nbr_off[i + 1]):
            j = nbr[jj]
            if not query.may_meet(x, j, box, 0.0):
                continue
            if query.muscle_query(x, grid, off[j], nu[j], na[j], cen, coff[j], 0.0, q) and q[0] < q[1]:
                out[k] = j
                break



# ----------------------------------------------------------------------------- the fit


@dataclass
class _Frames:
    """A muscle's rest section frames: per control point (8N) the axis point, the two plane
    axes, and its twist angle; the surface bases."""

    c: np.ndarray  # (8N, 3)
    r: np.ndarray  # (8N, 3)
    s: np.ndarray  # (8N, 3)
    tw: np.ndarray  # (8N,)
    strength: float
    Bu: np.ndarray  # (U, m)
    Bv: np.ndarray  # (A, 8)


def _frames(model: MuscleModel, rest_world: np.ndarray, sec_t: np.ndarray) -> _Frames:
    """The rest frames of sections at ``sec_t`` on ``model``'s axis, and the surface basis
    along for that many sections (the model's own where they are its sections)."""
    cp_t = np.repeat(sec_t, OCT)
    c, rr, ss, tw = model.rest_frames(rest_world, cp_t)
    m = len(sec_t) + 2
    if len(sec_t) == len(model.spec.sections):
        Bu = model.Bu
    else:
        Bu = bspline.basis_matrix(bspline.clamped_knots(m, 2), 2, np.linspace(0.0, 1.0, model.U))
    return _Frames(c, rr, ss, tw, float(model.spec.strength), Bu, model.Bv)


def section_layout(spec: MuscleSpec, n: int) -> np.ndarray:
    """The packed muscle's section parameters: ``n`` evenly between its first and last
    section's (its own where it has rational weights, or already as many)."""
    t = np.array([s.t for s in spec.sections])
    if spec.weights is not None or len(t) >= n:
        return t
    return np.linspace(t[0], t[-1], n)


class Fit:
    """The least-squares fit of a muscle's section control points (frames ``fr``, 2 unknowns
    each in their planes) to targets for its rest mesh's rings between the poles, pulled
    towards ``x0`` (8N, 2) with weight ``pull`` relative to the data's (None: no pull). The
    rest surface is linear in them; the normal equations are factored once.

    ``rays`` (8N, 2), a section layout's reference coordinates (the original rest shape's):
    the sections stay star-shaped. Each control point then keeps to its own ray from its
    section's centre: point l of section k is c_k + rho_kl d_kl, with d_kl the unit direction
    of rays' point from the mean of its section's points, the centre c_k free and the radii
    rho_kl free with sum_l rho_kl d_kl = 0 (so c_k stays the mean of the section's points,
    which is where contact measures a ring from); radii below tol.PACK_RAY_MIN of the
    reference's mean are raised to it. The surface stays linear in (c, rho): 8 unknowns a
    section instead of 16. Unconstrained, a fit to a territory that wraps around a neighbour
    (the soleus round tibialis posterior) folds its section into a bow tie, a surface that cuts
    itself."""

    def __init__(self, model: MuscleModel, fr: _Frames, x0: np.ndarray | None, pull: float, smooth: float = 0.0,
                 rays: np.ndarray | None = None):
        from scipy.linalg import cho_factor

        A = model.A
        Q = fr.c.shape[0]
        N = Q // OCT
        self.Q, self.shape = Q, (model.U - 2, A, 3)
        Bu = fr.Bu[1:-1]  # (U-2, m): net rows pole0, sections 1..N, pole1; the poles are fixed
        pole0 = model.rest_vertices[0].astype(np.float64)
        pole1 = model.rest_vertices[-1].astype(np.float64)
        fixed = (Bu[:, 0, None, None] * pole0 + Bu[:, -1, None, None] * pole1) * np.ones((1, A, 1))
        self.fixed = fixed + np.einsum("uk,al,klc->uac", Bu[:, 1:-1], fr.Bv, fr.c.reshape(N, OCT, 3))
        w = np.einsum("uk,al->ualk", Bu[:, 1:-1], fr.Bv)  # (U-2, A, 8, N)
        cols_r = np.einsum("ualk,klc->uackl", w, fr.r.reshape(N, OCT, 3)).reshape(-1, Q)
        cols_s = np.einsum("ualk,klc->uackl", w, fr.s.reshape(N, OCT, 3)).reshape(-1, Q)
        self.A = np.concatenate([cols_r, cols_s], axis=1)  # unknowns: r of every (k, l), then s
        ata = self.A.T @ self.A
        scale2 = float(np.linalg.norm(self.A, axis=0).mean()) ** 2
        if smooth > 0 and N >= 3:
            # smooth along the muscle: second differences of each control point's in-plane
            # coordinates over consecutive sections (the frames turn little between them)
            D = np.zeros((N - 2, N))
            for k in range(N - 2):
                D[k, k:k + 3] = (1.0, -2.0, 1.0)
            DtD = D.T @ D  # (N, N) over sections; unknowns ordered (k, l) within r, then s
            L = np.kron(DtD, np.eye(OCT))
            ata = ata + smooth * scale2 * np.kron(np.eye(2), L)
        self.prior = np.zeros(2 * Q)
        if x0 is not None and pull > 0:
            lam2 = pull ** 2 * scale2
            ata = ata + lam2 * np.eye(2 * Q)
            self.prior = lam2 * np.concatenate([x0[:, 0], x0[:, 1]])
        self.T = None
        if rays is not None:
            self.T, self.dirs, self.floor = _ray_map(rays)
            ata = self.T.T @ ata @ self.T
        ata = ata + 1e-12 * np.trace(ata) / len(ata) * np.eye(len(ata))
        self.factor = cho_factor(ata)

    def __call__(self, targets: np.ndarray):
        """targets (U, A, 3) → (in-plane coordinates (8N, 2), the fitted rings (U-2, A, 3))."""
        from scipy.linalg import cho_solve

        rhs = self.A.T @ (targets[1:-1] - self.fixed).reshape(-1) + self.prior
        if self.T is None:
            sol = cho_solve(self.factor, rhs)
        else:
            z = cho_solve(self.factor, self.T.T @ rhs)
            sol = _from_rays(z, self.T, self.dirs, self.floor)
        fitted = (self.A @ sol).reshape(self.shape) + self.fixed
        return np.stack([sol[:self.Q], sol[self.Q:]], axis=1), fitted


def _ray_map(rays: np.ndarray):
    """(T (2Q, 8N): the in-plane coordinates (r of every point, then s) from a section's centre
    and the free part of its radii, the directions (N, 8, 2), the radii's floor (N,))."""
    Q = len(rays)
    N = Q // OCT
    pts = rays.reshape(N, OCT, 2)
    ctr = pts.mean(axis=1)
    d = pts - ctr[:, None]
    rad = np.linalg.norm(d, axis=2)
    dirs = d / np.maximum(rad, 1e-12)[..., None]
    T = np.zeros((2 * Q, N * OCT))
    for k in range(N):
        # radii with sum_l rho_l d_l = 0: the null space of the 2 x 8 directions (6 columns)
        _, _, vt = np.linalg.svd(dirs[k].T)
        Z = vt[2:].T  # (8, 6)
        col = k * OCT
        for l in range(OCT):
            row = k * OCT + l
            T[row, col] = 1.0  # c_r
            T[Q + row, col + 1] = 1.0  # c_s
            T[row, col + 2:col + OCT] = dirs[k, l, 0] * Z[l]
            T[Q + row, col + 2:col + OCT] = dirs[k, l, 1] * Z[l]
    return T, dirs, tol.PACK_RAY_MIN * rad.mean(axis=1)


def _from_rays(z: np.ndarray, T: np.ndarray, dirs: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """The in-plane coordinates of the fit ``z``, every radius raised to its section's floor."""
    y = T @ z
    Q = len(y) // 2
    N = Q // OCT
    pts = np.stack([y[:Q], y[Q:]], axis=1).reshape(N, OCT, 2)
    ctr = z.reshape(N, OCT)[:, :2]
    rho = np.einsum("klc,klc->kl", pts - ctr[:, None], dirs)
    rho = np.maximum(rho, floor[:, None])
    pts = ctr[:, None] + rho[..., None] * dirs
    return np.concatenate([pts[..., 0].reshape(-1), pts[..., 1].reshape(-1)])


def to_file_outlines(coords: np.ndarray, fr: _Frames) -> np.ndarray:
    """In-plane coordinates (8N, 2) → the file's outlines (N, 8, 2): the muscle's own twist
    turned back and its strength divided out."""
    cw, sw = np.cos(fr.tw), np.sin(fr.tw)
    v, w = coords[:, 0], coords[:, 1]
    ov, ow = v * cw + w * sw, -v * sw + w * cw
    k = 1.0 / math.sqrt(fr.strength)
    return (np.stack([ov, ow], axis=1) * k).reshape(-1, OCT, 2)


def with_outlines(spec: MuscleSpec, sec_t: np.ndarray, outlines: np.ndarray) -> MuscleSpec:
    secs = tuple(Section(float(t), None, 0.0, tuple((float(a), float(b)) for a, b in o))
                 for t, o in zip(sec_t, outlines))
    return replace(spec, sections=secs)


# ----------------------------------------------------------------------------- the loop


@dataclass
class PackResult:
    specs: list  # MuscleSpec with outlines
    models: list  # their MuscleModels
    before: np.ndarray  # (M, 3) rest measures before: inside-muscle share, inside-bone share, deepest (m)
    after: np.ndarray  # (M, 3) after
    volume0: np.ndarray  # (M,) rest volumes before
    volume: np.ndarray  # (M,) after
    scale: np.ndarray  # (M,) the envelopes' scales s_i
    history: list  # per round: (mean inside-muscle share, mean inside-bone share, deepest, least and largest volume ratio)
    kept: int = 0  # the round whose shapes these are (the least overlap plus volume change)
    territory_rounds: int = 0  # history's first rows: steps 1-4; the rest: polish (step 5)


def _grids(models):
    shapes = [(m.U, m.A) for m in models]
    nu = np.array([s[0] for s in shapes], dtype=np.int64)
    na = np.array([s[1] for s in shapes], dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(nu * na)]).astype(np.int64)
    coff = np.concatenate([[0], np.cumsum(nu)]).astype(np.int64)
    grid = np.concatenate([contact.vertices_to_grid(m.rest_vertices.astype(np.float64), m.U, m.A) for m in models])
    cen = np.zeros((int(coff[-1]), contact.CEN_COLUMNS))
    box = np.empty((len(models), 6))
    query.centres(grid, off, nu, na, cen, coff)
    query.boxes(grid, off, box)
    return Mesh(grid, off, nu, na, cen, coff, box)


def measure_rest(models, cm: contact.ContactModel, rest_inv: np.ndarray, threads: bool = False) -> np.ndarray:
    """(M, 3) the rest meshes' inside-muscle share, inside-bone share and deepest penetration
    (``threads``: on numba's threads, the same values; :func:`contact.resolve_frame`)."""
    mesh = _grids(models)
    f = cm.fields
    out = np.zeros((len(models), 3))
    measure = contact.measures.measure if threads else contact.measures.measure_serial
    lists = Lists(*query.neighbours(mesh.box, cm.allow, 0.0), *query.field_lists(mesh.box, f, rest_inv, 0.0))
    measure(mesh, lists, f.posed(rest_inv), out, query.make_work(mesh.nu, mesh.na, f))
    return out


def pack(specs, models, skeleton, rest_world: np.ndarray, cm: "contact.ContactModel", *,
         iterations: int = tol.PACK_ITERATIONS, pixels: int = tol.PACK_PIXELS,
         sections: int = tol.PACK_SECTIONS, polish: int = tol.PACK_POLISH_ROUNDS, poses=None,
         progress=None, threads: bool = False) -> PackResult:
    """Pack the rest shapes (module doc): ``iterations`` rounds of steps 1-4, then ``polish``
    rounds of step 5 (over the rest pose and the frames of ``poses``: :func:`_polish`).
    ``cm``: the muscles' contact model (pairs, bone fields). ``threads``: the kernels run on
    numba's threads (the same bytes; never in a process forked from one that used them:
    :func:`axdf_cli.runtime.use_threads`)."""
    M = len(models)
    inv = np.linalg.inv(rest_world)
    f = cm.fields
    fields = f.posed(inv)
    ring_targets = _ring_targets if threads else _ring_targets_serial
    owned_all = _owned_all if threads else _owned_all_serial
    inside_of = _inside_of if threads else _inside_of_serial
    mesh = _grids(models)  # the envelopes: the original rest shapes
    grid, off, nu, na, cen, coff, box = mesh
    rmax = np.array([cen[coff[m]:coff[m + 1], 3].max() for m in range(M)])
    layouts = [section_layout(sp, sections) for sp in specs]
    frames = [_frames(m, rest_world, t) for m, t in zip(models, layouts)]
    # the original rest meshes in the new layouts: where the fit is pulled to
    x0 = [Fit(m, fr, None, 0.0)(contact.vertices_to_grid(m.rest_vertices.astype(np.float64), m.U, m.A)
                                 .reshape(m.U, m.A, 3))[0] for m, fr in zip(models, frames)]
    fitters = [Fit(m, fr, x, tol.PACK_PULL, tol.PACK_SMOOTH, rays=x) for m, fr, x in zip(models, frames, x0)]
    v0 = np.array([m.v0 for m in models])
    before = measure_rest(models, cm, inv, threads)
    s = np.ones(M)
    rows = np.array([(i, u) for i in range(M) for u in range(1, nu[i] - 1)], dtype=np.int64)
    history = []
    best = None
    for it in range(iterations):
        reach = (s - 1.0) * rmax + 1e-3
        growb = box.copy()
        growb[:, :3] -= reach[:, None]
        growb[:, 3:] += reach[:, None]
        lists = Lists(*query.neighbours(growb, cm.allow, 0.0), *query.field_lists(growb, f, inv, 0.0))
        targets = grid.copy()
        origins = grid.copy()
        full = np.zeros(len(rows), np.bool_)
        cut = RingCut(pixels, tol.PACK_GROW * max(1.0, float(s.max())), tol.CONTACT_BONE_MARGIN, tol.PACK_MARGIN)
        ring_targets(s, mesh, reach, lists, fields, cut, rows, targets, origins, full)
        # a muscle whose territory is its whole rest shape (nothing claims any of it) is kept as it is
        clear = (np.bincount(rows[:, 0], weights=(~full).astype(np.float64), minlength=M) == 0) & (s == 1.0)
        # fit; where a fitted vertex leaves its territory, its target is drawn in and fitted again
        owner = np.repeat(np.arange(M), [(nu[i] - 2) * na[i] for i in range(M)])
        ring_rows = np.concatenate([np.arange(off[i] + na[i], off[i + 1] - na[i]) for i in range(M)])
        for fr_round in range(tol.PACK_FIT_ROUNDS + 1):
            fits = [(None, grid[off[i]:off[i + 1]].reshape(nu[i], na[i], 3)[1:-1]) if clear[i] else
                    fitters[i](targets[off[i]:off[i + 1]].reshape(nu[i], na[i], 3)) for i in range(M)]
            if fr_round == tol.PACK_FIT_ROUNDS:
                break
            pts = np.concatenate([ft[1].reshape(-1, 3) for ft in fits])
            ok = np.zeros(len(pts), np.bool_)
            owned_all(pts, owner, s, mesh, reach, lists, fields, 0.0, ok)
            draw = np.zeros(len(grid), np.bool_)
            draw[ring_rows[~ok]] = True
            # where the fit overshot its target outwards, the target is set back by the overshoot
            fitted = np.zeros_like(grid)
            fitted[ring_rows] = pts
            d = targets - origins
            rt = np.linalg.norm(d, axis=1)
            rf = np.einsum("kc,kc->k", fitted - origins, d) / np.maximum(rt, 1e-12)
            over = draw & (rf > rt)
            targets[over] = origins[over] + (np.maximum(2.0 * rt[over] - rf[over], 0.0) / np.maximum(rt[over], 1e-12))[:, None] * d[over]
            draw &= ~over
            # a muscle whose fitted mesh holds another's fitted vertex (one its rays missed,
            # a thin tendon): drawn in around the nearest of its own vertices
            fg = grid.copy()
            fg[ring_rows] = pts
            fcen = np.zeros_like(cen)
            fbox = np.empty_like(box)
            query.centres(fg, off, nu, na, fcen, coff)
            query.boxes(fg, off, fbox)
            held = np.empty(len(fg), np.int64)
            inside_of(Mesh(fg, off, nu, na, fcen, coff, fbox), *query.neighbours(fbox, cm.allow, 0.0), held)
            for k in np.nonzero(held >= 0)[0]:
                j = int(held[k])
                vj = fg[off[j]:off[j + 1]]
                n = int(np.argmin(((vj - fg[k]) ** 2).sum(axis=1)))
                u, a_ = divmod(n, int(na[j]))
                for du in (-1, 0, 1):
                    if 1 <= u + du <= nu[j] - 2:
                        for da in (-1, 0, 1):
                            draw[off[j] + (u + du) * na[j] + (a_ + da) % na[j]] = True
            if not draw.any() and not over.any():
                break
            targets[draw] = origins[draw] + tol.PACK_DRAW_IN * (targets[draw] - origins[draw])
        new_specs, new_models = [], []
        for i in range(M):
            if clear[i]:
                new_specs.append(specs[i])
                new_models.append(models[i])
                continue
            spec = with_outlines(specs[i], layouts[i], to_file_outlines(fits[i][0], frames[i]))
            new_specs.append(spec)
            new_models.append(MuscleModel(spec, skeleton.bone_index, rest_world, skeleton))
        score, row, ratio = _score(new_models, cm, inv, v0, threads)
        history.append(row)
        # the round kept: the least overlap plus volume change (all shares)
        if best is None or score < best[0]:
            best = (score, it, new_specs, new_models, s.copy())
        if progress is not None:
            progress(it, history[-1])
        # grow the envelope of each muscle short of its volume (area ~ s^2 where free)
        s = np.clip(s * np.clip(ratio ** -tol.PACK_GAIN, 1.0 / tol.PACK_STEP, tol.PACK_STEP), 1.0, tol.PACK_SCALE_MAX)
    job = _Job(specs, models, skeleton, rest_world, cm, layouts, frames, v0, x0, threads)
    best = _polish(best, job, history, polish, progress, poses)
    _, kept, cur_specs, cur_models, s = best
    after = measure_rest(cur_models, cm, inv, threads)
    return PackResult(cur_specs, cur_models, before, after, v0, np.array([m.v0 for m in cur_models]), s, history, kept,
                      iterations)


def _score(models, cm, inv, v0, threads):
    """(the round's score: mean inside-muscle share + mean inside-bone share + mean |volume
    ratio - 1|, its history row, the volume ratios)."""
    vol = np.array([m.v0 for m in models])
    ratio = vol / v0
    meas = measure_rest(models, cm, inv, threads)
    row = (float(meas[:, 0].mean()), float(meas[:, 1].mean()), float(meas[:, 2].max()), float(ratio.min()),
           float(ratio.max()))
    return float(meas[:, 0].mean() + meas[:, 1].mean() + np.abs(ratio - 1.0).mean()), row, ratio


#: The polish asks for each push once (no over-relaxation, tol.CONTACT_RELAX): its passes
#: run to the end (tol.PACK_POLISH_PASSES), and the shipped libraries were packed so.
PACK_RELAX = (1.0, 1.0, 1.0)


@dataclass(frozen=True)
class _Job:
    """What the polish works on: the muscles as given, their section layouts and frames, the
    rest volumes v0, the rays the fits keep (None: the sections' own), and ``threads``."""

    specs: list
    models: list
    skeleton: object
    rest_world: np.ndarray
    cm: contact.ContactModel
    layouts: list
    frames: list
    v0: np.ndarray
    rays: list | None
    threads: bool


def _polish(best, job: _Job, history, rounds, progress, poses=None):
    """Step 5 (module doc): the frame's own contact, resolved at the rest pose (and at every
    frame ``poses`` gives) with tol.PACK_POLISH_PASSES passes, and the sections fitted to the
    mean of where it put the rings, mapped back to the rest pose; ``rounds`` times, from the
    best round so far. ``poses(specs, models)`` → (world to bone-local (F, B, 4, 4), [(F, V, 3)
    every muscle's no-contact vertices]). Returns the best (score, round, specs, models, scales)."""
    specs, models, skeleton, rest_world, cm = job.specs, job.models, job.skeleton, job.rest_world, job.cm
    layouts, frames, v0, rays, threads = job.layouts, job.frames, job.v0, job.rays, job.threads
    inv = np.linalg.inv(rest_world)
    _, _, cur_specs, cur_models, s = best
    fits = {}
    for r in range(rounds):
        verts = [m.rest_vertices.astype(np.float64) for m in cur_models]
        moved, _, touched, _, _ = contact.resolve_frame(cm, verts, inv, tol.PACK_POLISH_PASSES, False, poles=False,
                                                        relax=PACK_RELAX, threads=threads)
        shift = [mv - v for mv, v in zip(moved, verts)]
        n = 1
        if poses is not None:
            pinv, pverts = poses(cur_specs, cur_models)
            for fi in range(len(pinv)):
                vs = [pv[fi].astype(np.float64) for pv in pverts]
                if not all(np.isfinite(v).all() for v in vs):
                    continue
                pm, _, pt, _, _ = contact.resolve_frame(cm, vs, pinv[fi], tol.PACK_POLISH_PASSES, False, poles=False,
                                                        relax=PACK_RELAX, threads=threads)
                n += 1
                for i in np.nonzero(pt)[0]:
                    shift[i] = shift[i] + to_rest(pm[i] - vs[i], verts[i], vs[i], models[i].U, models[i].A)
                touched |= pt
        if not touched.any():
            break
        cur_specs, cur_models = list(cur_specs), list(cur_models)
        for i in np.nonzero(touched)[0]:
            m = models[i]
            if i not in fits:  # the sections' own least squares: contact's rings are smooth already
                fits[i] = Fit(m, frames[i], None, 0.0, rays=None if rays is None else rays[i])
            target = verts[i] + shift[i] / n
            coords, _ = fits[i](contact.vertices_to_grid(target, m.U, m.A).reshape(m.U, m.A, 3))
            cur_specs[i] = with_outlines(specs[i], layouts[i], to_file_outlines(coords, frames[i]))
            cur_models[i] = MuscleModel(cur_specs[i], skeleton.bone_index, rest_world, skeleton)
        score, row, _ = _score(cur_models, cm, inv, v0, threads)
        history.append(row)
        if score < best[0]:
            best = (score, len(history) - 1, cur_specs, cur_models, s)
        if progress is not None:
            progress(len(history) - 1, row)
    return best


def to_rest(d: np.ndarray, rest: np.ndarray, posed: np.ndarray, U: int, A: int) -> np.ndarray:
    """Displacements ``d`` (V, 3) of a posed mesh's vertices, carried back to its rest mesh:
    ring by ring, through the linear map that takes the rest ring's offsets from its centre
    (and its centre line's direction) to the posed ring's (least squares; the axial model moves
    a ring as a turned, scaled section). The poles' displacements are dropped (they are the
    attachments)."""
    R = rest[1:-1].reshape(U - 2, A, 3)
    P = posed[1:-1].reshape(U - 2, A, 3)
    cr, cp = R.mean(axis=1), P.mean(axis=1)
    x, y = R - cr[:, None], P - cp[:, None]
    line_r = np.concatenate([rest[:1], cr, rest[-1:]])
    line_p = np.concatenate([posed[:1], cp, posed[-1:]])
    tr, tp = line_r[2:] - line_r[:-2], line_p[2:] - line_p[:-2]
    tr *= (np.linalg.norm(x, axis=2).mean(axis=1) / np.maximum(np.linalg.norm(tr, axis=1), 1e-12))[:, None]
    tp *= (np.linalg.norm(y, axis=2).mean(axis=1) / np.maximum(np.linalg.norm(tp, axis=1), 1e-12))[:, None]
    x = np.concatenate([x, tr[:, None]], axis=1)  # (U-2, A+1, 3)
    y = np.concatenate([y, tp[:, None]], axis=1)
    # y ~= x @ Mk per ring; a displacement e of the posed ring is e @ inv(Mk) at rest
    xtx = np.einsum("uac,uad->ucd", x, x)
    xty = np.einsum("uac,uad->ucd", x, y)
    mk = np.linalg.solve(xtx, xty)
    out = np.zeros_like(d)
    dr = d[1:-1].reshape(U - 2, A, 3)
    out[1:-1] = np.einsum("uac,ucd->uad", dr, np.linalg.inv(mk)).reshape(-1, 3)
    return out
