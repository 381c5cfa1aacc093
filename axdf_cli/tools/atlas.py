"""An anatomical atlas (the Visible Human Female's lower limb, millimetres) registered onto a
model's skeleton at rest (gait2392, metres), one leg at a time.

1. **Landmarks** (:func:`atlas_landmarks`, :func:`model_landmarks`): the hip centres (a sphere
   fitted to the femoral head cartilage, both sides, so that the pelvis' width fixes the turn
   about the leg's long axis), the knee (a sphere fitted to the distal femur's cartilage: the
   condyles' centre) and the ankle (a sphere fitted to the talar dome's cartilage), against
   the skeleton's joint centres at rest (the femurs', the tibia's and the talus' origins).
   A similarity transform (rotation, uniform scale, translation; Umeyama) maps one onto the
   other by least squares.
2. **Warp** (:func:`register`): the atlas' bones (tibia with fibula, talus, the hindfoot and
   midfoot bones) are pulled onto the model's bone meshes by a few rounds of closest points
   (the atlas' samples to the model's surface; for the tibia and talus also the model's
   vertices to the atlas' nearest sample, so a bone is not squeezed onto part of its
   partner), each round a thin-plate spline (scipy's RBFInterpolator, degree 1, smoothed)
   from the landmark-registered atlas to its targets, with the landmarks held. The femur and
   pelvis, which the atlas lacks, are held by their landmarks. The muscles are carried by the
   last round's spline (:meth:`Registration.apply`).

The atlas' names (its files' pattern, its sides' folders, the landmarks' cartilages and model
bones, which atlas bones go onto which model bone) are the map ``axdf atlas --map`` reads
(:func:`axdf_cli.tools.tables.load_atlas_map`; atlases/gait2392.yaml). Nothing here reads the
skeleton's file or writes anything: the caller passes the skeleton, its rest transforms and its
bone meshes (world, metres) and the :class:`Atlas` (its folder and map).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import did_you_mean
from axdf_cli.tools.tables import AtlasMap


@dataclass(frozen=True)
class Atlas:
    """An atlas folder (meshes in millimetres, its own frame) and its map onto a model."""
    root: Path
    map: AtlasMap

    def path(self, side: str, kind: str, name: str, where: Mark | None = None) -> Path:
        """The atlas file of a structure (kind Bone, Cartilage, Muscle) on a side ('r', 'l'):
        the map's files: pattern, the name's ``{side}``/``{Side}`` the side's word; a pattern
        with ``*`` is matched in the folder (one file, else refused). Refused (at ``where``,
        else the map's files:) where it, a link resolved, leaves the atlas folder."""
        word = self.map.sides[side]
        name = name.replace("{side}", word.lower()).replace("{Side}", word[:1].upper() + word[1:].lower())
        rel = self.map.files.format(folder=word, kind=kind, name=name)
        p = Path(self.root) / rel
        if any(c in rel for c in "*?["):
            found = sorted(Path(self.root).glob(rel))
            if len(found) > 1:
                raise InputError(where or self.map.marks.get("files", Mark(self.map.path)),
                                 f"{kind.lower()} {name}: {len(found)} atlas files match {rel} "
                                 f"({', '.join(q.name for q in found[:3])})", "a pattern and names that match one file")
            p = found[0] if found else Path(self.root) / rel.replace("*", "")
        root = os.path.realpath(self.root)
        real = os.path.realpath(p)
        if os.path.lexists(p) and real != root and not real.startswith(root.rstrip(os.sep) + os.sep):
            raise InputError(where or self.map.marks.get("files", Mark(self.map.path)),
                             f"atlas file {p} leaves the atlas folder {self.root} (it is {real})",
                             "atlas files inside ATLAS_DIR (no link out of it)")
        return p

    def check(self, sides) -> None:
        """Refuse, at the map's line, a side the map lacks, or a landmark's or a warped bone's
        file the folder lacks."""
        if not Path(self.root).is_dir():
            raise InputError(Mark(str(self.root)), "atlas folder not found",
                             f"the folder the map's files: pattern ({self.map.files}) is read in")
        for side in sides:
            if side not in self.map.sides:
                raise InputError(self.map.marks.get("sides", Mark(self.map.path)),
                                 f"side {side} is not in the map's sides ({', '.join(self.map.sides)})",
                                 "--sides among the map's sides")
        for side in sides:
            need = []
            for k, lm in self.map.landmarks.items():
                s = _leg(side, lm.other)
                if s not in self.map.sides:
                    raise InputError(self.map.marks.get(("landmark", k), Mark(self.map.path)),
                                     f"landmark {k} is on side {s}, which the map's sides lack",
                                     "leg: same, or both sides in sides:")
                need += [(("landmark", k), "Cartilage", lm.cartilage, s)] if lm.cartilage else \
                    [(("landmark", k), "Bone", n, s) for n in lm.centroid]
            need += [(("bone", i), "Bone", n, side) for i, (names, *_) in enumerate(self.map.bones) for n in names]
            for key, kind, name, s in need:
                p = self.path(s, kind, name, self.map.marks.get(key))
                if not p.is_file():
                    raise InputError(self.map.marks.get(key, Mark(self.map.path)),
                                     f"{key[0]} {key[1] if key[0] == 'landmark' else name}: no atlas file {p}",
                                     f"a {kind.lower()} of {self.root} by the map's files: pattern ({self.map.files})")


def read_atlas_mesh(path: Path, closed: bool = True):
    """(vertices (V, 3) float64 in metres, faces (F, 3) int64) of an atlas mesh (PLY or OBJ,
    millimetres), read strictly (axdf_cli.formats: counts checked against the file's length,
    every face naming a vertex of the file) and refused by name unless it is one closed,
    consistently wound surface (``closed`` False: any triangle surface, for the map's ``close:``)
    of finite coordinates within ``tol.ATLAS_MAX_REACH`` of the atlas' origin and at least
    ``tol.ATLAS_MIN_EXTENT`` across."""
    from axdf_cli.formats import load_triangles_and_bytes
    from axdf_cli.geometry.mesh import surface_problem

    where = Mark(str(path))
    allowed = "a closed triangle surface in millimetres (PLY or OBJ), as the atlas map's files: pattern names"
    if not Path(path).is_file():
        raise InputError(where, "atlas file not found", allowed)
    (v, _, f), _ = load_triangles_and_bytes(path)
    v, f = np.asarray(v, np.float64) * 1e-3, np.asarray(f, np.int64)
    bad = np.flatnonzero(~np.isfinite(v).all(axis=1))
    if len(bad):
        raise InputError(where, f"has {len(bad)} non-finite vertices (the first, vertex {int(bad[0])})",
                         "finite coordinates (millimetres)")
    problem = surface_problem(f, len(v)) if closed else None
    if problem:
        raise InputError(where, problem, allowed)
    extent, far = float(np.ptp(v, axis=0).max()), float(np.abs(v).max())
    if not extent >= tol.ATLAS_MIN_EXTENT or far > tol.ATLAS_MAX_REACH:
        raise InputError(where, f"is {extent * 1e3:.4g} mm across, {far * 1e3:.4g} mm from the origin at most",
                         f"a surface at least {tol.ATLAS_MIN_EXTENT * 1e3:g} mm across within "
                         f"{tol.ATLAS_MAX_REACH:g} m of the atlas' origin (millimetres)")
    return v, f


def sphere_fit(points: np.ndarray) -> tuple[np.ndarray, float]:
    """The least-squares sphere (centre, radius) through points (P, 3) (algebraic fit)."""
    A = np.concatenate([2.0 * points, np.ones((len(points), 1))], axis=1)
    b = (points * points).sum(axis=1)
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    c = sol[:3]
    return c, float(np.sqrt(max(sol[3] + c @ c, 0.0)))


def _leg(side: str, other: bool) -> str:
    return ("l" if side == "r" else "r") if other else side


def surface_centroid(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """The area-weighted centroid of a triangle surface (open or closed): the same point on two
    meshes of one bone however their vertices are spread."""
    t = v[f]
    area = 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)
    return (area @ t.mean(axis=1)) / max(float(area.sum()), 1e-300)


def atlas_landmarks(atlas: Atlas, side: str) -> dict[str, np.ndarray]:
    """The atlas' landmarks (metres, the atlas' frame) for ``side``: the centres of the spheres
    fitted to the map's cartilages, or the surface centroids of the map's bones."""
    def point(s, lm):
        if lm.cartilage:
            return sphere_fit(read_atlas_mesh(atlas.path(s, "Cartilage", lm.cartilage))[0])[0]
        parts = [read_atlas_mesh(atlas.path(s, "Bone", n)) for n in lm.centroid]
        v = np.concatenate([p[0] for p in parts])
        f = np.concatenate([p[1] + o for p, o in zip(parts, np.cumsum([0] + [len(p[0]) for p in parts[:-1]]))])
        return surface_centroid(v, f)

    return {k: point(_leg(side, lm.other), lm) for k, lm in atlas.map.landmarks.items()}


def model_landmarks(skel, rest: np.ndarray, amap: AtlasMap, side: str, bone_meshes: dict | None = None) \
        -> dict[str, np.ndarray]:
    """The skeleton's landmarks at rest (world, metres) for ``side``: the rest origins of the
    map's landmark bones (gait2392's: the femur's, the other femur's, the tibia's and the
    talus'), or, for a ``centroid:`` landmark, the surface centroid of the bone's mesh."""
    names = {k: amap.bone_name(lm.bone, _leg(side, lm.other), lm.midline) for k, lm in amap.landmarks.items()}
    out = {}
    for k, n in names.items():
        lm = amap.landmarks[k]
        if n not in skel.bone_index:
            raise InputError(amap.marks.get(("landmark", k), Mark(amap.path)),
                             f"landmark {k}: skeleton {skel.name} has no bone {n!r}",
                             f"{did_you_mean(n, list(skel.bone_index))}a bone of the skeleton --onto names "
                             "(its name without the side suffix)")
        if lm.centroid:
            if not bone_meshes or n not in bone_meshes:
                raise InputError(amap.marks.get(("landmark", k), Mark(amap.path)),
                                 f"landmark {k}: skeleton {skel.name}'s bone {n} has no mesh to take a centroid of",
                                 "centroid: landmarks on bones with meshes (else cartilage:, the bone's origin)")
            out[k] = surface_centroid(*bone_meshes[n])
        else:
            out[k] = rest[skel.bone_index[n], :3, 3].astype(np.float64)
    return out


def similarity(src: np.ndarray, dst: np.ndarray, weight: np.ndarray | None = None) -> tuple[float, np.ndarray, np.ndarray]:
    """Scale s, rotation R (3, 3) and translation t with dst ~ s R src + t by weighted least
    squares (Umeyama 1991, each point weighted)."""
    w = np.ones(len(src)) if weight is None else np.asarray(weight, dtype=np.float64)
    w = w / w.sum()
    ms, md = w @ src, w @ dst
    a, b = src - ms, dst - md
    u, sv, vt = np.linalg.svd((b * w[:, None]).T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    D = np.diag([1.0, 1.0, d])
    R = u @ D @ vt
    s = float((sv * np.diag(D)).sum() / (w @ (a * a).sum(axis=1)))
    return s, R, md - s * R @ ms


@dataclass
class Registration:
    """One leg's map from the atlas (metres, its frame) into the model's rest frame."""
    side: str
    scale: float
    rotation: np.ndarray
    shift: np.ndarray
    landmarks_atlas: dict
    landmarks_model: dict
    warp: object | None = None  # RBFInterpolator of the displacement after the similarity
    report: dict = field(default_factory=dict)
    pieces: dict = field(default_factory=dict)  # an articulated map's model bone -> (samples (P, 3), R, t)

    def blend(self, y: np.ndarray) -> np.ndarray:
        """Points after the similarity moved by the bones' rigid motions blended as dual
        quaternions (Kavan et al. 2008: no collapse at a joint that turns), each weighted by
        1 / d^k of its distance d to that bone's samples (normalised): a point near one bone
        moves with it, one between bones with a blend."""
        from scipy.spatial import cKDTree

        d = np.stack([cKDTree(x).query(y)[0] for x, _, _ in self.pieces.values()], axis=1)
        w = 1.0 / np.maximum(d, tol.ATLAS_BLEND_NEAR) ** tol.ATLAS_BLEND_POWER
        return _blend(w / w.sum(axis=1, keepdims=True), [(R, t) for _, R, t in self.pieces.values()], y)

    def along(self, points: np.ndarray, ends: tuple) -> np.ndarray:
        """Atlas points of one muscle (P, 3) in the model's rest frame, moved with its two ends'
        bones: ``ends`` ((origin bone | None, origin point), (insertion bone | None, insertion
        point)), model bones of :attr:`pieces` (None: no motion after the similarity) and rest
        points (world). Each point's weight is its place along the line between the ends
        (smoothstep), so a muscle twists along its length as a forearm's do when the radius turns
        about the ulna, instead of shearing across it where a blend by distance would."""
        (b0, p0), (b1, p1) = ends
        y = self.rigid(points)
        motion = [(np.eye(3), np.zeros(3)) if b is None else self.pieces[b][1:] for b in (b0, b1)]
        if b0 == b1:
            R, t = motion[0]
            return y @ R.T + t
        d = p1 - p0
        s = np.clip((y - p0) @ d / max(float(d @ d), 1e-12), 0.0, 1.0)
        s = s * s * (3.0 - 2.0 * s)
        return _blend(np.stack([1.0 - s, s], axis=1), motion, y)

    def rigid(self, points: np.ndarray) -> np.ndarray:
        return self.scale * points @ self.rotation.T + self.shift

    def apply(self, points: np.ndarray, warp: bool = True) -> np.ndarray:
        """Atlas points (P, 3, metres) in the model's rest frame: the similarity, then the warp."""
        y = self.rigid(points)
        if warp and self.pieces:
            return self.blend(y)
        if warp and self.warp is not None:
            out = np.empty_like(y)
            for i in range(0, len(y), tol.ATLAS_WARP_CHUNK):
                out[i:i + tol.ATLAS_WARP_CHUNK] = y[i:i + tol.ATLAS_WARP_CHUNK] + self.warp(y[i:i + tol.ATLAS_WARP_CHUNK])
            return out
        return y


def _blend(w: np.ndarray, motions: list, y: np.ndarray) -> np.ndarray:
    """Points (P, 3) moved by rigid motions [(R, t)] blended as dual quaternions with weights w
    (P, K) (Kavan et al. 2008: no collapse where the motions turn apart)."""
    from axdf_cli.model.skinning import blend_dq, dual_quaternions

    rel = np.stack([np.concatenate([R, t[:, None]], axis=1) for R, t in motions])
    out = np.empty_like(y)
    blend_dq(np.ascontiguousarray(w), dual_quaternions(rel), np.ascontiguousarray(y), out)
    return out


def _samples(v: np.ndarray, f: np.ndarray, n: int, seed: int) -> np.ndarray:
    import trimesh

    pts, _ = trimesh.sample.sample_surface_even(trimesh.Trimesh(v, f, process=False), n, seed=seed)
    return np.asarray(pts, dtype=np.float64)


def bone_distance(points: np.ndarray, mesh: tuple) -> np.ndarray:
    """Distance (P,) of points to a triangle mesh (vertices, faces)."""
    import igl

    return np.sqrt(igl.point_mesh_squared_distance(points, mesh[0], mesh[1].astype(np.int64))[0])


def register(atlas: Atlas, skel, rest: np.ndarray, bone_meshes: dict, side: str, rounds: int | None = None,
             smoothing: float | None = None) -> Registration:
    """Register the atlas' leg of ``side`` onto the skeleton at rest. ``bone_meshes``: model
    bone name -> (world vertices (V, 3), faces) at rest. ``rounds`` 0: the landmarks'
    similarity only (no warp)."""
    import igl
    from scipy.interpolate import RBFInterpolator
    from scipy.spatial import cKDTree

    rounds = tol.ATLAS_WARP_ROUNDS if rounds is None else rounds
    smoothing = tol.ATLAS_WARP_SMOOTHING if smoothing is None else smoothing
    amap = atlas.map
    names = tuple(amap.landmarks)
    la, lm = atlas_landmarks(atlas, side), model_landmarks(skel, rest, amap, side, bone_meshes)
    src = np.array([la[k] for k in names])
    dst = np.array([lm[k] for k in names])
    for pts, whose in ((src, "the atlas' cartilages' sphere centres"), (dst, f"skeleton {skel.name}'s bone origins")):
        sv = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if not (np.isfinite(sv).all() and sv[0] > tol.ATLAS_MIN_EXTENT and sv[1] > tol.ATLAS_LANDMARK_SPREAD * sv[0]):
            raise InputError(amap.marks.get("landmarks", Mark(amap.path)),
                             f"side {side}'s landmarks ({', '.join(names)}) are {whose} on one line or point",
                             "landmarks that span a plane (e.g. joint centres of both hips, the knee and the ankle)")
    for k, (atlas_bones, bone, both, midline) in enumerate(amap.bones):
        mb = amap.bone_name(bone, side, midline)
        if mb not in bone_meshes:
            has = mb in skel.bone_index
            raise InputError(amap.marks.get(("bone", k), Mark(amap.path)),
                             f"bone {bone}: skeleton {skel.name}'s bone {mb} " +
                             ("has no mesh to pull the atlas' bones onto" if has else "does not exist"),
                             f"{did_you_mean(mb, list(bone_meshes))}a bone of --onto with a mesh (without the "
                             "side suffix _r, _l)")
    # the other leg's landmark only fixes the turn about the leg's long axis: weighted less
    s, R, t = similarity(src, dst, [tol.ATLAS_OTHER_HIP_WEIGHT if amap.landmarks[k].other else 1.0 for k in names])
    reg = Registration(side, s, R, t, la, lm)
    lm_res = np.linalg.norm(reg.rigid(src) - dst, axis=1)
    reg.report = {"side": side, "scale": s, "landmark_residual_mm": dict(zip(names, (lm_res * 1e3).round(2).tolist()))}
    # the bones: samples in the similarity's frame, each with its model bone
    groups = []
    for k, (atlas_bones, bone, both, midline) in enumerate(amap.bones):
        mb = amap.bone_name(bone, side, midline)
        pts = [_samples(*read_atlas_mesh(atlas.path(side, "Bone", n)), tol.ATLAS_BONE_SAMPLES, tol.FIT_SEED + k)
               for n in atlas_bones]
        groups.append((mb, reg.rigid(np.concatenate(pts)), both))
    reg.report["bones_before"] = _bone_residual(groups, bone_meshes, lambda p: p)
    if rounds == 0 and not amap.articulated:
        return reg
    lm_y = reg.rigid(src)
    model_samples = {mb: _samples(*bone_meshes[mb], tol.ATLAS_BONE_SAMPLES, tol.FIT_SEED) for mb, _, both in groups if both}
    if amap.articulated:  # each bone placed rigidly on its model bone; the space between blends them
        for mb, x, _ in groups:
            R, t = rigid_icp(x, bone_meshes[mb], model_samples.get(mb))
            reg.pieces[mb] = (x, R, t)
        reg.report["bones_after"] = _bone_residual(groups, bone_meshes, reg.blend)
        reg.report["landmarks_after_mm"] = dict(zip(names, (np.linalg.norm(reg.blend(lm_y) - dst, axis=1)
                                                                 * 1e3).round(3).tolist()))
        return reg
    for _ in range(rounds):
        current = (lambda p: p) if reg.warp is None else (lambda p: p + reg.warp(p))
        xs, ys = [lm_y], [dst]
        for mb, x, both in groups:
            y = current(x)
            V, F = bone_meshes[mb]
            _, _, near = igl.point_mesh_squared_distance(y, V, F.astype(np.int64))
            if both:  # and the model's surface samples to the atlas' nearest (warped) sample:
                # each atlas sample's target is the mean of its nearest model point and the model
                # samples that chose it
                ms = model_samples[mb]
                _, j = cKDTree(y).query(ms)
                count = 1.0 + np.bincount(j, minlength=len(x))
                near = (near + np.stack([np.bincount(j, ms[:, c], minlength=len(x)) for c in range(3)], axis=1)) \
                    / count[:, None]
            xs.append(x)
            ys.append(near)
        X, Y = np.concatenate(xs), np.concatenate(ys)
        smooth = np.full(len(X), smoothing)
        smooth[:len(lm_y)] = 0.0  # the landmarks are held
        reg.warp = RBFInterpolator(X, Y - X, kernel="thin_plate_spline", smoothing=smooth, degree=1)
    reg.report["bones_after"] = _bone_residual(groups, bone_meshes, lambda p: p + reg.warp(p))
    reg.report["landmarks_after_mm"] = dict(zip(names, (np.linalg.norm(lm_y + reg.warp(lm_y) - dst, axis=1)
                                                             * 1e3).round(3).tolist()))
    return reg


def rigid_icp(x: np.ndarray, mesh: tuple, model_samples: np.ndarray | None = None) -> tuple:
    """The rigid motion (R (3, 3), t) that places one bone's points ``x`` (P, 3) on ``mesh``
    (iterative closest points; each round a Kabsch fit to the points' nearest on the mesh and,
    where ``model_samples`` are given, to the model samples that chose each point)."""
    import igl
    from scipy.spatial import cKDTree

    V, F = mesh[0], mesh[1].astype(np.int64)
    R, t = np.eye(3), np.zeros(3)
    for _ in range(tol.ATLAS_RIGID_ROUNDS):
        y = x @ R.T + t
        _, _, near = igl.point_mesh_squared_distance(y, V, F)
        a, b = [x], [near]
        if model_samples is not None:
            _, j = cKDTree(y).query(model_samples)
            a.append(x[j])
            b.append(model_samples)
        a, b = np.concatenate(a), np.concatenate(b)
        _, R, _ = similarity(a, b)
        t = b.mean(axis=0) - R @ a.mean(axis=0)
    return R, t


def _bone_residual(groups, bone_meshes, move) -> dict:
    """Per model bone: the mean and max distance (mm) of the moved atlas samples to its mesh."""
    out = {}
    for mb, x, _ in groups:
        d = bone_distance(move(x), bone_meshes[mb]) * 1e3
        out[mb] = {"mean_mm": round(float(d.mean()), 2), "max_mm": round(float(d.max()), 2)}
    return out
