"""Execution: which sequences this process makes (``--shard K/N``), on what (a local process
pool by default, ``--engine ray`` for a Ray cluster), and the index at the end.

Sequences go to shards by a pure function of their number (``index % N == K``) and each
sequence is made whole by one worker (:func:`axdf_cli.dataset.worker.build_sequence`), whose
draws depend only on (seed, sequence, frame, view): so 1 process, N workers, K shards and a
Ray cluster write the same bytes. Ray is used as it is (tasks, ``ray.wait``); there is no
scheduler here.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

from axdf_cli import runtime
from axdf_cli.fileio import atomic, lock
from axdf_cli.fileio.runfolder import LOCK, Root, remove_stale_staging
from axdf_cli.dataset import folder as dsfolder
from axdf_cli.dataset import worker as wk
from axdf_cli.dataset.index import write_index
from axdf_cli.errors import AxdfError, EnvironmentProblem, InputError, Interrupted
from axdf_cli.pipeline.overlap import overlaps_in_bulk
from axdf_cli.workers import WorkerDied, one_thread, process_map

ENGINES = ("local", "ray")


@dataclass
class Outcome:
    """What a build did (printed by the CLI; nothing of it goes into files)."""

    out: Path
    sequences: int = 0  # sequences of this run (this shard)
    built: int = 0
    skipped: int = 0  # complete already (--resume)
    samples: int = 0  # samples of this run
    built_samples: int = 0  # samples of the sequences made now (not kept by --resume)
    seconds: float = 0.0
    timing: dict = field(default_factory=lambda: {"run": 0.0, "read": 0.0, "render": 0.0, "write": 0.0, "cpu": 0.0})
    index: Path | None = None
    rows: int = 0
    missing: list = field(default_factory=list)  # sequences of the data set not complete yet
    gl_renderer: str = ""
    # With contact, over the sequences made now: frames measured, the sum of their share of
    # vertices inside another muscle over those frames, and how many sequences overlap in bulk
    # (their manifests say so; axdf_cli.pipeline.overlap.overlaps_in_bulk)
    overlap_frames: int = 0
    overlap_sum: float = 0.0
    overlap_bulk: int = 0

    @property
    def overlap(self) -> float | None:
        """The share of the vertices made now inside another muscle after contact (mean over
        the frames of the sequences made now); None without contact or sequences."""
        return self.overlap_sum / self.overlap_frames if self.overlap_frames else None


class WorkerFailed(AxdfError):
    """A worker process died or failed; the sequences it left are named (exit 3: --resume finishes)."""

    exit_code = 3


# ----------------------------------------------------------------------------- the output folder


def check_out(out: Path, ctx: wk.Context, mine: list[int], resume: bool, overwrite: bool,
              shards: int = 1) -> dsfolder.DatasetTarget:
    """Every check of OUT before anything is written (dataset/folder.py): what it holds,
    whether this build may write it, no links on the way to any folder it writes."""
    names = [ctx.sequences[i].name for i in mine]
    dirs = dsfolder.sequence_dirs(names, ctx.spec.views, ctx.names, ctx.spec.format)
    return dsfolder.check(out, ctx.dataset_json, names, dirs, resume=resume, overwrite=overwrite, shards=shards)


def claim(target: dsfolder.DatasetTarget, ctx: wk.Context, mine: list[int], resume: bool, shared: bool) -> int:
    """Create OUT, lock it (exclusive while claiming), check that it is still what
    :func:`check_out` saw, write dataset.json and the bone meshes (into the staging folder
    when replacing another data set); returns the lock's descriptor (shared afterwards when
    ``shared``: the shards of one data set write side by side)."""
    out = target.out
    atomic.ensure_dir(out)
    fd = lock.lock_folder(out, what=str(out))
    try:
        dj = out / wk.DATASET_JSON
        now = dj.read_bytes() if dj.is_file() and not dj.is_symlink() else None
        if (now not in (None, ctx.dataset_json) if target.mode == "new" else
                now is None or hashlib.sha256(now).hexdigest() != target.old.sha):
            raise InputError(None, f"output folder {out} changed while axdf was checking it",
                             "another process wrote there; run again")
        remove_stale_staging(out)  # a killed --overwrite's new data set (no other writer: we hold OUT)
        root = target.root
        if target.mode == "replace":
            shutil.rmtree(root, ignore_errors=True)
        atomic.ensure_dir(root)
        names = [ctx.sequences[i].name for i in mine]
        if resume:  # temporaries and lock files of a killed build in the data set's own folders
            folders = [root, root / dsfolder.BONES]
            for n in names:
                folders += [root / n] + [root / n / "views" / v for v in ctx.spec.views]
                lock.remove_stale_lock(root / n / LOCK)
            atomic.remove_stale_temporaries(folders)
        rroot = Root(root)
        if not (root / wk.DATASET_JSON).is_file() or (root / wk.DATASET_JSON).read_bytes() != ctx.dataset_json:
            atomic.write_bytes(rroot.path(wk.DATASET_JSON), ctx.dataset_json)
        for i, (_, _, data) in sorted(ctx.bone_meshes.items()):
            p = rroot.path(f"{dsfolder.BONES}/{ctx.skeleton.bones[i].name}.ply")
            if not (p.is_file() and not p.is_symlink() and p.read_bytes() == data):
                atomic.write_bytes(p, data)
        if shared:
            lock.relock_folder(fd, True, str(out))
    except BaseException:
        dsfolder.discard_staging(target)
        lock.unlock_folder(fd)
        raise
    return fd


# ----------------------------------------------------------------------------- workers


def _safe_build(ctx: wk.Context, index: int, out: Path, resume: bool) -> tuple:
    """Run one sequence; errors come back as values (they cross process boundaries intact)."""
    try:
        rec, timing = wk.build_sequence(ctx, index, out, resume)
        vr = wk.RENDERERS.get(os.getpid())
        return ("ok", index, rec, timing, vr.info.renderer if vr else "")
    except InputError as e:
        return ("input", index, str(e), None, "")
    except EnvironmentProblem as e:
        return ("env", index, e.problem, e.hint, "")
    except (KeyboardInterrupt, Interrupted):
        return ("interrupt", index, "interrupted", None, "")
    except Exception as e:  # a bug: reported with the sequence's name
        return ("bug", index, f"{type(e).__name__}: {e}", None, "")


_CONTEXTS: dict = {}  # a worker process's contexts, by (dataset file, seed, folder)


def worker_context(where: tuple) -> wk.Context:
    """The context in a worker process (pool or Ray), built once from the dataset file: the
    worker works in the driver's folder (manifests name inputs relative to it) under the
    driver's path policy. ``where`` = (dataset file, seed, folder, policy roots, allow_outside)."""
    from axdf_cli.specs import RefPolicy

    path, seed, cwd, roots, allow_outside = where
    # the workers are the parallelism: each renders with one llvmpipe thread (Mesa's default is
    # one per core, which oversubscribes the cores N workers share); a value you set is kept
    os.environ.setdefault("LP_NUM_THREADS", "1")
    runtime.configure()  # (a Ray worker is a fresh interpreter)
    one_thread()  # contact's kernels likewise: one thread each
    os.chdir(cwd)
    ctx = _CONTEXTS.get(where)
    if ctx is None:
        policy = RefPolicy(tuple(Path(r) for r in roots), allow_outside)
        ctx = _CONTEXTS[where] = wk.build_context(path, seed, policy)
    return ctx


def _worker_task(where: tuple, out: str, index: int, resume: bool) -> tuple:
    """One sequence in a worker process (a pool's or a Ray task)."""
    return _safe_build(worker_context(where), index, Path(out), resume)


def _where(path, seed, policy) -> tuple:
    return (str(Path(path).resolve()), seed, str(Path.cwd()), tuple(str(r) for r in policy.roots),
            bool(policy.allow_outside))


def _raise_failure(ctx: wk.Context, result: tuple, left: list[int]) -> None:
    kind, index, msg, hint, _ = result
    name = ctx.sequences[index].name
    if kind == "input":
        raise InputError(None, f"{name}: {msg}")
    if kind == "interrupt":
        raise Interrupted("interrupted")
    rest = f"; not finished: {_names(ctx, left)}" if left else ""
    if kind == "env":
        raise EnvironmentProblem(f"{name}: {msg}{rest}", hint or "fix the cause, then rerun with --resume")
    raise WorkerFailed(f"{name} failed in a worker: {msg}{rest}; rerun with --resume to finish "
                       "(with --jobs 1 --traceback to see where it fails)")


def _names(ctx: wk.Context, indices: list[int], at_most: int = 8) -> str:
    names = [ctx.sequences[i].name for i in sorted(indices)]
    more = f" and {len(names) - at_most} more" if len(names) > at_most else ""
    return ", ".join(names[:at_most]) + more


def _samples(ctx: wk.Context, index: int) -> int:
    return ctx.sequences[index].n_frames * len(ctx.spec.views)


def _run_local(ctx, mine, out, jobs, resume, done, where) -> None:
    if jobs <= 1 or len(mine) <= 1:  # in this process: errors propagate as they are (--traceback)
        try:
            for i in mine:
                rec, timing = wk.build_sequence(ctx, i, out, resume)
                vr = wk.RENDERERS.get(os.getpid())
                done(("ok", i, rec, timing, vr.info.renderer if vr else ""))
        finally:
            wk.release_renderer()
        return
    # Workers come from a fork server (a fresh interpreter), never from this process: a GL
    # driver used here before would hang in a forked child (run.pool.process_map, as
    # `axdf run --jobs` renders). Each worker builds the context once from the (already
    # checked) dataset file.
    left = set(mine)

    def finished(r: tuple) -> None:
        left.discard(r[1])
        if r[0] != "ok":
            _raise_failure(ctx, r, sorted(left))
        done(r)

    try:
        process_map(_pool_task, list(mine), (where, str(Path(out).resolve()), resume), jobs=jobs,
                    on_result=finished, fresh=True, preload=("axdf_cli.dataset.worker",))
    except WorkerDied:
        raise WorkerFailed(f"a worker process died (killed, or out of memory) while making "
                           f"{_names(ctx, sorted(left))}; the other sequences of this run are complete; "
                           "rerun the same command with --resume to finish") from None


def _pool_task(shared: tuple, index: int) -> tuple:
    where, out, resume = shared
    return _worker_task(where, out, index, resume)


def _run_ray(ray, ctx, mine, out, resume, done, where) -> None:
    """One Ray task per sequence on a started Ray (:class:`raycluster.RayEngine`). Stopped
    (Ctrl-C, SIGTERM, a failure): Ray is shut down with its workers, and what they leave is
    cleaned (:func:`clean_stopped`)."""
    task = ray.remote(num_cpus=1)(_worker_task)
    refs = {task.remote(where, str(Path(out).resolve()), i, resume): i for i in mine}
    left = set(mine)
    # stopped, no ray.cancel: cancelling tasks as they complete trips a check inside Ray (2.60:
    # "Tried to complete task that was not pending", abort); Ray is shut down instead
    while refs:
        ready, _ = ray.wait(list(refs), num_returns=1)
        i = refs.pop(ready[0])
        try:
            r = ray.get(ready[0])
        except Exception as e:  # ray.exceptions.RayError: the worker died, or the task could not run
            raise WorkerFailed(f"Ray task for {ctx.sequences[i].name} failed ({type(e).__name__}); "
                               f"not finished: {_names(ctx, sorted(left))}; rerun with --resume to finish") from None
        left.discard(i)
        if r[0] != "ok":
            _raise_failure(ctx, r, sorted(left))
        done(r)


def clean_stopped(root: Path, names: list[str], views) -> None:
    """After workers were killed (a stopped Ray build): in this build's sequence folders, the
    temporaries and staging folders of processes that are gone and lock files nobody holds
    (never a live process's, never through a link)."""
    from axdf_cli.fileio import runfolder

    for n in names:
        folder = Path(root) / n
        if not folder.is_dir() or folder.is_symlink():
            continue
        lock.remove_stale_lock(folder / LOCK)
        try:
            runfolder.remove_stale(folder)
        except OSError:
            pass
        atomic.remove_stale_temporaries([folder / "views" / v for v in views])


# ----------------------------------------------------------------------------- build and merge


def build(path: Path | str, out: Path | str, *, seed: int | None = None, jobs: int = 1, shard=(0, 1),
          engine: str = "local", address: str | None = None, resume: bool = False, overwrite: bool = False,
          progress=None, policy=None, ctx: wk.Context | None = None) -> Outcome:
    """Make this run's sequences (``shard`` = (K, N)); write the index when the whole data set
    is complete. ``progress(samples)`` is called as sequences finish; ``policy``: the command's
    RefPolicy (the workers read the inputs with it).

    Order: every check of OUT (reads only), then the engine (a Ray address that does not
    answer is refused here), then OUT is locked and written (dataset/folder.py)."""
    out = Path(out)
    ctx = ctx or wk.build_context(path, seed, policy)
    k, n = shard
    mine = [s.index for s in ctx.sequences if s.index % n == k]
    target = check_out(out, ctx, mine, resume, overwrite, n)
    ray_engine = None
    if engine == "ray":
        from axdf_cli.dataset.raycluster import RayEngine

        ray_engine = RayEngine(address, jobs)
    with contextlib.ExitStack() as stack:
        if ray_engine is not None:  # (runs last: once Ray and its workers are gone)
            stack.callback(clean_stopped, target.root, [ctx.sequences[i].name for i in mine], ctx.spec.views)
        ray = stack.enter_context(ray_engine) if ray_engine is not None else None
        fd = claim(target, ctx, mine, resume, shared=n > 1 and target.mode != "replace")
        stack.callback(lock.unlock_folder, fd)
        stack.callback(dsfolder.discard_staging, target)
        res = Outcome(out, sequences=len(mine), samples=sum(_samples(ctx, i) for i in mine))
        t0 = time.perf_counter()

        def done(r):
            _, i, _, timing, renderer = r
            if timing.get("skipped"):
                res.skipped += 1
            else:
                res.built += 1
                res.built_samples += _samples(ctx, i)
                for key in res.timing:
                    res.timing[key] += timing[key]
                if "overlap" in timing:
                    share, frames = timing["overlap"]
                    res.overlap_frames += frames
                    res.overlap_sum += share * frames
                    res.overlap_bulk += overlaps_in_bulk(share)
            res.gl_renderer = res.gl_renderer or renderer
            if progress:
                progress(_samples(ctx, i))

        where = _where(path, seed, ctx.spec.policy)
        if ray is not None:
            _run_ray(ray, ctx, mine, target.root, resume, done, where)
        else:
            _run_local(ctx, mine, target.root, jobs, resume, done, where)
        res.seconds = time.perf_counter() - t0
        idx, rows, missing = finish(target.root, ctx.dataset_json)
        if target.mode == "replace":
            if missing:  # (cannot happen: one process made every sequence)
                raise WorkerFailed(f"the new data set is incomplete ({', '.join(missing[:3])}); the old one stays")
            dsfolder.commit_replace(target)
            idx = out / wk.INDEX
        res.index, res.rows, res.missing = idx, rows, missing
    return res


def finish(out: Path, dataset_json: bytes) -> tuple[Path | None, int, list[str]]:
    """Write ``OUT/index.parquet`` when every sequence is complete: (path or None, rows,
    missing names)."""
    idx, rows, missing = _finish(out, dataset_json)
    return idx, rows, [name for name, _ in missing]


def _finish(out: Path, dataset_json: bytes) -> tuple[Path | None, int, list[tuple[str, str]]]:
    d = json.loads(dataset_json)
    digest = hashlib.sha256(dataset_json).hexdigest()
    records, missing = [], []
    for s in d["sequences"]:
        rec, why = wk.record_state(Path(out) / s["name"], digest)
        if rec is None:
            missing.append((s["name"], why))
        else:
            records.append(rec)
    if missing:
        return None, 0, missing
    write_index(out, records, d["seed"], d["shards"], d["image"]["passes"])
    rows = sum(len(r["frames"]) * len(r["views"]) for r in records)
    return Path(out) / wk.INDEX, rows, []


def merge(out: Path | str) -> tuple[Path, int]:
    """``axdf dataset merge OUT``: join the shards' sequences into the index (OUT locked; a
    folder that holds no axdf data set, or a damaged dataset.json, is exit 2 with its
    position)."""
    out = Path(out)
    m = dsfolder.check_merge(out)
    fd = lock.lock_folder(out, what=str(out))
    try:
        data = (out / wk.DATASET_JSON).read_bytes()
        if hashlib.sha256(data).hexdigest() != m.sha:
            raise InputError(None, f"{out / wk.DATASET_JSON} changed while axdf was reading it", "run again")
        idx, rows, missing = _finish(out, data)
    finally:
        lock.unlock_folder(fd)
    if missing:
        other = [n for n, why in missing if why.startswith("made for another data set")]
        names = [n for n, _ in missing]
        more = f" and {len(missing) - 8} more" if len(missing) > 8 else ""
        if other:
            raise InputError(m.mark(("seed",)), f"{len(other)} sequence(s) of {out} were made for another data set "
                             f"than its dataset.json (other seed, inputs or settings; first: {other[0]}); "
                             f"{len(missing)} not complete: {', '.join(names[:8])}{more}",
                             "build every shard with the same dataset file and --seed (rerun the others with "
                             "--overwrite), then merge")
        raise InputError(None, f"{len(missing)} sequence(s) of {out} are not complete: {', '.join(names[:8])}{more} "
                         f"({missing[0][0]}: {missing[0][1]})",
                         "finish every shard (rerun it with --resume), then merge")
    return idx, rows


# ----------------------------------------------------------------------------- a dry run's estimate
#: frames of the sampled sequences a dry run makes and times, in order: the first warms the
#: process (imports, the GL context, the kernels: what a worker pays once), the other two give
#: a sequence's own cost and each sample's (their difference)
PROBE_FRAMES = (1, 2, 6)


@dataclass
class Probe:
    """What small sequences of a data set cost to make (``axdf dataset build --dry-run``)."""

    samples: int  # samples made by the longest probe (frames x views)
    seconds: float  # wall time of the probes' builds (process set-up, GL context included)
    per_sample: float  # seconds per sample beyond a sequence's own (phases run, read, render, write)
    per_sequence: float  # seconds a sequence costs whatever its length (its set-up, its first frame's)
    bytes_per_sample: float  # bytes written per sample (meshes, images, labels, the sequence's files)
    timing: dict  # the longest probe's phases' seconds (Outcome.timing)


def probe(ctx: wk.Context, path) -> Probe:
    """Make and time sampled sequences of PROBE_FRAMES frames (a uniform pose sample, the data
    set's muscles, stages, views, render size and passes) in a temporary folder that is removed
    after: what each sequence and each sample of the data set cost on this machine, fitted as
    ``a + b samples`` to the last two (the inputs' own motions are not made: a take's fit is not
    measured)."""
    import tempfile

    from axdf_cli.dataset.spec import Entry, expand_sequences

    tmp = Path(tempfile.mkdtemp(prefix="axdf-dry-run-"))
    made, wall = [], 0.0
    try:
        for k, frames in enumerate(PROBE_FRAMES):
            spec = replace(ctx.spec, entries=(Entry("uniform", 1, None, frames, None, {}),), shards=1)
            small = replace(ctx, spec=spec, sequences=expand_sequences(spec))
            small.dataset_json = (json.dumps(wk.dataset_dict(small), indent=1) + "\n").encode()
            small.digest = hashlib.sha256(small.dataset_json).hexdigest()
            t0 = time.perf_counter()
            res = build(path, tmp / f"probe{k}", ctx=small, policy=ctx.spec.policy)
            wall += time.perf_counter() - t0
            seq = tmp / f"probe{k}" / small.sequences[0].name
            size = sum(f.stat().st_size for f in seq.rglob("*") if f.is_file())
            cost = sum(v for key, v in res.timing.items() if key in ("run", "read", "render", "write"))
            made.append((max(1, res.built_samples), cost, size, dict(res.timing)))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    (na, ta, _, _), (nb, tb, size, timing) = made[-2], made[-1]
    per = (tb - ta) / (nb - na) if nb > na and tb > ta else tb / nb
    return Probe(nb, wall, per, max(ta - per * na, 0.0), size / nb, timing)
