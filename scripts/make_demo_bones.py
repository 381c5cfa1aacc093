"""Make the simple bone meshes of the demo skeleton (poses/skeletons/human_r_meshes/*.ply).

Capsules and ellipsoids in each bone's local frame: enough to show where the muscles sit in
previews. Run once; the PLY files are committed. Deterministic (no randomness).
"""
from pathlib import Path

import numpy as np
import trimesh

OUT = Path(__file__).resolve().parents[1] / "poses" / "skeletons" / "human_r_meshes"


def capsule(a, b, r):
    a, b = np.asarray(a, float), np.asarray(b, float)
    h = np.linalg.norm(b - a)
    m = trimesh.creation.capsule(height=h, radius=r, count=[16, 16])
    # trimesh's capsule runs along +Z from 0 to h... centred: align +Z with b - a
    z = (b - a) / h
    rot = trimesh.geometry.align_vectors([0, 0, 1], z)
    m.apply_transform(rot)
    m.apply_translation((a + b) / 2 - m.bounds.mean(axis=0) + (m.bounds.mean(axis=0) - (rot[:3, :3] @ [0, 0, 0])) * 0)
    m.apply_translation((a + b) / 2 - (m.vertices.max(0) + m.vertices.min(0)) / 2)
    return m


def ellipsoid(c, radii):
    m = trimesh.creation.icosphere(subdivisions=3)
    m.vertices = m.vertices * np.asarray(radii) + np.asarray(c)
    return m


BONES = {
    "pelvis": [ellipsoid([0, 0.01, -0.03], [0.14, 0.08, 0.07])],
    "femur_r": [capsule([0, 0, 0], [0, 0, -0.42], 0.016), ellipsoid([0, 0, -0.41], [0.04, 0.03, 0.025])],
    "tibia_r": [capsule([0, 0, -0.01], [0, 0, -0.40], 0.015), ellipsoid([0, 0, -0.015], [0.04, 0.03, 0.02])],
    "foot_r": [capsule([0, 0.05, -0.04], [0, -0.16, -0.06], 0.022)],
    "thorax": [ellipsoid([0, 0.01, 0.2], [0.14, 0.1, 0.2])],
    "scapula_r": [ellipsoid([0.02, 0.06, -0.03], [0.05, 0.012, 0.07]), capsule([0.1, -0.04, 0.03], [-0.03, -0.01, 0.03], 0.008)],
    "humerus_r": [capsule([0, 0, -0.02], [0, 0, -0.29], 0.012), ellipsoid([0, 0, -0.01], [0.025, 0.025, 0.025])],
    "ulna_r": [capsule([0.005, 0.01, -0.01], [0.0, 0.0, -0.25], 0.008)],
    "radius_r": [capsule([0.0, -0.005, -0.01], [0.02, -0.01, -0.25], 0.008)],
}

if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    for name, parts in BONES.items():
        mesh = trimesh.util.concatenate(parts)
        (OUT / f"{name}.ply").write_bytes(trimesh.exchange.ply.export_ply(mesh, encoding="binary", include_attributes=False))
        print(name, len(mesh.vertices))
