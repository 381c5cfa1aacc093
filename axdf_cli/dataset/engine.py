"""Execution: which sequences this process makes (``--shard K/N``), on what (a local process
pool by default, ``--engine ray`` for a Ray cluster), and the index at the end.

Sequences go to shards by a pure function of their number (``index % N == K``) and each
sequence is made whole by one worker (:func:`axdf_cli.dataset.worker.build_sequence`), whose
draws depend only on (seed, sequence, frame, view): so 1 process, N workers, K shards and a
Ray cluster write the same bytes. Ray is used as it is (tasks, ``ray.wait``); there is no
scheduler here.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path

from axdf_cli.fileio import atomic
from axdf_cli.dataset import worker as wk
from axdf_cli.dataset.index import write_index
from axdf_cli.errors import AxdfError, EnvironmentProblem, InputError, Interrupted, Mark
from axdf_cli.dataset import door
from axdf_cli.dataset.door import own_entry
from axdf_cli.fileio.yamlio import is_name

ENGINES = ("local", "ray")
RAY_HINT = "pip install 'ray>=2.9' (or the project's extra: pip install -e '.[ray]')"


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


class WorkerFailed(AxdfError):
    """A worker process died or failed; the sequences it left are named (exit 3: --resume finishes)."""

    exit_code = 3


# ----------------------------------------------------------------------------- the output folder


def prepare_out(out: Path, ctx: wk.Context, mine: list[int], resume: bool, overwrite: bool) -> None:
    """Refuse an OUT that holds something else; make room for this run's sequences."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(None, f"--out {out} exists and is not a folder", "give a folder")
    names = [ctx.sequences[i].name for i in mine]
    dj = out / wk.DATASET_JSON
    for n in names + ["bones"]:
        if os.path.islink(out / n):
            raise InputError(None, f"{out / n} is a link", "a data set's folders are plain folders (no links)")
    if out.is_dir() and any(not own_entry(n) for n in os.listdir(out)):
        old = _read_dataset_json(dj)
        if old is None:
            raise InputError(None, f"output folder {out} is not empty and holds no axdf data set (no dataset.json "
                             "written by axdf)", "--overwrite and --resume only replace or finish axdf's own data "
                             "sets; choose an empty or new output folder")
        same = dj.read_bytes() == ctx.dataset_json
        if not same and not overwrite:
            raise InputError(None, f"output folder {out} holds another data set (its dataset.json differs: "
                             "other inputs, settings or seed)",
                             "pass --overwrite to replace it, or another --out (shards of one data set share one --out)")
        if not same:  # --overwrite: remove what the old data set wrote there, nothing else
            olds = [s.get("name") for s in old.get("sequences", []) if isinstance(s, dict)]
            for n in sorted({n for n in olds if is_name(n)} | set(names)):
                if not os.path.islink(out / n):
                    shutil.rmtree(out / n, ignore_errors=True)
            shutil.rmtree(out / "bones", ignore_errors=True)
            for f in (wk.DATASET_JSON, wk.INDEX):
                (out / f).unlink(missing_ok=True)
        else:
            present = [n for n in names if (out / n).exists()]
            if present and not (resume or overwrite):
                raise InputError(None, f"{len(present)} sequence folder(s) of this run exist in {out} "
                                 f"(first: {present[0]})",
                                 "pass --resume to finish them, --overwrite to make them again, or another --out")
            if overwrite:
                for n in present:
                    shutil.rmtree(out / n)
    atomic.ensure_dir(out)
    if resume:  # temporaries of a killed build in the data set's own folders (a run cleans its own)
        folders = [out, out / "bones"]
        for n in names:
            folders += [out / n] + [out / n / "views" / v for v in ctx.spec.views]
        atomic.remove_stale_temporaries(folders)
    atomic.write_bytes(dj, ctx.dataset_json)
    for i, (_, _, data) in sorted(ctx.bone_meshes.items()):
        p = out / "bones" / f"{ctx.skeleton.bones[i].name}.ply"
        if not (p.is_file() and p.read_bytes() == data):
            atomic.write_bytes(p, data)


# ----------------------------------------------------------------------------- workers


def _read_dataset_json(path: Path) -> dict | None:
    """An axdf data set's dataset.json, or None when ``path`` is not one."""
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return d if isinstance(d, dict) and d.get("tool") == "axdf" and "dataset" in d else None


def _safe_build(ctx: wk.Context, index: int, out: Path, resume: bool) -> tuple:
    """Run one sequence; errors come back as values (they cross process boundaries intact)."""
    try:
        rec, timing = wk.build_sequence(ctx, index, out, resume)
        vr = wk._RENDERERS.get(os.getpid())
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
                vr = wk._RENDERERS.get(os.getpid())
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
        door.process_map(_pool_task, list(mine), (where, str(Path(out).resolve()), resume), jobs=jobs,
                           on_result=finished, fresh=True, preload=("axdf_cli.dataset.worker",))
    except door.WorkerDied:
        raise WorkerFailed(f"a worker process died (killed, or out of memory) while making "
                           f"{_names(ctx, sorted(left))}; the other sequences of this run are complete; "
                           "rerun the same command with --resume to finish") from None


def _pool_task(shared: tuple, index: int) -> tuple:
    where, out, resume = shared
    return _worker_task(where, out, index, resume)


def _run_ray(ctx, mine, out, jobs, resume, done, address, where) -> None:
    try:
        import ray
    except ImportError:
        raise EnvironmentProblem("cannot import ray (--engine ray)", RAY_HINT) from None
    started = False
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=False)
        else:
            ray.init(num_cpus=jobs, include_dashboard=False, log_to_driver=False)
        started = True
    try:
        task = ray.remote(num_cpus=1)(_worker_task)
        refs = {task.remote(where, str(Path(out).resolve()), i, resume): i for i in mine}
        left = set(mine)
        while refs:
            ready, _ = ray.wait(list(refs), num_returns=1)
            i = refs.pop(ready[0])
            try:
                r = ray.get(ready[0])
            except Exception as e:  # ray.exceptions.RayError: the worker died, or the task could not run
                for ref in refs:
                    ray.cancel(ref, force=True)
                raise WorkerFailed(f"Ray task for {ctx.sequences[i].name} failed ({type(e).__name__}); "
                                   f"not finished: {_names(ctx, sorted(left))}; rerun with --resume to finish") from None
            left.discard(i)
            if r[0] != "ok":
                for ref in refs:
                    ray.cancel(ref, force=True)
                _raise_failure(ctx, r, sorted(left))
            done(r)
    finally:
        if started:
            ray.shutdown()


# ----------------------------------------------------------------------------- build and merge


def build(path: Path | str, out: Path | str, *, seed: int | None = None, jobs: int = 1, shard=(0, 1),
          engine: str = "local", address: str | None = None, resume: bool = False, overwrite: bool = False,
          progress=None, policy=None, ctx: wk.Context | None = None) -> Outcome:
    """Make this run's sequences (``shard`` = (K, N)); write the index when the whole data set
    is complete. ``progress(samples)`` is called as sequences finish; ``policy``: the command's
    RefPolicy (the workers read the inputs with it)."""
    out = Path(out)
    ctx = ctx or wk.build_context(path, seed, policy)
    k, n = shard
    mine = [s.index for s in ctx.sequences if s.index % n == k]
    prepare_out(out, ctx, mine, resume, overwrite)
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
        res.gl_renderer = res.gl_renderer or renderer
        if progress:
            progress(_samples(ctx, i))

    where = _where(path, seed, ctx.spec.policy)
    if engine == "ray":
        _run_ray(ctx, mine, out, jobs, resume, done, address, where)
    else:
        _run_local(ctx, mine, out, jobs, resume, done, where)
    res.seconds = time.perf_counter() - t0
    idx, rows, missing = finish(out, ctx.dataset_json)
    res.index, res.rows, res.missing = idx, rows, missing
    return res


def finish(out: Path, dataset_json: bytes) -> tuple[Path | None, int, list[str]]:
    """Write ``OUT/index.parquet`` when every sequence is complete: (path or None, rows, missing names)."""
    import hashlib

    d = json.loads(dataset_json)
    digest = hashlib.sha256(dataset_json).hexdigest()
    records, missing = [], []
    for s in d["sequences"]:
        rec = wk.read_record(Path(out) / s["name"], digest)
        if rec is None:
            missing.append(s["name"])
        else:
            records.append(rec)
    if missing:
        return None, 0, missing
    write_index(out, records, d["seed"], d["shards"], d["image"]["passes"])
    rows = sum(len(r["frames"]) * len(r["views"]) for r in records)
    return Path(out) / wk.INDEX, rows, []


def merge(out: Path | str) -> tuple[Path, int]:
    """``axdf dataset merge OUT``: join the shards' sequences into the index."""
    out = Path(out)
    dj = out / wk.DATASET_JSON
    try:
        data = dj.read_bytes()
        json.loads(data)
    except FileNotFoundError:
        raise InputError(Mark(str(dj)), "no dataset.json", "give a folder written by axdf dataset build") from None
    except (OSError, ValueError) as e:
        raise InputError(Mark(str(dj)), f"unreadable dataset.json ({e})", "give a folder written by axdf dataset build") \
            from None
    idx, rows, missing = finish(out, data)
    if missing:
        more = f" and {len(missing) - 8} more" if len(missing) > 8 else ""
        raise InputError(None, f"{len(missing)} sequence(s) of {out} are not complete: {', '.join(missing[:8])}{more}",
                         "finish every shard (rerun it with --resume), then merge")
    return idx, rows
