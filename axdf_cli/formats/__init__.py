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
- ``"sequence"``: one file per muscle holding every frame (USD, PC2, MDD, NPZ: packed
  formats, :mod:`axdf_cli.formats.sequence`). The writer streams:
  ``writer(path, SequenceInfo(frames, fps, name, color), faces, n_vertices)``, then
  ``.append(positions (C, V, 3), normals (C, V, 3))`` chunk by chunk in frame order, then
  ``.finish() -> sha256`` (whole or absent). The reader takes the file's path (a long
  sequence is memory-mapped or read a frame at a time, never whole) and returns a
  :class:`~axdf_cli.formats.sequence.PointSequence`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from axdf_cli.formats.mesh import Mesh, MeshReadError
from axdf_cli.formats.npz import NpzWriter, read_npz, verify_npz
from axdf_cli.formats.obj import ObjWriter, read_obj
from axdf_cli.formats.pc2 import MddWriter, Pc2Writer, read_mdd, read_pc2, verify_mdd, verify_pc2
from axdf_cli.formats.ply import PlyWriter, read_ply
from axdf_cli.formats.usd import UsdWriter, read_usd, verify_usd

LAYOUTS = ("frame", "sequence")


@dataclass(frozen=True)
class Format:
    name: str  # the --format value
    suffix: str  # the file suffix, with its dot
    writer: type  # see the module doc for the per-frame and per-sequence interfaces
    reader: Callable  # file bytes -> Mesh ("frame"); file path -> PointSequence ("sequence")
    layout: str = "frame"  # one of LAYOUTS
    verify: Callable | None = None  # ("sequence") file path -> None: its own checks (checksums, frame
    #                                  times), MeshReadError naming the first problem


FORMATS: dict[str, Format] = {
    "ply": Format("ply", ".ply", PlyWriter, read_ply),
    "obj": Format("obj", ".obj", ObjWriter, read_obj),
    "usd": Format("usd", ".usdc", UsdWriter, read_usd, "sequence", verify_usd),  # (+ the run's stage scene.usda)
    "pc2": Format("pc2", ".pc2", Pc2Writer, read_pc2, "sequence", verify_pc2),
    "mdd": Format("mdd", ".mdd", MddWriter, read_mdd, "sequence", verify_mdd),
    "npz": Format("npz", ".npz", NpzWriter, read_npz, "sequence", verify_npz),
}
assert all(f.layout in LAYOUTS and f.suffix == "." + f.writer.extension for f in FORMATS.values())

# The per-frame formats and their writer classes: a view of FORMATS, for the call sites that
# only build per-frame writers (the per-sequence ones: axdf_cli.pipeline.sequences).
WRITERS = {name: f.writer for name, f in FORMATS.items() if f.layout == "frame"}


FORMAT_ALIASES = {"usdc": "usd"}  # --format usdc: the USD layers are usdc, the stage is the format


def format_names() -> tuple[str, ...]:
    """Every ``--format`` value: the table's names, then the aliases."""
    return tuple(FORMATS) + tuple(FORMAT_ALIASES)


def parse_formats(value, mark) -> tuple[str, ...]:
    """``ply``, ``ply,usd``, ``[ply, usd]`` or a list of such strings (a flag repeated, a job's
    ``format:``) -> ('ply', 'usd'): in the order given, each once, aliases resolved. Anything
    else is an InputError at ``mark`` listing the names."""
    from axdf_cli.errors import InputError

    allowed = "one or more of " + ", ".join(format_names()) + " (a name, a comma-separated list or a list)"
    items = value if isinstance(value, (list, tuple)) else [value]
    out: list[str] = []
    for item in items:
        if not isinstance(item, str):
            raise InputError(mark, f"format is {item!r}", allowed)
        for name in item.split(","):
            name = name.strip().lower()
            if name not in FORMATS and name not in FORMAT_ALIASES:
                raise InputError(mark, f"unknown format {name!r}", allowed)
            name = FORMAT_ALIASES.get(name, name)
            if name not in out:
                out.append(name)
    if not out:
        raise InputError(mark, "no format given", allowed)
    return tuple(out)


def format_of(suffix: str, layout: str = "frame") -> Format:
    """The format of this ``layout`` whose files end in ``suffix`` (``.ply``,
    case-insensitive); MeshReadError for any other suffix."""
    s = suffix.lower()
    for f in FORMATS.values():
        if f.suffix == s and f.layout == layout:
            return f
    raise MeshReadError(f"unknown mesh format {suffix!r}; "
                        + " or ".join(f.suffix for f in FORMATS.values() if f.layout == layout))


def read_mesh(data: bytes, suffix: str) -> Mesh:
    """Mesh bytes -> :class:`Mesh` by the file's suffix (a per-frame format)."""
    return format_of(suffix).reader(data)


def read_sequence(path: Path | str):
    """A per-sequence file -> :class:`~axdf_cli.formats.sequence.PointSequence` by its suffix."""
    return format_of(Path(path).suffix, "sequence").reader(path)


def verify_sequence(path: Path | str) -> None:
    """A per-sequence file's own checks by its suffix (:attr:`Format.verify`)."""
    f = format_of(Path(path).suffix, "sequence")
    if f.verify is not None:
        f.verify(path)


def read_triangles(data: bytes, suffix: str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Triangle mesh bytes -> (V, 3) float32 positions, (V, 3) float32 normals or None,
    (T, 3) int32 faces; MeshReadError when it is unreadable or not all triangles."""
    mesh = read_mesh(data, suffix)
    nrm = None if mesh.normals is None else mesh.normals.astype(np.float32)
    return mesh.vertices.astype(np.float32), nrm, mesh.triangles()


def load_triangles(path: Path | str) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """:func:`read_triangles` of the file at ``path``, read as every input file is
    (``yamlio.read_input``: regular files only, bounded); problems are InputErrors naming it."""
    return load_triangles_and_bytes(path)[0]


def load_triangles_and_bytes(path: Path | str) -> tuple[tuple, bytes]:
    """:func:`load_triangles` and the file's bytes, from one read."""
    from axdf_cli.errors import InputError, Mark
    from axdf_cli.fileio.yamlio import read_input

    path = Path(path)
    allowed = "a PLY or OBJ triangle mesh"
    data = read_input(path, str(path), allowed)
    try:
        return read_triangles(data, path.suffix), data
    except MeshReadError as e:
        raise InputError(Mark(str(path)), f"not a readable mesh ({e})", allowed) from None


__all__ = ["FORMATS", "Format", "LAYOUTS", "WRITERS", "Mesh", "MeshReadError", "PlyWriter", "ObjWriter",
           "format_of", "format_names", "parse_formats", "read_mesh", "read_sequence", "read_triangles",
           "load_triangles", "load_triangles_and_bytes"]
