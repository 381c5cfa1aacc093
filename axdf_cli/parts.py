"""One frame of named parts: what a run's stages make and its sinks consume.

A run's meshes are parts, each with a name and a kind. The muscles are parts of kind
``muscle`` (one per muscle, made by the model); the bones are parts of kind ``bone`` (rigid,
carried by the skeleton); a stage may add parts of its own kind (the skin stage: one part
of kind ``skin``; a tendon or fat layer: its own). A stage declares the parts it makes
(:class:`Part`: the topology, the rest mesh, the colour) before a run starts, and each
chunk carries their frames (:class:`PartFrames`) by name. Every sink (mesh files, packed
sequences, USD, rendering, data sets, compare) takes the declared parts in order and writes
each the same way; what differs by kind (a skin drawn see-through) is looked up by kind,
never by a part's name.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np


class Kind(str, Enum):
    """What a part is (:class:`Part`)."""

    MUSCLE = "muscle"
    BONE = "bone"
    SKIN = "skin"
    TENDON = "tendon"
    FAT = "fat"


#: The colour of a part of each kind that is not a muscle's (linear RGB in [0, 1]): the skin's
#: is sRGB #e0ac96, a light skin tone; a tendon's a pale straw; fat a pale yellow.
COLORS = {Kind.SKIN: (0.745, 0.413, 0.305), Kind.TENDON: (0.80, 0.75, 0.60), Kind.FAT: (0.90, 0.80, 0.45)}


@dataclass(frozen=True)
class Part:
    """A mesh a stage adds to every frame of a run: its name (the folder and file stem of its
    meshes, ``meshes/<name>/<name>_<frame>.<ext>``: unique among the run's muscles and
    parts), its kind, its triangles (T, 3) int (counter-clockwise seen from outside), its rest
    vertices and normals (V, 3) float64, and its colour (linear RGB in [0, 1])."""

    name: str
    kind: Kind
    faces: np.ndarray = field(repr=False)
    rest_vertices: np.ndarray = field(repr=False)
    rest_normals: np.ndarray = field(repr=False)
    color: tuple[float, float, float]

    @property
    def n_vertices(self) -> int:
        return int(len(self.rest_vertices))


@dataclass
class PartFrames:
    """A part over a chunk's frames: positions and normals, (C, V, 3) float32 each."""

    positions: np.ndarray
    normals: np.ndarray


@dataclass(frozen=True)
class Table:
    """A table a stage adds to the run folder (a row per output frame): its file name and its
    numeric columns; a chunk carries its rows ``(C, len(columns))`` float64 by file name."""

    file: str
    columns: tuple[str, ...]

    def encode(self, frames, rows: np.ndarray) -> bytes:
        """The CSV: a header, then a row per frame, numbers to 9 significant digits (-0 written 0)."""
        fmt = "%d" + ",%.9g" * len(self.columns) + "\n"
        out = [",".join(("frame",) + tuple(self.columns)) + "\n"]
        out += [fmt % (f, *r) for f, r in zip(np.asarray(frames).tolist(), (np.asarray(rows) + 0.0).tolist())]
        return "".join(out).encode()


def of_kind(parts, kind: Kind) -> tuple:
    """The parts of ``parts`` of one kind, in order."""
    return tuple(p for p in parts if Kind(p.kind) is kind)
