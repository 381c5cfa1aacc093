"""Shape measures of a gait2392 muscle library at the skeleton's rest pose (right leg), the
numbers docs/ATLAS.md reports:

    python scripts/atlas_measure.py muscles/gait2392_atlas [muscles/gait2392 ...]

- thigh fill: muscle + femur area over the area of their convex hull, in the plane across
  the hip -> knee line at 25, 50 and 75% of its length (a 1 mm grid, winding-number insides);
- vastus lateralis' and medial gastrocnemius' aspect ratio at their widest section (50 cuts
  across the muscle's principal axis; the ratio of the section's principal extents,
  sqrt of its second moments' eigenvalue ratio);
- vastus lateralis' widest section's position as a fraction of the way from hip to knee;
- the share of the leg's muscle vertices inside another muscle, and inside a bone.
Prints one JSON object per library.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from axdf_cli.geometry.winding import inside  # noqa: E402  (signed: w > 0.5, as docs/FIT.md's numbers were made)
from axdf_cli.tools.atlas_library import rest_state  # noqa: E402  (the skeleton, rest, bone meshes)


def leg_muscles(folder: Path, skel, rest, side: str = "r") -> dict:
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.specs import load_muscle_file

    out = {}
    for p in sorted(Path(folder).glob(f"*_{side}.yaml")):
        for spec in load_muscle_file(p):
            m = MuscleModel(spec, skel.bone_index, rest, skel)
            out[spec.name] = (np.asarray(m.rest_vertices, np.float64), np.asarray(m.faces, np.int64))
    return out


def plane_grid(centre, normal, half, step):
    a = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    u = np.arange(-half, half + step / 2, step)
    U, V = np.meshgrid(u, u, indexing="ij")
    return centre + U.ravel()[:, None] * a + V.ravel()[:, None] * b, np.stack([U.ravel(), V.ravel()], axis=1)


def thigh_fill(muscles, bones, hip, knee, frac) -> float:
    from scipy.spatial import Delaunay

    d = (knee - hip) / np.linalg.norm(knee - hip)
    pts, uv = plane_grid(hip + frac * (knee - hip), d, 0.15, 0.001)
    full = inside(*bones["femur_r"], pts, signed=True)
    for mesh in muscles.values():
        lo, hi = mesh[0].min(axis=0), mesh[0].max(axis=0)
        near = ((pts >= lo) & (pts <= hi)).all(axis=1)
        if near.any():
            full[near] |= inside(*mesh, pts[near], signed=True)
    hull = Delaunay(uv[full])
    return float(full.sum() / (hull.find_simplex(uv) >= 0).sum())


def widest(mesh, hip, knee):
    v = mesh[0]
    c = v.mean(axis=0)
    _, _, vt = np.linalg.svd(v - c, full_matrices=False)
    ax = vt[0]
    s = (v - c) @ ax
    best = (0, None, None)
    for t in np.linspace(s.min(), s.max(), 52)[1:-1]:
        pts, uv = plane_grid(c + t * ax, ax, 0.12, 0.001)
        ins = inside(*mesh, pts, signed=True)
        if ins.sum() > best[0]:
            q = uv[ins] - uv[ins].mean(axis=0)
            ev = np.linalg.eigvalsh(q.T @ q / len(q))
            best = (int(ins.sum()), float(np.sqrt(ev[1] / max(ev[0], 1e-30))), pts[ins].mean(axis=0))
    hk = knee - hip
    return best[1], float((best[2] - hip) @ hk / (hk @ hk))


def overlaps(muscles, bones) -> tuple[float, float]:
    n = in_m = in_b = 0
    boxes = {k: (m[0].min(axis=0), m[0].max(axis=0)) for k, m in {**muscles, **bones}.items()}
    for name, (v, _) in muscles.items():
        hit_m = np.zeros(len(v), bool)
        hit_b = np.zeros(len(v), bool)
        for other, mesh in list(muscles.items()) + list(bones.items()):
            if other == name:
                continue
            lo, hi = boxes[other]
            near = ((v >= lo) & (v <= hi)).all(axis=1)
            if near.any():
                (hit_b if other in bones else hit_m)[near] |= inside(*mesh, v[near], signed=True)
        n += len(v)
        in_m += int(hit_m.sum())
        in_b += int(hit_b.sum())
    return in_m / n, in_b / n


def measure(folder: Path, skel, rest, bones) -> dict:
    muscles = leg_muscles(folder, skel, rest)
    hip = rest[skel.bone_index["femur_r"], :3, 3]
    knee = rest[skel.bone_index["tibia_r"], :3, 3]
    vl_ar, vl_at = widest(muscles["vas_lat_r"], hip, knee)
    mg_ar, _ = widest(muscles["med_gas_r"], hip, knee)
    im, ib = overlaps(muscles, {k: v for k, v in bones.items() if k != "ground"})
    return {"library": str(folder), "muscles": len(muscles),
            "thigh_fill": {f"{int(f * 100)}%": round(thigh_fill(muscles, bones, hip, knee, f), 3) for f in (0.25, 0.5, 0.75)},
            "aspect_widest": {"vas_lat_r": round(vl_ar, 2), "med_gas_r": round(mg_ar, 2)},
            "vas_lat_r_widest_at": round(vl_at, 3),
            "inside_muscle": round(im, 4), "inside_bone": round(ib, 4)}


def main() -> int:
    skel, rest, bones = rest_state(ROOT / "poses/skeletons/gait2392.yaml")
    for folder in sys.argv[1:] or ["muscles/gait2392_atlas", "muscles/gait2392"]:
        print(json.dumps(measure(Path(folder), skel, rest, bones)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
