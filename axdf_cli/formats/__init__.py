"""Mesh formats: one module per format holding its writer and its reader side by side,
registered in one table, :data:`FORMATS` (as meshio and trimesh do).

Every consumer goes through the table: ``axdf run --format`` (the writers), ``axdf compare``,
``axdf render RUN_DIR`` and bone meshes (the readers, by file suffix).

A format is laid out per frame or per sequence (:attr:`Format.layout`):

- ``"frame"``: one file per muscle per frame (``meshes/<m>/<m>_<frame:04d>.<suffix>``), as
  PLY and OBJ. The writer is built once per muscle from its fixed faces ``(T, 3) int32``
  (``writer(faces, name)``) and writes one frame: ``.encode(positions (V, 3), normals (V, 3))
  -> bytes`` and ``.write(path, positions, normals, sha256=False)``. The reader turns one
  file's bytes into one :class:`Mesh`.
- ``"sequence"``: one file holding every frame (per muscle or per run: packed formats such as
  USD, PC2 or NPZ, not registered yet). Its writer takes the frames as a batch (``positions
  (F, V, 3)``) and its reader returns one :class:`Mesh` per frame, in frame order.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from axdf_cli.formats.mesh import Mesh, MeshReadError
from axdf_cli.formats.obj import ObjWriter, read_obj
from axdf_cli.formats.ply import PlyWriter, read_ply

LAYOUTS = ("frame", "sequence")


@dataclass(frozen=True)
class Format:
    name: str  # the --format value
    suffix: str  # the file suffix, with its dot
    writer: type  # see the module doc for the per-frame and per-sequence interfaces
    reader: Callable[[bytes], Mesh]  # file bytes -> Mesh ("frame"), or a list of Mesh ("sequence")
    layout: str = "frame"  # one of LAYOUTS


FORMATS: dict[str, Format] = {
    "ply": Format("ply", ".ply", PlyWriter, read_ply),
    "obj": Format("obj", ".obj", ObjWriter, read_obj),
}
assert all(f.layout in LAYOUTS and f.writer.extension == f.name for f in FORMATS.values())

# The --format choices and their writer classes: a view of FORMATS, for the call sites that
# only build writers.
WRITERS = {name: f.writer for name, f in FORMATS.items()}


def format_of(suffix: str) -> Format:
    """The format whose files end in ``suffix`` (``.ply``, case-insensitive); MeshReadError
    for any other suffix."""
    s = suffix.lower()
    for f in FORMATS.values():
        if f.suffix == s:
            return f
    raise MeshReadError(f"unknown mesh format {suffix!r}; " + " or ".join(f.suffix for f in FORMATS.values()))


def read_mesh(data: bytes, suffix: str) -> Mesh:
    """Mesh bytes -> :class:`Mesh` by the file's suffix (a per-frame format)."""
    return format_of(suffix).reader(data)


def read_triangles(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Triangle mesh bytes -> (V, 3) float32 positions, (V, 3) float32 normals or None,
    (T, 3) int32 faces; MeshReadError when it is unreadable or not all triangles."""
    mesh = read_mesh(data, suffix)
    nrm = None if mesh.normals is None else mesh.normals.astype(np.float32)
    return mesh.vertices.astype(np.float32), nrm, mesh.triangles()


def load_triangles(path: Path | str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """:func:`read_triangles` of the file at ``path``, read as every input file is
    (``yamlio.read_input``: regular files only, bounded); problems are InputErrors naming it."""
    from axdf_cli.errors import InputError, Mark
    from axdf_cli.yamlio import read_input

    path = Path(path)
    allowed = "a PLY or OBJ triangle mesh"
    data = read_input(path, str(path), allowed)
    try:
        return read_triangles(data, path.suffix)
    except MeshReadError as e:
        raise InputError(Mark(str(path)), f"not a readable mesh ({e})", allowed) from None


__all__ = ["FORMATS", "Format", "LAYOUTS", "WRITERS", "Mesh", "MeshReadError", "PlyWriter", "ObjWriter",
           "format_of", "read_mesh", "read_triangles", "load_triangles"]
