"""Wavefront OBJ: ``v``, ``vn`` and ``f a//a b//b c//c`` lines (1-based), one object per file.

Coordinates are written with 6 decimals (micrometres), enough for metres-scale muscles. The
face block is formatted once per muscle; per frame only the vertex lines are.
"""
from __future__ import annotations

import numpy as np


class ObjWriter:
    extension = "obj"

    def __init__(self, faces: np.ndarray, name: str = ""):
        f = np.asarray(faces, dtype=np.int64) + 1
        self._faces = (("f %d//%d %d//%d %d//%d\n" * len(f)) % tuple(np.repeat(f, 2, axis=1).ravel())).encode("ascii")
        self._head = (f"o {name}\n" if name else "").encode("ascii")

    def encode(self, positions: np.ndarray, normals: np.ndarray) -> bytes:
        """positions, normals : (V, 3) → file bytes."""
        n = len(positions)
        p = np.round(np.asarray(positions, dtype=np.float64), 6) + 0.0  # +0.0: no "-0.000000"
        nn = np.round(np.asarray(normals, dtype=np.float64), 6) + 0.0
        v = ("v %.6f %.6f %.6f\n" * n) % tuple(p.ravel())
        vn = ("vn %.6f %.6f %.6f\n" * n) % tuple(nn.ravel())
        return b"".join([self._head, v.encode("ascii"), vn.encode("ascii"), self._faces])
