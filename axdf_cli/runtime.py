"""The process's numeric runtime: BLAS and OpenMP threads, numba's threading layer and kernel
cache, and whether contact's kernels may run on numba's threads.

Importing axdf changes nothing; :func:`configure` does, once, and is called by the command
line's entry (before numba or numpy's BLAS start), by every worker process as it starts, and
by the tests. A value already set in the environment is kept.

- BLAS and OpenMP pools: one thread. The muscle engine's matrix products are small (tens of
  control points by a few thousand vertices): more threads only add start-up and contention
  cost. axdf parallelises with processes (``--jobs``) and runs the contact kernels (and
  ``axdf pack``'s) on numba's threads, muscle by muscle, the same bytes for any number of
  threads.
- numba's threading layer: GNU OpenMP where its library loads (faster for contact than
  numba's own work queue, whose waiting thread competes with the workers), else the work
  queue. GNU OpenMP's threads do not survive fork: a forked child that starts a parallel
  kernel is stopped ("fork() called from a process already using GNU OpenMP"), so a forked
  process runs the kernels' serial twins (:func:`use_threads`). TBB is not used: it prints
  to stdout when a process that used it forks.
- numba's kernel cache: a folder keyed by every source under axdf_cli/model/ and
  tolerances.py (:func:`kernel_cache`).
"""
from __future__ import annotations

import os
import sys

#: Set to 1 in a worker process: contact's kernels stay on its thread (:func:`use_threads`).
THREADS_VAR = "AXDF_NUM_THREADS"

_STATE = {"configured": False, "home": os.getpid()}


def configure() -> None:
    """Set the process's thread pools, numba's threading layer and kernel cache (idempotent;
    values already in the environment are kept). Call before numba is imported: numba reads
    NUMBA_* when it loads (where it is loaded already, its layer is still set here, as it is
    chosen when its threads start)."""
    if _STATE["configured"]:
        return
    _STATE["configured"] = True
    _STATE["home"] = os.getpid()
    for var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    if "NUMBA_THREADING_LAYER" not in os.environ:
        os.environ["NUMBA_THREADING_LAYER"] = _threading_layer()
        if "numba" in sys.modules:
            sys.modules["numba"].config.THREADING_LAYER = os.environ["NUMBA_THREADING_LAYER"]
    if "NUMBA_CACHE_DIR" not in os.environ and "numba" not in sys.modules:
        cache = kernel_cache()
        if cache:
            os.environ["NUMBA_CACHE_DIR"] = cache
    try:  # numpy may already be loaded: limit its BLAS pool directly
        from threadpoolctl import threadpool_limits

        threadpool_limits(1, user_api="blas")
    except ImportError:  # threadpoolctl is a dependency; tolerate its absence in odd installs
        pass


def _threading_layer() -> str:
    import ctypes

    try:
        ctypes.CDLL("libgomp.so.1")
    except OSError:
        return "workqueue"
    return "omp"


def kernel_cache() -> str | None:
    """numba's cache folder for axdf's kernels: $XDG_CACHE_HOME/axdf/numba/<hash> (default
    ~/.cache), the hash of every source file under axdf_cli/model/ (where all the kernels
    are) and of tolerances.py (whose constants the kernels read as compile-time globals).
    numba keys a cached kernel by its own file only, while a kernel holds the code of the
    kernels it calls from other files (pack's hold contact's query), so a change to one file
    must miss the cache of all. Folders unused for 30 days are removed. None where the
    folder cannot be written (numba then finds its own place)."""
    import hashlib
    import shutil
    import time
    from pathlib import Path

    model = Path(__file__).resolve().parent / "model"
    h = hashlib.sha256()
    for f in [*sorted(model.rglob("*.py")), model.parent / "tolerances.py"]:
        h.update(str(f.relative_to(model.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "axdf" / "numba"
    here = base / h.hexdigest()[:16]
    try:
        if base.is_dir():
            for old in base.iterdir():
                if old != here and time.time() - old.stat().st_mtime > 30 * 86400:
                    shutil.rmtree(old, ignore_errors=True)
        here.mkdir(parents=True, exist_ok=True)
        os.utime(here)  # (in use)
    except OSError:
        return None
    return str(here) if os.access(here, os.W_OK) else None


def one_thread() -> None:
    """This process (a worker) runs contact's kernels on its own thread (the workers are the
    parallelism: N workers with a thread per core each would oversubscribe the cores)."""
    os.environ[THREADS_VAR] = "1"


def use_threads() -> bool:
    """Whether contact's (and pack's) kernels may run muscle by muscle on numba's threads
    (the bytes are the same either way): not where ``AXDF_NUM_THREADS`` is 1 (a worker:
    :func:`one_thread`), nor in a process forked from the one that configured (GNU OpenMP
    stops a forked child that starts its threads), nor where numba has one thread."""
    import numba

    return (os.getpid() == _STATE["home"] and os.environ.get(THREADS_VAR, "") != "1"
            and numba.config.NUMBA_NUM_THREADS > 1)
