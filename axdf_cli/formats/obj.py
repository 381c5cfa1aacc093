"""Wavefront OBJ: the writers (``v``, ``vn`` and ``f a//a b//b c//c`` lines, 1-based: one
object per file, :class:`ObjWriter`, or every muscle of a frame as named objects,
:class:`ObjFrameWriter`) and the reader (``v``/``vn``/``f`` lines in file order, at C speed).

The reader keeps the file's vertex order (trimesh's OBJ loader may merge or split vertices by
normals, so it is not used here); ``o`` lines name parts (:attr:`Mesh.groups`, by the ``v``
lines before them); other lines (``g``, ``vt``, ``usemtl`` ...) are skipped. Malformed files
raise :class:`MeshReadError`.

Coordinates are written with 6 decimals (micrometres), enough for metres-scale muscles. The
face block is formatted once per muscle; per frame only the vertex lines are.

Speed: the vertex lines are formatted with numpy, not with ``%``: each coordinate x is the
integer k = rint(x * 1e6) (exactly what ``np.round(x, 6)`` rounds to, so ``'%.6f'`` would
print k's digits); its text is three 4-byte groups (sign and integer part, '.' and 3
decimals, 3 decimals and the separator) taken from 1000-entry uint32 tables, every line is
laid out in 40 fixed columns padded with NUL bytes, and ``bytes.translate`` drops the
padding in one pass. Coordinates of 1000 or more (or not finite) fall back to ``%``
formatting, which gives the same bytes.
"""
from __future__ import annotations

import hashlib
import re
import warnings
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.formats.mesh import Mesh, MeshReadError

_BIG = 1000  # integer parts below this use the tables; larger ones take the % path


def _table(fmt: str) -> np.ndarray:
    """(1000,) little-endian uint32: the 4 ASCII bytes of ``fmt.format(i)``, spaces as NUL."""
    raw = b"".join(fmt.format(i).encode("ascii").replace(b" ", b"\0") for i in range(1000))
    return np.frombuffer(raw, dtype="<u4").copy()


# 4-byte groups: sign slot + integer part (NUL-padded), '.' + 3 decimals, 3 decimals + separator
_INT4 = _table(" {:>3d}")
_DOT4 = _table(".{:03d}")
_SP4 = _table("{:03d}\x01") + np.uint32((ord(" ") - 1) << 24)  # \x01: a placeholder, not NUL
_NL4 = _table("{:03d}\x01") + np.uint32((ord("\n") - 1) << 24)
_MINUS = np.uint32(ord("-"))  # added to the (NUL) sign byte, the group's lowest byte
_V = np.frombuffer(b"v \0\0", dtype="<u4")[0]
_VN = np.frombuffer(b"vn \0", dtype="<u4")[0]


def _format_percent(p: np.ndarray, nn: np.ndarray) -> bytes:
    """The reference formatting: ``'%.6f'`` of the coordinates rounded to 6 decimals."""
    n = len(p)
    p = np.round(np.asarray(p, dtype=np.float64), 6) + 0.0  # +0.0: no "-0.000000"
    nn = np.round(np.asarray(nn, dtype=np.float64), 6) + 0.0
    v = ("v %.6f %.6f %.6f\n" * n) % tuple(p.ravel())
    vn = ("vn %.6f %.6f %.6f\n" * n) % tuple(nn.ravel())
    return (v + vn).encode("ascii")


def _vertex_lines(positions: np.ndarray, normals: np.ndarray) -> bytes:
    """``v`` lines then ``vn`` lines for positions, normals (V, 3): ASCII bytes."""
    n = len(positions)
    x = np.empty((2 * n, 3), dtype=np.float64)
    x[:n] = positions
    x[n:] = normals
    # the same float operations as np.round(x, 6): multiply by 1e6, round half to even
    y = np.rint(x * 1e6)
    if not np.isfinite(y).all() or (np.abs(y).max(initial=0.0) >= _BIG * 1e6):
        return _format_percent(positions, normals)
    neg = y < 0.0  # a rounded zero prints without a sign ("-0.000000" never appears)
    a = np.abs(y).astype(np.int32)  # < 1e9: int32 division is vectorized, int64 is not
    ip = a // 1_000_000
    fp = a - ip * 1_000_000
    hi = fp // 1000
    lo = fp - hi * 1000
    # a line: prefix + 3 numbers of 3 groups each = 10 uint32 = 40 bytes, NUL-padded
    cols = np.empty((2 * n, 10), dtype="<u4")
    cols[:n, 0] = _V  # 'v ' (NUL-padded)
    cols[n:, 0] = _VN  # 'vn '
    num = cols[:, 1:].reshape(2 * n, 3, 3)  # a view
    num[..., 0] = _INT4.take(ip) + neg * _MINUS
    num[..., 1] = _DOT4.take(hi)
    num[:, :2, 2] = _SP4.take(lo[:, :2])
    num[:, 2, 2] = _NL4.take(lo[:, 2])
    return cols.tobytes().translate(None, b"\0")


class ObjWriter:
    extension = "obj"

    def __init__(self, faces: np.ndarray, name: str = ""):
        f = np.asarray(faces, dtype=np.int64) + 1
        self._faces = (("f %d//%d %d//%d %d//%d\n" * len(f)) % tuple(np.repeat(f, 2, axis=1).ravel())).encode("ascii")
        self._head = (f"o {name}\n" if name else "").encode("ascii")

    def encode(self, positions: np.ndarray, normals: np.ndarray) -> bytes:
        """positions, normals : (V, 3) → file bytes."""
        return b"".join([self._head, _vertex_lines(positions, normals), self._faces])

    def write(self, path: Path | str, positions: np.ndarray, normals: np.ndarray, sha256: bool = False) -> str | None:
        """Write one frame to ``path`` atomically (the bytes :meth:`encode` gives); return the
        file's sha256 hex digest when ``sha256`` is true, else None."""
        parts = (self._head, _vertex_lines(positions, normals), self._faces)
        atomic.write_parts(path, parts)
        if not sha256:
            return None
        h = hashlib.sha256()
        for part in parts:
            h.update(part)
        return h.hexdigest()


class ObjFrameWriter:
    """One OBJ per frame holding every muscle: per muscle an ``o <name>`` line (Blender's
    importer makes it one object; trimesh one geometry of that name), then its ``v`` and
    ``vn`` lines and its ``f a//a`` lines, indices counted over the whole file (1-based). The
    vertex and face lines are the per-muscle file's, so each object equals that muscle's
    :class:`ObjWriter` file with its indices shifted."""

    extension = "obj"

    def __init__(self, parts):
        """``parts``: ``[(name, faces (T, 3) int, vertex count)]`` in file order (the run's
        muscle order)."""
        self.names = [p[0] for p in parts]
        self._heads, self._faces, self.n_vertices = [], [], []
        offset = 0
        for name, faces, n in parts:
            f = np.asarray(faces, dtype=np.int64)
            self._heads.append(f"o {name}\n".encode("ascii"))
            self._faces.append(ObjWriter(f + offset)._faces)
            self.n_vertices.append(int(n))
            offset += int(n)

    def _parts(self, positions, normals) -> list[bytes]:
        if len(positions) != len(self.names) or len(normals) != len(self.names):
            raise ValueError(f"{len(positions)} position and {len(normals)} normal arrays for "
                             f"{len(self.names)} muscles")
        out: list[bytes] = []
        for head, p, nn, f in zip(self._heads, positions, normals, self._faces):
            out += [head, _vertex_lines(p, nn), f]
        return out

    def encode(self, positions, normals) -> bytes:
        """positions, normals : one (V_m, 3) array per muscle, in the writer's order → file bytes."""
        return b"".join(self._parts(positions, normals))

    def write(self, path: Path | str, positions, normals, sha256: bool = False) -> str | None:
        """Write one frame to ``path`` atomically (the bytes :meth:`encode` gives); return its
        sha256 hex digest when ``sha256`` is true, else None."""
        data = self.encode(positions, normals)
        atomic.write_parts(path, (data,))
        return hashlib.sha256(data).hexdigest() if sha256 else None


# ----------------------------------------------------------------------------- reading
_OBJ_V = re.compile(rb"^v[ \t]+([^\n]*)", re.M)
_OBJ_VN = re.compile(rb"^vn[ \t]+([^\n]*)", re.M)
_OBJ_F = re.compile(rb"^f[ \t]+([^\n]*)", re.M)
_OBJ_O = re.compile(rb"^o[ \t]+([^\n]*)", re.M)


def _objects(data: bytes) -> tuple:
    """``((name, first vertex), ...)`` of the ``o`` lines: the ``v`` lines before each."""
    out = []
    n, last = 0, 0
    for m in _OBJ_O.finditer(data):
        seg = b"\n" + data[last:m.start()]
        n += seg.count(b"\nv ") + seg.count(b"\nv\t")
        last = m.start()
        out.append((m.group(1).strip().decode("utf-8", "replace"), n))
    return tuple(out)


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
                    np.zeros(0, np.int64), np.zeros(0, np.int64), _objects(data))
    sizes = np.array([len(line.split()) for line in face_lines], np.int64)
    if sizes.min() == 0:
        raise MeshReadError("an OBJ 'f' line names no vertex")
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
    return Mesh(verts, normals, sizes, flat, _objects(data))
