"""IoU of an atlas library's muscle groups at rest, bundles unioned, against the registered
atlas meshes `axdf atlas` wrote (issue 47's shape measure):

    python scripts/atlas_groups.py LIBRARY SKELETON MAP REGISTERED [--sides ,_l] [--report R ...]

A group is a ``split:`` entry of the map (LAT1-3 share one atlas latissimus) or the muscles
whose names differ by their trailing digits (DELT1-3, PECM1-3, glmax1-3); any other muscle is a
group of one. Only the fitted muscles count (the reports' ``fitted``; a group whose every
member was fitted). Each group's fitted surfaces at the skeleton's rest pose, concatenated,
against its members' registered meshes (REGISTERED/NAME.ply, each bundle's share of its atlas
muscle), concatenated: a point is inside a union where its winding number exceeds 0.5, so the
measure is :func:`axdf_cli.tools.fit_sections.measure`'s on the unions. Prints a JSON object:
each group's IoU, the median and the worst.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def union(meshes):
    v = np.concatenate([m[0] for m in meshes])
    offs = np.cumsum([0] + [len(m[0]) for m in meshes[:-1]])
    return v, np.concatenate([m[1] + o for m, o in zip(meshes, offs)])


def main(argv=None) -> int:
    import trimesh
    import yaml

    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
    from axdf_cli.tools.fit_sections import measure

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("library", type=Path)
    ap.add_argument("skeleton", type=Path)
    ap.add_argument("map", type=Path)
    ap.add_argument("registered", type=Path)
    ap.add_argument("--sides", default="", help="the muscles' side suffixes, comma-separated (myobody: ,_l)")
    ap.add_argument("--report", type=Path, nargs="+", required=True)
    a = ap.parse_args(argv)
    fitted = {m["muscle"] for r in a.report for m in json.loads(r.read_text())["fitted"]}
    spec = yaml.safe_load(a.map.read_text())
    key = {}
    for name, entry in (spec.get("split") or {}).items():
        for part in entry["parts"]:
            key[part] = name
    for name in spec.get("muscles") or {}:
        key[name] = re.sub(r"\d+$", "", name) or name
    skel = load_skeleton(a.skeleton, RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    groups = defaultdict(list)
    for sfx in a.sides.split(","):
        for name, k in key.items():
            groups[k + sfx].append(name + sfx)
    out = {}
    for g, names in sorted(groups.items()):
        if not all(n in fitted for n in names):
            continue
        fits, regs = [], []
        for n in names:
            (m,) = load_muscle_file(a.library / f"{n}.yaml")
            model = MuscleModel(m, skel.bone_index, rest, skel)
            fits.append((np.asarray(model.rest_vertices, np.float64), np.asarray(model.faces, np.int64)))
            r = trimesh.load(a.registered / f"{n}.ply", process=False)
            regs.append((np.asarray(r.vertices, np.float64), np.asarray(r.faces, np.int64)))
        rv, rf = union(regs)
        fv, ff = union(fits)
        out[g] = {"members": len(names), "iou": round(measure(rv, rf, fv, ff)["iou"], 4)}
    ious = np.array([v["iou"] for v in out.values()])
    print(json.dumps({"groups": len(out), "median_iou": float(np.median(ious)), "worst_iou": float(ious.min()),
                      "worst": min(out, key=lambda g: out[g]["iou"]), "per_group": out}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
