"""What every mesh reader returns: a :class:`Mesh` in the file's own vertex order, or a
:class:`MeshReadError` saying what is wrong with the file."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class MeshReadError(ValueError):
    """A file cannot be read as the mesh format its name says."""


@dataclass(frozen=True)
class Mesh:
    """Faces are kept as polygon sizes plus a flat index array, so triangles and any other
    polygons read (and compare) alike."""

    vertices: np.ndarray  # (V, 3) float64
    normals: np.ndarray | None  # (V, 3) float64 per-vertex normals, or None
    face_sizes: np.ndarray  # (M,) int64 vertices per face
    face_indices: np.ndarray  # (sum(face_sizes),) int64 zero-based vertex indices
    # the file's named parts in vertex order, ((name, first vertex), ...): OBJ ``o`` lines, a
    # PLY's ``muscle`` vertex property (one file per frame holding every muscle); () if none
    groups: tuple = ()

    def __post_init__(self):
        v = self.vertices
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshReadError(f"vertices have shape {v.shape}, expected (V, 3)")
        if self.normals is not None and self.normals.shape != v.shape:
            raise MeshReadError(f"{len(self.normals)} normals for {len(v)} vertices")
        if len(self.face_sizes) and self.face_sizes.min() < 0:
            raise MeshReadError("a face has a negative number of corners")
        if int(self.face_sizes.sum()) != len(self.face_indices):
            raise MeshReadError("face sizes and indices disagree")
        starts = [g[1] for g in self.groups]
        if starts and (starts != sorted(starts) or starts[0] < 0 or starts[-1] > len(v)):
            raise MeshReadError(f"named parts start at vertices {starts[:8]}, not in order within 0..{len(v)}")
        if len(self.face_indices) and (self.face_indices.min() < 0 or self.face_indices.max() >= len(v)):
            out = np.flatnonzero((self.face_indices < 0) | (self.face_indices >= len(v)))
            face = np.searchsorted(np.cumsum(self.face_sizes), out, side="right")
            many = len(np.unique(face))
            raise MeshReadError(f"face {int(face[0])} (of {len(self.face_sizes)}, counted from 0) names vertex "
                                f"{int(self.face_indices[out[0]])}, but the file has {len(v)} vertices"
                                + (f" ({many} such faces)" if many > 1 else "")
                                + f"; faces naming vertices 0..{len(v) - 1}")

    def group_slices(self) -> dict[str, slice]:
        """Each named part's vertices, ``name -> slice`` (a name used twice: its first part)."""
        out: dict[str, slice] = {}
        ends = [g[1] for g in self.groups[1:]] + [len(self.vertices)]
        for (name, start), end in zip(self.groups, ends):
            out.setdefault(name, slice(start, end))
        return out

    def triangles(self) -> np.ndarray:
        """The faces as (T, 3) int32; raises MeshReadError unless every face is a triangle."""
        if len(self.face_sizes) and not np.all(self.face_sizes == 3):
            raise MeshReadError("faces are not all triangles")
        return self.face_indices.reshape(-1, 3).astype(np.int32)
