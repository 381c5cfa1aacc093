"""The packed sink: a run's per-sequence (packed) files, one per muscle and format holding
every frame (each format's folder, faces and rest mesh: its ``FORMATS`` entry).

The mesh pass evaluates all its muscles chunk by chunk; :class:`SequenceFiles` streams each
chunk of every part (the muscles, then the parts the stages add: :func:`parts_of`) into every selected
per-sequence format on its own background thread (so writing
overlaps evaluation, as the per-frame writer's thread does) and completes the files when
the pass ends. Every file is written under a temporary name and renamed when whole; its
sha256 goes into the manifest. On ``--resume`` a file is written again (a killed run leaves
only temporaries) and, when the result equals the file already there and its manifest
entry, the old one is kept and counted as skipped.

After the mesh pass, :func:`write_run_files` writes what belongs to the run rather than to
one muscle: the USD root stage (``scene.usda``) with the bones and camera, ``usd/bones.usdc``,
and the rest meshes the point caches apply to (every part's).
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.formats import FORMATS, of_layout
from axdf_cli.formats.packed import SequenceInfo
from axdf_cli.fileio.runfolder import USD_BONES, USD_STAGE, is_file_with, rest_mesh_relpath, sequence_relpath

MAX_PENDING_CHUNKS = 2  # chunks (every muscle's frames of one) queued for the sequence thread (bounds memory)
CLOSE_THREADS = 2  # files completed (headers, sha256 read back) at once at the end; USD layers one at a time


def sequence_formats(formats) -> list[str]:
    """The per-sequence formats among ``formats``, in that order."""
    return of_layout("sequence", formats)


def parts_of(plan) -> int:
    """How many parts have per-sequence files: the muscles (part j: muscle j), then the parts
    the stages add (``plan.layers``: part ``len(plan.models) + k``)."""
    return len(plan.models) + len(plan.layers)


def part_sizes(plan) -> list[int]:
    """Every part's vertex count, in part order."""
    return [m.n_vertices for m in plan.models] + [p.n_vertices for p in plan.layers]


def part_of(plan, j: int) -> tuple:
    """Part j's (name, colour, faces (T, 3), vertex count, rest vertices, rest normals)."""
    if j < len(plan.models):
        spec, m = plan.muscles[j], plan.models[j]
        return spec.name, tuple(spec.color), m.faces, m.n_vertices, m.rest_vertices, m.rest_normals
    p = plan.layers[j - len(plan.models)]
    return p.name, p.color, p.faces, p.n_vertices, p.rest_vertices, p.rest_normals


def file_relpath(muscle: str, fmt: str) -> str:
    """Where muscle's file of the per-sequence format ``fmt`` lies in the run."""
    f = FORMATS[fmt]
    return sequence_relpath(muscle, f.folder, f.writer.extension)


def unchanged(previous: dict, path: Path, rel: str, sha: str) -> bool:
    """The file ``rel`` (at ``path``) already holds these bytes (the sha256 the manifest says
    and the file on disk has): ``--resume`` keeps it."""
    return previous.get(rel) == sha and is_file_with(path, sha)


class SequenceFiles:
    """The per-sequence files of some parts (:func:`parts_of`: muscles, the stages' parts), fed chunk by
    chunk on a background thread.

    ``append(j, positions, normals)`` queues part ``j``'s next chunk ((C, V, 3) float32,
    frame order); :meth:`finish` completes every file and returns ``({relpath: sha256},
    skipped)``; :meth:`abort` removes every temporary (the files stay absent)."""

    def __init__(self, plan, muscles: list[int], writer):
        self.plan, self.previous = plan, writer.previous
        fps = float(plan.pose.fps)
        self.writers = {}
        try:
            for j in muscles:
                name, color, faces, n_vertices = part_of(plan, j)[:4]
                info = SequenceInfo(np.asarray(plan.frames), fps, name, color)
                for fmt in sequence_formats(plan.formats):
                    rel = file_relpath(name, fmt)
                    path = writer.root.path(rel)  # (the way there checked for links)
                    self.writers[(j, fmt)] = (rel, path, FORMATS[fmt].writer(path, info, faces, n_vertices))
        except BaseException:
            self.abort()
            raise
        self._by_muscle: dict = {}
        for (k, _), (_, _, w) in self.writers.items():
            self._by_muscle.setdefault(k, []).append(w)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="axdf-sequences")
        self._pending: list = []
        self._chunk: list = []

    def append(self, j: int, positions: np.ndarray, normals: np.ndarray) -> None:
        """Part j's next frames; handed to the thread with the rest of the chunk at
        :meth:`end_chunk` (one hand-over per chunk, not per muscle: each costs a thread switch)."""
        self._chunk.append((self._by_muscle.get(j, []), positions, normals))

    def end_chunk(self) -> None:
        """Queue the chunk's appends for the sequence thread (at most MAX_PENDING_CHUNKS wait)."""
        if self._chunk:
            self._pending.append(self._pool.submit(_append_chunk, self._chunk))
            self._chunk = []
        while len(self._pending) > MAX_PENDING_CHUNKS:
            self._pending.pop(0).result()

    def finish(self) -> tuple[dict, int]:
        self.end_chunk()
        for fut in self._pending:
            fut.result()
        self._pending = []
        self._pool.shutdown()
        files, skipped = {}, 0
        entries = list(self.writers.items())
        # USD layers one at a time (one muscle's layer in memory); the others' closing (headers,
        # and reading a file back for its sha256) CLOSE_THREADS at a time
        usd = [e for e in entries if e[0][1] == "usd"]
        rest = [e for e in entries if e[0][1] != "usd"]
        with ThreadPoolExecutor(max_workers=CLOSE_THREADS, thread_name_prefix="axdf-close") as pool:
            closing = [(e, pool.submit(e[1][2].close)) for e in rest]
            shas = {e[0]: fut.result() for e, fut in closing}
        for e in usd:
            shas[e[0]] = e[1][2].close()
        for key, (rel, path, w) in entries:
            sha = shas[key]
            if unchanged(self.previous, path, rel, sha):
                w.abort()
                skipped += 1
            else:
                w.commit()
            files[rel] = sha
        return files, skipped

    def abort(self) -> None:
        self._chunk = []
        pool = getattr(self, "_pool", None)
        if pool is not None:
            for fut in self._pending:
                fut.cancel()
            pool.shutdown(wait=True)
        for _, _, w in self.writers.values():
            w.abort()


def _append_chunk(items) -> None:
    for writers, positions, normals in items:
        for w in writers:
            w.append(positions, normals)


def write_run_files(plan, writer, bone_rows: np.ndarray, bounds: np.ndarray, framing) -> None:
    """Per-run files of the per-sequence formats, through ``writer`` (an OutputWriter: atomic,
    hashed, skipped on resume when unchanged): the point caches' rest meshes, and for USD
    ``usd/bones.usdc`` and the root stage ``scene.usda``. ``bone_rows``: (F, B, 7) x y z qw
    qx qy qz; ``bounds``: (2, 3) of every vertex written; ``framing``: what the
    automatic camera frames (:func:`axdf_cli.render.framing.run_framing`), as ``--render`` frames it."""
    from axdf_cli.formats.ply import PlyWriter

    for fmt in sequence_formats(plan.formats):
        if not FORMATS[fmt].faces:  # a point cache: the rest mesh it applies to, beside it
            for j in range(parts_of(plan)):
                name, _, faces, _, rest, normals = part_of(plan, j)
                writer.write(rest_mesh_relpath(name, FORMATS[fmt].folder),
                             PlyWriter(faces, name).encode(rest, normals))
    if "usd" in plan.formats:
        writer.flush()
        _write_usd_stage(plan, writer, bone_rows, bounds, framing)


def _write_usd_stage(plan, writer, bone_rows, bounds, framing) -> None:
    from axdf_cli.formats.usd import write_bones_layer, write_stage

    bones = plan.pose.skeleton.bones
    meshes = [(bones[i].name, v, f) for i, (v, f, _) in sorted(plan.bone_meshes.items())]
    if meshes:
        _write_with(writer, USD_BONES, lambda tmp: write_bones_layer(tmp, meshes))
    with_mesh = {i for i in plan.bone_meshes}
    muscles = [(s.name, file_relpath(s.name, "usd")) for s in plan.muscles]
    bone_refs = [(b.name, USD_BONES if i in with_mesh else None) for i, b in enumerate(bones)]
    layers = [(p.name, file_relpath(p.name, "usd")) for p in plan.layers]
    camera = usd_camera(plan, bounds, framing)
    _write_with(writer, USD_STAGE, lambda tmp: write_stage(tmp, plan.frames, float(plan.pose.fps), muscles,
                                                           bone_refs, bone_rows, camera, layers))


def usd_camera(plan, bounds, framing) -> dict:
    """The run's camera for the USD stage: the first panel of the render settings' view, the
    camera ``axdf run --render`` uses (framed on ``framing``)."""
    from axdf_cli.pipeline.plan import camera_targets
    from axdf_cli.render.camera import sequence_cameras
    from axdf_cli.render.framing import scene_framing
    from axdf_cli.specs.render import RenderSettings
    from axdf_cli.render.scene import Scene

    settings = plan.render if plan.render is not None else RenderSettings()
    scene = Scene((), (), np.asarray(bounds, np.float64), tuple(int(f) for f in plan.frames),
                  first_frame=int(plan.pose.first), targets=camera_targets(plan),
                  **scene_framing(framing, plan.pose, plan.frames))
    cams = sequence_cameras(scene, settings)
    first = cams[0][0]
    return {"world_to_camera": np.stack([c[0].world_to_camera for c in cams]), "K": first.K,
            "size": tuple(settings.size), "near": first.near, "far": first.far}


def _write_with(writer, rel: str, author) -> None:
    """A file made by a library that writes to a path (pxr): authored at a temporary name,
    renamed into place unless ``--resume`` finds it unchanged; recorded in ``writer.files``."""
    path = writer.root.path(rel)
    f = atomic.StreamingFile(path)
    try:
        author(f.tmp)
        sha = atomic.sha256_file(f.tmp)
    except BaseException:
        f.discard()
        raise
    if unchanged(writer.previous, path, rel, sha):
        f.discard()
        writer.skipped += 1
    else:
        f.commit()
    writer.files[rel] = sha
