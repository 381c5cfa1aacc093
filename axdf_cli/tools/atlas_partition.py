"""``axdf atlas --partition``: the registered atlas as a partition of space
(axdf_cli/geometry/partition.py). Its tissues, from the highest level down: the model's bones
at rest (they win), the atlas' registered muscles (deepest wins among them), and the model's
muscles of the registered sides that the atlas lacks (at rest, as the model's library has
them: they take the room left). Each muscle's territory is written as a closed mesh
(``territories/NAME.ply``), with its volume against its mesh's and the depth measure of the
registered meshes and of the territories in the report: the input that tools requiring
intersection-free tissues take, and what a fit into territories starts from.

Built after the warp, in the skeleton's frame: whatever overlap registration adds (a muscle
carried into the model's coarse bone, two neighbours pressed together) is resolved by the
partition itself.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol

TERRITORIES = "territories"


def model_rest_meshes(folder: Path, names: list[str], skel, rest) -> dict:
    """The model's muscles ``names`` of ``folder`` at rest: name -> ((V, 3), (F, 3))."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.specs import load_muscle_file

    out = {}
    for n in names:
        for spec in load_muscle_file(Path(folder) / f"{n}.yaml"):
            m = MuscleModel(spec, skel.bone_index, rest, skel)
            out[spec.name] = (np.asarray(m.rest_vertices, np.float64), np.asarray(m.faces, np.int64))
    return out


def depth_shares(meshes: dict, bones: dict) -> dict:
    """The depth measure of closed meshes (name -> (V, F)) at their vertices: the share more
    than 0.25, 1 and 3 mm inside another of them and more than 1 mm inside a bone, and the
    deepest (mm)."""
    from axdf_cli.geometry.partition import depth_inside

    names = list(meshes)
    ms = [meshes[n] for n in names]
    pts = np.concatenate([m[0] for m in ms])
    own = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(ms)])
    d = depth_inside(pts, own, ms)
    db = depth_inside(pts, np.full(len(pts), -1), list(bones.values()))
    return {"vertices": int(len(pts)), "inside_muscle_over_0.25mm": float((d > 2.5e-4).mean()),
            "inside_muscle_over_1mm": float((d > 1e-3).mean()), "inside_muscle_over_3mm": float((d > 3e-3).mean()),
            "deepest_mm": float(1000.0 * d.max()), "inside_bone_over_1mm": float((db > 1e-3).mean())}


def build_partition(carried: list, old: Path, sides, skel, rest, bones: dict, tell=None, amap=None) \
        -> tuple[dict, dict]:
    """The partition of the registered atlas ``carried`` [(name, V, F)], the model's muscles of
    ``old`` on ``sides`` it lacks and the bones (name -> (V, F)): (territory meshes name -> (V,
    F), the report's ``partition`` entry)."""
    import trimesh

    from axdf_cli.geometry.partition import Tissue, partition

    tell = tell or (lambda text: None)
    have = {n for n, _, _ in carried}
    lacks = sorted(p.stem for p in Path(old).glob("*.yaml")
                   if p.stem not in have and any(amap.on_side(p.stem, s) if amap is not None
                                                 else p.stem.endswith(f"_{s}") for s in sides))
    kept = model_rest_meshes(old, lacks, skel, rest)
    tissues = [Tissue(n, v, f, 1) for n, v, f in carried]
    tissues += [Tissue(n, v, f, 0) for n, (v, f) in kept.items()]
    tissues += [Tissue(n, v, f, 2, territory=False) for n, (v, f) in bones.items()]
    tell(f"partition of {len(carried)} atlas muscles, {len(kept)} the atlas lacks and {len(bones)} bones "
         f"({tol.ATLAS_PARTITION_SPACING * 1000:g} mm grid, {tol.ATLAS_PARTITION_GAP * 1000:g} mm gap)")
    part = partition(tissues, tol.ATLAS_PARTITION_SPACING, tol.ATLAS_PARTITION_GAP, tell)
    meshes, volumes, empty = {}, {}, []
    source = {n: (v, f) for n, v, f in carried} | kept
    for t in tissues:
        if not t.territory:
            continue
        s = part.surface(t.name)
        if s is None:
            empty.append(t.name)
            continue
        meshes[t.name] = s
        before = abs(trimesh.Trimesh(*source[t.name], process=False).volume)
        volumes[t.name] = float(abs(trimesh.Trimesh(*s, process=False).volume) / max(before, 1e-300))
    tell("partition: measuring the registered meshes and the territories by depth")
    ratio = np.array(list(volumes.values())) if volumes else np.ones(1)
    entry = {"spacing_mm": tol.ATLAS_PARTITION_SPACING * 1000, "gap_mm": tol.ATLAS_PARTITION_GAP * 1000,
             "seconds": round(part.seconds, 1), "lacked": lacks, "empty": empty,
             "volume_ratio": volumes, "volume_ratio_median": float(np.median(ratio)),
             "volume_ratio_least": float(ratio.min()),
             "registered": depth_shares(source, bones),
             "territories": depth_shares(meshes, bones)}
    return meshes, entry
