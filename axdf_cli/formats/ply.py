"""Binary little-endian PLY: float32 x y z nx ny nz per vertex, ``list uchar int`` faces.

Read back by Blender, trimesh (``process=False``) and meshio. The header holds no timestamp
or path, so identical meshes give identical bytes.

Speed: the whole file lives in one preallocated buffer per writer (header, interleaved
vertex block, face block formatted once); a frame only overwrites the vertex block in
place. :meth:`PlyWriter.write` hands that buffer to the file in one ``write`` call, with
no further copy; :meth:`PlyWriter.encode` copies it once into ``bytes``.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from axdf_cli import atomic


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
        self._n_vertices = -1  # vertex count the buffer is laid out for
        self._buf = bytearray()
        self._verts = np.empty((0, 6), dtype="<f4")

    def header(self, n_vertices: int) -> bytes:
        lines = ["ply", "format binary_little_endian 1.0"]
        if self.name:
            lines.append(f"comment axdf muscle {self.name}")
        lines += [f"element vertex {n_vertices}",
                  "property float x", "property float y", "property float z",
                  "property float nx", "property float ny", "property float nz",
                  f"element face {self.n_faces}", "property list uchar int vertex_indices", "end_header", ""]
        return "\n".join(lines).encode("ascii")

    def _fill(self, positions: np.ndarray, normals: np.ndarray) -> bytearray:
        """Write one frame into the file buffer (laid out on first use for this vertex count)."""
        n = len(positions)
        if len(normals) != n:
            raise ValueError(f"positions ({n}, 3) and normals ({len(normals)}, 3) differ in length")
        if n != self._n_vertices:
            head = self.header(n)
            self._buf = bytearray(len(head) + 24 * n + len(self._faces))
            self._buf[:len(head)] = head
            self._buf[len(head) + 24 * n:] = self._faces
            # (V, 6) float32 view of the vertex block: x y z nx ny nz interleaved
            self._verts = np.frombuffer(self._buf, dtype="<f4", count=6 * n, offset=len(head)).reshape(n, 6)
            self._n_vertices = n
        self._verts[:, :3] = positions
        self._verts[:, 3:] = normals
        return self._buf

    def encode(self, positions: np.ndarray, normals: np.ndarray) -> bytes:
        """positions, normals : (V, 3) → file bytes."""
        return bytes(self._fill(positions, normals))

    def write(self, path: Path | str, positions: np.ndarray, normals: np.ndarray, sha256: bool = False) -> str | None:
        """Write one frame to ``path`` atomically (the bytes :meth:`encode` gives); return the
        file's sha256 hex digest when ``sha256`` is true, else None."""
        buf = self._fill(positions, normals)
        atomic.write_parts(path, (buf,))
        return hashlib.sha256(buf).hexdigest() if sha256 else None


def read_ply(data: bytes):
    """Read a triangle PLY: positions (V, 3) float32, normals (V, 3) float32 or None, faces (T, 3) int32."""
    from axdf_cli.formats.read import read_ply as read_any, triangles

    mesh = read_any(data)
    nrm = None if mesh.normals is None else mesh.normals.astype(np.float32)
    return mesh.vertices.astype(np.float32), nrm, triangles(mesh)
