"""Forked worker processes for the mesh pass.

:func:`fork_map` runs ``fn(shared, item)`` for each item in its own forked process and
returns the results in order. ``shared`` (the plan, the twist references ...) reaches the
workers by fork, not by pickling; only the items and the results are pickled."""
from __future__ import annotations

_SHARED: dict = {}  # set in the parent just before the workers fork


def _call(task):
    fn, item = task
    return fn(_SHARED["value"], item)


def fork_map(fn, items: list, shared, on_result=None) -> list:
    """``[fn(shared, item) for item in items]``, each call in a forked process; ``on_result``
    is called in the parent with each result as it arrives. Any error stops every worker."""
    import multiprocessing as mp

    _SHARED["value"] = shared
    pool = mp.get_context("fork").Pool(len(items))
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
