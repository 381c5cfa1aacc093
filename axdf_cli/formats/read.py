"""Reading PLY and OBJ meshes back, in the file's own vertex order.

One reader for every consumer (``axdf compare``, ``axdf render RUN_DIR``, bone meshes):
PLY binary little/big endian or ascii, any vertex properties (x y z required, nx ny nz
used), ``list`` faces of any polygon size; OBJ ``v``/``vn``/``f`` lines (trimesh's loader
may merge or split vertices by normals, so it is not used here). Malformed files raise
:class:`MeshReadError` with what is wrong.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

import numpy as np


class MeshReadError(ValueError):
    """A file cannot be read as the mesh format its name says."""


@dataclass(frozen=True)
class Mesh:
    vertices: np.ndarray  # (V, 3) float64
    normals: np.ndarray | None  # (V, 3) float64 per-vertex normals, or None
    face_sizes: np.ndarray  # (M,) int64 vertices per face
    face_indices: np.ndarray  # (sum(face_sizes),) int64 zero-based vertex indices

    def __post_init__(self):
        v = self.vertices
        if v.ndim != 2 or v.shape[1] != 3:
            raise MeshReadError(f"vertices have shape {v.shape}, expected (V, 3)")
        if self.normals is not None and self.normals.shape != v.shape:
            raise MeshReadError(f"{len(self.normals)} normals for {len(v)} vertices")
        if int(self.face_sizes.sum()) != len(self.face_indices):
            raise MeshReadError("face sizes and indices disagree")
        if len(self.face_indices) and (self.face_indices.min() < 0 or self.face_indices.max() >= len(v)):
            raise MeshReadError(f"a face index is outside 0..{len(v) - 1}")


# ----------------------------------------------------------------------------- PLY
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply(data: bytes) -> Mesh:
    """Read a PLY (binary little/big endian or ascii) with a ``vertex`` element (x y z,
    optional nx ny nz) and an optional ``face`` element (``list <count> <index>``)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshReadError("not a PLY file (no 'ply' magic or no end_header)")
    nl = data.find(b"\n", end)
    if nl < 0:
        raise MeshReadError("PLY header is not terminated")
    body = memoryview(data)[nl + 1:]
    fmt = None
    elements: list[tuple[str, int, list]] = []  # (name, count, [(prop, type) | (prop, (count_t, item_t))])
    for line in data[:end].decode("ascii", "replace").splitlines():
        tok = line.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        try:
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                elements.append((tok[1], int(tok[2]), []))
            elif tok[0] == "property" and tok[1] == "list":
                elements[-1][2].append((tok[4], (_PLY_TYPES[tok[2]], _PLY_TYPES[tok[3]])))
            elif tok[0] == "property":
                elements[-1][2].append((tok[2], _PLY_TYPES[tok[1]]))
        except (IndexError, KeyError, ValueError):
            raise MeshReadError(f"bad PLY header line {line!r}") from None
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise MeshReadError(f"PLY format {fmt!r} is not binary_little_endian, binary_big_endian or ascii")
    if fmt == "ascii":
        return _ply_ascii(bytes(body).decode("ascii", "replace"), elements)
    order = "<" if fmt == "binary_little_endian" else ">"
    arrays: dict[str, dict] = {}
    pos = 0
    for name, count, props in elements:
        if all(not isinstance(t, tuple) for _, t in props):
            dt = np.dtype([(p, order + t) for p, t in props])
            need = dt.itemsize * count
            if pos + need > len(body):
                raise MeshReadError(f"PLY file ends inside element {name!r}")
            rec = np.frombuffer(body, dt, count, pos)
            pos += need
            arrays[name] = {p: rec[p] for p, _ in props}
            continue
        if len(props) != 1:
            raise MeshReadError(f"PLY element {name!r} mixes a list with other properties")
        pname, (ct, it) = props[0]
        sizes, flat, pos = _read_list(body, pos, count, order + ct, order + it, name)
        arrays[name] = {pname: (sizes, flat)}
    v = arrays.get("vertex")
    if v is None or not all(k in v for k in "xyz"):
        raise MeshReadError("PLY has no vertex element with x, y, z")
    verts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    normals = None
    if all(k in v for k in ("nx", "ny", "nz")):
        normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float64)
    sizes, flat = _faces_of(arrays)
    return Mesh(verts, normals, sizes, flat)


def _read_list(body, pos, count, ct, it, name):
    """Read ``count`` lists; fast path when every list has the first list's length."""
    ct, it = np.dtype(ct), np.dtype(it)
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), pos
    if pos + ct.itemsize > len(body):
        raise MeshReadError(f"PLY file ends inside element {name!r}")
    k = int(np.frombuffer(body, ct, 1, pos)[0])
    dt = np.dtype([("n", ct), ("i", it, (k,))])
    if pos + dt.itemsize * count <= len(body):
        rec = np.frombuffer(body, dt, count, pos)
        if np.all(rec["n"] == k):
            return (np.full(count, k, np.int64), rec["i"].reshape(-1).astype(np.int64),
                    pos + dt.itemsize * count)
    sizes, chunks = [], []  # mixed polygon sizes: one list at a time
    for _ in range(count):
        if pos + ct.itemsize > len(body):
            raise MeshReadError(f"PLY file ends inside element {name!r}")
        n = int(np.frombuffer(body, ct, 1, pos)[0])
        pos += ct.itemsize
        if pos + n * it.itemsize > len(body):
            raise MeshReadError(f"PLY file ends inside element {name!r}")
        chunks.append(np.frombuffer(body, it, n, pos))
        pos += n * it.itemsize
        sizes.append(n)
    flat = np.concatenate(chunks).astype(np.int64) if chunks else np.zeros(0, np.int64)
    return np.asarray(sizes, np.int64), flat, pos


def _faces_of(arrays) -> tuple[np.ndarray, np.ndarray]:
    f = arrays.get("face")
    if not f:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    value = next(iter(f.values()))
    if not isinstance(value, tuple):
        raise MeshReadError("PLY face element has no vertex index list")
    return value


def _ply_ascii(text: str, elements) -> Mesh:
    lines = iter(text.splitlines())
    arrays: dict[str, dict] = {}
    try:
        for name, count, props in elements:
            rows = [next(lines).split() for _ in range(count)]
            if props and isinstance(props[0][1], tuple):
                sizes = np.array([int(r[0]) for r in rows], np.int64)
                flat = np.array([int(x) for r in rows for x in r[1:1 + int(r[0])]], np.int64)
                arrays[name] = {props[0][0]: (sizes, flat)}
            else:
                a = np.array(rows, np.float64).reshape(count, len(props))
                arrays[name] = {p: a[:, j] for j, (p, _) in enumerate(props)}
    except (StopIteration, ValueError):
        raise MeshReadError("ascii PLY body is short or not numeric") from None
    v = arrays.get("vertex", {})
    if not all(k in v for k in "xyz"):
        raise MeshReadError("PLY has no vertex element with x, y, z")
    verts = np.stack([v["x"], v["y"], v["z"]], axis=1)
    normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1) if all(k in v for k in ("nx", "ny", "nz")) else None
    sizes, flat = _faces_of(arrays)
    return Mesh(verts, normals, sizes, flat)


# ----------------------------------------------------------------------------- OBJ
_OBJ_V = re.compile(rb"^v[ \t]+([^\n]*)", re.M)
_OBJ_VN = re.compile(rb"^vn[ \t]+([^\n]*)", re.M)
_OBJ_F = re.compile(rb"^f[ \t]+([^\n]*)", re.M)


def _parse_numbers(text: bytes, dtype, what: str) -> np.ndarray:
    """Whitespace-separated numbers -> ``(n,)`` array at C speed; any other text is MeshReadError."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns (not raises) when it stops at bad text
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            raise MeshReadError(f"an OBJ {what} line is not numeric") from None


def _obj_numbers(lines: list[bytes], what: str, dtype) -> np.ndarray:
    """The numbers of OBJ lines (without their keyword) as ``(len(lines), k)``; every line
    must have the same count k."""
    if not lines:
        return np.zeros((0, 3), dtype)
    out = _parse_numbers(b" ".join(lines), dtype, what)
    if out.size % len(lines):
        raise MeshReadError(f"OBJ {what} lines have different numbers of values")
    return out.reshape(len(lines), -1)


def read_obj(data: bytes) -> Mesh:
    """Read ``v``/``vn``/``f`` lines of an OBJ in file order. Per-vertex normals are taken
    when every face corner names the normal with its vertex's own index (``f a//a``)."""
    v = _obj_numbers(_OBJ_V.findall(data), "v", np.float64)
    if v.shape[1] < 3:
        raise MeshReadError("OBJ 'v' lines have fewer than 3 values")
    verts = v[:, :3]  # x y z (a w or a colour may follow)
    vn = _obj_numbers(_OBJ_VN.findall(data), "vn", np.float64)
    face_lines = _OBJ_F.findall(data)
    if not face_lines:
        return Mesh(verts, vn if len(vn) == len(verts) and len(vn) else None,
                    np.zeros(0, np.int64), np.zeros(0, np.int64))
    sizes = np.array([len(line.split()) for line in face_lines], np.int64)
    joined = b" ".join(face_lines)
    first = joined.split(None, 1)[0]
    # every corner written alike: a | a/t | a//n | a/t/n -> (vertex, texture, normal) columns
    if b"//" in first:
        text, cols = joined.replace(b"//", b" "), ("v", "n")
    else:
        cols = ("v", "t", "n")[: first.count(b"/") + 1]
        text = joined.replace(b"/", b" ")
    n_corners = int(sizes.sum())
    idx = _parse_numbers(text, np.int64, "f")
    if idx.size != n_corners * len(cols):
        raise MeshReadError("OBJ face corners are not all written alike (a, a/t, a//n or a/t/n)")
    idx = idx.reshape(n_corners, len(cols))
    flat = idx[:, 0]
    flat = np.where(flat < 0, flat + len(verts), flat - 1)  # 1-based; negative is relative
    normals = None
    if "n" in cols and len(vn) == len(verts):
        ni = idx[:, cols.index("n")]
        ni = np.where(ni < 0, ni + len(vn), ni - 1)
        if np.array_equal(ni, flat):
            normals = vn[:, :3]
    return Mesh(verts, normals, sizes, flat)


READERS = {".ply": read_ply, ".obj": read_obj}


def read_mesh(data: bytes, suffix: str) -> Mesh:
    """Read mesh bytes by file suffix (``.ply`` or ``.obj``)."""
    try:
        reader = READERS[suffix.lower()]
    except KeyError:
        raise MeshReadError(f"unknown mesh format {suffix!r}; .ply or .obj") from None
    return reader(data)


def triangles(mesh: Mesh) -> np.ndarray:
    """The faces as (T, 3) int32; raises MeshReadError unless every face is a triangle."""
    if len(mesh.face_sizes) and not np.all(mesh.face_sizes == 3):
        raise MeshReadError("faces are not all triangles")
    return mesh.face_indices.reshape(-1, 3).astype(np.int32)
