"""Worker processes: the mesh pass, the render pass, the EGL check and a data set's sequences.

:func:`process_map` runs ``fn(shared, item)`` for each item in a pool of worker processes
and returns the results in order (``on_result`` sees each as it arrives). Workers come
either

- forked from this process (``fresh=False``): ``shared`` (the plan, the twist references
  ...) reaches them by fork, not by pickling. Never for work that renders: a GL driver used
  in this process before (llvmpipe's thread pool) hangs a forked child that renders; or
- from a fork server (``fresh=True``), a fresh interpreter that has imported ``preload``
  and never touched GL, so each worker makes its own GL context whatever this process did
  before. ``shared`` is pickled once per worker; the workers work in this process's current
  folder and render with one llvmpipe thread each (the workers are the parallelism; Mesa's
  default of one thread per core oversubscribes the cores they share; a value you set is
  kept).

A worker runs the contact stage's kernels on its own thread (:func:`axdf_cli.runtime.one_thread`),
where a single process (``--jobs 1``) runs them on numba's threads: N workers with a thread per core
each would oversubscribe the cores they share (and a worker that starts numba's threads
leaves a semaphore behind when it is stopped). The bytes do not depend on it.

Workers never outlive the parent: a forked worker asks the kernel for SIGTERM when its
parent dies (``prctl(PR_SET_PDEATHSIG)`` on Linux) and checks its parent between chunks
(:func:`check_parent`); a fork server's worker (whose parent is the fork server, which
lives as long as any of its workers does) watches this process with a thread that waits on
a pidfd (``os.pidfd_open``; polling where there is none) and sends itself SIGTERM when this
process is gone. A worker stopped by SIGTERM (the parent stopping the pool, or the
parent's death) finishes the file it is writing, then exits quietly, also when its task
catches the interrupt; Ctrl-C goes to the parent only, which stops the pool (workers and the
fork server start with SIGINT blocked: :func:`_sigint_held`). No worker
prints a traceback for being stopped. A worker that dies (killed, out of memory) stops the
pool with :class:`WorkerDied` (exit 3).
"""
from __future__ import annotations

import contextlib
import os
import signal
import threading

from axdf_cli import runtime
from axdf_cli.errors import EnvironmentProblem
from axdf_cli.fileio import atomic
from axdf_cli.runtime import THREADS_VAR, one_thread  # noqa: F401  (a worker's switch, for its callers)

_STATE = {"parent": None, "in_task": False, "stopping": False}
_SHARED: dict = {}  # a worker's ``shared``
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


class WorkerDied(EnvironmentProblem):
    """A worker process died without a result (killed, out of memory): exit 3."""

    def __reduce__(self):
        return WorkerDied, (self.problem, self.hint)


def _die_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: check_parent() between chunks remains
        pass


def _on_sigterm(signum, frame) -> None:
    if not _STATE["in_task"]:
        os._exit(128 + signum)  # between tasks nothing is being written
    _STATE["stopping"] = True
    atomic.on_signal(signum, frame)  # KeyboardInterrupt once the current file is whole


def _watch(pid: int) -> None:
    """In a fork server's worker: SIGTERM to itself once process ``pid`` (the pool's owner,
    not this worker's parent) has ended."""
    import select
    import time

    try:
        fd = os.pidfd_open(pid)
    except (AttributeError, OSError):  # no pidfd (old kernel, not Linux), or gone already
        fd = None

    def wait() -> None:
        if fd is not None:
            select.select([fd], [], [])  # readable once the process has ended
        else:
            while True:
                try:
                    os.kill(pid, 0)
                except ProcessLookupError:
                    break
                except PermissionError:
                    pass
                time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=wait, name="axdf-parent-watch", daemon=True).start()


def _init_worker(owner: int, shared, cwd: str | None) -> None:
    """Each worker's start (nothing here may raise: the executor would print a traceback).
    ``cwd``: None for a forked worker, the owner's current folder for a fork server's."""
    fresh = cwd is not None
    runtime.configure()  # (a fork server's worker is a fresh interpreter; a forked one: already done)
    one_thread()
    _STATE["parent"] = os.getppid() if fresh else owner
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    atomic.catch_interrupts_in_callbacks()
    _die_with_parent()
    check_parent()
    _SHARED["value"] = shared
    if fresh:
        _watch(owner)
        os.environ.setdefault("LP_NUM_THREADS", "1")
        try:
            os.chdir(cwd)  # where the owner is now (relative paths)
        except OSError:
            pass  # the task's own file access reports it


def check_parent() -> None:
    """In a worker: stop (quietly) when the parent process is gone."""
    if _STATE["parent"] is not None and os.getppid() != _STATE["parent"]:
        os._exit(1)


def _call(fn, item):
    _STATE["in_task"] = True
    try:
        return fn(_SHARED["value"], item)
    except KeyboardInterrupt:
        os._exit(130)  # stopped while working: the writer has finished its file
    finally:
        _STATE["in_task"] = False
        if _STATE["stopping"]:  # the task caught the interrupt itself: still stop
            os._exit(130)


def _stop(pool) -> None:
    """SIGTERM to every worker (each finishes its file), then wait for them."""
    for p in list((getattr(pool, "_processes", None) or {}).values()):  # (Python 3.14: terminate_workers())
        try:
            p.terminate()
        except (OSError, ValueError, AttributeError):
            pass
    pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def _sigint_held():
    """SIGINT blocked in this thread while the pool starts its processes. A child inherits
    the mask (through fork, and through the fork server's exec and forks), so a Ctrl-C to
    the whole process group while a worker starts, or while the fork server imports its
    preload, is never a KeyboardInterrupt traceback there (the fork server ignores SIGINT
    only once its imports are done, a worker once :func:`_init_worker` runs); this
    process gets the signal when it is unblocked: held, not lost (as multiprocessing's own
    resource tracker is started)."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def process_map(fn, items: list, shared, *, jobs: int | None = None, on_result=None, fresh: bool = False,
                preload: tuple[str, ...] = ()) -> list:
    """``[fn(shared, item) for item in items]`` over ``jobs`` worker processes (default one
    per item); ``on_result(result)`` is called in this process as each result arrives (in
    the order they finish) and may raise to stop the pool. ``fn`` and the items and results
    must pickle (``fn`` a module-level function). Any error, here or in a worker, stops
    every worker and is raised here; a worker that dies raises :class:`WorkerDied`."""
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    if not items:
        return []
    n = max(1, min(jobs or len(items), len(items)))
    if fresh:
        ctx = mp.get_context("forkserver")
        ctx.set_forkserver_preload(list(preload))  # (takes effect when the fork server starts)
        initargs = (os.getpid(), shared, os.getcwd())
    else:
        ctx = mp.get_context("fork")
        initargs = (os.getpid(), shared, None)
    pool = ProcessPoolExecutor(max_workers=n, mp_context=ctx, initializer=_init_worker, initargs=initargs)
    try:
        with _sigint_held():  # workers (and a fork server) start with SIGINT blocked, for good
            pending = {pool.submit(_call, fn, item): k for k, item in enumerate(items)}
        results: list = [None] * len(items)
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in sorted(finished, key=pending.get):
                k = pending.pop(fut)
                try:
                    results[k] = fut.result()
                except BrokenProcessPool:
                    raise WorkerDied("a worker process died (killed, or out of memory)",
                                     "rerun the same command with --resume to finish") from None
                if on_result:
                    on_result(results[k])
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown(wait=True)
    return results


def in_child(fn, arg):
    """``fn(arg)`` in a forked process (state it creates, such as a GL context, stays there)."""
    return process_map(_apply, [arg], fn)[0]


def _apply(fn, arg):
    return fn(arg)
