"""The run folder's layout: where each file of a run lives and how its manifest is written.

One module for everything that knows the layout (README "What a run writes"), shared by
``axdf run`` (:mod:`axdf_cli.run`), ``axdf render`` and reading a run back
(:mod:`axdf_cli.render.runio`)::

    manifest.json                 MANIFEST_KEYS, in that order
    meshes/<m>/<m>_<frame:04d>.<fmt>
    bones/<bone>.ply
    stats.csv, bones.csv
    frames/<frame:04d>.png|exr, camera.json
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

from axdf_cli import atomic

MANIFEST = "manifest.json"
STATS = "stats.csv"
BONES_CSV = "bones.csv"
CAMERA = "camera.json"
FRAME_EXTENSIONS = ("png", "exr")
MAX_PENDING_WRITES = 64  # files queued for the writer thread (bounds memory)

# the manifest's keys, in the one order every writer uses (unknown keys follow, sorted)
MANIFEST_KEYS = ("tool", "version", "complete", "inputs", "settings", "frames", "muscles", "bones",
                 "warnings", "files", "bounds", "gl")


def mesh_relpath(muscle: str, frame: int, fmt: str) -> str:
    return f"meshes/{muscle}/{muscle}_{frame:04d}.{fmt}"


def bone_mesh_relpath(bone: str) -> str:
    """Bone meshes are copied into the run, so that a run folder renders on its own."""
    return f"bones/{bone}.ply"


def frame_relpath(frame: int, ext: str) -> str:
    return f"frames/{frame:04d}.{ext}"


def gl_record(renderer: str, version: str) -> dict:
    """The manifest's ``gl`` entry: the GL renderer that drew the frames."""
    return {"renderer": renderer, "version": version}


def manifest_text(manifest: dict) -> str:
    ordered = {k: manifest[k] for k in MANIFEST_KEYS if k in manifest}
    ordered.update(sorted((k, v) for k, v in manifest.items() if k not in ordered))
    if isinstance(ordered.get("files"), dict):
        ordered["files"] = dict(sorted(ordered["files"].items()))
    return json.dumps(ordered, indent=1) + "\n"


def write_manifest(folder: Path, manifest: dict) -> None:
    atomic.write_text(Path(folder) / MANIFEST, manifest_text(manifest))


class OutputWriter:
    """Writes files atomically on a background thread (so writing overlaps evaluation),
    records their sha256, and skips files whose bytes already match on resume.

    :meth:`write` queues the bytes (at most MAX_PENDING_WRITES wait); :meth:`flush` waits
    for all and re-raises a failed write's error (full disk: EnvironmentProblem) in the
    caller. ``files`` lists what is on disk, in the order written."""

    def __init__(self, out: Path, previous: dict):
        from concurrent.futures import ThreadPoolExecutor

        self.out = Path(out)
        self.previous = previous
        self.files: dict[str, str] = {}
        self.skipped = 0
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="axdf-writer")
        self._pending: list = []

    def write(self, rel: str, data: bytes) -> None:
        self._pending.append(self._pool.submit(self._write_now, rel, data))
        if len(self._pending) > MAX_PENDING_WRITES:
            self._collect(len(self._pending) - MAX_PENDING_WRITES)

    def _write_now(self, rel: str, data: bytes):
        sha = hashlib.sha256(data).hexdigest()
        path = self.out / rel
        if self.previous.get(rel) == sha and path.is_file() and path.stat().st_size == len(data) \
                and atomic.sha256_file(path) == sha:
            return rel, sha, True
        atomic.write_bytes(path, data)
        return rel, sha, False

    def _collect(self, n: int) -> None:
        done, self._pending = self._pending[:n], self._pending[n:]
        for fut in done:
            rel, sha, skipped = fut.result()
            self.files[rel] = sha
            self.skipped += skipped

    def flush(self) -> None:
        self._collect(len(self._pending))

    def close(self, cancel: bool = False) -> None:
        """Stop the thread: after :meth:`flush`, or (cancel) dropping queued writes; a write
        in progress always finishes (files are whole or absent)."""
        if cancel:
            for fut in self._pending:
                fut.cancel()
            self._pending = []
        self._pool.shutdown(wait=True)
