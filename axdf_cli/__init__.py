"""axdf: AxDf axial-deformation muscles (Zuo, Li, Wang) as a headless command-line tool."""

__version__ = "0.1.0"

# The muscle engine's matrix products are small (tens of control points by a few thousand
# vertices): multi-threaded BLAS only adds start-up and contention cost there (measured 5x
# slower on 2 busy cores). axdf parallelises with processes (--jobs), and runs the contact
# stage's kernels (and axdf pack's) on numba's threads, muscle by muscle, the same bytes for
# any number of threads; a worker process keeps them on its own thread (axdf_cli.workers).
import os as _os
import sys as _sys

for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")
# numba's threading layer (a value you set is kept): GNU OpenMP where its library loads (the
# contact stage runs ~20% faster on it than on numba's own work queue, whose waiting thread
# competes with the two workers on two cores), else the work queue. GNU OpenMP's threads do
# not survive fork: a forked child that starts a parallel kernel is stopped ("fork() called
# from a process already using GNU OpenMP"), so a forked process never does
# (axdf_cli.model.contact.use_threads: another process id, or a worker, runs the kernels'
# twins on its own thread). TBB is not used: it prints to stdout when a process that used it
# forks.


def _threading_layer() -> str:
    import ctypes

    try:
        ctypes.CDLL("libgomp.so.1")
    except OSError:
        return "workqueue"
    return "omp"


if "NUMBA_THREADING_LAYER" not in _os.environ:
    _os.environ["NUMBA_THREADING_LAYER"] = _threading_layer()
    if "numba" in _sys.modules:
        # numba already loaded (an embedding program): its layer is chosen when its threads start
        _sys.modules["numba"].config.THREADING_LAYER = _os.environ["NUMBA_THREADING_LAYER"]


def _kernel_cache() -> str | None:
    """numba's cache folder for axdf's kernels: $XDG_CACHE_HOME/axdf/numba/<hash> (default
    ~/.cache), the hash of every source file under axdf_cli/model/ (where all the kernels
    are) and of tolerances.py (whose constants the kernels read as compile-time globals).
    numba keys a cached kernel by its own file only, while a kernel holds the code of
    the kernels it calls from other files (pack.py's hold contact.py's query): after an
    edit or an upgrade of one file, the others' cached kernels ran the old code (a packed
    library made so was not what its code makes). Folders unused for 30 days are removed."""
    import hashlib
    import shutil
    import time
    from pathlib import Path

    model = Path(__file__).resolve().parent / "model"
    h = hashlib.sha256()
    for f in [*sorted(model.rglob("*.py")), model.parent / "tolerances.py"]:
        h.update(str(f.relative_to(model.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
    base = Path(_os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "axdf" / "numba"
    here = base / h.hexdigest()[:16]
    try:
        if base.is_dir():
            for old in base.iterdir():
                if old != here and time.time() - old.stat().st_mtime > 30 * 86400:
                    shutil.rmtree(old, ignore_errors=True)
        here.mkdir(parents=True, exist_ok=True)
        _os.utime(here)  # (in use)
    except OSError:  # unwritable: numba finds its own place (beside the sources, or none)
        return None
    return str(here) if _os.access(here, _os.W_OK) else None


if "NUMBA_CACHE_DIR" not in _os.environ and "numba" not in _sys.modules:
    _cache = _kernel_cache()
    if _cache:
        _os.environ["NUMBA_CACHE_DIR"] = _cache
try:  # numpy may already be loaded (an embedding program): limit its BLAS pool directly
    from threadpoolctl import threadpool_limits as _limits

    _limits(1, user_api="blas")
except ImportError:  # threadpoolctl is a dependency; tolerate its absence in odd installs
    pass
