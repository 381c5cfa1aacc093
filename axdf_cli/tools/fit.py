"""``axdf fit``: closed muscle surfaces (STL, PLY, OBJ) → ordinary AxDf muscle files.

Each mesh, given in the skeleton's rest frame, becomes one ``axis:`` muscle named after the
file's stem: 5 axis control points through its medial curve, each bound to the nearest bone
at rest (its mesh where the skeleton has bone meshes, else its segment to its children), N
sections of 8 ``outline:`` points fitted so that the model's own rest surface passes through
the mesh (axdf_cli/tools/fit_sections.py), and ``tendons:`` where the belly's ends are thin.
The files are read back by the muscle spec loader and evaluated by the muscle model at the
rest pose; the report (``fit_report.json``, ``FIT.md``) holds each fit's volumetric overlap
(IoU), surface distance and volume ratio against its mesh. Nothing is written here.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark, raise_all
from axdf_cli.geometry.partition import MeshField
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name
from axdf_cli.importers import emit
from axdf_cli.model.muscle import OCT, AxisPoint, MuscleModel, MuscleSpec, Section, outline_area
from axdf_cli.model.pose import muscle_bones
from axdf_cli.model.skeleton import Skeleton, bones_between, forward_kinematics
from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
from axdf_cli.specs.muscle import default_color, parse_muscle_text
from axdf_cli.tools import fit_sections as fs
from axdf_cli.tools.fit_mesh import UNITS, load_transform, read_mesh, unit_name, unit_scale
from axdf_cli.tools.muscle_files import muscle_doc

REPORT = "fit_report.json"
SUMMARY = "FIT.md"
__all__ = ["UNITS", "unit_scale", "unit_name", "build_fit", "read_mesh"]  # (the reading: tools/fit_mesh.py)


@dataclass
class FitOutputs:
    files: dict  # output path relative to DIR -> bytes
    report: dict
    inputs: list = field(default_factory=list)  # every file read


# ----------------------------------------------------------------------------- reading


def muscle_name(path: Path) -> str:
    stem = path.stem
    if not is_name(stem):  # (a stem ending in a newline too: is_name matches the whole)
        raise InputError(Mark(str(path)), f"the file's stem {stem!r} cannot name a muscle",
                         f"rename the file: {NAME_ALLOWED}")
    return stem


# ----------------------------------------------------------------------------- bones


def bone_geometry(skel: Skeleton, rest: np.ndarray, skeleton_path: Path, meshes: bool = True) -> list:
    """Per bone what a point is bound to by nearness: ('mesh', world vertices, faces) where the
    skeleton has bone meshes (only those bones then, and the bones welded to one of them;
    ``meshes`` False: never), else
    ('segments', (k, 2, 3)) from its origin to each child's origin (a leaf: its origin)."""
    from axdf_cli.geometry.bones import load_bone_mesh

    if meshes and any(b.mesh for b in skel.bones):
        out = []
        for i, b in enumerate(skel.bones):
            if not b.mesh:
                out.append(None)
                continue
            v, f, _ = load_bone_mesh(b.mesh, str(skeleton_path))
            w = v.astype(np.float64) @ rest[i, :3, :3].T + rest[i, :3, 3]
            out.append(("mesh", w, np.asarray(f, dtype=np.int64)))
        # a bone without a mesh welded to an ancestor with one (no coordinate between: myoarm's
        # chest_r on its torso) is as near as that mesh, so a muscle's trunk end binds to it
        for i, b in enumerate(skel.bones):
            j = i
            while out[j] is None and not skel.bones[j].dofs and skel.bones[j].parent >= 0:
                j = skel.bones[j].parent
            if out[i] is None and out[j] is not None:
                out[i] = out[j]
        return out
    origins = rest[:, :3, 3]
    out = []
    for i in range(len(skel.bones)):
        kids = [j for j, c in enumerate(skel.bones) if c.parent == i]
        ends = origins[kids] if kids else origins[i:i + 1]
        out.append(("segments", np.stack([np.broadcast_to(origins[i], ends.shape), ends], axis=1)))
    return out


def nearest_bones(points: np.ndarray, geometry: list) -> np.ndarray:
    """The index of the nearest bone (B,) to each point (P, 3)."""
    import igl

    dist = np.full((len(points), len(geometry)), np.inf)
    for b, g in enumerate(geometry):
        if g is None:
            continue
        if g[0] == "mesh":
            dist[:, b] = igl.point_mesh_squared_distance(points, g[1], g[2])[0]
        else:
            a, e = g[1][:, 0], g[1][:, 1] - g[1][:, 0]  # (k, 3)
            rel = points[:, None] - a[None]
            lam = np.clip(np.einsum("pkc,kc->pk", rel, e) / np.maximum((e * e).sum(axis=1), 1e-300), 0.0, 1.0)
            dist[:, b] = (np.linalg.norm(rel - lam[..., None] * e[None], axis=-1) ** 2).min(axis=1)
    return np.argmin(dist, axis=1)


def model_bones(folder: Path, name: str, skel: Skeleton, rest: np.ndarray, policy: RefPolicy | None = None) -> tuple:
    """The bones (indices) of the muscle file ``folder/NAME.yaml`` of a model (its path's
    points and wraps, or its axis) and the bones between them (:func:`bones_between`): the
    only bones a fit of mesh NAME binds to, each control point to the nearest, so that a
    muscle that crosses two joints hangs on the bones it spans (gastrocnemius: the femur at
    its heads, the tibia along its belly, not the femur down to the ankle); its origin (its first
    path or axis point) in the world at rest, which the fitted axis starts at; its path (a
    single muscle's, else None), which the fitted muscle keeps as its line of action; and its
    colour, which it keeps too (a muscle looks the same in either library). Refused when the
    file is missing, names a bone the skeleton lacks, or (``policy``) is a link out of the
    project folder tree, as ``axdf run --muscles`` refuses it."""
    path = Path(folder) / f"{name}.yaml"
    if not path.is_file():
        raise InputError(Mark(str(path)), f"no muscle file {name}.yaml in --paths {folder}",
                         "a muscle file of the model per mesh, named as the mesh's stem")
    if policy is not None:
        policy.check(path, Mark(str(path)), Path(folder), "muscle file")
    specs = load_muscle_file(path)
    bones = set().union(*(muscle_bones(spec) for spec in specs))  # (every head of a group)
    lack = sorted(bones - set(skel.bone_index))
    if lack:
        raise InputError(Mark(str(path)), f"muscle file {path.name} hangs on bone {lack[0]!r}, which the skeleton "
                         "lacks", f"a muscle of the skeleton {skel.name}")
    first = specs[0].path.points[0] if specs[0].path is not None else specs[0].axis[0]
    b = skel.bone_index[first.bone]
    line = specs[0].path if len(specs) == 1 else None
    return (bones_between(skel, {skel.bone_index[n] for n in bones}), rest[b, :3, :3] @ np.asarray(first.at, dtype=np.float64) + rest[b, :3, 3],
            line, specs[0].color)


# ----------------------------------------------------------------------------- one muscle


def tendon_fractions(areas: np.ndarray, arc: np.ndarray) -> tuple[float, float]:
    """Tendon fractions (origin, insertion) of rest arc length from the sections' areas (N,)
    at arc fractions (N,): each end's run of sections thinner than tol.FIT_TENDON_AREA_SHARE of
    the widest, up to the last such section before the belly."""
    thick = areas >= tol.FIT_TENDON_AREA_SHARE * areas.max()
    first, last = int(np.argmax(thick)), len(thick) - 1 - int(np.argmax(thick[::-1]))
    a0 = float(arc[first - 1]) if first > 0 else 0.0
    a1 = float(1.0 - arc[last + 1]) if last < len(thick) - 1 else 0.0
    total = a0 + a1
    if total > tol.FIT_TENDON_MAX:  # a belly must remain (the spec allows < 0.95)
        a0, a1 = a0 * tol.FIT_TENDON_MAX / total, a1 * tol.FIT_TENDON_MAX / total
    return round(a0, 4), round(a1, 4)


def fit_one(mesh, name: str, n_sections: int, skel: Skeleton, rest: np.ndarray, geometry: list,
            origin: np.ndarray | None = None, line=None, color=None, bound=None, shape: bool = False):
    """One mesh (metres) → (the muscle's YAML text, its report entry without the measures).
    ``origin``: a world point the axis starts at the end nearer to (a model's origin);
    ``line``: a model's path (:class:`~axdf_cli.model.paths.PathSpec`), written beside the
    fitted axis as the muscle's line of action (its length, as the model's); ``color``: the
    muscle's colour (default: :func:`default_color` of its name); ``bound``: a territory the
    surface stays inside (:func:`~axdf_cli.tools.fit_sections.fit_rows`); ``shape``: a muscle the
    model lacks (its header says so: no path, its length is its axis')."""
    import trimesh

    samples, face = trimesh.sample.sample_surface(mesh, tol.FIT_SAMPLES, seed=tol.FIT_SEED)
    ctrl = fs.medial_axis(samples)
    if origin is not None and np.linalg.norm(ctrl[-1] - origin) < np.linalg.norm(ctrl[0] - origin):
        ctrl = ctrl[::-1].copy()  # (the same curve, run from the model's origin)
    bones = nearest_bones(ctrl, geometry)
    axis = tuple(AxisPoint(skel.bones[b].name, tuple(float(x) for x in rest[b, :3, :3].T @ (p - rest[b, :3, 3])))
                 for p, b in zip(ctrl, bones))
    sec_t = fs.greville(n_sections)
    probe = MuscleSpec(name, default_color(name), axis, tuple(Section(float(t), None) for t in sec_t))
    model = MuscleModel(probe, skel.bone_index, rest, skel)

    def frames(t):
        c, r, s, _ = model.rest_frames(rest, np.asarray(t, dtype=np.float64))
        return c, r, s

    c, r, s = frames(sec_t)
    poles = fs.curve_points(ctrl, np.array([0.0, 1.0]))
    rows = fs.RowFit(c, r, s, poles)
    xy = fs.fit_rows(mesh, rows, frames, samples, np.asarray(mesh.face_normals)[face], bound)
    areas = np.abs([outline_area(o) for o in xy])
    arc = np.interp(sec_t, model.ts, model.arc)
    tendons = tendon_fractions(areas, arc)
    along = max(tol.FIT_ALONG_MIN, tol.FIT_ALONG_PER_SECTION * n_sections + 8)
    spec = MuscleSpec(name, default_color(name) if color is None else color, axis,
                      tuple(Section(float(t), None, 0.0, tuple((float(a), float(b)) for a, b in o))
                            for t, o in zip(sec_t, xy)),
                      tendons=tendons, resolution=(along, tol.FIT_OUTPUT_AROUND), path=line)
    kept = "; its path, the model's line of action" if line is not None else \
        "; a shape muscle the model lacks: no path, its length is its axis'" if shape else ""
    text = emit.dump_yaml(emit.rounded(muscle_doc(spec)),
                          header=f"{name}: fitted by `axdf fit` to its mesh ({n_sections} sections{kept}; "
                                 f"report: {REPORT}).")
    entry = {"muscle": name, "sections": n_sections, "tendons": list(tendons),
             "bones": [skel.bones[b].name for b in bones], "length_m": float(model.l0),
             "mesh_volume_cm3": float(mesh.volume) * 1e6}
    return text, entry


def measure_file(text: str, path: str, mesh, skel: Skeleton, rest: np.ndarray, bound=None) -> dict:
    """The written file read back by the muscle spec loader and evaluated at the rest pose by
    the muscle model, compared with its mesh; with ``bound`` (the mesh's
    :class:`~axdf_cli.geometry.partition.MeshField`) also the share of the written surface's
    vertices more than 0.25 and 1 mm outside the mesh, and the farthest (mm)."""
    spec = parse_muscle_text(text, path)[0]
    model = MuscleModel(spec, skel.bone_index, rest, skel)
    got = model.rest_vertices.astype(np.float64)
    out = fs.measure(np.asarray(mesh.vertices), np.asarray(mesh.faces), got,
                     np.asarray(model.faces, dtype=np.int64), seed=tol.FIT_SEED)
    if bound is not None:
        away = np.maximum(-bound.value(got), 0.0)
        out.update({"outside_over_0.25mm": float((away > 2.5e-4).mean()), "outside_over_1mm": float((away > 1e-3).mean()),
                    "outside_farthest_mm": float(1000.0 * away.max())})
    return out


def bone_gap(points: np.ndarray, geometry: list) -> tuple[float, int]:
    """The distance (metres) from points (P, 3) to the nearest bone of ``geometry``
    (:func:`bone_geometry`) and that bone's index."""
    import igl

    best, which = np.inf, -1
    for b, g in enumerate(geometry):
        if g is None:
            continue
        if g[0] == "mesh":
            d = float(igl.point_mesh_squared_distance(points, g[1], g[2])[0].min())
        else:
            a, e = g[1][:, 0], g[1][:, 1] - g[1][:, 0]
            rel = points[:, None] - a[None]
            lam = np.clip(np.einsum("pkc,kc->pk", rel, e) / np.maximum((e * e).sum(axis=1), 1e-300), 0.0, 1.0)
            d = float((np.linalg.norm(rel - lam[..., None] * e[None], axis=-1) ** 2).min())
        if d < best:
            best, which = d, b
    return float(np.sqrt(best)), which


def _read_all(mesh_paths, scale, transform, skel, rest, geometry, paths, policy, units, added=None) -> tuple:
    """Every mesh read and checked (with its muscle name and, under ``paths``, its model's
    bones; ``added``'s muscles: their given bones and origin) before any is fitted; every
    refusal of the batch at once."""
    added = added or {}
    meshes, names, errors, allowed = [], {}, [], {}
    for p in map(Path, mesh_paths):
        try:
            name = muscle_name(p)
            if name in names:
                raise InputError(Mark(str(p)), f"muscle {name!r} is also fitted from {names[name]}",
                                 "mesh files with distinct stems (each names a muscle file)")
            names[name] = p
            got = read_mesh(p, scale, transform)
            gap, bone = bone_gap(np.asarray(got.mesh.vertices, dtype=np.float64), geometry)
            if gap > tol.FIT_MAX_BONE_GAP:
                how = "carried by --transform" if transform is not None else f"read in {unit_name(scale)}"
                raise InputError(Mark(str(p)), f"the mesh lies {gap:.3f} m from the nearest bone of {skel.name} at "
                                 f"rest ({skel.bones[bone].name}), {how}: it is not in the skeleton's rest frame",
                                 f"a muscle within {tol.FIT_MAX_BONE_GAP:g} m of a bone: register the meshes onto the "
                                 "skeleton first (an atlas: `axdf atlas ATLAS_DIR --onto SKELETON --map MAP "
                                 "--muscles DIR --out DIR --register-only`, then fit DIR/registered/*.ply; docs/ATLAS.md), "
                                 "or carry them with --transform FILE (a 4x4 matrix into the rest frame; docs/FIT.md, "
                                 f"\"Meshes in another frame\"), or check --units (now {units})")
            if name in added:  # a shape muscle the model lacks: no path, its own bones
                bones, origin, color = added[name]
                allowed[name] = ({skel.bone_index[b] for b in bones}, np.asarray(origin, dtype=np.float64), None, color)
            elif paths is not None:
                allowed[name] = model_bones(paths, name, skel, rest, policy)
            meshes.append((p, name, got))
        except InputError as e:
            errors.append(e)
    raise_all(errors)
    return meshes, allowed


def build_fit(mesh_paths: list[Path], skeleton_path: Path | str, units: str = "m", sections: int | None = None,
              policy: RefPolicy | None = None, on_muscle=None, paths: Path | None = None,
              transform: Path | None = None, inside: bool = False, added: dict | None = None) -> FitOutputs:
    """Fit every mesh; the bytes of ``muscles/STEM.yaml`` per mesh, the report's two files.
    Every mesh is read and checked before any is fitted, and every refusal is raised at once
    (one :class:`~axdf_cli.errors.InputErrors`). ``on_muscle(name, entry)`` is told as each fit
    is measured. ``paths``: a folder of the model's muscle files; each mesh binds only to the
    bones of the file of its name there (:func:`model_bones`). ``transform``: a ``--transform``
    file, the map from the meshes' frame (metres after ``units``) into the rest frame.
    ``inside``: each fit is kept inside its own mesh (:func:`fit_one`'s ``bound``: the mesh's
    :class:`~axdf_cli.geometry.partition.MeshField`), and the report says how far it is not.
    For meshes that share no space (``axdf atlas --partition``'s territories) the fits then
    share none either. ``added``: muscles the model lacks (``axdf atlas``'s ``added:``), name ->
    (the bones they bind to, a world point their axis starts near, their colour): fitted without a path."""
    scale = unit_scale(units)
    n = tol.FIT_SECTIONS_DEFAULT if sections is None else sections
    if not tol.FIT_SECTIONS_MIN <= n <= tol.FIT_SECTIONS_MAX:
        raise InputError(Mark("--sections"), f"--sections {n}",
                         f"{tol.FIT_SECTIONS_MIN}..{tol.FIT_SECTIONS_MAX} sections")
    matrix = None if transform is None else load_transform(transform)
    skeleton_path = Path(skeleton_path)
    skel = load_skeleton(skeleton_path, policy or RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    geometry = bone_geometry(skel, rest, skeleton_path)
    meshes, allowed = _read_all(mesh_paths, scale, matrix, skel, rest, geometry, paths, policy, units, added)
    files: dict[str, bytes] = {}
    entries = []
    for p, name, got in meshes:
        mesh = got.mesh
        own, origin, line, color = geometry, None, None, None
        if name in allowed:
            keep, origin, line, color = allowed[name]
            own = [g if i in keep else None for i, g in enumerate(geometry)]
            if all(g is None for g in own):  # the path's bones have no meshes: their segments then
                own = [g if i in keep else None for i, g in enumerate(bone_geometry(skel, rest, skeleton_path, False))]
        bound = MeshField(mesh.vertices, mesh.faces) if inside else None
        text, entry = fit_one(mesh, name, n, skel, rest, own, origin, line, color, bound, shape=name in (added or {}))
        rel = f"muscles/{name}.yaml"
        entry.update({"file": rel, "mesh": p.name})
        if got.dropped:
            entry.update({"dropped_pieces": got.dropped, "dropped_volume_share": got.dropped_share})
        entry.update(measure_file(text, rel, mesh, skel, rest, bound))
        files[rel] = text.encode()
        entries.append(entry)
        if on_muscle is not None:
            on_muscle(name, entry)
    report = {"skeleton": skeleton_path.name, "units": units, "sections": n, "muscles": entries}
    if inside:
        report["inside"] = True
    if transform is not None:
        report["transform"] = Path(transform).name
    files[REPORT] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[SUMMARY] = summary(report).encode()
    inputs = [skeleton_path] + [Path(b.mesh) for b in skel.bones if b.mesh] + [p for p, _, _ in meshes] + \
        [Path(paths) / f"{name}.yaml" for name in allowed if name not in (added or {})] + \
        ([Path(transform)] if transform is not None else [])
    return FitOutputs(files, report, [str(p) for p in inputs])


def summary(report: dict) -> str:
    lines = [f"# Muscles fitted on {report['skeleton']}", "",
             f"`axdf fit` ({report['sections']} sections of {OCT} outline points; docs/FIT.md). Each muscle file",
             "is read back and evaluated by the muscle model at the rest pose, then compared with its mesh:",
             "IoU of the insides on a grid, surface distance both ways, volume fitted / mesh.", "",
             "| muscle | IoU | mean distance | median distance | volume ratio | tendons | bones |",
             "|---|---|---|---|---|---|---|"]
    for m in report["muscles"]:
        lines.append(f"| {m['muscle']} | {m['iou']:.3f} | {m['distance_mean_mm']:.2f} mm | "
                     f"{m['distance_median_mm']:.2f} mm | {m['volume_ratio']:.3f} | "
                     f"{m['tendons'][0]:g}, {m['tendons'][1]:g} | {', '.join(dict.fromkeys(m['bones']))} |")
    if report.get("inside"):
        ms = report["muscles"]
        lines += ["", "Kept inside each mesh (`--inside`): vertices of the written surface more than 1 mm outside "
                  "their mesh: " + "; ".join(f"{m['muscle']} {100 * m['outside_over_1mm']:.2f}% "
                                            f"(farthest {m['outside_farthest_mm']:.1f} mm)" for m in ms) + "."]
    dropped = [m for m in report["muscles"] if m.get("dropped_pieces")]
    if dropped:
        lines += ["", f"Slivers dropped (closed pieces under {100 * tol.FIT_MIN_PIECE_SHARE:g}% of a mesh's volume): " +
                  "; ".join(f"{m['mesh']}: {m['dropped_pieces']} pieces, {100 * m['dropped_volume_share']:.2f}%"
                            for m in dropped) + "."]
    return "\n".join(lines) + "\n"
