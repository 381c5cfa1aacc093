"""NPZ: one numpy archive per muscle, for ``np.load``.

Entries (``.npy``, stored uncompressed, in this order)::

    frames   (F,) int64       the frame numbers
    fps      () float64
    faces    (T, 3) int32     once: the same topology every frame
    points   (F, V, 3) float32
    normals  (F, V, 3) float32

``np.savez`` stamps each entry with the current time, so the zip is written here: stored
entries at offsets fixed up front (every size is known from F, V and T), the points and
normals of each chunk written in place as they arrive (two regions of one file, each with a
running CRC-32, computed by zlib-ng: zlib's own costs as much as writing the bytes), the
local headers, central directory and end record last, every date the zip epoch 1980-01-01
00:00 (same inputs, same bytes). ZIP64 records are used for any size or
offset past 4 GiB (APPNOTE 6.3.x, 4.5.3), as zipfile reads them.
"""
from __future__ import annotations

import io
import struct
from pathlib import Path

import numpy as np
from zlib_ng.zlib_ng import crc32  # zlib's CRC-32, ~5x faster (folding with carry-less multiply)

from axdf_cli.formats.mesh import MeshReadError
from axdf_cli.formats.packed import PointSequence, SequenceWriter, check_frame_times

ENTRIES = ("frames", "fps", "faces", "points", "normals")
ZIP32_MAX = 0xFFFFFFFF  # sizes and offsets at or past this need ZIP64 records
_FULL = 0xFFFFFFFF  # a 32-bit field whose value is in the ZIP64 record
DOS_DATE = (0 << 9) | (1 << 5) | 1  # 1980-01-01
DOS_TIME = 0  # 00:00:00
_LOCAL = struct.Struct("<IHHHHHIIIHH")  # signature .. extra length (30 bytes)
_CENTRAL = struct.Struct("<IHHHHHHIIIHHHHHII")  # 46 bytes
_END = struct.Struct("<IHHHHIIH")  # 22 bytes
_END64 = struct.Struct("<IQHHIIQQQQ")  # 56 bytes
_LOCATOR = struct.Struct("<IIQI")  # 20 bytes


def npy_header(dtype: str, shape: tuple) -> bytes:
    """The ``.npy`` header (format 1.0) numpy writes for an array of this dtype and shape."""
    from numpy.lib import format as npformat

    buf = io.BytesIO()
    npformat.write_array_header_1_0(buf, {"descr": np.dtype(dtype).str, "fortran_order": False,
                                          "shape": tuple(int(n) for n in shape)})
    return buf.getvalue()


class _Entry:
    """One stored zip entry: where it sits and its running CRC-32."""

    def __init__(self, name: str, size: int, offset: int):
        self.name = (name + ".npy").encode("ascii")
        self.size = size  # uncompressed = compressed (stored)
        self.offset = offset  # of its local header
        self.zip64 = size >= ZIP32_MAX
        self.crc = 0

    @property
    def local_size(self) -> int:
        return _LOCAL.size + len(self.name) + (20 if self.zip64 else 0)

    @property
    def data_offset(self) -> int:
        return self.offset + self.local_size

    def local_header(self) -> bytes:
        size32 = _FULL if self.zip64 else self.size
        extra = struct.pack("<HHQQ", 1, 16, self.size, self.size) if self.zip64 else b""
        return _LOCAL.pack(0x04034B50, 45 if self.zip64 else 20, 0, 0, DOS_TIME, DOS_DATE, self.crc,
                           size32, size32, len(self.name), len(extra)) + self.name + extra

    def central_header(self) -> bytes:
        fields = []  # ZIP64 extra: the overflowing values in APPNOTE order
        size32 = self.size
        if self.zip64:
            size32 = _FULL
            fields += [self.size, self.size]
        off32 = self.offset
        if self.offset >= ZIP32_MAX:
            off32 = _FULL
            fields.append(self.offset)
        extra = struct.pack(f"<HH{len(fields)}Q", 1, 8 * len(fields), *fields) if fields else b""
        version = 45 if fields else 20
        return _CENTRAL.pack(0x02014B50, version, version, 0, 0, DOS_TIME, DOS_DATE, self.crc, size32, size32,
                             len(self.name), len(extra), 0, 0, 0, 0, off32) + self.name + extra


def end_records(n_entries: int, cd_offset: int, cd_size: int) -> bytes:
    """End of central directory (with the ZIP64 end record and locator when needed)."""
    out = b""
    if cd_offset >= ZIP32_MAX or cd_size >= ZIP32_MAX or n_entries >= 0xFFFF:
        end64 = cd_offset + cd_size
        out += _END64.pack(0x06064B50, _END64.size - 12, 45, 45, 0, 0, n_entries, n_entries, cd_size, cd_offset)
        out += _LOCATOR.pack(0x07064B50, 0, end64, 1)
        return out + _END.pack(0x06054B50, 0, 0, 0xFFFF, 0xFFFF, _FULL, _FULL, 0)
    return out + _END.pack(0x06054B50, 0, 0, n_entries, n_entries, cd_size, cd_offset, 0)


class NpzWriter(SequenceWriter):
    extension = "npz"

    def __init__(self, path, info, faces, n_vertices, sha256: bool = True):
        super().__init__(path, info, faces, n_vertices, sha256)
        F, V = self.n_frames, self.n_vertices
        small = {"frames": np.asarray(info.frames, "<i8"), "fps": np.asarray(float(info.fps), "<f8"),
                 "faces": self.faces.astype("<i4")}
        self._heads = {k: npy_header(a.dtype.str, a.shape) for k, a in small.items()}
        self._heads["points"] = self._heads["normals"] = npy_header("<f4", (F, V, 3))
        payload = {k: self._heads[k] + a.tobytes() for k, a in small.items()}
        self._entries: dict[str, _Entry] = {}
        offset = 0
        for k in ENTRIES:
            size = len(payload[k]) if k in payload else len(self._heads[k]) + F * V * 12
            e = self._entries[k] = _Entry(k, size, offset)
            offset = e.data_offset + size
        self._end = offset
        for k, data in payload.items():
            e = self._entries[k]
            e.crc = crc32(data)
            self.file.pwrite(data, e.data_offset)
        for k in ("points", "normals"):
            e = self._entries[k]
            e.crc = crc32(self._heads[k])
            self.file.pwrite(self._heads[k], e.data_offset)

    def _chunk(self, k0, positions, normals):
        at = k0 * self.n_vertices * 12
        for k, a in (("points", positions), ("normals", normals)):
            e = self._entries[k]
            self.file.pwrite(a, e.data_offset + len(self._heads[k]) + at)
            e.crc = crc32(a, e.crc)  # chunks arrive in frame order: the running CRC is the entry's

    def _close(self):
        central = b""
        for e in self._entries.values():
            self.file.pwrite(e.local_header(), e.offset)
            central += e.central_header()
        self.file.pwrite(central + end_records(len(self._entries), self._end, len(central)), self._end)
        return None  # bytes were written out of order: hash the file


def read_npz(path: Path | str) -> PointSequence:
    """An axdf NPZ -> :class:`PointSequence`; stored (uncompressed) points and normals are
    memory-mapped, so a long sequence is read a frame at a time."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            missing = [k for k in ENTRIES if k + ".npy" not in names]
            if missing:
                raise MeshReadError(f"NPZ lacks {', '.join(missing)}; an axdf NPZ has {', '.join(ENTRIES)}")
            a = {k: _entry_array(path, z, k + ".npy") for k in ENTRIES}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        if isinstance(e, MeshReadError):
            raise
        raise MeshReadError(f"not a readable NPZ ({e})") from None
    faces, pts, nrm = a["faces"], a["points"], a["normals"]
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise MeshReadError(f"faces have shape {faces.shape}, expected (T, 3)")
    if pts.dtype.kind != "f" or nrm.dtype.kind != "f":
        raise MeshReadError(f"points are {pts.dtype}, normals {nrm.dtype}; float arrays")
    return PointSequence(np.asarray(a["frames"], np.float64).reshape(-1), pts, nrm, faces.astype(np.int32),
                         float(a["fps"]))


def _entry_array(path, z, name: str) -> np.ndarray:
    """One ``.npy`` entry: memory-mapped when stored uncompressed in C order, else read."""
    from numpy.lib import format as npformat

    info = z.getinfo(name)
    if info.compress_type != 0:  # deflated (np.savez_compressed): read it whole
        with z.open(info) as f:
            return npformat.read_array(f, allow_pickle=False)
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        local = f.read(_LOCAL.size)
        if len(local) != _LOCAL.size or _LOCAL.unpack(local)[0] != 0x04034B50:
            raise MeshReadError(f"NPZ entry {name}: bad local header")
        n_name, n_extra = _LOCAL.unpack(local)[-2:]
        start = info.header_offset + _LOCAL.size + n_name + n_extra  # the entry's data
        f.seek(start)
        version = npformat.read_magic(f)
        reader = npformat.read_array_header_1_0 if version == (1, 0) else npformat.read_array_header_2_0
        shape, fortran, dtype = reader(f)
        offset = f.tell()
    n = int(np.prod(shape, dtype=np.int64))
    if dtype.hasobject or fortran or offset + n * dtype.itemsize > start + info.file_size:
        raise MeshReadError(f"NPZ entry {name}: {dtype} {shape} does not fit the entry")
    if n == 0:
        return np.zeros(shape, dtype)
    return np.memmap(path, dtype, "r", offset=offset, shape=shape)


VERIFY_BLOCK = 64 << 20  # bytes hashed at a time: bounded memory on any file


def verify_npz(path: Path | str) -> None:
    """The archive's own checks: its members those axdf writes, no more; the CRC-32 of every
    member (``np.load`` checks them only for the entries it reads, memory-mapped ones never) and frame numbers finite and strictly
    increasing; MeshReadError naming the first problem."""
    import zipfile

    try:
        with zipfile.ZipFile(path) as z, open(path, "rb") as f:
            extra = sorted(set(z.namelist()) - {k + ".npy" for k in ENTRIES})
            if extra:  # an axdf NPZ holds its entries only: more is another writer's file, or a changed one
                raise MeshReadError(f"NPZ member {extra[0]} is not one axdf writes (an axdf NPZ holds "
                                    f"{', '.join(k + '.npy' for k in ENTRIES)})")
            for info in z.infolist():
                if info.compress_type != 0:  # deflated: zipfile checks the CRC as it reads to the end
                    with z.open(info) as m:
                        while m.read(VERIFY_BLOCK):
                            pass
                    continue
                f.seek(info.header_offset)
                local = f.read(_LOCAL.size)
                if len(local) != _LOCAL.size or _LOCAL.unpack(local)[0] != 0x04034B50:
                    raise MeshReadError(f"NPZ member {info.filename}: bad local header")
                n_name, n_extra = _LOCAL.unpack(local)[-2:]
                f.seek(info.header_offset + _LOCAL.size + n_name + n_extra)
                crc, left = 0, info.compress_size
                while left:
                    block = f.read(min(left, VERIFY_BLOCK))
                    if not block:
                        raise MeshReadError(f"NPZ member {info.filename}: the file ends inside it")
                    crc = crc32(block, crc)
                    left -= len(block)
                if crc != info.CRC:
                    raise MeshReadError(f"NPZ member {info.filename}: CRC-32 {crc:08x}, the archive says "
                                        f"{info.CRC:08x} (the bytes were changed after writing)")
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        if isinstance(e, MeshReadError):
            raise
        raise MeshReadError(f"not a readable NPZ ({e})") from None
    check_frame_times(read_npz(path).frames, "frames")
