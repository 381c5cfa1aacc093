"""Forked worker processes: the mesh pass (and the EGL check) in processes of their own.

:func:`fork_map` runs ``fn(shared, item)`` for each item in its own forked process and
returns the results in order. ``shared`` (the plan, the twist references ...) reaches the
workers by fork, not by pickling; only the items and the results are pickled.

Workers never outlive the parent: each asks the kernel for SIGTERM when its parent dies
(``prctl(PR_SET_PDEATHSIG)`` on Linux) and checks ``os.getppid()`` (everywhere, also
between chunks through :func:`check_parent`). A worker stopped by SIGTERM (the parent
stopping the pool, or the parent's death) finishes the file it is writing, then exits
quietly; Ctrl-C goes to the parent only, which stops the pool. No worker prints a traceback
for being stopped.
"""
from __future__ import annotations

import os
import signal

from axdf_cli import atomic

_SHARED: dict = {}  # set in the parent just before the workers fork
_STATE = {"parent": None, "in_task": False}
PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _die_with_parent() -> None:
    try:
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM), 0, 0, 0)
    except (OSError, AttributeError):  # not Linux: check_parent() between chunks remains
        pass


def _on_sigterm(signum, frame) -> None:
    if not _STATE["in_task"]:
        os._exit(128 + signum)  # between tasks nothing is being written
    atomic.on_signal(signum, frame)  # KeyboardInterrupt once the current file is whole


def _init_worker(parent: int) -> None:
    _STATE["parent"] = parent
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    _die_with_parent()
    check_parent()


def check_parent() -> None:
    """In a worker: stop (quietly) when the parent process is gone."""
    if _STATE["parent"] is not None and os.getppid() != _STATE["parent"]:
        os._exit(1)


def _call(task):
    fn, item = task
    _STATE["in_task"] = True
    try:
        return fn(_SHARED["value"], item)
    except KeyboardInterrupt:
        os._exit(130)  # stopped while working: the writer has finished its file
    finally:
        _STATE["in_task"] = False


def fork_map(fn, items: list, shared, on_result=None) -> list:
    """``[fn(shared, item) for item in items]``, each call in a forked process; ``on_result``
    is called in the parent with each result as it arrives. Any error stops every worker."""
    import multiprocessing as mp

    _SHARED["value"] = shared
    pool = mp.get_context("fork").Pool(len(items), initializer=_init_worker, initargs=(os.getpid(),))
    try:
        results = []
        for r in pool.imap(_call, [(fn, item) for item in items]):
            results.append(r)
            if on_result:
                on_result(r)
        pool.close()
        return results
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()
        _SHARED.clear()


def in_child(fn, arg):
    """``fn(arg)`` in a forked process (state it creates, such as a GL context, stays there)."""
    return fork_map(_apply, [arg], fn)[0]


def _apply(fn, arg):
    return fn(arg)
