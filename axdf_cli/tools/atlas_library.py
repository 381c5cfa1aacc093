"""``axdf atlas``: a muscle library of a model from an atlas. Every muscle of the model the
atlas has is registered onto the skeleton (axdf_cli/tools/atlas.py) and fitted
(axdf_cli/tools/fit.py) under the model's name; the muscles the atlas lacks are copied from the
model's own library.

The name map is the command's ``--map`` (:func:`axdf_cli.tools.tables.load_atlas_map`;
atlases/gait2392.yaml). Per side: the atlas' muscle meshes are carried by the leg's registration, their vertices inside
a model bone put just outside it (:func:`~axdf_cli.geometry.winding.push_out_of_meshes`), a
muscle shared by a model group
cut into the group's parts (:func:`split_parts`), and each is fitted as an ``axis:`` muscle
bound to the bones of the model muscle's path (``axdf fit --paths``). Nothing here writes:
the caller gets the files' bytes and the report.
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.geometry.winding import inside_share, push_out_of_meshes, winding_numbers
from axdf_cli.tools import atlas as at
from axdf_cli.tools.atlas_partition import TERRITORIES

REPORT = "atlas_report.json"
REGISTERED = "registered"  # the carried atlas meshes, world metres at rest, under the model's names
LIBRARY = "muscles"  # the fitted library


def find_atlas(atlas: at.Atlas, side: str, names: list[str]) -> Path | None:
    """The first atlas muscle file of ``names`` on the side, or None."""
    for n in names:
        p = atlas.path(side, "Muscle", n)
        if p.is_file():
            return p
    return None


def path_centroid(folder: Path, name: str, skel, rest: np.ndarray) -> np.ndarray:
    """The mean of a model muscle's path points at rest (world)."""
    from axdf_cli.specs import load_muscle_file

    spec = load_muscle_file(Path(folder) / f"{name}.yaml")[0]
    pts = spec.path.points if spec.path is not None else spec.axis
    return np.mean([rest[skel.bone_index[p.bone], :3, :3] @ np.asarray(p.at) + rest[skel.bone_index[p.bone], :3, 3]
                    for p in pts], axis=0)


def path_ends(folder: Path, name: str, skel, rest: np.ndarray, pieces: dict) -> tuple:
    """A model muscle's two ends for :meth:`~axdf_cli.tools.atlas.Registration.along`: for its
    path's first and last point, the registered bone it moves with (the point's bone or its
    nearest ancestor among ``pieces``; None where there is none, e.g. the thorax) and the
    point at rest (world)."""
    from axdf_cli.specs import load_muscle_file

    spec = load_muscle_file(Path(folder) / f"{name}.yaml")[0]
    pts = spec.path.points if spec.path is not None else spec.axis
    ends = []
    for p in (pts[0], pts[-1]):
        i = skel.bone_index[p.bone]
        ends.append((moving_piece(skel, p.bone, pieces), rest[i, :3, :3] @ np.asarray(p.at) + rest[i, :3, 3]))
    return tuple(ends)


def moving_piece(skel, bone: str, pieces: dict) -> str | None:
    """The registered bone a model bone moves with: itself or its nearest ancestor among
    ``pieces``; None where there is none (the thorax)."""
    i = skel.bone_index[bone]
    while i >= 0 and skel.bones[i].name not in pieces:
        i = skel.bones[i].parent
    return skel.bones[i].name if i >= 0 else None


def bone_ends(points: np.ndarray, names: list[str], bones: dict) -> tuple[np.ndarray, np.ndarray]:
    """The two ends of an added muscle's points (P, 3, world at rest): the mean of those nearer
    its first bone's mesh than any other of its bones' (``names``; ``bones``: name -> (V, F)),
    and of those nearer its last's."""
    import igl

    d = np.stack([igl.point_mesh_squared_distance(points, bones[n][0], bones[n][1].astype(np.int64))[0]
                  for n in names], axis=1)
    near = np.argmin(d, axis=1)
    return tuple(points[near == k].mean(axis=0) if (near == k).any() else points[np.argmin(d[:, k])]
                 for k in (0, len(names) - 1))


def added_ends(points: np.ndarray, names: list[str], skel, bones: dict, pieces: dict) -> tuple:
    """An added muscle's two ends for :meth:`~axdf_cli.tools.atlas.Registration.along`, as
    :func:`path_ends` gives a model muscle's: each end's registered bone (its first or last bone,
    or that bone's nearest ancestor among ``pieces``; None for none, e.g. the thorax) and the
    point (:func:`bone_ends`)."""
    return tuple((moving_piece(skel, name, pieces), x)
                 for name, x in zip((names[0], names[-1]), bone_ends(points, names, bones)))


def split_parts(v: np.ndarray, f: np.ndarray, centres: np.ndarray, spacing: float) -> list[tuple]:
    """A closed mesh (V, F) cut into len(centres) closed parts by planes across the line from
    the first centre to the last, each halfway between neighbouring centres' projections:
    the inside (winding number) on a grid, limited to each slab, turned back into a surface
    (marching cubes)."""
    import igl

    d = centres[-1] - centres[0]
    d = d / np.linalg.norm(d) if len(centres) > 1 else np.array([1.0, 0.0, 0.0])  # one part: the mesh closed
    s = centres @ d
    cuts = (s[1:] + s[:-1]) / 2.0
    lo, hi = v.min(axis=0) - 2 * spacing, v.max(axis=0) + 2 * spacing
    n = np.ceil((hi - lo) / spacing).astype(int) + 1
    axes = [lo[i] + spacing * np.arange(n[i]) for i in range(3)]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    # igl.marching_cubes takes x fastest
    grid = np.stack([gx.ravel(order="F"), gy.ravel(order="F"), gz.ravel(order="F")], axis=1)
    w = winding_numbers(v, f, grid)
    proj = grid @ d
    parts = []
    edges = np.concatenate([[-np.inf], cuts, [np.inf]])
    for k in range(len(centres)):
        field = np.maximum(0.5 - w, np.maximum(edges[k] - proj, proj - edges[k + 1]) / spacing * 0.5)
        field[np.abs(field) < 1e-9] = 1e-9  # a corner exactly on the surface makes degenerate triangles
        V, F, _ = igl.marching_cubes(field, grid, int(n[0]), int(n[1]), int(n[2]), 0.0)
        parts.append((np.asarray(V, np.float64), np.asarray(F, np.int64)))
    return parts


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """A closed mesh's volume (positive when wound outward)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def one_piece(v: np.ndarray, f: np.ndarray, spacing: float) -> tuple:
    """A closed mesh as one piece: unchanged where every piece but one is a sliver (under
    tol.FIT_MIN_PIECE_SHARE of the volume; the fit drops those), else its inside (winding
    numbers on a grid) closed morphologically by the fewest grid steps that join the pieces
    above the share (at most tol.ATLAS_JOIN_STEPS), the rest dropped, turned back into a
    surface (marching cubes). Returns (V, F, the bridge's width in metres, 0 if unchanged)."""
    import igl
    import trimesh
    from scipy import ndimage

    parts = trimesh.Trimesh(v, f, process=True).split(only_watertight=False)
    vols = np.array([abs(signed_volume(q.vertices, q.faces)) for q in parts])
    if (vols / max(vols.sum(), 1e-300) >= tol.FIT_MIN_PIECE_SHARE).sum() <= 1:
        return v, f, 0.0
    pad = tol.ATLAS_JOIN_STEPS + 2
    lo, hi = v.min(axis=0) - pad * spacing, v.max(axis=0) + pad * spacing
    n = np.ceil((hi - lo) / spacing).astype(int) + 1
    axes = [lo[i] + spacing * np.arange(n[i]) for i in range(3)]
    grid = np.stack([a.ravel(order="F") for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    w = winding_numbers(v, f, grid).reshape(n, order="F")
    inside = w > 0.5
    for k in range(1, tol.ATLAS_JOIN_STEPS + 1):
        closed = ndimage.binary_closing(inside, structure=ndimage.generate_binary_structure(3, 1), iterations=k,
                                        border_value=0)
        lab, m = ndimage.label(closed | inside)
        sizes = np.bincount(lab.ravel())[1:]
        if m and (sizes / sizes.sum() >= tol.FIT_MIN_PIECE_SHARE).sum() == 1:
            break
    keep = lab == 1 + int(np.argmax(sizes))
    field = np.where(keep & ~inside, -0.5, np.where(keep, 0.5 - w, np.maximum(0.5 - w, 1e-3)))
    field[np.abs(field) < 1e-3] = 1e-3  # a corner on the surface makes triangles that merge away
    V, F, _ = igl.marching_cubes(field.ravel(order="F"), grid, int(n[0]), int(n[1]), int(n[2]), 0.0)
    return np.asarray(V, np.float64), np.asarray(F, np.int64), k * spacing


def ply_bytes(v: np.ndarray, f: np.ndarray) -> bytes:
    """A closed mesh as binary PLY, wound outward (vertices merged)."""
    import trimesh

    m = trimesh.Trimesh(v, f, process=True)
    if m.volume < 0:
        m.invert()
    return m.export(file_type="ply")


def write_ply(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    Path(path).write_bytes(ply_bytes(v, f))


def fit_holds(entry: dict) -> bool:
    """Whether a fit is kept: IoU with its mesh at least tol.ATLAS_MIN_IOU and its volume
    within a factor tol.ATLAS_MAX_VOLUME_FACTOR of the mesh's (else the model's own muscle is
    kept: the mesh was not one belly along one axis, e.g. a tendon turning round the ankle)."""
    r = entry["volume_ratio"]
    return entry["iou"] >= tol.ATLAS_MIN_IOU and 1.0 / tol.ATLAS_MAX_VOLUME_FACTOR <= r <= tol.ATLAS_MAX_VOLUME_FACTOR


def rest_state(skeleton_path: Path) -> tuple:
    """The skeleton read, its bones' rest world transforms (B, 4, 4) and each moving bone's mesh
    in the world at rest (:func:`~axdf_cli.geometry.bones.rest_bone_meshes`): name -> ((V, 3)
    float64, (T, 3) int64)."""
    from axdf_cli.geometry.bones import rest_bone_meshes
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_skeleton

    skel = load_skeleton(skeleton_path, RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    meshes = rest_bone_meshes(skel, str(skeleton_path), lambda b: b.parent is not None)
    return skel, rest, {name: (v, f) for name, (v, f, _) in meshes.items()}


def registered_meshes(atlas: at.Atlas, skel, rest, bones: dict, old: Path, sides=("r",), tell=None,
                      registrations: dict | None = None) -> tuple:
    """The atlas' muscles carried onto the skeleton at rest, under the model's names: a list of
    (name, (V, 3) float64 world metres, (F, 3) int64) and the report of each leg (the
    registration's residuals, each muscle's source and how many of its vertices were pushed
    out of the bones). ``old``: the model's own muscle folder (the paths that cut a shared
    atlas muscle into the model's parts). ``registrations``, when given, receives each side's
    :class:`~axdf_cli.tools.atlas.Registration`."""
    tell = tell or (lambda text: None)
    names = atlas.map
    meshes, sides_rep = [], {}
    for side in sides:
        tell(f"registering the atlas' side {side} ({names.sides[side]})")
        reg = at.register(atlas, skel, rest, bones, side)
        if registrations is not None:
            registrations[side] = reg
        side_rep = dict(reg.report, muscles={})
        ta = find_atlas(atlas, side, ["TibialisAnterior"]) if names.bone_name("tibia", side) in bones else None
        if ta is not None:
            tv = at.read_atlas_mesh(ta)[0]
            tib = bones[names.bone_name("tibia", side)]
            side_rep["tib_ant_inside_tibia"] = {"landmarks": inside_share(*tib, reg.apply(tv, warp=False)),
                                                "warp": inside_share(*tib, reg.apply(tv))}
        jobs = [(m, [m], list(src)) for m, src in names.muscles.items()] + \
               [(g, list(parts), list(src)) for g, (src, parts) in names.split.items()] + \
               [(m, [m], list(src)) for m, (src, _) in names.added.items()]
        for key, parts, src in jobs:
            p = find_atlas(atlas, side, src)
            if p is None:
                continue
            closed = any(atlas.path(side, "Muscle", n) == p for n in names.close)
            v, fc = at.read_atlas_mesh(p, closed=not closed)
            # an articulated map carries each muscle with the bones of its ends (a split group's:
            # its first part's origin, its last part's insertion; an added muscle's: its first and
            # last bone's)
            if not reg.pieces:
                w = reg.apply(v)
            elif key in names.added:
                w = reg.along(v, added_ends(reg.rigid(v), names.added_bones(key, side, skel.bone_index), skel, bones,
                                            reg.pieces))
            else:
                w = reg.along(v, (path_ends(old, names.muscle_name(parts[0], side), skel, rest, reg.pieces)[0],
                                  path_ends(old, names.muscle_name(parts[-1], side), skel, rest, reg.pieces)[1]))
            kept = None if closed else round(signed_volume(w, fc) / signed_volume(reg.apply(v, warp=False), fc), 3)
            if closed:  # an open surface: closed by its winding numbers on a grid
                w, fc = split_parts(w, fc, np.zeros((1, 3)), tol.ATLAS_SPLIT_SPACING)[0]
            pieces = [(w, fc)] if len(parts) == 1 else split_parts(
                w, fc, np.array([path_centroid(old, names.muscle_name(q, side), skel, rest) for q in parts]),
                tol.ATLAS_SPLIT_SPACING)
            for q, (pv, pf) in zip(parts, pieces):
                pv, pf, joined = one_piece(pv, pf, tol.ATLAS_SPLIT_SPACING)
                # (signed: w > 0.5, as the shipped library was made; gait2392's torso is wound inconsistently)
                pv, moved = push_out_of_meshes(pv, bones.values(), tol.ATLAS_BONE_MARGIN, signed=True)
                name = names.muscle_name(q, side)
                meshes.append((name, pv, pf))
                side_rep["muscles"][name] = {"atlas": p.name, "pushed_out_of_bones": moved,
                                             "part": f"{parts.index(q) + 1}/{len(parts)}" if len(parts) > 1 else None,
                                             **({"closed": True} if closed else {}),
                                             **({"volume_kept": kept} if atlas.map.articulated and kept else {}),
                                             **({"joined_mm": round(joined * 1e3, 1)} if joined else {})}
        sides_rep[side] = side_rep
    return meshes, sides_rep


def transform_file(atlas: at.Atlas, reg, skel, skeleton_path: Path) -> str:
    """The ``axdf fit --transform`` file (text) of one side's landmark similarity (the
    registration without its warp), from the atlas' frame in metres (``--units mm``) into the
    skeleton's rest frame."""
    from axdf_cli.tools.fit_mesh import transform_text

    res = ", ".join(f"{k} {v:g} mm" for k, v in reg.report["landmark_residual_mm"].items())
    return transform_text(reg.scale, reg.rotation, reg.shift,
                          f"Side {reg.side} of the atlas {Path(atlas.root).name} onto {skel.name} at rest: the "
                          f"similarity of its landmarks\n(axdf atlas; scale {reg.scale:.4f}; residuals {res}).\n"
                          f"Use: axdf fit MESH ... --units mm --transform FILE --skeleton {Path(skeleton_path).name} "
                          "(docs/ATLAS.md)")


def _check_model(atlas: at.Atlas, old: Path, sides) -> None:
    """Refuse, at the map's line, a model muscle the map names that --muscles lacks."""
    if not Path(old).is_dir():
        raise InputError(Mark(str(old)), "muscle folder not found", "the model's muscle files (--muscles DIR)")
    for key, parts in [(m, [m]) for m in atlas.map.muscles] + [(g, list(p)) for g, (_, p) in atlas.map.split.items()]:
        for q in parts:
            for side in sides:
                name = atlas.map.muscle_name(q, side)
                if not (Path(old) / f"{name}.yaml").is_file():
                    raise InputError(atlas.map.marks.get(("muscle", key), Mark(atlas.map.path)),
                                     f"muscle {q}: {old} has no {name}.yaml",
                                     "a muscle of the model's library (--muscles), without its side suffix")


def _check_added(atlas: at.Atlas, old: Path, sides, skel, bones: dict) -> dict:
    """Refuse, at the map's line, an added muscle the model has already or whose bones the
    skeleton lacks or has no mesh of; else each added muscle's name on each side -> (its bones,
    the map's name)."""
    out = {}
    for key, (_, names) in atlas.map.added.items():
        where = atlas.map.marks.get(("muscle", key), Mark(atlas.map.path))
        for side in sides:
            name = atlas.map.muscle_name(key, side)
            if (Path(old) / f"{name}.yaml").is_file():
                raise InputError(where, f"added muscle {key}: {old} has {name}.yaml already",
                                 "added: names muscles the model lacks (a model muscle goes in muscles: or split:)")
            got = atlas.map.added_bones(key, side, bones)  # (bones with meshes)
            if got is None:
                lack = next(b for b in names if not {atlas.map.bone_name(b, side), b} & set(bones))
                raise InputError(where, f"added muscle {key}: bone {lack!r} is not a bone with a mesh of "
                                 f"{skel.name} on side {side}",
                                 "bones of the skeleton with meshes, without the side suffix (a midline bone as "
                                 "it is), the origin's first and the insertion's last")
            out[name] = (got, key)
    return out


def build_library(atlas: at.Atlas, skeleton_path: Path, old: Path, sides=("r",), sections: int | None = None,
                  on_muscle=None, on_phase=None, fit: bool = True, partition: bool = False) -> tuple[dict, dict]:
    """What ``axdf atlas`` writes (path relative to its folder -> bytes) and the report:
    ``registered/NAME.ply`` (each carried atlas muscle), ``landmarks_SIDE.yaml`` (each side's
    landmark similarity as an ``axdf fit --transform`` file), ``atlas_report.json`` and, with
    ``fit``, the library ``muscles/`` (one file per model muscle and the credit README.md).
    ``old``: the model's own muscle folder (paths, and the muscles the atlas lacks).
    ``on_phase(text)`` is told as each phase starts; ``on_muscle(name, entry)`` as each fit ends.
    ``partition``: also the registered atlas as a partition of space, ``territories/NAME.ply``
    and the report's ``partition`` (axdf_cli/tools/atlas_partition.py); the library is then
    fitted to the territories, each fit kept inside its own (``axdf fit --inside``), and
    measured against the registered mesh as well (each fit's ``atlas``)."""
    from axdf_cli.specs.muscle import default_color
    from axdf_cli.tools.fit import build_fit

    tell = on_phase or (lambda text: None)
    skeleton_path, old = Path(skeleton_path), Path(old)
    atlas.check(sides)
    _check_model(atlas, old, sides)
    skel, rest, bones = rest_state(skeleton_path)
    added = _check_added(atlas, old, sides, skel, bones)
    report = {"atlas": str(Path(atlas.root).name), "map": Path(atlas.map.path).name, "skeleton": skeleton_path.name,
              "sides": {}, "fitted": [], "failed": [], "kept": []}
    files: dict[str, bytes] = {}
    regs: dict = {}
    carried, report["sides"] = registered_meshes(atlas, skel, rest, bones, old, sides, tell, regs)
    for side, reg in regs.items():
        files[f"landmarks_{side}.yaml"] = transform_file(atlas, reg, skel, skeleton_path).encode()
    for name, pv, pf in carried:
        files[f"{REGISTERED}/{name}.ply"] = ply_bytes(pv, pf)
    if partition:
        from axdf_cli.tools.atlas_partition import build_partition

        terr, report["partition"] = build_partition(carried, old, sides, skel, rest, bones, tell, atlas.map)
        for name, (tv, tf) in terr.items():
            files[f"{TERRITORIES}/{name}.ply"] = ply_bytes(tv, tf)
    if fit:
        # with the partition, each muscle's territory is fitted (the muscles the atlas lacks
        # too: their shapes clipped to the room left), each fit held inside it
        folder = TERRITORIES if partition else REGISTERED
        names = sorted(terr) if partition else [name for name, _, _ in carried]
        with tempfile.TemporaryDirectory(prefix="axdf-atlas-") as tmp:
            meshes = []
            for name in names:
                out = Path(tmp) / f"{name}.ply"
                out.write_bytes(files[f"{folder}/{name}.ply"])
                meshes.append(out)
            tell(f"fitting {len(meshes)} muscles" + (" into their territories" if partition else ""))
            source = {name: pv for name, pv, _ in carried}
            # (a side's colour is the other's, as the model's muscles are: that of the map's name)
            shape = {name: (bs, bone_ends(source[name], bs, bones)[0], default_color(key))
                     for name, (bs, key) in added.items() if name in source}
            res = build_fit(meshes, skeleton_path, "m", sections, on_muscle=on_muscle, paths=old, inside=partition,
                            added=shape)
        if partition:
            _measure_against_atlas(res, carried, skel, rest)
        # a fit below the bar is refused (the model's own muscle copied instead), but not a fit
        # into a territory: the model's muscle would cross its neighbours', where the fit shares
        # no space; it is kept and listed (``weak``)
        weak = [m["muscle"] for m in res.report["muscles"] if not fit_holds(m)]
        failed = set() if partition else set(weak)
        if partition:
            report["weak"] = weak
        for rel, data in res.files.items():
            if rel.startswith(f"{LIBRARY}/") and Path(rel).stem not in failed:
                files[rel] = data
        report["fitted"] = [m for m in res.report["muscles"] if m["muscle"] not in failed]
        report["failed"] = [m for m in res.report["muscles"] if m["muscle"] in failed]
        report["added"] = sorted(m["muscle"] for m in report["fitted"] if m["muscle"] in added)
        for p in sorted(old.glob("*.yaml")):
            if f"{LIBRARY}/{p.name}" not in files:
                files[f"{LIBRARY}/{p.name}"] = p.read_bytes()
                report["kept"].append(p.stem)
        files[f"{LIBRARY}/README.md"] = library_readme(atlas, skel, old, sides, report).encode()
    files[REPORT] = (json.dumps(report, indent=1, sort_keys=True, default=float) + "\n").encode()
    return files, report


def _measure_against_atlas(res, carried: list, skel, rest) -> None:
    """Each fit of a territory also measured against its registered atlas mesh (what the
    territory was cut from): the report entry's ``atlas`` (IoU, distances, volume ratio)."""
    import trimesh

    from axdf_cli.tools.fit import measure_file

    source = {name: (v, f) for name, v, f in carried}
    for m in res.report["muscles"]:
        if m["muscle"] in source:
            rel = m["file"]
            mesh = trimesh.Trimesh(*source[m["muscle"]], process=False)
            m["atlas"] = measure_file(res.files[rel].decode(), rel, mesh, skel, rest)


def library_readme(atlas: at.Atlas, skel, old: Path, sides, report: dict) -> str:
    """The library's README: how it was made and the atlas' credit (the map's ``credit:``)."""
    credit = atlas.map.credit.strip() or "The atlas map gives no credit: name the atlas' source and licence here."
    return (f"# {skel.name} muscles fitted to the atlas {Path(atlas.root).name}\n\n"
            f"Made by `axdf atlas` (docs/ATLAS.md) with the map {Path(atlas.map.path).name}: the atlas' muscles of "
            f"side{'s' if len(sides) > 1 else ''} {', '.join(sides)} registered onto {skel.name}'s skeleton at rest "
            + ("(landmarks, then each bone placed rigidly on the model's and each muscle carried by the bones "
               "of its ends) " if atlas.map.articulated else "(landmarks, then a thin-plate warp onto the model's "
               "bones) ") + "and fitted as axis muscles under "
            f"{skel.name}'s names. {len(report['fitted'])} are fitted"
            + (f", {len(report['added'])} of them shape muscles {skel.name} lacks, added on their bones without a "
               f"path (their length is their axis'): {', '.join(report['added'])}" if report.get("added") else "")
            + f"; the rest ({len(report['kept'])}: the sides not "
            f"registered, what the atlas lacks and the fits that did not hold) are copied from {old.name}. "
            "atlas_report.json holds the registration's residuals and each fit's error.\n\n"
            f"## Credit\n\n{credit}\n")
