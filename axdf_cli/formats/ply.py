"""PLY: the writers (binary little-endian, float32 x y z nx ny nz per vertex, ``list uchar
int`` faces: one muscle per file, :class:`PlyWriter`, or every muscle of a frame with a
``muscle`` index per vertex, :class:`PlyFrameWriter`) and the reader (any PLY: binary
little/big endian or ascii).

What the writer writes is read back by Blender, trimesh (``process=False``) and meshio. The
header holds no timestamp or path, so identical meshes give identical bytes.

The reader keeps the file's vertex order exactly; it takes any vertex properties (x y z
required, nx ny nz used) and ``list`` faces of any polygon size. A malformed or hostile
header (negative or impossible counts, repeated properties, non-integer list types, list
lengths beyond the file) is a :class:`MeshReadError`, never a numpy error: everything the
header says is checked against the file's length before any array is made.

Without normals (``encode(positions)``: bone meshes) a vertex is x y z only.

Speed: the whole file lives in one preallocated buffer per writer (header, interleaved
vertex block, face block formatted once); a frame only overwrites the vertex block in
place. :meth:`PlyWriter.write` hands that buffer to the file in one ``write`` call, with
no further copy; :meth:`PlyWriter.encode` copies it once into ``bytes``.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.formats.mesh import Mesh, MeshReadError


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
        self._layout = (-1, 0)  # (vertex count, floats per vertex) the buffer is laid out for
        self._buf = bytearray()
        self._verts = np.empty((0, 6), dtype="<f4")

    def header(self, n_vertices: int, normals: bool = True) -> bytes:
        lines = ["ply", "format binary_little_endian 1.0"]
        if self.name:
            lines.append(f"comment axdf muscle {self.name}")
        lines += [f"element vertex {n_vertices}", "property float x", "property float y", "property float z"]
        if normals:
            lines += ["property float nx", "property float ny", "property float nz"]
        lines += [f"element face {self.n_faces}", "property list uchar int vertex_indices", "end_header", ""]
        return "\n".join(lines).encode("ascii")

    def _fill(self, positions: np.ndarray, normals: np.ndarray | None) -> bytearray:
        """Write one frame into the file buffer (laid out on first use for this vertex count)."""
        n = len(positions)
        if normals is not None and len(normals) != n:
            raise ValueError(f"positions ({n}, 3) and normals ({len(normals)}, 3) differ in length")
        k = 3 if normals is None else 6
        if (n, k) != self._layout:
            head = self.header(n, normals is not None)
            self._buf = bytearray(len(head) + 4 * k * n + len(self._faces))
            self._buf[:len(head)] = head
            self._buf[len(head) + 4 * k * n:] = self._faces
            # (V, k) float32 view of the vertex block: x y z [nx ny nz] interleaved
            self._verts = np.frombuffer(self._buf, dtype="<f4", count=k * n, offset=len(head)).reshape(n, k)
            self._layout = (n, k)
        self._verts[:, :3] = positions
        if normals is not None:
            self._verts[:, 3:] = normals
        return self._buf

    def encode(self, positions: np.ndarray, normals: np.ndarray | None = None) -> bytes:
        """positions, normals : (V, 3) → file bytes (no normals: x y z only)."""
        return bytes(self._fill(positions, normals))

    def write(self, path: Path | str, positions: np.ndarray, normals: np.ndarray, sha256: bool = False) -> str | None:
        """Write one frame to ``path`` atomically (the bytes :meth:`encode` gives); return the
        file's sha256 hex digest when ``sha256`` is true, else None."""
        buf = self._fill(positions, normals)
        atomic.write_parts(path, (buf,))
        return hashlib.sha256(buf).hexdigest() if sha256 else None


#: The vertex property of :class:`PlyFrameWriter` naming each vertex's muscle (an index into
#: the header's ``comment axdf muscle <index> <name>`` lines).
MUSCLE_PROPERTY = "muscle"


class PlyFrameWriter:
    """One PLY per frame holding every muscle: binary little-endian, per vertex float32
    ``x y z nx ny nz`` and ``ushort muscle`` (the muscle's index, 0-based, in the header's
    ``comment axdf muscle <index> <name>`` lines), muscles one after another in the run's
    order; faces as :class:`PlyWriter`'s, indices counted over the whole file. A reader
    that ignores the ``muscle`` property (Blender, meshio) gets every muscle as one mesh."""

    extension = "ply"

    def __init__(self, parts):
        """``parts``: ``[(name, faces (T, 3) int, vertex count)]`` in file order."""
        if len(parts) > 65536:
            raise ValueError(f"{len(parts)} muscles; a ushort muscle index holds at most 65536")
        self.names = [p[0] for p in parts]
        counts = np.array([int(p[2]) for p in parts], np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        faces = [np.asarray(p[1], np.int64) + offsets[k] for k, p in enumerate(parts)]
        self._writer = PlyWriter(np.concatenate(faces) if faces else np.zeros((0, 3), np.int64))
        n = int(offsets[-1])
        self._rec = np.zeros(n, dtype=[("p", "<f4", (6,)), ("m", "<u2")])
        self._rec["m"] = np.repeat(np.arange(len(parts)), counts)
        self._offsets = offsets
        lines = ["ply", "format binary_little_endian 1.0"]
        lines += [f"comment axdf muscle {k} {name}" for k, name in enumerate(self.names)]
        lines += [f"element vertex {n}"] + [f"property float {c}" for c in ("x", "y", "z", "nx", "ny", "nz")]
        lines += [f"property ushort {MUSCLE_PROPERTY}", f"element face {self._writer.n_faces}",
                  "property list uchar int vertex_indices", "end_header", ""]
        self._head = "\n".join(lines).encode("ascii")

    def encode(self, positions, normals) -> bytes:
        """positions, normals : one (V_m, 3) array per muscle, in the writer's order → file bytes."""
        if len(positions) != len(self.names) or len(normals) != len(self.names):
            raise ValueError(f"{len(positions)} position and {len(normals)} normal arrays for "
                             f"{len(self.names)} muscles")
        o = self._offsets
        for k, (p, nn) in enumerate(zip(positions, normals)):
            self._rec["p"][o[k]:o[k + 1], :3] = p
            self._rec["p"][o[k]:o[k + 1], 3:] = nn
        return b"".join([self._head, self._rec.tobytes(), self._writer._faces])

    def write(self, path: Path | str, positions, normals, sha256: bool = False) -> str | None:
        """Write one frame to ``path`` atomically (the bytes :meth:`encode` gives); return its
        sha256 hex digest when ``sha256`` is true, else None."""
        data = self.encode(positions, normals)
        atomic.write_parts(path, (data,))
        return hashlib.sha256(data).hexdigest() if sha256 else None


# ----------------------------------------------------------------------------- reading
_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_FORMATS = ("binary_little_endian", "binary_big_endian", "ascii")


def _header(text: str) -> tuple[str | None, list[tuple[str, int, list]]]:
    """The format and the elements ``(name, count, [(prop, type) | (prop, (count_t, item_t))])``."""
    fmt = None
    elements: list[tuple[str, int, list]] = []
    for line in text.splitlines():
        tok = line.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        try:
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                count = int(tok[2])
                if count < 0 or any(e[0] == tok[1] for e in elements):
                    raise ValueError
                elements.append((tok[1], count, []))
            elif tok[0] == "property":
                props = elements[-1][2]
                if tok[1] == "list":
                    name, t = tok[4], (_TYPES[tok[2]], _TYPES[tok[3]])
                    if t[0][0] not in "iu" or t[1][0] not in "iu":
                        raise ValueError  # list lengths and indices are integers
                else:
                    name, t = tok[2], _TYPES[tok[1]]
                if any(p == name for p, _ in props):
                    raise ValueError
                props.append((name, t))
        except (IndexError, KeyError, ValueError):
            raise MeshReadError(f"bad PLY header line {line[:80]!r}") from None
    return fmt, elements


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
    fmt, elements = _header(data[:end].decode("ascii", "replace"))
    if fmt not in _FORMATS:
        raise MeshReadError(f"PLY format {fmt!r} is not {', '.join(_FORMATS)}")
    for name, _, props in elements:
        if len(props) > 1 and any(isinstance(t, tuple) for _, t in props[1:]):
            raise MeshReadError(f"PLY element {name!r} has a list after its first property")
        if len(props) > 1 and isinstance(props[0][1], tuple) and fmt == "ascii":
            raise MeshReadError(f"PLY element {name!r} mixes a list with other properties")
    if fmt == "ascii":
        arrays = _ascii_body(bytes(body).decode("ascii", "replace"), elements)
    else:
        arrays = _binary_body(body, elements, "<" if fmt == "binary_little_endian" else ">")
    v = arrays.get("vertex")
    if v is None or not all(k in v for k in "xyz"):
        raise MeshReadError("PLY has no vertex element with x, y, z")
    verts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    normals = None
    if all(k in v for k in ("nx", "ny", "nz")):
        normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float64)
    groups = _muscle_groups(data[:end].decode("ascii", "replace"), v.get(MUSCLE_PROPERTY))
    f = arrays.get("face")
    if not f:
        return Mesh(verts, normals, np.zeros(0, np.int64), np.zeros(0, np.int64), groups)
    value = next(iter(f.values()))
    if not isinstance(value, tuple):
        raise MeshReadError("PLY face element has no vertex index list")
    return Mesh(verts, normals, *value, groups)


def _muscle_groups(header: str, index) -> tuple:
    """``((name, first vertex), ...)`` from a ``muscle`` vertex property (a run of equal
    indices is one part) named by ``comment axdf muscle <index> <name>`` lines (an index
    without a line is named by its number); () without the property."""
    if index is None or isinstance(index, tuple) or not len(index) or np.asarray(index).dtype.kind not in "iu":
        return ()  # (an ascii PLY's or a float property is no muscle index)
    names = {}
    for line in header.splitlines():
        tok = line.split()
        if len(tok) == 5 and tok[:3] == ["comment", "axdf", "muscle"] and tok[3].isdigit():
            names.setdefault(int(tok[3]), tok[4])
    idx = np.asarray(index)
    starts = np.flatnonzero(np.concatenate([[True], idx[1:] != idx[:-1]]))
    return tuple((names.get(int(idx[s]), str(idx[s])), int(s)) for s in starts)


def _binary_body(body: memoryview, elements, order: str) -> dict[str, dict]:
    arrays: dict[str, dict] = {}
    pos = 0
    for name, count, props in elements:
        if not any(isinstance(t, tuple) for _, t in props):
            dt = np.dtype([(p, order + t) for p, t in props])
            need = dt.itemsize * count
            if pos + need > len(body):
                raise MeshReadError(f"PLY file ends inside element {name!r}")
            rec = np.frombuffer(body, dt, count, pos)
            pos += need
            arrays[name] = {p: rec[p] for p, _ in props}
            continue
        pname, (ct, it) = props[0]
        # scalar properties after the list (trimesh's STL-derived PLYs: "property ushort stl"): skipped
        rest = np.dtype([(p, order + t) for p, t in props[1:]])
        sizes, flat, pos = _read_lists(body, pos, count, np.dtype(order + ct), np.dtype(order + it), name, rest)
        arrays[name] = {pname: (sizes, flat)}
    return arrays


def _read_lists(body: memoryview, pos: int, count: int, ct: np.dtype, it: np.dtype, name: str,
                rest: np.dtype = np.dtype([])):
    """Read ``count`` lists, each followed by the scalar properties ``rest`` (skipped) -> sizes
    ``(count,)``, flat indices, the position after them. Fast path when every list has the first
    list's length; otherwise one list at a time."""
    extra = rest.itemsize
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), pos
    short = MeshReadError(f"PLY file ends inside element {name!r}")
    if pos + count * (ct.itemsize + extra) > len(body):  # every list holds at least its length
        raise short
    k = int(np.frombuffer(body, ct, 1, pos)[0])
    if k < 0:
        raise MeshReadError(f"PLY element {name!r} has a list of length {k}")
    if pos + count * (ct.itemsize + k * it.itemsize + extra) <= len(body):
        dt = np.dtype([("n", ct), ("i", it, (k,))] + [(f"_{j}", rest[j]) for j in range(len(rest))])
        rec = np.frombuffer(body, dt, count, pos)
        if np.all(rec["n"] == k):
            return (np.full(count, k, np.int64), rec["i"].reshape(-1).astype(np.int64),
                    pos + dt.itemsize * count)
    sizes = np.empty(count, np.int64)
    chunks = []
    for j in range(count):
        if pos + ct.itemsize > len(body):
            raise short
        n = int(np.frombuffer(body, ct, 1, pos)[0])
        pos += ct.itemsize
        if n < 0:
            raise MeshReadError(f"PLY element {name!r} has a list of length {n}")
        if pos + n * it.itemsize > len(body):
            raise short
        chunks.append(np.frombuffer(body, it, n, pos))
        pos += n * it.itemsize
        if pos + extra > len(body):
            raise short
        pos += extra
        sizes[j] = n
    return sizes, np.concatenate(chunks).astype(np.int64), pos


def _ascii_body(text: str, elements) -> dict[str, dict]:
    lines = iter(text.splitlines())
    arrays: dict[str, dict] = {}
    try:
        for name, count, props in elements:
            rows = [next(lines).split() for _ in range(count)]
            if props and isinstance(props[0][1], tuple):
                sizes = np.array([int(r[0]) for r in rows], np.int64)
                flat = np.array([int(x) for r in rows for x in r[1:1 + int(r[0])]], np.int64)
                if len(sizes) and sizes.min() < 0:
                    raise MeshReadError(f"PLY element {name!r} has a list of negative length")
                arrays[name] = {props[0][0]: (sizes, flat)}
            else:
                a = np.array(rows, np.float64).reshape(count, len(props))
                arrays[name] = {p: a[:, j] for j, (p, _) in enumerate(props)}
    except MeshReadError:
        raise
    except (StopIteration, ValueError, IndexError, OverflowError):  # short, not numeric, beyond int64
        raise MeshReadError("ascii PLY body is short, not numeric, or has an index beyond int64") from None
    return arrays
