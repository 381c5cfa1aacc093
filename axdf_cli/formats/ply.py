"""Binary little-endian PLY: float32 x y z nx ny nz per vertex, ``list uchar int`` faces.

Read back by Blender, trimesh (``process=False``) and meshio. The header holds no timestamp
or path, so identical meshes give identical bytes.
"""
from __future__ import annotations

import numpy as np


class PlyWriter:
    extension = "ply"

    def __init__(self, faces: np.ndarray, name: str = ""):
        faces = np.asarray(faces, dtype=np.int32)
        self.n_faces = len(faces)
        rec = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
        rec["n"] = 3
        rec["i"] = faces
        self._faces = rec.tobytes()
        self.name = name

    def header(self, n_vertices: int) -> bytes:
        lines = ["ply", "format binary_little_endian 1.0"]
        if self.name:
            lines.append(f"comment axdf muscle {self.name}")
        lines += [f"element vertex {n_vertices}",
                  "property float x", "property float y", "property float z",
                  "property float nx", "property float ny", "property float nz",
                  f"element face {self.n_faces}", "property list uchar int vertex_indices", "end_header", ""]
        return "\n".join(lines).encode("ascii")

    def encode(self, positions: np.ndarray, normals: np.ndarray) -> bytes:
        """positions, normals : (V, 3) → file bytes."""
        v = np.empty((len(positions), 6), dtype="<f4")
        v[:, :3] = positions
        v[:, 3:] = normals
        return b"".join([self.header(len(positions)), v.tobytes(), self._faces])


def read_ply(data: bytes):
    """Read a triangle PLY: positions (V, 3) float32, normals (V, 3) float32 or None, faces (T, 3) int32."""
    from axdf_cli.formats.read import read_ply as read_any, triangles

    mesh = read_any(data)
    nrm = None if mesh.normals is None else mesh.normals.astype(np.float32)
    return mesh.vertices.astype(np.float32), nrm, triangles(mesh)
