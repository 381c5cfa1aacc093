"""Executing a plan: every check first, then the mesh pass (in this process or forked
workers), the tables, the render pass (in this process or render workers) and the manifest,
written into the run folder (:mod:`axdf_cli.fileio.runfolder`). The manifest's schema is
:mod:`.manifest`'s, the tables' :mod:`.tables`', the bulk-overlap policy :mod:`.overlap`'s.

How ``--jobs`` splits the mesh pass follows from the plan's stages (:func:`split_of`):
without a FRAME stage each worker takes some muscles over every frame; with one (it needs
every muscle of a frame) each takes blocks of frames with every muscle, and the per-muscle
packed files are then streamed from the blocks' raw meshes (spilled to temporaries in OUT)
in frame order, muscles split over the workers again: the same bytes as one process."""
from __future__ import annotations

import os
import time
from dataclasses import dataclass, replace
from pathlib import Path, PurePosixPath

import numpy as np

from axdf_cli.errors import InputError
from axdf_cli.fileio import atomic, runfolder
from axdf_cli.fileio.runfolder import (BONES_CSV, FRAME_EXTENSIONS, MANIFEST_INTERVAL_S, STATS, OutputWriter,
                                       bone_mesh_relpath, frame_mesh_relpath, frame_relpath, gl_record, is_file_with,
                                       mesh_relpath, write_manifest)
from axdf_cli.formats import FORMATS, WRITERS
from axdf_cli.pipeline.evaluate import Prepass, chunk_frames, evaluate_plan, finite_or_rest, prepare
from axdf_cli.pipeline.manifest import check_resume, manifest_dict
from axdf_cli.pipeline.overlap import bulk_overlap, bulk_overlap_text, overlap_share, with_pack_command
from axdf_cli.pipeline.packed import SequenceFiles, file_relpath, part_sizes, parts_of, sequence_formats, write_run_files
from axdf_cli.pipeline.plan import RunPlan
from axdf_cli.pipeline.stages import Scope, of_scope
from axdf_cli.render.framing import framing_record, plan_framing
from axdf_cli.pipeline.tables import NSTATS, STATS_COLUMNS, bones_csv, stats_csv
from axdf_cli.pipeline.volume import volume_breaches
from axdf_cli.workers import check_parent, process_map
from axdf_cli.model.skeleton import matrix_to_quaternion


def run_dirs(plan: RunPlan) -> list[str]:
    """The folders below OUT that the plan writes into."""
    if plan.mesh_files == "frame":
        dirs = sorted({PurePosixPath(frame_mesh_relpath(0, f)).parent.as_posix() for f in plan.formats if f in WRITERS})
    else:
        dirs = [PurePosixPath(mesh_relpath(n, 0, f)).parent.as_posix() for f in plan.formats if f in WRITERS
                for n in plan.names]
    dirs += sorted({PurePosixPath(file_relpath(n, f)).parent.as_posix() for f in sequence_formats(plan.formats)
                    for n in plan.names + [p.name for p in plan.layers]})
    dirs += [PurePosixPath(bone_mesh_relpath("b")).parent.as_posix()]
    for part in plan.layers:
        dirs += [PurePosixPath(mesh_relpath(part.name, 0, f)).parent.as_posix() for f in plan.formats if f in WRITERS][:1]
    if plan.rendering:
        dirs.append(PurePosixPath(frame_relpath(0, "png")).parent.as_posix())
    return dirs


def previous_subset(previous: dict, out: Path) -> dict:
    """The previous manifest's files that are still on disk (kept listed while resuming)."""
    return {k: v for k, v in previous.items() if (out / k).is_file()}


@dataclass
class MeshPassResult:
    """What a mesh pass over some muscles and frames returns (picklable, for worker processes)."""

    muscles: list  # muscle indices, in order
    rows: slice  # the frames covered (positions in plan.frames)
    files: dict  # relpath -> sha256
    stats: np.ndarray  # (R, len(muscles), NSTATS): STATS_COLUMNS
    warnings: list  # [(frame index, muscle index, message)]
    lo: np.ndarray  # (3,) bounds of every written vertex
    hi: np.ndarray
    skipped: int = 0
    bone_rows: np.ndarray | None = None  # (R, B, 7) x y z qw qx qy qz, when asked for
    spill: str | None = None  # the raw meshes of these frames, for the packed files (see Spill)
    tables: dict | None = None  # the stages' tables: file -> (R, columns) rows (axdf_cli.parts.Table)


def split_of(plan: RunPlan) -> str:
    """How ``--jobs`` splits the mesh pass: ``"frames"`` when a FRAME stage needs every muscle
    of a frame together, or one mesh file per frame holds every muscle, else ``"muscles"``."""
    return "frames" if of_scope(plan.stages, Scope.FRAME) or plan.mesh_files == "frame" else "muscles"


class Spill:
    """Every part's (the muscles', then the stages' parts: :func:`parts_of`) positions and normals over a
    block of R frames, raw float32 in one
    ``.npy`` (2, R, sum V, 3) at a temporary name in OUT (so that a killed run's is removed
    as any temporary): a frames worker's share of the packed files, streamed in frame order
    by :func:`_sequence_worker`."""

    def __init__(self, path: Path, plan: RunPlan, n_rows: int):
        sizes = part_sizes(plan)
        self.offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.path = path
        try:
            self.data = np.lib.format.open_memmap(path, mode="w+", dtype="<f4",
                                                  shape=(2, n_rows, int(self.offsets[-1]), 3))
        except OSError as e:
            raise atomic.environment_problem(path, e) from None

    def put(self, j: int, rows: slice, positions: np.ndarray, normals: np.ndarray) -> None:
        a, b = self.offsets[j], self.offsets[j + 1]
        self.data[0, rows, a:b] = positions
        self.data[1, rows, a:b] = normals

    def close(self) -> None:
        try:
            self.data.flush()
        except OSError as e:
            raise atomic.environment_problem(self.path, e) from None
        del self.data


def mesh_pass(plan: RunPlan, prep: Prepass, writer: OutputWriter, muscles: list[int] | None = None,
              rows: slice | None = None, progress=None, on_chunk=None, bones: bool = False,
              spill: Path | None = None) -> MeshPassResult:
    """Evaluate and write the meshes of ``muscles`` (default all) for the selected frames
    ``rows`` (default all), chunk by chunk, in every selected format: per-frame files through
    ``writer``; per-sequence files streamed by :class:`SequenceFiles` and completed at the end
    (every frame only), or with ``spill`` raw into that file for :func:`_sequence_worker`.
    With ``bones``, also return every bone's world pose (from the same kinematics)."""
    nm = len(plan.models)
    muscles = list(range(nm)) if muscles is None else list(muscles)
    rows = slice(0, len(plan.frames)) if rows is None else rows
    n_rows = rows.stop - rows.start
    frame_formats = [f for f in plan.formats if f in WRITERS]
    per_frame = plan.mesh_files == "frame"  # one file per frame, every muscle (muscles: all of them, split_of)
    if per_frame:
        parts = [(plan.muscles[j].name, plan.models[j].faces, plan.models[j].n_vertices) for j in muscles]
        writers = {f: FORMATS[f].frame_writer(parts) for f in frame_formats}
    else:
        writers = {(j, f): WRITERS[f](plan.models[j].faces, plan.muscles[j].name) for j in muscles
                   for f in frame_formats}
    col = {j: k for k, j in enumerate(muscles)}
    stats = np.zeros((n_rows, len(muscles), NSTATS))
    tables = {t.file: np.zeros((n_rows, len(t.columns))) for s in plan.stages for t in s.tables}
    layer_writers = [{f: WRITERS[f](part.faces, part.name) for f in frame_formats} for part in plan.layers]
    bone_rows = np.zeros((n_rows, len(plan.pose.skeleton.bones), 7)) if bones else None
    warns: list = []
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    packed = bool(sequence_formats(plan.formats))
    seq_parts = muscles + list(range(nm, nm + len(plan.layers)))  # (the stages' parts follow the muscles: parts_of)
    seq = SequenceFiles(plan, seq_parts, writer) if packed and spill is None else None
    raw = None
    try:
        raw = Spill(spill, plan, n_rows) if packed and spill is not None else None
        for chunk, results in evaluate_plan(plan, prep, rows, muscles):
            sl = chunk.rows
            here = slice(sl.start - rows.start, sl.stop - rows.start)
            frames = chunk.frames
            meshes = []  # (positions, normals) per muscle of the chunk, for the files per frame
            if bones:
                bone_rows[here, :, :3] = chunk.world[:, :, :3, 3]
                bone_rows[here, :, 3:] = matrix_to_quaternion(chunk.world[:, :, :3, :3])
            for j, res in results:
                if j not in col:  # (a FRAME stage carries every muscle)
                    continue
                name = plan.muscles[j].name
                pos, nrm, bad = finite_or_rest(res, plan.models[j], box := np.empty((len(frames), 2, 3), np.float32))
                res.warnings += [(int(i), "non-finite vertices; the rest shape was written instead") for i in bad]
                for f in frame_formats if not per_frame else ():
                    w = writers[(j, f)]
                    for i, frame in enumerate(frames):
                        writer.write(mesh_relpath(name, int(frame), f), w.encode(pos[i], nrm[i]))
                if per_frame:
                    meshes.append((pos, nrm))
                if seq is not None:
                    seq.append(j, pos, nrm)
                if raw is not None:
                    raw.put(j, here, pos, nrm)
                lo = np.minimum(lo, box[:, 0].min(axis=0))
                hi = np.maximum(hi, box[:, 1].max(axis=0))
                cm = res.contact if res.contact is not None else np.zeros((len(res.length), 3))
                st = np.concatenate([np.stack([res.length, res.volume, res.volume / plan.models[j].v0, res.tension,
                                               res.twist, res.scale], axis=1), cm], axis=1)
                stats[here, col[j]] = np.where(np.isfinite(st), st, 0.0)
                warns += [(sl.start + i, j, msg) for i, msg in res.warnings]
                if progress:
                    progress(len(frames))
            if per_frame:
                for f in frame_formats:
                    for i, frame in enumerate(frames):
                        writer.write(frame_mesh_relpath(int(frame), f),
                                     writers[f].encode([p[i] for p, _ in meshes], [n[i] for _, n in meshes]))
            for file, rows_of in chunk.tables.items():  # (the FRAME stages ran while the results were handed out)
                tables[file][here] = rows_of
            for k, part in enumerate(plan.layers):
                pf = chunk.parts[part.name]
                lo, hi = _with_bounds(lo, hi, pf.positions)  # (the bounds of every written vertex)
                for f in frame_formats:
                    for i, frame in enumerate(frames):
                        writer.write(mesh_relpath(part.name, int(frame), f),
                                     layer_writers[k][f].encode(pf.positions[i], pf.normals[i]))
                if seq is not None:
                    seq.append(nm + k, pf.positions, pf.normals)
                if raw is not None:
                    raw.put(nm + k, here, pf.positions, pf.normals)
            if seq is not None:
                seq.end_chunk()
            if on_chunk:
                on_chunk()
        writer.flush()
        if raw is not None:
            raw.close()
        if seq is not None:
            files, skipped = seq.finish()
            writer.files.update(files)
            writer.skipped += skipped
    except BaseException:
        if seq is not None:
            seq.abort()
        if spill is not None:
            Path(spill).unlink(missing_ok=True)
        raise
    return MeshPassResult(muscles, rows, writer.files, stats, warns, lo, hi, writer.skipped, bone_rows,
                          str(spill) if raw is not None else None, tables)


def _with_bounds(lo: np.ndarray, hi: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bounds ``lo``, ``hi`` (3,) grown by a part's (C, V, 3) positions where all are finite."""
    if positions.size and np.isfinite(positions).all():
        return np.minimum(lo, positions.min(axis=(0, 1))), np.maximum(hi, positions.max(axis=(0, 1)))
    return lo, hi


def _mesh_worker(shared: dict, task) -> MeshPassResult:
    muscles, rows, bones, spill = task
    writer = OutputWriter(shared["root"], shared["previous"])
    try:
        return mesh_pass(shared["plan"], shared["prep"], writer, muscles, rows, on_chunk=check_parent, bones=bones,
                         spill=spill)
    finally:
        writer.close(cancel=True)


def _sequence_worker(shared: dict, muscles: list[int]) -> tuple[dict, int]:
    """Stream the packed files of ``muscles`` (parts: :func:`parts_of`) from the spilled
    blocks, in frame order."""
    plan = shared["plan"]
    writer = OutputWriter(shared["root"], shared["previous"])
    seq = SequenceFiles(plan, muscles, writer)
    try:
        for path in shared["spills"]:
            data = np.load(path, mmap_mode="r")
            offsets = np.concatenate([[0], np.cumsum(part_sizes(plan))])
            for j in muscles:
                a, b = offsets[j], offsets[j + 1]
                seq.append(j, data[0, :, a:b], data[1, :, a:b])
            seq.end_chunk()
            check_parent()
        return seq.finish()
    except BaseException:
        seq.abort()
        raise
    finally:
        writer.close(cancel=True)


def _parallel_mesh_pass(plan: RunPlan, root: Path, jobs: int, prep: Prepass, previous: dict,
                        progress) -> list[MeshPassResult]:
    """The mesh pass over ``jobs`` forked processes, split as the stages allow (:func:`split_of`):
    the muscles round robin (similar work each; the first also returns the bones' poses), or
    blocks of frames with every muscle, then the packed files streamed from the blocks."""
    nm, nf = len(plan.models), len(plan.frames)
    shared = {"plan": plan, "root": root, "prep": prep, "previous": previous}
    if split_of(plan) == "muscles":
        groups = [list(range(k, nm, jobs)) for k in range(jobs)]
        tasks = [(g, None, k == 0, None) for k, g in enumerate(groups) if g]
        on_result = (lambda r: progress(len(r.muscles) * nf)) if progress else None
        return process_map(_mesh_worker, tasks, shared, on_result=on_result)
    size = max(1, min(chunk_frames(plan, list(range(nm))), -(-nf // jobs)))
    packed = bool(sequence_formats(plan.formats))
    tasks = [(None, slice(s, min(s + size, nf)), True,
              root / f"{atomic.TMP_PREFIX}{os.getpid()}-frames-{s:09d}.npy" if packed else None)
             for s in range(0, nf, size)]
    on_result = (lambda r: progress((r.rows.stop - r.rows.start) * nm)) if progress else None
    parts: list = []
    try:
        parts = process_map(_mesh_worker, tasks, shared, jobs=jobs, on_result=on_result)
        if packed:
            shared["spills"] = [p.spill for p in parts]
            npart = parts_of(plan)
            groups = [g for g in (list(range(k, npart, jobs)) for k in range(jobs)) if g]
            for files, skipped in process_map(_sequence_worker, groups, shared):
                parts[0].files.update(files)
                parts[0].skipped += skipped
    finally:
        for t in tasks:
            if t[3] is not None:
                Path(t[3]).unlink(missing_ok=True)
    return parts


class Checkpoint:
    """Calling it writes the in-progress manifest (``write()``: finished files only) at most
    every MANIFEST_INTERVAL_S and never more than ~5% of the run's time: on a long run the
    file list grows to many MB."""

    def __init__(self, write):
        self.write = write
        self.t = time.monotonic()
        self.cost = 0.0

    def __call__(self) -> None:
        now = time.monotonic()
        if now - self.t >= max(MANIFEST_INTERVAL_S, 20.0 * self.cost):
            self.write()
            self.cost = time.monotonic() - now
            self.t = time.monotonic()


def frame_files(frame: int) -> list[str]:
    """A rendered frame's files (one per pass)."""
    return [frame_relpath(frame, ext) for ext in FRAME_EXTENSIONS]


def rendered_frames(plan: RunPlan, previous: dict, root: Path) -> set[int]:
    """The frames an interrupted run rendered whole (every pass listed in its manifest and
    on disk with those bytes): --resume keeps them."""
    return {int(f) for f in plan.frames
            if all(r in previous and is_file_with(root / r, previous[r]) for r in frame_files(int(f)))}


def strict_check(plan: RunPlan, prep: Prepass) -> None:
    """Evaluate everything once: with --strict, any warning stops the run before it writes."""
    found = [f"{plan.names[j]} frame {int(plan.frames[i])}: {msg}" for i, j, msg in plan.frame_warnings]
    inside = np.zeros((len(plan.frames), len(plan.models)))
    for chunk, results in evaluate_plan(plan, prep):
        sl = chunk.rows
        for j, res in results:
            if res.contact is not None:
                inside[sl, j] = np.nan_to_num(res.contact[:, 0])
            found += [f"{plan.names[j]} frame {int(plan.frames[sl.start + i])}: {msg}" for i, msg in res.warnings]
            bad = ~(np.isfinite(res.vertices).all(axis=(1, 2)) & np.isfinite(res.normals).all(axis=(1, 2)))
            found += [f"{plan.names[j]} frame {int(plan.frames[sl.start + i])}: non-finite vertices"
                      for i in np.nonzero(bad)[0]]
    bulk = bulk_overlap(plan, inside)
    found += [with_pack_command(plan, bulk)] if bulk else []
    if found:
        raise InputError(None, f"{len(found)} warning(s) with --strict; first: {found[0]}",
                         "fix the inputs or run without --strict")


def check_output(plan: RunPlan, *, resume: bool = False, overwrite: bool = False) -> runfolder.Target:
    """The output folder's checks (reads only): what OUT holds, and for --resume that it is
    the same run."""
    target = runfolder.prepare(plan.out, resume=resume, overwrite=overwrite, dirs=run_dirs(plan))
    base = Path(os.getcwd()) if plan.base is None else Path(plan.base)
    runfolder.check_inputs_outside(target, [base / name for name in plan.inputs])  # (named from base)
    if resume and target.previous is not None:
        check_resume(plan, target.previous)
    return target


def execute(plan: RunPlan, *, resume: bool = False, overwrite: bool = False, progress=None,
            strict: bool = False, render_progress=None, jobs: int = 1, on_note=None) -> dict:
    """Run the plan; return a summary dict. ``progress(n)`` is called with muscle-frames done;
    ``on_note(text)`` with remarks worth printing at once (a lowered supersampling).

    Every check comes first (the output folder, --resume against the earlier manifest,
    --strict, EGL and the render size): a refused run writes nothing. With ``jobs`` > 1 the
    muscles are split over forked worker processes for the mesh pass, then the frames over
    render workers (:func:`axdf_cli.render.framefiles.render_frames_of`: from a fork server,
    each with its own GL context; this process never makes one); the output is the same
    bytes. With one job the frames are rendered in this process, after every fork."""
    target = check_output(plan, resume=resume, overwrite=overwrite)
    prep = prepare(plan)
    if strict:
        strict_check(plan, prep)
    if plan.rendering:
        from axdf_cli.render.framefiles import check_render

        plan = replace(plan, render=check_render(plan.render, on_note))
    with runfolder.Session(target) as session:
        return _write_run(plan, session, prep, progress, render_progress, jobs)


def _write_run(plan: RunPlan, session, prep: Prepass, progress, render_progress, jobs: int) -> dict:
    root = session.root
    previous = session.previous_files
    write_manifest(root, manifest_dict(plan, previous_subset(previous, root), [], complete=False))
    nf, nm = len(plan.frames), len(plan.models)
    bones = plan.pose.skeleton.bones
    writer = OutputWriter(root, previous)
    rendered = {"files": {}}  # frames rendered so far
    try:
        if jobs > 1 and (nm if split_of(plan) == "muscles" else nf) > 1:
            try:
                parts = _parallel_mesh_pass(plan, root, min(jobs, nm if split_of(plan) == "muscles" else nf), prep,
                                            previous, progress)
            except BaseException:
                runfolder.remove_stale(root, run_dirs(plan))  # a worker killed mid-write (the others finish theirs)
                raise
        else:
            checkpoint = Checkpoint(lambda: write_manifest(root, manifest_dict(plan, writer.files, [], complete=False)))
            parts = [mesh_pass(plan, prep, writer, progress=progress, on_chunk=checkpoint, bones=True)]
        stats = np.zeros((nf, nm, NSTATS))
        warn_text = [[""] * nm for _ in range(nf)]
        lo = np.min([p.lo for p in parts], axis=0)
        hi = np.max([p.hi for p in parts], axis=0)
        all_warns = list(plan.frame_warnings)
        writer.skipped = sum(p.skipped for p in parts)  # (one pass in this process: its writer is ours)
        bone_rows = np.zeros((nf, len(bones), 7))
        tables = {t.file: (t, np.zeros((nf, len(t.columns)))) for s in plan.stages for t in s.tables}
        for part in parts:
            writer.files.update(part.files)
            stats[part.rows, part.muscles] = part.stats
            if part.bone_rows is not None:
                bone_rows[part.rows] = part.bone_rows
            for file, rows_of in (part.tables or {}).items():
                tables[file][1][part.rows] = rows_of
            all_warns += part.warnings
        warnings: list[str] = list(plan.warnings)
        share = overlap_share(plan, stats[..., STATS_COLUMNS.index("inside_muscle")])
        bulk = bulk_overlap_text(share, f"{nf} frame(s)")
        warnings += [bulk] if bulk else []
        run_warnings = [with_pack_command(plan, bulk)] if bulk else []
        breaches = volume_breaches(plan.names, [m.volume_mode.value for m in plan.models], plan.frames,
                                   stats[..., STATS_COLUMNS.index("volume_ratio")])
        warnings += breaches
        run_warnings += breaches
        for fi, j, msg in sorted(all_warns, key=lambda w: (w[0], w[1])):
            warn_text[fi][j] = (warn_text[fi][j] + "; " if warn_text[fi][j] else "") + msg
            warnings.append(f"{plan.names[j]} frame {int(plan.frames[fi])}: {msg}")

        for i, (_, _, data) in sorted(plan.bone_meshes.items()):
            writer.write(bone_mesh_relpath(bones[i].name), data)
        writer.write(STATS, stats_csv(plan, stats, warn_text))
        writer.write(BONES_CSV, bones_csv(plan, bone_rows))
        for file, (table, rows_of) in tables.items():
            writer.write(file, table.encode(plan.frames, rows_of))
        frame_pts = plan_framing(plan)
        extra = {"bounds": [[float(f"{x:.9g}") for x in lo], [float(f"{x:.9g}") for x in hi]],
                 "framing": framing_record(frame_pts, plan.pose.first)}
        if sequence_formats(plan.formats):
            write_run_files(plan, writer, bone_rows, np.array([lo, hi]), frame_pts)
        if plan.rendering:
            writer.flush()
            write_manifest(root, manifest_dict(plan, writer.files, warnings, complete=False, extra=extra))
            info = _render_pass(plan, root, previous, writer, rendered, lambda files: manifest_dict(
                plan, files, warnings, complete=False, extra=extra), np.array([lo, hi]), prep, frame_pts,
                render_progress, jobs)
            extra["gl"] = gl_record(info["gl_renderer"], info["gl_version"])
        writer.flush()
        session.commit(manifest_dict(plan, writer.files, warnings, complete=True, extra=extra))
    except BaseException:
        writer.close(cancel=True)
        writer.files.update(rendered["files"])
        if jobs > 1:
            runfolder.remove_stale(root, run_dirs(plan))  # a render worker killed mid-write (the others finish theirs)
        if root == plan.out:  # stopped: list what is whole, for --resume (a staging folder goes)
            runfolder.try_write_manifest(root, manifest_dict(plan, writer.files, [], complete=False))
        raise
    writer.close()
    ratio = stats[..., 2]
    return {
        "out": str(plan.out), "muscles": nm, "frames": nf, "files": len(writer.files), "skipped": writer.skipped,
        "warnings": warnings, "worst_volume_error": float(np.max(np.abs(ratio - 1.0))) if ratio.size else 0.0,
        "stats": stats, "run_warnings": run_warnings, "overlap": share,
    }


def _render_pass(plan: RunPlan, root: Path, previous: dict, writer: OutputWriter, rendered: dict, manifest,
                 bounds: np.ndarray, prep: Prepass, frame_pts, progress, jobs: int) -> dict:
    """Render the plan's frames into ``root`` over ``jobs`` processes; the frames an
    interrupted run rendered whole are kept (--resume). ``rendered["files"]`` follows the
    frames' files as they are written; ``manifest(files)`` is the in-progress manifest,
    written at checkpoints. Every frame's files end up in ``writer.files``."""
    from axdf_cli.pipeline.frames import render_plan

    done = rendered_frames(plan, previous, root)
    for f in sorted(done):
        writer.files.update({r: previous[r] for r in frame_files(f)})
        writer.skipped += len(FRAME_EXTENSIONS)
        if progress:
            progress(f)
    checkpoint = Checkpoint(lambda: write_manifest(root, manifest({**writer.files, **rendered["files"]})))

    def on_frame(files: dict) -> None:  # the frames' files written so far (one growing dict)
        rendered["files"] = files
        checkpoint()

    todo = [int(f) for f in plan.frames if int(f) not in done]
    info = render_plan(plan, root, bounds, prep, progress, frame_pts, jobs, todo, on_frame)
    writer.files.update(info["files"])
    return info


