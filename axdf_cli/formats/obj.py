"""Wavefront OBJ: ``v``, ``vn`` and ``f a//a b//b c//c`` lines (1-based), one object per file.

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
from pathlib import Path

import numpy as np

from axdf_cli import atomic

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
