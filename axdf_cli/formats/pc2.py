"""Point caches: PC2 and MDD, one file per muscle holding every frame's vertex positions.

A cache holds no faces: it applies to a rest mesh with the same vertex order (the run writes
``<m>.ply`` beside each cache), e.g. Blender's Mesh Cache modifier, 3ds Max's Point Cache,
Maya and Houdini importers.

PC2 (little-endian)::

    char[12] 'POINTCACHE2\\0'  int32 version = 1  int32 numPoints
    float32 startFrame  float32 sampleRate  int32 numSamples
    numSamples x numPoints x float32 (x, y, z)

``startFrame`` is the first frame number and ``sampleRate`` the frame step between samples
(1 for every frame; 2 for ``--frames 0:48:2``), so sample k is frame startFrame + k·sampleRate:
the frames must be evenly spaced (:func:`check_frames`).

MDD (big-endian, LightWave's layout, read by Blender's Mesh Cache)::

    int32 numFrames  int32 numPoints  numFrames x float32 time (seconds: frame / fps)
    numFrames x numPoints x float32 (x, y, z)

Both are written frame after frame as the chunks arrive (the header is known up front), and
hashed as written.
"""
from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np

from axdf_cli.formats.mesh import MeshReadError
from axdf_cli.formats.packed import InOrderHash, PointSequence, SequenceWriter, check_frame_times, uniform_step

PC2_MAGIC = b"POINTCACHE2\0"
PC2_HEADER = struct.Struct("<12siiffi")  # magic, version, numPoints, startFrame, sampleRate, numSamples
MDD_HEADER = struct.Struct(">ii")  # numFrames, numPoints


def check_frames(frames) -> str | None:
    """Why a point cache cannot hold these frames (None when it can): PC2 has one start and
    one step, MDD's times are read the same way by most importers."""
    if uniform_step(frames) is None:
        return "point caches (pc2, mdd) need evenly spaced frames (one start and one step)"
    return None


class _CacheWriter(SequenceWriter):
    """Frame-major caches: a fixed header, then each frame's (V, 3) float32 in ``_dtype``."""

    _dtype = "<f4"

    def __init__(self, path, info, faces, n_vertices, sha256: bool = True):
        super().__init__(path, info, faces, n_vertices, sha256)
        why = check_frames(info.frames)
        if why:
            self.abort()
            raise ValueError(why)
        self._head = self._header()
        self._hash = InOrderHash() if sha256 else None
        self._write(self._head, 0)

    def _write(self, data, offset: int) -> None:
        self.file.pwrite(data, offset)
        if self._hash is not None:
            self._hash.update(data, offset)

    def _chunk(self, k0, positions, normals):
        self._write(positions.astype(self._dtype, copy=False), len(self._head) + k0 * self.n_vertices * 12)

    def _close(self):
        return self._hash.hexdigest() if self._hash is not None else None


class Pc2Writer(_CacheWriter):
    extension = "pc2"

    def _header(self) -> bytes:
        f = self.info.frames
        return PC2_HEADER.pack(PC2_MAGIC, 1, self.n_vertices, float(f[0]), uniform_step(f), self.n_frames)


class MddWriter(_CacheWriter):
    extension = "mdd"
    _dtype = ">f4"

    def _header(self) -> bytes:
        times = np.asarray(self.info.frames, np.float64) / self.info.fps
        return MDD_HEADER.pack(self.n_frames, self.n_vertices) + times.astype(">f4").tobytes()


def _open(path: Path | str, head_size: int) -> tuple[bytes, int]:
    """The first ``head_size`` bytes of a file and its length."""
    try:
        with open(path, "rb") as f:
            return f.read(head_size), os.fstat(f.fileno()).st_size
    except OSError as e:
        raise MeshReadError(f"cannot read {Path(path).name} ({e.strerror})") from None


def _frames_of(path, dtype: str, offset: int, n_frames: int, n_points: int) -> np.ndarray:
    """(F, V, 3) float32 memory-mapped from ``offset`` (read one frame at a time by consumers)."""
    if n_frames * n_points == 0:
        return np.zeros((n_frames, n_points, 3), np.float32)
    return np.memmap(path, dtype, "r", offset=offset, shape=(n_frames, n_points, 3))


def read_pc2(path: Path | str) -> PointSequence:
    """A PC2 file -> :class:`PointSequence` (frames startFrame + k·sampleRate; no normals or faces)."""
    head, size = _open(path, PC2_HEADER.size)
    if len(head) < PC2_HEADER.size or not head.startswith(PC2_MAGIC):
        raise MeshReadError("not a PC2 file (no 'POINTCACHE2' magic)")
    _, version, n_points, start, rate, n_samples = PC2_HEADER.unpack(head)
    if version != 1 or n_points < 0 or n_samples < 0:
        raise MeshReadError(f"PC2 header: version {version}, {n_points} points, {n_samples} samples; "
                            "version 1 and counts >= 0")
    need = PC2_HEADER.size + n_samples * n_points * 12
    if size != need:
        raise MeshReadError(f"PC2 file has {size} bytes; its header says {need}")
    frames = float(start) + float(rate) * np.arange(n_samples)
    return PointSequence(frames, _frames_of(path, "<f4", PC2_HEADER.size, n_samples, n_points), None, None)


def read_mdd(path: Path | str, fps: float | None = None) -> PointSequence:
    """An MDD file -> :class:`PointSequence`; frame numbers are time·fps when ``fps`` is
    given, else the frame indices 0, 1, ..."""
    head, size = _open(path, MDD_HEADER.size)
    if len(head) < MDD_HEADER.size:
        raise MeshReadError("MDD file is shorter than its header")
    n_frames, n_points = MDD_HEADER.unpack(head)
    if n_frames < 0 or n_points < 0:
        raise MeshReadError(f"MDD header: {n_frames} frames, {n_points} points; counts >= 0")
    start = MDD_HEADER.size + 4 * n_frames
    need = start + n_frames * n_points * 12
    if size != need:
        raise MeshReadError(f"MDD file has {size} bytes; its header says {need}")
    times = np.fromfile(path, ">f4", n_frames, offset=MDD_HEADER.size).astype(np.float64)
    frames = np.rint(times * fps) if fps else np.arange(n_frames, dtype=np.float64)
    return PointSequence(frames, _frames_of(path, ">f4", start, n_frames, n_points), None, None, fps)


def verify_pc2(path: Path | str) -> None:
    """A PC2's own checks: its header's size agrees with the file (:func:`read_pc2`), and
    startFrame and sampleRate give finite, strictly increasing frames (sampleRate > 0)."""
    seq = read_pc2(path)
    head, _ = _open(path, PC2_HEADER.size)
    _, _, _, start, rate, n = PC2_HEADER.unpack(head)
    if not (np.isfinite(start) and np.isfinite(rate) and (rate > 0 or n <= 1)):
        raise MeshReadError(f"PC2 header: startFrame {start!r}, sampleRate {rate!r}; finite, sampleRate > 0")
    check_frame_times(seq.frames, "PC2 frames")


def verify_mdd(path: Path | str) -> None:
    """An MDD's own checks: its header's size agrees with the file (:func:`read_mdd`), and its
    frame times are finite and strictly increasing."""
    seq = read_mdd(path)
    times = np.fromfile(path, ">f4", len(seq.frames), offset=MDD_HEADER.size)
    check_frame_times(times, "MDD frame times")
