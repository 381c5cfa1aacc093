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
    """Read what :class:`PlyWriter` writes: positions (V, 3) f4, normals (V, 3) f4, faces (T, 3) i4."""
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    nv = nf = 0
    for line in header:
        if line.startswith("element vertex"):
            nv = int(line.split()[-1])
        elif line.startswith("element face"):
            nf = int(line.split()[-1])
    v = np.frombuffer(data, dtype="<f4", count=nv * 6, offset=end).reshape(nv, 6)
    f = np.frombuffer(data, dtype=[("n", "u1"), ("i", "<i4", (3,))], count=nf, offset=end + nv * 24)
    return v[:, :3], v[:, 3:], f["i"].copy()
