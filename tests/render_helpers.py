"""Shared helpers for the render tests: a synthetic run folder on disk, EXR reading."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from axdf_cli.render.synthetic import synthetic_scene


def write_ply(path: Path, pos: np.ndarray, nrm: np.ndarray | None, faces: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    props = ["x", "y", "z"] + (["nx", "ny", "nz"] if nrm is not None else [])
    head = ["ply", "format binary_little_endian 1.0", f"element vertex {len(pos)}"]
    head += [f"property float {p}" for p in props]
    head += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header", ""]
    v = pos if nrm is None else np.concatenate([pos, nrm], 1)
    f = np.zeros(len(faces), dtype=[("n", "u1"), ("i", "<i4", 3)])
    f["n"] = 3
    f["i"] = faces
    path.write_bytes("\n".join(head).encode() + v.astype("<f4").tobytes() + f.tobytes())


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    w = np.sqrt(max(1.0 + np.trace(R), 1e-12)) / 2
    return np.array([w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)])


def write_run(run_dir: Path, n_muscles=3, verts=300, n_frames=3, render=None):
    """A run folder like `axdf run` writes; returns (scene, chunks) it was made from."""
    scene, chunks = synthetic_scene(n_muscles, verts, n_frames)
    for m_i, m in enumerate(scene.muscles):
        for ch in chunks:
            f = int(ch.frames[0])
            write_ply(run_dir / "meshes" / m.name / f"{m.name}_{f:04d}.ply",
                      ch.positions[m_i][0], ch.normals[m_i][0], m.faces)
    b = scene.bones[0]
    write_ply(run_dir / "bones" / "bone.ply", b.vertices, None, b.faces)
    rows = ["frame,bone,x,y,z,qw,qx,qy,qz"]
    for ch in chunks:
        M = ch.bone_world[0, 0]
        q = matrix_to_quat(M[:3, :3])
        rows.append(",".join([str(int(ch.frames[0])), "bone"] + [repr(float(x)) for x in (*M[:3, 3], *q)]))
    (run_dir / "bones.csv").write_text("\n".join(rows) + "\n")
    manifest = {"tool": "axdf", "version": "test", "complete": True,
                "settings": {"format": "ply", "render": render},
                "muscles": [{"name": m.name, "color": list(m.color)} for m in scene.muscles],
                "frames": list(scene.frames), "bones": [{"name": "bone", "mesh": "bones/bone.ply"}], "files": {}}
    (run_dir / "manifest.json").write_text(json.dumps(manifest))
    return scene, chunks


def read_exr(path: Path) -> dict:
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {name: np.array(c.pixels) for name, c in f.channels().items()}
