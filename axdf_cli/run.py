"""``axdf run``: muscles × pose → mesh sequence, stats, bones (and frames), plus a manifest.

Data flow: YAML → frozen specs (:mod:`axdf_cli.loaders`) → :class:`~axdf_cli.muscle.MuscleModel`
(basis matrices and binding, once per muscle) → batched evaluation over chunks of frames
(batch dimension first) → writers. Every file is written atomically; the manifest is
rewritten (atomically) after each chunk, so it is valid JSON at every moment and a killed
run can be resumed (``--resume`` skips files whose bytes already match the manifest).
"""
from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli import __version__, atomic, rmf
from axdf_cli.errors import InputError, Mark
from axdf_cli.formats import WRITERS
from axdf_cli.loaders import Job, Pose, RefPolicy, expand_muscle_paths, load_muscle_file, load_pose
from axdf_cli.muscle import MuscleModel, MuscleSpec
from axdf_cli.pose import (activation_problems, effective_tension, muscle_range_warnings, parse_frames,
                           sample_activation, sample_coordinates, subject_points)
from axdf_cli.skeleton import forward_kinematics, matrix_to_quaternion

CHUNK_FRAMES = 128  # frames evaluated together: bounds memory for any sequence length
EVAL_BUDGET_BYTES = 128 * 1024 * 1024  # per-muscle chunk memory budget (see chunk_frames)
MANIFEST_INTERVAL_S = 1.0  # the in-progress manifest is rewritten at most this often
MAX_PENDING_WRITES = 64  # files queued for the writer thread (bounds memory)
TOP_FILES = ("manifest.json", "stats.csv", "bones.csv", "camera.json")


@dataclass
class RunPlan:
    pose: Pose
    muscles: list[MuscleSpec]
    models: list[MuscleModel]
    frames: np.ndarray  # (F,) selected output frames
    fmt: str
    out: Path
    inputs: dict  # display path -> sha256
    render: object = None  # render settings (or None: no rendering)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)  # remarks printed with --verbose; not warnings
    frame_warnings: list = field(default_factory=list)  # [(frame index, muscle index, message)] known before evaluation
    bone_meshes: dict = field(default_factory=dict)  # bone index -> (vertices (V,3) f4, faces (T,3) i4, file bytes)

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.muscles]


def _display(p: Path) -> str:
    """A path for the manifest: relative to the current folder when below it."""
    try:
        return Path(os.path.relpath(Path(p).resolve(), Path.cwd().resolve())).as_posix()
    except ValueError:
        return Path(p).resolve().as_posix()


def plan_run(job: Job | None, *, muscle_args=None, pose_arg=None, out_arg=None, fmt_arg=None,
             frames_arg=None, policy: RefPolicy | None = None, clamp_ranges: bool = False) -> RunPlan:
    """Load and check every input; build the muscle models. Writes nothing. ``policy``: where
    referenced files may lie (default: the job's)."""
    policy = policy or (job.policy if job is not None else RefPolicy())
    if pose_arg is not None:
        pose_path, pose_mark = Path(pose_arg), Mark(str(pose_arg))
    elif job is not None:
        pose_path, pose_mark = job.pose
    else:
        raise InputError(None, "no pose given", "give a JOB.yaml or --pose FILE")
    if not pose_path.is_file():
        raise InputError(pose_mark, f"pose file {str(pose_path)!r} not found", "an existing pose YAML file")
    pose = load_pose(pose_path, policy)
    if clamp_ranges:
        from dataclasses import replace

        pose = replace(pose, clamp_ranges=True)

    if muscle_args:
        entries = [(Path(m), Mark(str(m))) for m in muscle_args]
    elif job is not None:
        entries = list(job.muscles)
    else:
        raise InputError(None, "no muscles given", "give a JOB.yaml or --muscles PATH ...")
    files = expand_muscle_paths(entries, policy, Path(job.source).parent if not muscle_args else None)
    specs: list[MuscleSpec] = []
    seen: dict[str, str] = {}
    for fpath in files:
        for spec in load_muscle_file(fpath):
            if spec.name in seen:
                raise InputError(Mark(str(fpath), 1, 1), f"muscle {spec.name!r} is also defined in {seen[spec.name]}",
                                 "muscle names are unique within a run")
            seen[spec.name] = str(fpath)
            specs.append(spec)
    if not specs:
        raise InputError(None, "no muscles found", "give muscle YAML files")

    warnings, notes = activation_problems(pose, seen)

    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    models = [MuscleModel(s, skel.bone_index, rest) for s in specs]

    if frames_arg is not None:
        frames = parse_frames(frames_arg, Mark("--frames"), pose.first, pose.last)
    elif job is not None and job.frames is not None:
        frames = parse_frames(job.frames, job.frames_mark, pose.first, pose.last)
    else:
        frames = pose.frames
    fmt = fmt_arg or (job.format if job is not None else None) or "ply"
    out = Path(out_arg or (job.out if job is not None and job.out else None) or "out/run")

    bone_meshes = {i: load_bone_mesh(b.mesh, pose.skeleton_path) for i, b in enumerate(skel.bones) if b.mesh}

    inputs = {}
    srcs = ([job.source] if job is not None else []) + [pose.source, pose.skeleton_path] + [str(f) for f in files]
    srcs += sorted({b.mesh for b in skel.bones if b.mesh})
    for s in srcs:
        if Path(s).is_file():
            inputs[_display(Path(s))] = atomic.sha256_file(s)
    return RunPlan(pose, specs, models, frames, fmt, out, inputs, warnings=warnings, bone_meshes=bone_meshes,
                   notes=notes, frame_warnings=muscle_range_warnings(pose, frames, specs))


def load_bone_mesh(path: str, skeleton_file: str):
    """Read a bone's mesh (PLY or OBJ triangles) → (vertices, faces, bytes); bad files are input errors."""
    from axdf_cli.render.runio import read_mesh_file

    if not Path(path).is_file():
        raise InputError(Mark(skeleton_file), f"bone mesh {path} not found", "a PLY file relative to the skeleton file")
    v, _, f = read_mesh_file(Path(path))
    if len(f) == 0:
        raise InputError(Mark(str(path)), "bone mesh has no triangles", "a PLY or OBJ mesh with at least one triangle")
    if not np.isfinite(v).all():
        raise InputError(Mark(str(path)), "non-finite vertex coordinates", "finite numbers only")
    return np.ascontiguousarray(v, dtype=np.float32), f, Path(path).read_bytes()


# ----------------------------------------------------------------------------- evaluation


def twist_references(plan: RunPlan) -> np.ndarray:
    """Unwrapped coarse insertion roll for every selected frame and muscle: (F, M) radians.

    Computed over the pose's whole frame range in order, so the branch (past ±180°) of any
    frame does not depend on which frames are selected."""
    pose = plan.pose
    all_frames = pose.frames
    out = np.empty((len(all_frames), len(plan.models)))
    prev = np.zeros(len(plan.models))
    for s in range(0, len(all_frames), 4 * CHUNK_FRAMES):
        fr = all_frames[s:s + 4 * CHUNK_FRAMES]
        world = forward_kinematics(pose.skeleton, sample_coordinates(pose, fr))
        frames = batched_axis_frames(plan.models, range(len(plan.models)), world, coarse=True)
        for j, m in enumerate(plan.models):
            th = np.unwrap(np.concatenate([[prev[j]], m.end_twist(world, r_end=frames[j][3][:, -1])]))[1:]
            out[s:s + len(fr), j] = th
            prev[j] = th[-1]
    return out[plan.frames - pose.first]


def batched_axis_frames(models, indices, world: np.ndarray, coarse: bool = False) -> dict:
    """Axis frames (p, x, t, r) of several muscles at once, by muscle index. Muscles with the
    same number of axis samples share one double-reflection recurrence, so its loop over the
    samples runs once per group, not once per muscle (row by row the same arithmetic)."""
    groups: dict[int, list[int]] = {}
    for j in indices:
        m = models[j]
        groups.setdefault(len(m.Bc) if coarse else len(m.ts), []).append(j)
    nf = world.shape[0]
    out = {}
    for js in groups.values():
        ins = [models[j].rmf_inputs(world, coarse) for j in js]
        r = rmf.propagate(np.concatenate([i[1] for i in ins]), np.concatenate([i[2] for i in ins]),
                          np.concatenate([i[3] for i in ins]))
        for k, j in enumerate(js):
            p, x, t, _ = ins[k]
            out[j] = (p, x, t, r[k * nf:(k + 1) * nf])
    return out


def chunk_frames(plan: RunPlan) -> int:
    """Frames per evaluation chunk: at most CHUNK_FRAMES, fewer for very fine meshes, so that
    one muscle's chunk (about 8 float64 arrays of (F, V, 3)) stays within EVAL_BUDGET_BYTES."""
    v = max(m.n_vertices for m in plan.models)
    return int(np.clip(EVAL_BUDGET_BYTES // (v * 3 * 8 * 8), 1, CHUNK_FRAMES))


def evaluate_chunks(plan: RunPlan, chunk: int | None = None, twist_ref: np.ndarray | None = None,
                    muscles: list[int] | None = None):
    """Yield (frame_slice, world (C, B, 4, 4), results) over the selected frames, where
    ``results`` is a lazy iterator of (muscle index, FrameResult): a consumer that handles one
    muscle at a time holds one muscle's chunk in memory, never all of them."""
    if twist_ref is None:
        twist_ref = twist_references(plan)
    chunk = chunk or chunk_frames(plan)
    names = plan.names
    for s in range(0, len(plan.frames), chunk):
        fr = plan.frames[s:s + chunk]
        world = forward_kinematics(plan.pose.skeleton, sample_coordinates(plan.pose, fr))
        act = sample_activation(plan.pose, names, fr)

        def results(world=world, act=act, s=s, n=len(fr)):
            which = list(range(len(plan.models))) if muscles is None else list(muscles)
            frames = batched_axis_frames(plan.models, which, world)
            for j in which:
                m = plan.models[j]
                yield j, m.evaluate(world, effective_tension(m.spec.tension, act[:, j]), twist_ref[s:s + n, j],
                                    frames=frames.pop(j))

        yield slice(s, s + len(fr)), world, results()


# ----------------------------------------------------------------------------- output


def mesh_relpath(muscle: str, frame: int, fmt: str) -> str:
    return f"meshes/{muscle}/{muscle}_{frame:04d}.{fmt}"


def bone_mesh_relpath(bone: str) -> str:
    """Bone meshes are copied into the run, so that a run folder renders on its own."""
    return f"bones/{bone}.ply"


def render_dict(settings) -> dict | None:
    if settings is None or not settings.enabled:
        return None
    from axdf_cli.render.settings import settings_to_dict

    return settings_to_dict(settings)


def check_output_folder(out: Path, resume: bool, overwrite: bool) -> dict:
    """Refuse a non-empty OUT unless --resume or --overwrite; return the files of a previous
    manifest (for --resume)."""
    if out.exists() and not out.is_dir():
        raise InputError(None, f"--out {out} exists and is not a folder", "give a folder")
    if not out.exists() or not any(out.iterdir()):
        return {}
    if resume:
        man = out / "manifest.json"
        try:
            prev = json.loads(man.read_text())
            atomic.remove_stale_temporaries(out)
            return dict(prev.get("files", {}))
        except (OSError, ValueError):
            atomic.remove_stale_temporaries(out)
            return {}
    if overwrite:
        for sub in ("meshes", "frames", "bones"):
            shutil.rmtree(out / sub, ignore_errors=True)
        for name in TOP_FILES:
            try:
                (out / name).unlink()
            except FileNotFoundError:
                pass
        atomic.remove_stale_temporaries(out)
        return {}
    raise InputError(None, f"output folder {out} is not empty",
                     "pass --resume to finish an interrupted run, --overwrite to replace it, or another --out")


class OutputWriter:
    """Writes files atomically on a background thread (so writing overlaps evaluation),
    records their sha256, and skips files whose bytes already match on resume.

    :meth:`write` queues the bytes (at most MAX_PENDING_WRITES wait); :meth:`flush` waits
    for all and re-raises a failed write's error (full disk: EnvironmentProblem) in the
    caller. ``files`` lists what is on disk, in the order written."""

    def __init__(self, out: Path, previous: dict):
        from concurrent.futures import ThreadPoolExecutor

        self.out = out
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
        import hashlib

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


def previous_subset(previous: dict, out: Path) -> dict:
    """The previous manifest's files that are still on disk (kept listed while resuming)."""
    return {k: v for k, v in previous.items() if (out / k).is_file()}


def _fmt_rows(rows: list[list]) -> str:
    return "".join(",".join(r) + "\n" for r in rows)


def _g(x: float) -> str:
    return f"{x + 0.0:.9g}"


def manifest_dict(plan: RunPlan, files: dict, warnings: list, complete: bool, extra: dict | None = None) -> dict:
    m = {
        "tool": "axdf",
        "version": __version__,
        "complete": complete,
        "inputs": dict(sorted(plan.inputs.items())),
        "settings": {
            "format": plan.fmt,
            "pose": plan.pose.name,
            "skeleton": plan.pose.skeleton.name,
            "fps": plan.pose.fps,
            "render": render_dict(plan.render),
        },
        "frames": [int(f) for f in plan.frames],
        "muscles": [
            {"name": s.name, "group": s.group, "color": [round(c, 6) for c in s.color], "source": _display(Path(s.source)),
             "volume": s.volume, "vertices": int(m.n_vertices), "faces": int(len(m.faces)),
             "rest_length": round(m.l0, 12), "rest_volume": float(f"{m.v0:.12g}")}
            for s, m in zip(plan.muscles, plan.models)
        ],
        "bones": [{"name": b.name, "mesh": bone_mesh_relpath(b.name) if b.mesh else None,
                   "parent": plan.pose.skeleton.bones[b.parent].name if b.parent >= 0 else None}
                  for b in plan.pose.skeleton.bones],
        "warnings": warnings,
        "files": dict(sorted(files.items())),
    }
    if extra:
        m.update(extra)
    return m


def write_manifest(out: Path, manifest: dict) -> None:
    atomic.write_text(out / "manifest.json", json.dumps(manifest, indent=1, sort_keys=False) + "\n")


@dataclass
class MeshPassResult:
    """What a mesh pass over some muscles returns (picklable, for worker processes)."""

    muscles: list  # muscle indices, in order
    files: dict  # relpath -> sha256
    stats: np.ndarray  # (F, len(muscles), 6) length, volume, ratio, tension, twist, scale
    warnings: list  # [(frame index, muscle index, message)]
    lo: np.ndarray  # (3,) bounds of every written vertex
    hi: np.ndarray
    skipped: int = 0


def mesh_pass(plan: RunPlan, muscles: list[int], twist_ref: np.ndarray, writer: "OutputWriter",
              progress=None, on_chunk=None) -> MeshPassResult:
    """Evaluate and write the meshes of ``muscles`` for every selected frame, chunk by chunk."""
    writers = {j: WRITERS[plan.fmt](plan.models[j].faces, plan.muscles[j].name) for j in muscles}
    col = {j: k for k, j in enumerate(muscles)}
    stats = np.zeros((len(plan.frames), len(muscles), 6))
    warns: list = []
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for sl, _, results in evaluate_chunks(plan, twist_ref=twist_ref, muscles=muscles):
        frames = plan.frames[sl]
        for j, res in results:
            name = plan.muscles[j].name
            pos = res.vertices.astype(np.float32)
            nrm = res.normals.astype(np.float32)
            finite = np.isfinite(pos).all(axis=(1, 2)) & np.isfinite(nrm).all(axis=(1, 2))
            for i in np.nonzero(~finite)[0]:
                res.warnings.append((int(i), "non-finite vertices; the rest shape was written instead"))
                pos[i] = plan.models[j].rest_vertices
                nrm[i] = plan.models[j].rest_normals
            w = writers[j]
            for i, frame in enumerate(frames):
                writer.write(mesh_relpath(name, int(frame), plan.fmt), w.encode(pos[i], nrm[i]))
            lo = np.minimum(lo, pos.reshape(-1, 3).min(axis=0))
            hi = np.maximum(hi, pos.reshape(-1, 3).max(axis=0))
            st = np.stack([res.length, res.volume, res.volume / plan.models[j].v0, res.tension,
                           res.twist, res.scale], axis=1)
            stats[sl, col[j]] = np.where(np.isfinite(st), st, 0.0)
            warns += [(sl.start + i, j, msg) for i, msg in res.warnings]
            if progress:
                progress(len(frames))
        if on_chunk:
            on_chunk()
    writer.flush()
    return MeshPassResult(list(muscles), writer.files, stats, warns, lo, hi, writer.skipped)


_WORKER: dict = {}  # set in the parent just before the worker processes fork


def _worker_pass(muscles: list[int]) -> MeshPassResult:
    w = _WORKER
    writer = OutputWriter(w["plan"].out, w["previous"])
    try:
        return mesh_pass(w["plan"], muscles, w["twist_ref"], writer)
    finally:
        writer.close(cancel=True)


def _parallel_mesh_pass(plan: RunPlan, jobs: int, twist_ref, previous: dict, progress) -> list[MeshPassResult]:
    """Split the muscles over ``jobs`` forked processes (round robin: similar work each)."""
    import multiprocessing as mp

    groups = [list(range(k, len(plan.models), jobs)) for k in range(jobs)]
    groups = [g for g in groups if g]
    _WORKER.update(plan=plan, twist_ref=twist_ref, previous=previous)
    pool = mp.get_context("fork").Pool(len(groups))
    try:
        results = []
        for r in pool.imap(_worker_pass, groups):
            results.append(r)
            if progress:
                progress(len(r.muscles) * len(plan.frames))
        pool.close()
        return results
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()
        _WORKER.clear()


def execute(plan: RunPlan, *, resume: bool = False, overwrite: bool = False, progress=None,
            strict: bool = False, render_progress=None, jobs: int = 1) -> dict:
    """Run the plan; return a summary dict. ``progress(n)`` is called with muscle-frames done.

    With ``jobs`` > 1 the muscles are split over forked worker processes for the mesh pass;
    the output is the same bytes. Rendering runs in this process afterwards (the GL context
    is created after every fork)."""
    out = plan.out
    previous = check_output_folder(out, resume, overwrite)
    atomic.ensure_dir(out)
    write_manifest(out, manifest_dict(plan, previous_subset(previous, out), [], complete=False))
    nf, nm = len(plan.frames), len(plan.models)
    bones = plan.pose.skeleton.bones
    twist_ref = twist_references(plan)
    if strict:  # evaluate everything first: with --strict, any warning stops the run before it writes
        found = [f"{plan.names[j]} frame {int(plan.frames[i])}: {msg}" for i, j, msg in plan.frame_warnings]
        for sl, _, results in evaluate_chunks(plan, twist_ref=twist_ref):
            for j, res in results:
                found += [f"{plan.names[j]} frame {int(plan.frames[sl.start + i])}: {msg}" for i, msg in res.warnings]
                bad = ~(np.isfinite(res.vertices).all(axis=(1, 2)) & np.isfinite(res.normals).all(axis=(1, 2)))
                found += [f"{plan.names[j]} frame {int(plan.frames[sl.start + i])}: non-finite vertices"
                          for i in np.nonzero(bad)[0]]
        if found:
            raise InputError(None, f"{len(found)} warning(s) with --strict; first: {found[0]}",
                             "fix the inputs or run without --strict")

    writer = OutputWriter(out, previous)
    try:
        if jobs > 1 and nm > 1:
            try:
                parts = _parallel_mesh_pass(plan, min(jobs, nm), twist_ref, previous, progress)
            except BaseException:
                atomic.remove_stale_temporaries(out)  # a worker stopped mid-write
                raise
        else:
            clock = {"t": time.monotonic(), "cost": 0.0}

            def checkpoint():
                # the in-progress manifest (finished files only), at most every
                # MANIFEST_INTERVAL_S and never more than ~5% of the run's time: on a long run
                # the file list grows to many MB
                now = time.monotonic()
                if now - clock["t"] >= max(MANIFEST_INTERVAL_S, 20.0 * clock["cost"]):
                    write_manifest(out, manifest_dict(plan, writer.files, [], complete=False))
                    clock["cost"] = time.monotonic() - now
                    clock["t"] = time.monotonic()

            parts = [mesh_pass(plan, list(range(nm)), twist_ref, writer, progress, checkpoint)]
        stats = np.zeros((nf, nm, 6))
        warn_text = [[""] * nm for _ in range(nf)]
        lo = np.min([p.lo for p in parts], axis=0)
        hi = np.max([p.hi for p in parts], axis=0)
        all_warns = list(plan.frame_warnings)
        writer.skipped = sum(p.skipped for p in parts)  # (one pass in this process: its writer is ours)
        for part in parts:
            writer.files.update(part.files)
            stats[:, part.muscles] = part.stats
            all_warns += part.warnings
        warnings: list[str] = list(plan.warnings)
        for fi, j, msg in sorted(all_warns, key=lambda w: (w[0], w[1])):
            warn_text[fi][j] = (warn_text[fi][j] + "; " if warn_text[fi][j] else "") + msg
            warnings.append(f"{plan.names[j]} frame {int(plan.frames[fi])}: {msg}")
        bone_rows = np.zeros((nf, len(bones), 7))
        for s0 in range(0, nf, CHUNK_FRAMES):
            sl = slice(s0, min(nf, s0 + CHUNK_FRAMES))
            world = forward_kinematics(plan.pose.skeleton, sample_coordinates(plan.pose, plan.frames[sl]))
            bone_rows[sl, :, :3] = world[:, :, :3, 3]
            bone_rows[sl, :, 3:] = matrix_to_quaternion(world[:, :, :3, :3])

        for i, (_, _, data) in sorted(plan.bone_meshes.items()):
            writer.write(bone_mesh_relpath(bones[i].name), data)

        rows = [["frame", "muscle", "length", "volume", "volume_ratio", "tension", "twist", "scale", "warning"]]
        for i, frame in enumerate(plan.frames):
            for j, name in enumerate(plan.names):
                rows.append([str(int(frame)), name] + [_g(x) for x in stats[i, j]] + [_csv_text(warn_text[i][j])])
        writer.write("stats.csv", _fmt_rows(rows).encode())
        brows = [["frame", "bone", "x", "y", "z", "qw", "qx", "qy", "qz"]]
        for i, frame in enumerate(plan.frames):
            for b, bone in enumerate(bones):
                brows.append([str(int(frame)), bone.name] + [_g(x) for x in bone_rows[i, b]])
        writer.write("bones.csv", _fmt_rows(brows).encode())
        frame_pts = framing(plan)
        extra = {"bounds": [[float(f"{x:.9g}") for x in lo], [float(f"{x:.9g}") for x in hi]],
                 "framing": {"first_frame": int(plan.pose.first), "points": frame_pts.tolist()}}
        if plan.render is not None and plan.render.enabled:
            writer.flush()
            write_manifest(out, manifest_dict(plan, writer.files, warnings, complete=False, extra=extra))
            info = render_run(plan, np.array([lo, hi]), twist_ref, render_progress, frame_pts)
            writer.files.update(info["files"])
            extra["gl"] = {"renderer": info["gl_renderer"], "version": info["gl_version"]}
        writer.flush()
        write_manifest(out, manifest_dict(plan, writer.files, warnings, complete=True, extra=extra))
    except BaseException:
        writer.close(cancel=True)
        raise
    writer.close()
    ratio = stats[..., 2]
    return {
        "out": str(out), "muscles": nm, "frames": nf, "files": len(writer.files), "skipped": writer.skipped,
        "warnings": warnings, "worst_volume_error": float(np.max(np.abs(ratio - 1.0))) if ratio.size else 0.0,
        "stats": stats,
    }


def _csv_text(s: str) -> str:
    if not s:
        return ""
    return '"' + s.replace('"', '""') + '"'


RENDER_CHUNK = 16  # frames per block handed to the renderer (all muscles of a frame at once)


def framing(plan: RunPlan) -> np.ndarray:
    """What the automatic camera frames: the skeleton over the whole pose (not the muscles,
    not the selected frames), rounded to 1 µm so that the manifest holds it exactly."""
    pts = subject_points(plan.pose, {i: v for i, (v, _, _) in plan.bone_meshes.items()})
    return np.round(pts, 6) + 0.0


def render_run(plan: RunPlan, bounds: np.ndarray, twist_ref: np.ndarray, progress=None,
               framing_points: np.ndarray | None = None) -> dict:
    """Render the plan's frames (the muscles evaluated again, block by block: evaluation is
    cheap next to rendering and this keeps memory bounded)."""
    from axdf_cli.render import render_sequence
    from axdf_cli.render.renderer import bone_layout
    from axdf_cli.scene import FrameChunk, Scene, SceneMuscle

    skel = plan.pose.skeleton
    framing_points = framing(plan) if framing_points is None else framing_points
    shown = skel.bones if plan.render.bones else ()
    layout = bone_layout([b.name for b in shown], [b.parent for b in shown],
                         {i: (v, f) for i, (v, f, _) in plan.bone_meshes.items() if shown},
                         float(np.ptp(framing_points, axis=0).max()))
    scene = Scene(
        muscles=tuple(SceneMuscle(s.name, s.color, m.faces) for s, m in zip(plan.muscles, plan.models)),
        bones=layout.bones, bounds=bounds, frames=tuple(int(f) for f in plan.frames),
        framing=framing_points, first_frame=int(plan.pose.first))

    def chunks():
        for sl, world, results in evaluate_chunks(plan, RENDER_CHUNK, twist_ref):
            res = [r for _, r in results]
            yield FrameChunk(frames=plan.frames[sl],
                             positions=tuple(_finite_or_rest(r.vertices, m.rest_vertices) for r, m in zip(res, plan.models)),
                             normals=tuple(_finite_or_rest(r.normals, m.rest_normals) for r, m in zip(res, plan.models)),
                             bone_world=layout.transforms(world))

    return render_sequence(scene, chunks(), plan.render, plan.out, progress=progress)


def _finite_or_rest(x: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(F, V, 3) as float32, frames with non-finite values replaced by the rest shape (as written)."""
    out = x.astype(np.float32)
    bad = ~np.isfinite(out).all(axis=(1, 2))
    out[bad] = rest
    return out
