"""A muscle library of a model from the atlas: every muscle of gait2392 the atlas has,
registered onto the skeleton (axdf_cli/tools/atlas.py) and fitted (axdf_cli/tools/fit.py)
under the model's name; the muscles the atlas lacks copied from the model's own library.

The name map is axdf_cli/data/atlas_gait2392.yaml (:func:`axdf_cli.tools.tables.atlas_map`).
Per leg: the atlas' muscle meshes are carried by the leg's registration, their vertices inside
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
from axdf_cli.tools.tables import atlas_map

REPORT = "atlas_report.json"


def find_atlas(root: Path, side: str, names: list[str]) -> Path | None:
    """The first atlas muscle file of ``names`` on the leg, or None."""
    for n in names:
        p = at.atlas_path(root, side, "Muscle", n)
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


def split_parts(v: np.ndarray, f: np.ndarray, centres: np.ndarray, spacing: float) -> list[tuple]:
    """A closed mesh (V, F) cut into len(centres) closed parts by planes across the line from
    the first centre to the last, each halfway between neighbouring centres' projections:
    the inside (winding number) on a grid, limited to each slab, turned back into a surface
    (marching cubes)."""
    import igl

    d = centres[-1] - centres[0]
    d = d / np.linalg.norm(d)
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


def write_ply(path: Path, v: np.ndarray, f: np.ndarray) -> None:
    import trimesh

    m = trimesh.Trimesh(v, f, process=True)
    if m.volume < 0:
        m.invert()
    m.export(str(path))


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


def registered_meshes(data_root: Path, skel, rest, bones: dict, old: Path, sides=("r",), tell=None) -> tuple:
    """The atlas' muscles carried onto the skeleton at rest, under the model's names: a list of
    (name, (V, 3) float64 world metres, (F, 3) int64) and the report of each leg (the
    registration's residuals, each muscle's source and how many of its vertices were pushed
    out of the bones). ``old``: the model's own muscle folder (the paths that cut a shared
    atlas muscle into the model's parts)."""
    tell = tell or (lambda text: None)
    names = atlas_map()
    meshes, sides_rep = [], {}
    for side in sides:
        tell(f"registering the atlas' {names.sides[side].lower()} leg")
        reg = at.register(data_root, skel, rest, bones, side)
        side_rep = dict(reg.report, muscles={})
        ta = find_atlas(data_root, side, ["TibialisAnterior"])
        if ta is not None:
            tv = at.read_atlas_mesh(ta)[0]
            tib = bones[f"tibia_{side}"]
            side_rep["tib_ant_inside_tibia"] = {"landmarks": inside_share(*tib, reg.apply(tv, warp=False)),
                                                "warp": inside_share(*tib, reg.apply(tv))}
        jobs = [(m, [m], list(src)) for m, src in names.muscles.items()] + \
               [(g, list(parts), list(src)) for g, (src, parts) in names.split.items()]
        for key, parts, src in jobs:
            p = find_atlas(data_root, side, src)
            if p is None:
                continue
            v, fc = at.read_atlas_mesh(p)
            w = reg.apply(v)
            pieces = [(w, fc)] if len(parts) == 1 else split_parts(
                w, fc, np.array([path_centroid(old, f"{q}_{side}", skel, rest) for q in parts]), tol.ATLAS_SPLIT_SPACING)
            for q, (pv, pf) in zip(parts, pieces):
                # (signed: w > 0.5, as the shipped library was made; gait2392's torso is wound inconsistently)
                pv, moved = push_out_of_meshes(pv, bones.values(), tol.ATLAS_BONE_MARGIN, signed=True)
                name = f"{q}_{side}"
                meshes.append((name, pv, pf))
                side_rep["muscles"][name] = {"atlas": p.name, "pushed_out_of_bones": moved,
                                             "part": f"{parts.index(q) + 1}/{len(parts)}" if len(parts) > 1 else None}
        sides_rep[side] = side_rep
    return meshes, sides_rep


def landmark_transform(data_root: Path, skeleton_path: Path, side: str = "r") -> str:
    """The ``axdf fit --transform`` file (text) of one leg's registration onto the skeleton at
    rest: the landmarks' similarity (:func:`atlas.register` without the warp), from the atlas'
    frame in metres (``--units mm``) into the skeleton's rest frame."""
    from axdf_cli.tools.fit_mesh import transform_text

    data_root, skeleton_path = Path(data_root), Path(skeleton_path)
    if not data_root.is_dir():
        raise InputError(Mark(str(data_root)), "atlas folder not found", "the Visible Human Female folder (Left/, Right/)")
    skel, rest, bones = rest_state(skeleton_path)
    reg = at.register(data_root, skel, rest, bones, side, rounds=0)
    res = ", ".join(f"{k} {v:g} mm" for k, v in reg.report["landmark_residual_mm"].items())
    return transform_text(reg.scale, reg.rotation, reg.shift,
                          f"The {atlas_map().sides[side].lower()} leg of the atlas {data_root.name} onto {skel.name} at rest: "
                          f"the similarity of its joint centres\n(scripts/atlas_library.py --transform; scale "
                          f"{reg.scale:.4f}; residuals {res}).\nUse: axdf fit MESH ... --units mm --transform FILE "
                          f"--skeleton {skeleton_path.name} (docs/FIT.md)")


def build_library(data_root: Path, skeleton_path: Path, old: Path, sides=("r",), sections: int | None = None,
                  on_muscle=None, on_phase=None) -> tuple[dict, dict]:
    """The library's files (name -> bytes: one muscle file per model muscle, the report) and
    the report. ``old``: the model's own muscle folder (paths, and the muscles the atlas lacks).
    ``on_phase(text)`` is told as each phase starts; ``on_muscle(name, entry)`` as each fit ends."""
    from axdf_cli.tools.fit import build_fit

    tell = on_phase or (lambda text: None)
    data_root, skeleton_path, old = Path(data_root), Path(skeleton_path), Path(old)
    if not data_root.is_dir():
        raise InputError(Mark(str(data_root)), "atlas folder not found", "the Visible Human Female folder (Left/, Right/)")
    skel, rest, bones = rest_state(skeleton_path)
    report = {"atlas": str(data_root.name), "skeleton": skeleton_path.name, "sides": {}, "fitted": [], "failed": [],
              "kept": []}
    files: dict[str, bytes] = {}
    with tempfile.TemporaryDirectory(prefix="axdf-atlas-") as tmp:
        carried, report["sides"] = registered_meshes(data_root, skel, rest, bones, old, sides, tell)
        meshes = []
        for name, pv, pf in carried:
            out = Path(tmp) / f"{name}.ply"
            write_ply(out, pv, pf)
            meshes.append(out)
        tell(f"fitting {len(meshes)} muscles")
        res = build_fit(meshes, skeleton_path, "m", sections, on_muscle=on_muscle, paths=old)
    failed = {m["muscle"] for m in res.report["muscles"] if not fit_holds(m)}
    for rel, data in res.files.items():
        if rel.startswith("muscles/") and Path(rel).stem not in failed:
            files[rel[len("muscles/"):]] = data
    report["fitted"] = [m for m in res.report["muscles"] if m["muscle"] not in failed]
    report["failed"] = [m for m in res.report["muscles"] if m["muscle"] in failed]
    for p in sorted(old.glob("*.yaml")):
        if p.name not in files:
            files[p.name] = p.read_bytes()
            report["kept"].append(p.stem)
    files[REPORT] = (json.dumps(report, indent=1, sort_keys=True, default=float) + "\n").encode()
    return files, report
