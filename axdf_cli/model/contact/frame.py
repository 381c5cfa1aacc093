"""Contact for a frame: every muscle's rings pushed out of its neighbours and the bones, the
volume kept (:func:`resolve_frame`), and the run's contact model (:func:`build`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.model.contact import measures, query, rings, volume
from axdf_cli.model.contact.fields import BoneFields, bone_field
from axdf_cli.model.contact.params import (CEN_COLUMNS, NMODES, Lists, Mesh, Modes, pair_mask, pair_shares,
                                           push_params)
from axdf_cli.model.contact.query import bone_query, field_lists, make_work, neighbours
from axdf_cli.model.contact.rings import add_reactions, smooth_rings
from axdf_cli.model.contact.volume import grid_volumes, to_grid


@dataclass(frozen=True)
class ContactModel:
    """What contact needs for a run: the pairs, their shares, the bone fields."""

    allow: np.ndarray  # (M, M) bool
    share: np.ndarray  # (M, M) float64
    fields: BoneFields
    shapes: tuple  # ((U, A) per muscle)
    yields: np.ndarray  # (M,) layers
    enabled: bool = True  # False: measure only (--no-contact)


def resolve_frame(model: ContactModel, vertices: list[np.ndarray], world_inv: np.ndarray,
                  iterations: int = tol.CONTACT_ITERATIONS, measure_before: bool = True,
                  volumes: np.ndarray | None = None, poles: bool = True, relax: tuple = tol.CONTACT_RELAX,
                  threads: bool = False):
    """Contact for one frame.

    vertices : [(V_m, 3) float64] every muscle's no-contact mesh; world_inv : (B, 4, 4) world
    to bone-local transforms. Returns (vertices [(V_m, 3)] (the input arrays themselves where
    nothing touched), normals [(V_m, 3) or None where unchanged], changed (M,) bool,
    before (M, 3), after (M, 3)): inside-muscle share, inside-bone share and deepest
    penetration before and after contact. ``measure_before`` False (the stage, to halve the
    measuring): before's inside-bone share is that of the first pass's samples, the rest NaN.
    ``volumes`` (M,): filled with each muscle's mesh volume after contact where any moved.
    ``poles`` False: the poles stay where they are (the packer, which fits the rest sections
    to the rings contact gives, the poles being the model's attachments). ``relax``: how many
    times over each pass asks for the muscles' pushes, the bones' and the thick muscles' giving
    way (tol.CONTACT_RELAX; the packer, iterating to the end, asks for them once: (1, 1, 1)).
    ``threads``: the kernels run muscle by muscle on numba's threads (the same bytes; never in
    a process forked from one that used them: :func:`axdf_cli.runtime.use_threads`)."""
    prm = push_params(relax)
    shapes = model.shapes
    M = len(vertices)
    measure = measures.measure if threads else measures.measure_serial
    ring_modes = rings.ring_modes if threads else rings.ring_modes_serial
    apply_and_solve = volume.apply_and_solve if threads else volume.apply_and_solve_serial
    normals_all = volume.normals_all if threads else volume.normals_all_serial
    centres_and_boxes = query.centres_and_boxes if threads else query.centres_and_boxes_serial
    if M == 0:
        return [], [], np.zeros(0, bool), np.zeros((0, 3)), np.zeros((0, 3))
    nu = np.array([s[0] for s in shapes], dtype=np.int64)
    na = np.array([s[1] for s in shapes], dtype=np.int64)
    off = np.concatenate([[0], np.cumsum(nu * na)]).astype(np.int64)
    coff = np.concatenate([[0], np.cumsum(nu)]).astype(np.int64)
    vo = np.concatenate([[0], np.cumsum([len(v) for v in vertices])]).astype(np.int64)
    grid = np.empty((int(off[-1]), 3))
    to_grid(np.concatenate(vertices).astype(np.float64, copy=False), vo, off, nu, na, grid)
    cen = np.zeros((int(coff[-1]), CEN_COLUMNS))
    box = np.empty((M, 6))
    f = model.fields
    mesh = Mesh(grid, off, nu, na, cen, coff, box)  # (grid, cen and box change in place)
    centres_and_boxes(mesh)
    reach = tol.CONTACT_BONE_MARGIN + iterations * tol.CONTACT_MAX_STEP
    fields = f.posed(world_inv)
    fl_off, fl = field_lists(box, f, world_inv, reach)
    before = np.full((M, 3), np.nan)
    work = make_work(nu, na, f)
    if measure_before or iterations == 0:
        measure(mesh, Lists(*neighbours(box, model.allow, 0.0), fl_off, fl), fields, before, work)
    rad = grid - np.repeat(cen[:, :3], np.repeat(na, nu), axis=0)  # radial offsets of the no-contact shape
    target = np.empty(M)
    grid_volumes(grid, off, nu, na, target)
    umax, amax = int(nu.max()), int(na.max())
    coef = np.zeros((int(coff[-1]), NMODES, 3))
    coefb = np.zeros_like(coef)
    tmp = np.empty((umax, NMODES, 3))
    sigma = np.zeros(M)
    touched = np.zeros(M, dtype=np.bool_)
    buried = np.zeros(M)
    out = Modes(coef, coefb, touched, buried)
    ga = np.empty((M, umax, amax, 3))
    for it in range(iterations):
        lists = Lists(*neighbours(box, model.allow, tol.CONTACT_MARGIN), fl_off, fl)
        while True:
            ring_modes(mesh, lists, fields, model.share, prm, tol.CONTACT_SAMPLE_COLUMNS, tol.CONTACT_SAMPLE_RINGS,
                       poles, out, work)
            need = int(work.rec[:, 0, 0].max())
            if need < work.rec.shape[1]:
                break
            work = work._replace(rec=np.empty((M, need + 1, work.rec.shape[2])))  # room for all: again
        add_reactions(work.rec, work.react, coef, nu, coff, touched, tol.CONTACT_MARGIN)
        if it == 0 and not measure_before:
            before[:, 1] = buried
        smooth_rings(coef, nu, coff, tol.CONTACT_SMOOTH_PASSES, False, tmp)
        smooth_rings(coefb, nu, coff, tol.CONTACT_SMOOTH_PASSES, True, tmp)
        coef += coefb
        apply_and_solve(grid, rad, coef, off, nu, na, coff, touched, target, tol.CONTACT_MAX_STEP, ga, sigma)
        centres_and_boxes(mesh)
    if volumes is not None and touched.any():
        grid_volumes(grid, off, nu, na, volumes)
    if not touched.any() and not np.isnan(before).any():  # nothing moved (or no pass): the first measures
        return list(vertices), [None] * M, touched, before, before.copy()
    after = np.zeros((M, 3))
    measure(mesh, Lists(*neighbours(box, model.allow, 0.0), fl_off, fl), fields, after, work)
    if not touched.any():
        return list(vertices), [None] * M, touched, before, after
    all_v = np.empty((int(vo[-1]), 3))
    all_n = np.empty((int(vo[-1]), 3))
    normals_all(grid, off, nu, na, touched, vo, all_v, all_n)
    out_v = [all_v[vo[m]:vo[m + 1]] if touched[m] else vertices[m] for m in range(M)]
    out_n = [all_n[vo[m]:vo[m + 1]] if touched[m] else None for m in range(M)]
    return out_v, out_n, touched, before, after


def build(specs, models, rest_world: np.ndarray, bone_meshes: dict, enabled: bool = True,
          field_cache=None) -> ContactModel:
    """The run's contact: pairs (groups, ignore lists), shares from the yields (explicit, or
    :func:`auto_yield`), and the bone fields, each cut to where the muscles' rest meshes,
    grown by tol.CONTACT_REACH, lie in that bone. ``enabled`` False: measure only.
    ``field_cache``: where the fields are looked up (:func:`fields.bone_field`'s ``cache``)."""
    names = [s.name for s in specs]
    rest = np.concatenate([m.rest_vertices.astype(np.float64) for m in models])
    fields = []
    for b, (v, f, _) in sorted(bone_meshes.items()):
        inv = np.linalg.inv(rest_world[b])
        # L[p,c] = sum_k inv[c,k] X[p,k] + inv[c,3]
        local = rest @ inv[:3, :3].T + inv[:3, 3]
        clip = np.array([local.min(axis=0) - tol.CONTACT_REACH, local.max(axis=0) + tol.CONTACT_REACH])
        fld = bone_field(b, v, f, clip, cache=field_cache)
        if fld is not None:
            fields.append(fld)
    packed = BoneFields.pack(fields)
    yields = np.array([s.contact.yield_ if s.contact.yield_ is not None else auto_yield(m, packed, rest_world)
                       for s, m in zip(specs, models)])
    return ContactModel(pair_mask(names, [s.contact for s in specs]), pair_shares(yields), packed,
                        tuple(s.resolution for s in specs), yields, enabled)


def auto_yield(model, fields: BoneFields, rest_world: np.ndarray) -> float:
    """A muscle's depth in layers when its file gives none: minus the distance (in units of
    tol.CONTACT_LAYER) from the bone surface of the centre of its rest mesh's middle ring, so
    that a muscle lying on a bone gives way to one lying over it (0 where no bone is near)."""
    U, A = model.spec.resolution
    ring = model.rest_vertices[1 + ((U - 2) // 2) * A: 1 + ((U - 2) // 2 + 1) * A].astype(np.float64)
    c = ring.mean(axis=0)
    g = np.zeros(6)
    d = bone_query(c, fields.posed(np.linalg.inv(rest_world)), np.arange(len(fields.bones)), 0, len(fields.bones),
                   -1e300, g)
    if d >= 1e29:
        return 0.0
    return round(-max(d, 0.0) / tol.CONTACT_LAYER, 6)


def apply(model: ContactModel, results: dict, world: np.ndarray, threads: bool = False) -> None:
    """The FRAME-scope stage over a chunk: ``results`` maps every muscle index to its
    FrameResult (F frames); each frame's meshes are resolved together (:func:`resolve_frame`)
    and the results updated in place: vertices, normals and volume where contact moved a
    muscle, ``contact`` (F, 3) the measures after contact, warnings for muscles that start a
    frame wholly inside a bone. world : (F, B, 4, 4); ``threads``: as :func:`resolve_frame`'s."""
    order = sorted(results)
    nf = world.shape[0]
    inv = np.linalg.inv(world)
    for r in results.values():
        r.contact = np.zeros((nf, 3))
    vol = np.empty(len(order))
    finite = np.ones(nf, dtype=bool)
    for j in order:
        finite &= np.isfinite(results[j].vertices.reshape(nf, -1)).all(axis=1)
    for fi in range(nf):
        if not finite[fi]:
            continue  # a frame that cannot be evaluated is written as the rest shape
        verts = [results[j].vertices[fi] for j in order]
        v, n, touched, before, after = resolve_frame(model, verts, inv[fi],
                                                     tol.CONTACT_ITERATIONS if model.enabled else 0, False, vol,
                                                     threads=threads)
        for k, j in enumerate(order):
            r = results[j]
            r.contact[fi] = after[k]
            if before[k, 1] >= 1.0:
                r.warnings.append((fi, "wholly inside a bone at the start of the frame: contact cannot place it"))
            if touched[k]:
                r.vertices[fi] = v[k]
                r.normals[fi] = n[k]
                r.volume[fi] = vol[k]

