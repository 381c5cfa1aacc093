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
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name
from axdf_cli.importers import emit
from axdf_cli.model.muscle import OCT, AxisPoint, MuscleModel, MuscleSpec, Section, outline_area
from axdf_cli.model.pose import muscle_bones
from axdf_cli.model.skeleton import Skeleton, forward_kinematics
from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
from axdf_cli.specs.muscle import default_color, parse_muscle_text
from axdf_cli.tools import fit_sections as fs

REPORT = "fit_report.json"
SUMMARY = "FIT.md"
UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
MESH_SUFFIXES = (".stl", ".ply", ".obj")
MESH_ALLOWED = "a closed (watertight) triangle surface in STL, PLY or OBJ"


@dataclass
class FitOutputs:
    files: dict  # output path relative to DIR -> bytes
    report: dict
    inputs: list = field(default_factory=list)  # every file read


# ----------------------------------------------------------------------------- reading


def unit_scale(units: str) -> float:
    """Metres per mesh unit; an unknown unit is refused."""
    if units not in UNITS:
        raise InputError(Mark("--units"), f"unit {units!r} is unknown", "--units mm, cm or m (the meshes' unit)")
    return UNITS[units]


def unit_name(scale: float) -> str:
    """The ``--units`` word of a scale (metres per unit)."""
    return next((u for u, k in UNITS.items() if k == scale), f"{scale:g} m")


def read_mesh(path: Path, scale: float):
    """A closed muscle surface in metres (a trimesh.Trimesh, outward-facing); refused by name
    when missing, unreadable, open or without volume."""
    import trimesh

    where = Mark(str(path))
    if not path.is_file():
        raise InputError(where, "mesh file not found", MESH_ALLOWED)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(where, f"{path.suffix or 'no suffix'} is not a mesh format axdf fit reads", MESH_ALLOWED)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds on a bad file
        raise InputError(where, f"cannot be read as a mesh ({type(e).__name__}: {e})", MESH_ALLOWED) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(where, "holds no triangles", MESH_ALLOWED)
    # checked before trimesh merges vertices: it drops a NaN vertex (the mesh then reads "not
    # closed") and casts an overflowing one to int
    if not np.isfinite(mesh.vertices).all():
        raise InputError(where, "has non-finite vertex coordinates", "finite numbers only")
    size = float(np.ptp(mesh.vertices, axis=0).max()) * scale
    far = float(np.abs(mesh.vertices).max()) * scale
    if not tol.FIT_MIN_SIZE <= size <= tol.FIT_MAX_SIZE or far > tol.FIT_MAX_REACH:
        raise InputError(where, f"mesh is {size:.3g} m across, {far:.3g} m from the origin at most, read in "
                         f"{unit_name(scale)}", f"a muscle {tol.FIT_MIN_SIZE * 1000:g} mm to {tol.FIT_MAX_SIZE:g} m "
                         f"long within {tol.FIT_MAX_REACH:g} m of the skeleton's origin: check --units (mm, cm or m)")
    mesh.apply_scale(scale)
    mesh.process(validate=False)
    if not mesh.is_watertight:
        edges = np.bincount(mesh.faces_unique_edges.ravel(), minlength=len(mesh.edges_unique)) \
            if hasattr(mesh, "faces_unique_edges") else np.zeros(0)
        open_edges = int((edges == 1).sum())
        raise InputError(where, "mesh is not closed (not watertight" +
                         (f": {open_edges} edges bound one triangle" if open_edges else "") + ")", MESH_ALLOWED)
    with np.errstate(all="ignore"):  # (trimesh divides by the volume for the centre of mass)
        vol = float(mesh.volume)
    box = float(np.prod(np.maximum(mesh.extents, 1e-300)))
    if not abs(vol) > tol.FIT_MIN_VOLUME_SHARE * box or not abs(vol) > tol.FIT_MIN_VOLUME:
        raise InputError(where, f"mesh encloses no volume ({abs(vol) * 1e6:.3g} cm^3)",
                         "a closed surface around a muscle's body")
    if mesh.body_count > 1:
        raise InputError(where, f"mesh is {mesh.body_count} separate closed pieces",
                         "one muscle per mesh file: split the pieces into files of their own")
    if vol < 0:  # inside out: face outwards
        mesh.invert()
    return mesh


def muscle_name(path: Path) -> str:
    stem = path.stem
    if not is_name(stem):
        raise InputError(Mark(str(path)), f"the file's stem {stem!r} cannot name a muscle",
                         f"rename the file: {NAME_ALLOWED}")
    return stem


# ----------------------------------------------------------------------------- bones


def bone_geometry(skel: Skeleton, rest: np.ndarray, skeleton_path: Path, meshes: bool = True) -> list:
    """Per bone what a point is bound to by nearness: ('mesh', world vertices, faces) where the
    skeleton has bone meshes (only those bones then; ``meshes`` False: never), else
    ('segments', (k, 2, 3)) from its origin to each child's origin (a leaf: its origin)."""
    from axdf_cli.pipeline.plan import load_bone_mesh

    if meshes and any(b.mesh for b in skel.bones):
        out = []
        for i, b in enumerate(skel.bones):
            if not b.mesh:
                out.append(None)
                continue
            v, f, _ = load_bone_mesh(b.mesh, str(skeleton_path))
            w = v.astype(np.float64) @ rest[i, :3, :3].T + rest[i, :3, 3]
            out.append(("mesh", w, np.asarray(f, dtype=np.int64)))
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


def bones_between(skel: Skeleton, bones: set[int]) -> set[int]:
    """``bones`` and every bone on the skeleton's tree between two of them: a path from the
    femur to the calcaneus crosses the tibia and the talus, where the calf's belly lies."""
    def up(b: int) -> list[int]:
        out = []
        while b >= 0:
            out.append(b)
            b = skel.bones[b].parent
        return out

    chains = [up(b) for b in bones]
    shared = set.intersection(*map(set, chains)) if chains else set()
    full = set()
    for chain in chains:  # each bone's way up to the bones' lowest common ancestor
        for b in chain:
            full.add(b)
            if b in shared:
                break
    return full


def model_bones(folder: Path, name: str, skel: Skeleton, rest: np.ndarray) -> tuple:
    """The bones (indices) of the muscle file ``folder/NAME.yaml`` of a model (its path's
    points and wraps, or its axis) and the bones between them (:func:`bones_between`): the
    only bones a fit of mesh NAME binds to, each control point to the nearest, so that a
    muscle that crosses two joints hangs on the bones it spans (gastrocnemius: the femur at
    its heads, the tibia along its belly, not the femur down to the ankle); its origin (its first
    path or axis point) in the world at rest, which the fitted axis starts at; its path (a
    single muscle's, else None), which the fitted muscle keeps as its line of action; and its
    colour, which it keeps too (a muscle looks the same in either library). Refused when the
    file is missing or names a bone the skeleton lacks."""
    path = Path(folder) / f"{name}.yaml"
    if not path.is_file():
        raise InputError(Mark(str(path)), f"no muscle file {name}.yaml in --paths {folder}",
                         "a muscle file of the model per mesh, named as the mesh's stem")
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
            origin: np.ndarray | None = None, line=None, color=None):
    """One mesh (metres) → (the muscle's YAML text, its report entry without the measures).
    ``origin``: a world point the axis starts at the end nearer to (a model's origin);
    ``line``: a model's path (:class:`~axdf_cli.model.paths.PathSpec`), written beside the
    fitted axis as the muscle's line of action (its length, as the model's); ``color``: the
    muscle's colour (default: :func:`default_color` of its name)."""
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
    xy = fs.fit_rows(mesh, rows, frames, samples, np.asarray(mesh.face_normals)[face])
    areas = np.abs([outline_area(o) for o in xy])
    arc = np.interp(sec_t, model.ts, model.arc)
    tendons = tendon_fractions(areas, arc)
    along = max(tol.FIT_ALONG_MIN, tol.FIT_ALONG_PER_SECTION * n_sections + 8)
    spec = MuscleSpec(name, default_color(name) if color is None else color, axis,
                      tuple(Section(float(t), None, 0.0, tuple((float(a), float(b)) for a, b in o))
                            for t, o in zip(sec_t, xy)),
                      tendons=tendons, resolution=(along, tol.FIT_OUTPUT_AROUND), path=line)
    from axdf_cli.tools.transfer import muscle_doc

    kept = "; its path, the model's line of action" if line is not None else ""
    text = emit.dump_yaml(emit.rounded(muscle_doc(spec)),
                          header=f"{name}: fitted by `axdf fit` to its mesh ({n_sections} sections{kept}; "
                                 f"report: {REPORT}).")
    entry = {"muscle": name, "sections": n_sections, "tendons": list(tendons),
             "bones": [skel.bones[b].name for b in bones], "length_m": float(model.l0),
             "mesh_volume_cm3": float(mesh.volume) * 1e6}
    return text, entry


def measure_file(text: str, path: str, mesh, skel: Skeleton, rest: np.ndarray) -> dict:
    """The written file read back by the muscle spec loader and evaluated at the rest pose by
    the muscle model, compared with its mesh."""
    spec = parse_muscle_text(text, path)[0]
    model = MuscleModel(spec, skel.bone_index, rest, skel)
    return fs.measure(np.asarray(mesh.vertices), np.asarray(mesh.faces), model.rest_vertices.astype(np.float64),
                      np.asarray(model.faces, dtype=np.int64), seed=tol.FIT_SEED)


def build_fit(mesh_paths: list[Path], skeleton_path: Path | str, units: str = "m", sections: int | None = None,
              policy: RefPolicy | None = None, on_muscle=None, paths: Path | None = None) -> FitOutputs:
    """Fit every mesh; the bytes of ``muscles/STEM.yaml`` per mesh, the report's two files.
    Every mesh is read and checked before any is fitted. ``on_muscle(name, entry)`` is told
    as each fit is measured. ``paths``: a folder of the model's muscle files; each mesh binds
    only to the bones of the file of its name there (:func:`model_bones`)."""
    scale = unit_scale(units)
    n = tol.FIT_SECTIONS_DEFAULT if sections is None else sections
    if not tol.FIT_SECTIONS_MIN <= n <= tol.FIT_SECTIONS_MAX:
        raise InputError(Mark("--sections"), f"--sections {n}",
                         f"{tol.FIT_SECTIONS_MIN}..{tol.FIT_SECTIONS_MAX} sections")
    skeleton_path = Path(skeleton_path)
    skel = load_skeleton(skeleton_path, policy or RefPolicy())
    meshes, names = [], {}
    for p in mesh_paths:
        p = Path(p)
        name = muscle_name(p)
        if name in names:
            raise InputError(Mark(str(p)), f"muscle {name!r} is also fitted from {names[name]}",
                             "mesh files with distinct stems (each names a muscle file)")
        names[name] = p
        meshes.append((p, name, read_mesh(p, scale)))
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    allowed = {name: model_bones(paths, name, skel, rest) for _, name, _ in meshes} if paths is not None else {}
    geometry = bone_geometry(skel, rest, skeleton_path)
    files: dict[str, bytes] = {}
    entries = []
    for p, name, mesh in meshes:
        own, origin, line, color = geometry, None, None, None
        if name in allowed:
            keep, origin, line, color = allowed[name]
            own = [g if i in keep else None for i, g in enumerate(geometry)]
            if all(g is None for g in own):  # the path's bones have no meshes: their segments then
                own = [g if i in keep else None for i, g in enumerate(bone_geometry(skel, rest, skeleton_path, False))]
        text, entry = fit_one(mesh, name, n, skel, rest, own, origin, line, color)
        rel = f"muscles/{name}.yaml"
        entry.update({"file": rel, "mesh": p.name})
        entry.update(measure_file(text, rel, mesh, skel, rest))
        files[rel] = text.encode()
        entries.append(entry)
        if on_muscle is not None:
            on_muscle(name, entry)
    report = {"skeleton": skeleton_path.name, "units": units, "sections": n, "muscles": entries}
    files[REPORT] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[SUMMARY] = summary(report).encode()
    inputs = [skeleton_path] + [Path(b.mesh) for b in skel.bones if b.mesh] + [p for p, _, _ in meshes] + \
        [Path(paths) / f"{name}.yaml" for name in allowed]
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
    return "\n".join(lines) + "\n"
