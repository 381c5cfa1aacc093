"""The meshes ``axdf fit`` reads (axdf_cli/tools/fit.py): a closed muscle surface (STL, PLY,
OBJ) in ``--units``, carried by ``--transform`` into the skeleton's rest frame, checked and
refused by the file's name when it is not one closed, consistently wound, finite surface of a
muscle's size.

Checks, in order (each a plain ``FILE: what is wrong; what is allowed``): the file exists and
has a mesh suffix; a binary STL holds the bytes its triangle count says; every face names a
vertex of the file; the coordinates are finite; the size fits a muscle in ``--units``; the
surface is closed (watertight); every edge is walked once each way by its two triangles (a
consistently oriented surface: a mesh inside out *as a whole* is turned outwards, one with some
triangles flipped is refused); it encloses a volume; it is one closed piece once pieces under
``tol.FIT_MIN_PIECE_SHARE`` of the volume (segmentation slivers) are dropped.
"""
from __future__ import annotations

import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark

UNITS = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}
MESH_SUFFIXES = (".stl", ".ply", ".obj")
MESH_ALLOWED = "a closed (watertight) triangle surface in STL, PLY or OBJ"
TRANSFORM_ALLOWED = ("a YAML file `matrix:` of 4 rows of 4 numbers (the last row 0, 0, 0, 1): the map from the "
                     "meshes' frame, in metres after --units, into the skeleton's rest frame (docs/FIT.md)")


@dataclass
class ReadMesh:
    """A mesh as read: the surface (trimesh.Trimesh, metres, outward) and the slivers dropped."""
    mesh: object
    dropped: int = 0  # pieces dropped (each under tol.FIT_MIN_PIECE_SHARE of the volume)
    dropped_share: float = 0.0  # their share of the whole volume


def unit_scale(units: str) -> float:
    """Metres per mesh unit; an unknown unit is refused."""
    if units not in UNITS:
        raise InputError(Mark("--units"), f"unit {units!r} is unknown", "--units mm, cm or m (the meshes' unit)")
    return UNITS[units]


def unit_name(scale: float) -> str:
    """The ``--units`` word of a scale (metres per unit)."""
    return next((u for u, k in UNITS.items() if k == scale), f"{scale:g} m")


def load_transform(path: Path | str) -> np.ndarray:
    """The (4, 4) affine map of a ``--transform`` file (``matrix:``, 4 rows of 4 numbers, last
    row 0 0 0 1, its 3x3 part invertible), refused by position when it is not one."""
    from axdf_cli.fileio.yamlio import Fields, check_vector, item_marks, load_yaml

    path = Path(path)
    doc = load_yaml(path)
    f = Fields(doc, Mark(str(path), 1, 1), "transform", keys=("matrix",))
    rows = f.seq("matrix", required=True)
    if len(rows) != 4:
        raise InputError(f.vmark("matrix"), f"matrix has {len(rows)} rows", TRANSFORM_ALLOWED)
    m = np.array([check_vector(r, mk, f"matrix row {i + 1}", 4) for i, (r, mk) in
                  enumerate(zip(rows, item_marks(rows, f.vmark("matrix"))))])
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise InputError(item_marks(rows, f.vmark("matrix"))[3], f"the last row is {m[3].tolist()}", TRANSFORM_ALLOWED)
    sv = np.linalg.svd(m[:3, :3], compute_uv=False)
    if not np.isfinite(m).all() or not sv[-1] > tol.FIT_TRANSFORM_MIN_SINGULAR * max(sv[0], 1e-300):
        raise InputError(f.vmark("matrix"), "the matrix's 3x3 part is singular (it flattens the mesh)",
                         TRANSFORM_ALLOWED)
    return m


def transform_text(scale: float, rotation: np.ndarray, shift: np.ndarray, header: str) -> str:
    """A ``--transform`` file of the similarity x -> scale rotation x + shift (metres)."""
    m = np.eye(4)
    m[:3, :3] = scale * np.asarray(rotation, dtype=np.float64)
    m[:3, 3] = shift
    lines = [f"# {h}" for h in header.splitlines()] + ["matrix:"]
    lines += ["  - [" + ", ".join(repr(float(x)) for x in row) + "]" for row in m]
    return "\n".join(lines) + "\n"


def check_stl(path: Path, where: Mark) -> None:
    """A binary STL must hold 84 + 50 n bytes for the n triangles its header counts (else,
    unless it is ASCII STL text, it is refused here, before a reader guesses at it)."""
    data = path.read_bytes()
    if len(data) >= 84:
        n = struct.unpack("<I", data[80:84])[0]
        if len(data) == 84 + 50 * n:
            return
    if data.lstrip()[:5].lower() == b"solid" and b"facet" in data[:4096] and max(data[:65536], default=0) < 128:
        return  # ASCII STL
    if len(data) < 84:
        raise InputError(where, f"a binary STL of {len(data)} bytes, shorter than its 84-byte header",
                         "a binary STL (80-byte header, triangle count, 50 bytes per triangle) or ASCII STL")
    raise InputError(where, f"the binary STL's header counts {n} triangles ({84 + 50 * n} bytes) but the file has "
                     f"{len(data)} bytes (a truncated or damaged file)",
                     "a binary STL of 84 + 50 bytes per triangle, or ASCII STL")


def _load(path: Path, where: Mark):
    import trimesh

    if path.suffix.lower() == ".stl":
        check_stl(path, where)
    else:  # PLY, OBJ: axdf's own strict reader first (counts against the file, faces naming its vertices)
        from axdf_cli.fileio.yamlio import read_input
        from axdf_cli.formats import MeshReadError, read_mesh

        try:
            read_mesh(read_input(path, str(path), MESH_ALLOWED), path.suffix.lower())
        except MeshReadError as e:
            raise InputError(where, str(e), MESH_ALLOWED) from None
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds on a bad file
        raise InputError(where, f"cannot be read as a mesh ({type(e).__name__}: {e})", MESH_ALLOWED) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(where, "holds no triangles", MESH_ALLOWED)
    faces = np.asarray(mesh.faces)
    bad = np.flatnonzero(((faces < 0) | (faces >= len(mesh.vertices))).any(axis=1))
    if len(bad):
        k = int(bad[0])
        v = int(faces[k][(faces[k] < 0) | (faces[k] >= len(mesh.vertices))][0])
        raise InputError(where, f"face {k} (of {len(faces)}, counted from 0) names vertex {v}, but the file has "
                         f"{len(mesh.vertices)} vertices" + (f" ({len(bad)} such faces)" if len(bad) > 1 else ""),
                         f"faces naming vertices 0..{len(mesh.vertices) - 1}")
    return mesh


def wrong_way_edges(faces: np.ndarray) -> int:
    """How many edges of a closed surface (F, 3) both their triangles walk the same way (0 for a
    consistently oriented surface: each edge walked once each way)."""
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int((counts > 1).sum())


def _pieces(mesh, where: Mark):
    """The mesh without its slivers (pieces under tol.FIT_MIN_PIECE_SHARE of the volume), the
    number dropped and their share; a second piece above the share is refused."""
    import trimesh

    if mesh.body_count <= 1:
        return mesh, 0, 0.0
    # (trimesh's split would fill holes through networkx, which axdf does not need)
    label = trimesh.graph.connected_component_labels(mesh.face_adjacency, node_count=len(mesh.faces))
    faces = np.asarray(mesh.faces)
    parts = [faces[label == k] for k in range(int(label.max()) + 1)]
    with np.errstate(all="ignore"):  # (a flat sliver has no centre of mass)
        vols = np.array([abs(float(trimesh.Trimesh(mesh.vertices, f, process=False).volume)) for f in parts])
    share = vols / max(vols.sum(), 1e-300)
    keep = share >= tol.FIT_MIN_PIECE_SHARE
    if keep.sum() != 1:
        big = ", ".join(f"{100 * s:.1f}%" for s in sorted(share, reverse=True)[:max(int(keep.sum()), 2)])
        raise InputError(where, f"mesh is {len(parts)} separate closed pieces, {int(keep.sum())} of them at least "
                         f"{100 * tol.FIT_MIN_PIECE_SHARE:g}% of its volume ({big})",
                         "one muscle per mesh file: split the pieces into files of their own (smaller pieces are "
                         "dropped as slivers)")
    k = int(np.argmax(share))
    one = trimesh.Trimesh(mesh.vertices, parts[k], process=False)
    one.remove_unreferenced_vertices()
    return one, len(parts) - 1, float(1.0 - share[k])


def read_mesh(path: Path, scale: float, transform: np.ndarray | None = None) -> ReadMesh:
    """A closed muscle surface in metres, in the skeleton's rest frame (``transform``: (4, 4)
    applied after ``scale``), outward-facing; refused by name (the module's doc)."""
    where = Mark(str(path))
    if not path.is_file():
        raise InputError(where, "mesh file not found", MESH_ALLOWED)
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise InputError(where, f"{path.suffix or 'no suffix'} is not a mesh format axdf fit reads", MESH_ALLOWED)
    mesh = _load(path, where)
    # checked before trimesh merges vertices: it drops a NaN vertex (the mesh then reads "not
    # closed") and casts an overflowing one to int
    if not np.isfinite(mesh.vertices).all():
        raise InputError(where, "has non-finite vertex coordinates", "finite numbers only")
    size = float(np.ptp(mesh.vertices, axis=0).max()) * scale
    far = float(np.abs(mesh.vertices).max()) * scale
    if not tol.FIT_MIN_SIZE <= size <= tol.FIT_MAX_SIZE or far > tol.FIT_MAX_REACH:
        raise InputError(where, f"mesh is {size:.3g} m across, {far:.3g} m from the origin at most, read in "
                         f"{unit_name(scale)}", f"a muscle {tol.FIT_MIN_SIZE * 1000:g} mm to {tol.FIT_MAX_SIZE:g} m "
                         f"long within {tol.FIT_MAX_REACH:g} m of the skeleton's origin: check --units (mm, cm or m)")
    mesh.apply_scale(scale)
    if transform is not None:
        mesh.apply_transform(transform)
    mesh.process(validate=False)
    if not mesh.is_watertight:
        edges = np.bincount(mesh.faces_unique_edges.ravel(), minlength=len(mesh.edges_unique)) \
            if hasattr(mesh, "faces_unique_edges") else np.zeros(0)
        open_edges = int((edges == 1).sum())
        raise InputError(where, "mesh is not closed (not watertight" +
                         (f": {open_edges} edges bound one triangle" if open_edges else "") + ")", MESH_ALLOWED)
    wrong = wrong_way_edges(np.asarray(mesh.faces))
    if wrong:
        raise InputError(where, f"mesh is not consistently oriented: {wrong} of its {len(mesh.edges_unique)} edges "
                         "are walked the same way by both their triangles (some triangles are flipped)",
                         "a closed surface whose triangles all wind the same way (a mesh inside out as a whole "
                         "is turned outwards)")
    with np.errstate(all="ignore"):  # (trimesh divides by the volume for the centre of mass)
        vol = float(mesh.volume)
    box = float(np.prod(np.maximum(mesh.extents, 1e-300)))
    if not abs(vol) > tol.FIT_MIN_VOLUME_SHARE * box or not abs(vol) > tol.FIT_MIN_VOLUME:
        raise InputError(where, f"mesh encloses no volume ({abs(vol) * 1e6:.3g} cm^3)",
                         "a closed surface around a muscle's body")
    mesh, dropped, share = _pieces(mesh, where)
    if float(mesh.volume) < 0:  # inside out: face outwards
        mesh.invert()
    return ReadMesh(mesh, dropped, share)
