"""What the per-sequence (packed) formats share: the streaming writer's life cycle and the
sequence every reader returns.

A per-sequence format holds every frame of one muscle in one file (USD, PC2, MDD, NPZ). Its
writer is built once per muscle and fed the frames in order, a chunk at a time, so memory
stays bounded on any sequence length::

    w = Pc2Writer(path, SequenceInfo(frames, fps, name, color), faces, n_vertices)
    for chunk: w.append(positions (C, V, 3) float32, normals (C, V, 3) float32)
    sha256 = w.finish()        # the file appears whole (or, after w.abort(), not at all)
                               # (w.close() + w.commit() do it in two steps)

The bytes go to a temporary name (:class:`axdf_cli.fileio.atomic.StreamingFile`) until
:meth:`SequenceWriter.finish`; a killed run leaves only temporaries, which ``--resume``
removes. Readers take a path and return a :class:`PointSequence`.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.formats.mesh import Mesh, MeshReadError


@dataclass(frozen=True)
class SequenceInfo:
    """What a sequence file records besides the points."""

    frames: np.ndarray  # (F,) int frame numbers, increasing
    fps: float
    name: str = ""  # the muscle
    color: tuple = (0.7, 0.3, 0.3)  # linear RGB 0..1


@dataclass(frozen=True)
class PointSequence:
    """A muscle's frames read back from a per-sequence file, in frame order."""

    frames: np.ndarray  # (F,) float64 frame numbers
    points: np.ndarray  # (F, V, 3) float32 (an array, a memory map, or frames read on demand: points[k])
    normals: np.ndarray | None  # (F, V, 3) float32 likewise, or None when the format has none (PC2, MDD)
    faces: np.ndarray | None  # (T, 3) int32, or None when the format has none (PC2, MDD)
    fps: float | None = None

    def __post_init__(self):
        p = self.points
        if len(p.shape) != 3 or p.shape[2] != 3 or p.shape[0] != len(self.frames):
            raise MeshReadError(f"points have shape {p.shape} for {len(self.frames)} frames, expected (F, V, 3)")
        if self.normals is not None and self.normals.shape != p.shape:
            raise MeshReadError(f"normals have shape {self.normals.shape}, points {p.shape}")

    def mesh(self, k: int, faces: np.ndarray | None = None) -> Mesh:
        """Frame ``k`` (an index, not a frame number) as a :class:`Mesh`; ``faces`` (T, 3)
        stand in for a format without faces (a point cache's rest mesh)."""
        f = self.faces if self.faces is not None else faces
        f = np.zeros((0, 3), np.int64) if f is None else np.asarray(f, np.int64)
        return Mesh(np.asarray(self.points[k], np.float64),
                    None if self.normals is None else np.asarray(self.normals[k], np.float64),
                    np.full(len(f), 3, np.int64), f.reshape(-1))


class SequenceWriter:
    """The streaming life cycle over one :class:`~axdf_cli.fileio.atomic.StreamingFile`.

    Subclasses give :attr:`extension`, lay the file out in ``__init__`` (sizes are known:
    frames x vertices) and implement :meth:`_chunk` (write one chunk at frame index ``k0``)
    and :meth:`_close` (headers, trailers; returns the file's sha256 or None to have it
    read back and hashed)."""

    extension = ""

    def __init__(self, path: Path | str, info: SequenceInfo, faces: np.ndarray, n_vertices: int,
                 sha256: bool = True):
        self.path = Path(path)
        self.sha256 = sha256  # False: close() returns "" (the bench times writing without the manifest's hash)
        self.info = info
        self.faces = np.asarray(faces, np.int32).reshape(-1, 3)
        self.n_frames = len(info.frames)
        self.n_vertices = int(n_vertices)
        self.done = 0  # frames appended so far
        self.file = atomic.StreamingFile(self.path)

    def append(self, positions: np.ndarray, normals: np.ndarray) -> None:
        """The next frames: positions, normals (C, V, 3) float32, in frame order."""
        c = len(positions)
        if positions.shape != (c, self.n_vertices, 3) or normals.shape != positions.shape:
            raise ValueError(f"chunk of shape {positions.shape} / {normals.shape}; "
                             f"expected (C, {self.n_vertices}, 3) for both")
        if self.done + c > self.n_frames:
            raise ValueError(f"{self.done + c} frames appended to a sequence of {self.n_frames}")
        try:
            self._chunk(self.done, np.ascontiguousarray(positions, "<f4"), np.ascontiguousarray(normals, "<f4"))
        except BaseException:
            self.abort()
            raise
        self.done += c

    def finish(self) -> str:
        """Complete the file and rename it into place; return its sha256 hex digest."""
        sha = self.close()
        self.commit()
        return sha

    def close(self) -> str:
        """Complete the file under its temporary name; return its sha256 hex digest. Then
        :meth:`commit` (rename it into place) or :meth:`abort` (an identical file is there)."""
        if self.done != self.n_frames:
            self.abort()
            raise ValueError(f"{self.path.name}: {self.done} of {self.n_frames} frames appended")
        try:
            sha = self._close()
            return "" if not self.sha256 else sha or atomic.sha256_file(self.file.tmp)
        except BaseException:
            self.abort()
            raise

    def commit(self) -> None:
        self.file.commit()

    def abort(self) -> None:
        """Remove the temporary: the file stays absent."""
        self.file.discard()

    def _chunk(self, k0: int, positions: np.ndarray, normals: np.ndarray) -> None:
        raise NotImplementedError

    def _close(self) -> str | None:
        raise NotImplementedError


class InOrderHash:
    """sha256 of a file whose bytes are written in order (header first, then each chunk):
    hashed as they are written, so the file need not be read back."""

    def __init__(self):
        self.h = hashlib.sha256()
        self.n = 0

    def update(self, data, offset: int) -> None:
        if offset != self.n:
            raise ValueError(f"bytes at {offset} hashed after {self.n}: out of order")
        view = memoryview(data).cast("B")
        self.h.update(view)
        self.n += len(view)

    def hexdigest(self) -> str:
        return self.h.hexdigest()


def uniform_step(frames) -> float | None:
    """The spacing of evenly spaced frame numbers (1 for a single frame), None otherwise."""
    f = np.asarray(frames, np.float64)
    if len(f) < 2:
        return 1.0
    d = np.diff(f)
    return float(d[0]) if np.all(d == d[0]) and d[0] > 0 else None


def check_frame_times(times, what: str = "frame numbers") -> None:
    """A packed file's frame numbers (or times) are finite and strictly increasing, as every
    reader of a sequence assumes; MeshReadError naming the first that is not."""
    t = np.asarray(times, np.float64).reshape(-1)
    bad = np.flatnonzero(~np.isfinite(t))
    if len(bad):
        raise MeshReadError(f"{what}: entry {int(bad[0])} is {t[bad[0]]!r}; finite numbers")
    if len(t) > 1:
        back = np.flatnonzero(np.diff(t) <= 0)
        if len(back):
            k = int(back[0]) + 1
            raise MeshReadError(f"{what}: entry {k} ({t[k]:g}) does not follow entry {k - 1} ({t[k - 1]:g}); "
                                "strictly increasing")
