"""Mesh formats: one module per format holding its writer and its reader side by side,
registered in one table, :data:`FORMATS` (as meshio and trimesh do). An entry carries every
capability of its format (:class:`Format`): layout, the run folder's folder for it, what it
holds (faces, normals, which frames), its preference when a run is read back, and what the
machine needs to write it. A new format is one module and one entry.

Every consumer goes through the table: ``axdf run --format`` (the writers, the checks before
the first byte, the point caches' rest meshes), ``axdf compare``, ``axdf render RUN_DIR``
(the readers, by suffix and read order), bone meshes, the data set's ``format:`` and the
tests (parametrized over the table).

A format is laid out per frame or per sequence (:attr:`Format.layout`):

- ``"frame"``: one file per muscle per frame (``meshes/<m>/<m>_<frame:04d>.<suffix>``), as
  PLY and OBJ; or, with ``--mesh-files frame`` (:data:`MESH_FILES`), one file per frame
  holding every muscle (``meshes/<frame:04d>.<suffix>``, :attr:`Format.frame_writer`). The
  writer is built once per muscle from its fixed faces ``(T, 3) int32`` (``writer(faces,
  name)``) and writes one frame: ``.encode(positions (V, 3), normals (V, 3)) -> bytes`` and
  ``.write(path, positions, normals, sha256=False)``. The reader turns one file's bytes into
  one :class:`Mesh`.
- ``"sequence"``: one file per muscle holding every frame (USD, PC2, MDD, NPZ: packed
  formats, :mod:`axdf_cli.formats.packed`). The writer streams:
  ``writer(path, SequenceInfo(frames, fps, name, color), faces, n_vertices)``, then
  ``.append(positions (C, V, 3), normals (C, V, 3))`` chunk by chunk in frame order, then
  ``.finish() -> sha256`` (whole or absent). The reader takes the file's path (a long
  sequence is memory-mapped or read a frame at a time, never whole) and returns a
  :class:`~axdf_cli.formats.packed.PointSequence`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from axdf_cli.formats.mesh import Mesh, MeshReadError
from axdf_cli.formats.npz import NpzWriter, read_npz, verify_npz
from axdf_cli.formats.obj import ObjFrameWriter, ObjWriter, read_obj
from axdf_cli.formats.pc2 import MddWriter, Pc2Writer, check_frames, read_mdd, read_pc2, verify_mdd, verify_pc2
from axdf_cli.formats.ply import PlyFrameWriter, PlyWriter, read_ply
from axdf_cli.formats.usd import UsdWriter, pxr, read_usd, verify_usd

LAYOUTS = ("frame", "sequence")
#: How a per-frame format's files are cut (a job's ``mesh_files:``, ``--mesh-files``):
#: ``muscle`` (the default), one file per muscle per frame; ``frame``, one file per frame
#: holding every muscle as a named part (:attr:`Format.frame_writer`).
MESH_FILES = ("muscle", "frame")
FRAME_SETS = ("any", "even")  # which frames a format holds: any, or evenly spaced (one start, one step)


@dataclass(frozen=True)
class Format:
    name: str  # the --format value
    suffix: str  # the file suffix, with its dot
    writer: type  # see the module doc for the per-frame and per-sequence interfaces
    reader: Callable  # file bytes -> Mesh ("frame"); file path [, fps if timed] -> PointSequence ("sequence")
    layout: str = "frame"  # one of LAYOUTS
    folder: str = "meshes"  # in a run: meshes/<m>/<m>_<frame:04d><suffix> ("frame"), <folder>/<m><suffix> ("sequence")
    faces: bool = True  # holds the faces; False: a point cache, the run writes a rest mesh <folder>/<m>.ply beside it
    normals: bool = True  # holds per-vertex normals
    decimals: int | None = None  # positions and normals rounded to this many decimals (text); None: float32 exactly
    frames: str = "any"  # one of FRAME_SETS
    read_order: int = 0  # reading a run back, the per-sequence format it wrote with the lowest is read (fastest)
    timed: bool = False  # stores times, not frame numbers: its reader takes the fps (MDD)
    check: Callable | None = None  # () -> None, raises EnvironmentProblem (exit 3, with the install hint)
    #                                when this machine cannot write the format
    verify: Callable | None = None  # ("sequence") file path -> None: the file's own checks (checksums, frame
    #                                  times), MeshReadError naming the first problem (axdf compare)
    frame_writer: type | None = None  # ("frame") one file per frame holding every muscle (--mesh-files frame):
    #                                   writer([(name, faces, n_vertices)]), .encode(positions, normals) with
    #                                   one (V_m, 3) array per muscle; its reader gives Mesh.groups


FORMATS: dict[str, Format] = {
    "ply": Format("ply", ".ply", PlyWriter, read_ply, frame_writer=PlyFrameWriter),
    "obj": Format("obj", ".obj", ObjWriter, read_obj, decimals=6, frame_writer=ObjFrameWriter),
    # (+ the run's stage scene.usda and usd/bones.usdc)
    "usd": Format("usd", ".usdc", UsdWriter, read_usd, "sequence", folder="usd", read_order=3, check=pxr,
                  verify=verify_usd),
    "pc2": Format("pc2", ".pc2", Pc2Writer, read_pc2, "sequence", folder="pc2", faces=False, normals=False,
                  frames="even", read_order=1, verify=verify_pc2),
    "mdd": Format("mdd", ".mdd", MddWriter, read_mdd, "sequence", folder="mdd", faces=False, normals=False,
                  frames="even", read_order=2, timed=True, verify=verify_mdd),
    "npz": Format("npz", ".npz", NpzWriter, read_npz, "sequence", folder="npz", read_order=0, verify=verify_npz),
}
assert all(f.layout in LAYOUTS and f.frames in FRAME_SETS and f.suffix == "." + f.writer.extension
           and (f.layout == "sequence" or (f.folder == "meshes" and f.faces)) for f in FORMATS.values())
assert len({f.folder for f in FORMATS.values() if f.layout == "sequence"}) == len(
    [f for f in FORMATS.values() if f.layout == "sequence"])  # one folder each

# The per-frame formats and their writer classes: a view of FORMATS, for the call sites that
# only build per-frame writers (the per-sequence ones: axdf_cli.pipeline.packed).
WRITERS = {name: f.writer for name, f in FORMATS.items() if f.layout == "frame"}


def of_layout(layout: str, formats=None) -> list[str]:
    """The names (of ``formats``, default the table's, in that order) laid out per ``layout``."""
    return [n for n in (FORMATS if formats is None else formats) if FORMATS[n].layout == layout]


def read_preference(formats) -> list[str]:
    """The per-sequence ``formats`` in the order a run is read back from them (fastest first)."""
    return sorted(of_layout("sequence", formats), key=lambda n: FORMATS[n].read_order)


def frames_problem(formats, frames) -> tuple[list[str], str | None]:
    """The ``formats`` that cannot hold ``frames``, and why (None: all can)."""
    even = [n for n in formats if FORMATS[n].frames == "even"]
    why = check_frames(frames) if even else None
    return (even, why) if why else ([], None)


FORMAT_ALIASES = {"usdc": "usd"}  # --format usdc: the USD layers are usdc, the stage is the format


def format_names() -> tuple[str, ...]:
    """Every ``--format`` value: the table's names, then the aliases."""
    return tuple(FORMATS) + tuple(FORMAT_ALIASES)


def parse_mesh_files(value, mark) -> str:
    """A job's ``mesh_files:`` or ``--mesh-files`` value -> one of :data:`MESH_FILES`;
    anything else is an InputError at ``mark`` listing them."""
    from axdf_cli.errors import InputError

    if not isinstance(value, str) or value.strip().lower() not in MESH_FILES:
        raise InputError(mark, f"mesh_files is {value!r}",
                         "muscle (a file per muscle per frame) or frame (a file per frame with every muscle)")
    return value.strip().lower()


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


def read_sequence(path: Path | str, fps: float | None = None):
    """A per-sequence file -> :class:`~axdf_cli.formats.packed.PointSequence` by its suffix.
    ``fps``: a format that stores times (MDD) gives frame numbers time x fps; without it, the
    frame indices 0, 1, ..."""
    f = format_of(Path(path).suffix, "sequence")
    return f.reader(path, fps) if f.timed else f.reader(path)


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


__all__ = ["FORMATS", "FRAME_SETS", "Format", "LAYOUTS", "MESH_FILES", "parse_mesh_files",
           "WRITERS", "Mesh", "MeshReadError", "PlyWriter", "ObjWriter",
           "format_of", "format_names", "frames_problem", "of_layout", "parse_formats", "read_mesh",
           "read_preference", "read_sequence", "read_triangles",
           "load_triangles", "load_triangles_and_bytes"]
