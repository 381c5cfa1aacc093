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


# ----------------------------------------------------------------------------- the compile notice
#: CPU seconds per kernel of a cold compile (measured: every kernel, an idle 2-core machine),
#: for the minutes the compile notice announces.
SECONDS_PER_KERNEL = 5.5
#: Kernels only ``axdf pack`` runs (the other commands never compile them).
PACK_ONLY = ("pack",)
#: The kernel modules a command compiles where it is not every one but pack's (measured from
#: the cache a cold `axdf import osim` leaves: the muscle surface and the path kernels).
COMMAND_MODULES = {"import": ("batch_kernels", "batch_surface", "kernels", "geometry", "mujoco_shapes",
                              "opensim_shapes", "wrap")}


def _kernels(modules=None) -> list[tuple[str, str]]:
    """(numba's cache subfolder, entry name) of every cached kernel (see :func:`cached_kernels`).
    numba keeps a source file's entries in ``<its folder's name>_<sha1 of the folder's absolute
    path>`` (so a checkout elsewhere has entries of its own)."""
    import ast
    import hashlib
    from pathlib import Path

    def cached(dec) -> bool:
        return isinstance(dec, ast.Call) and any(
            k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in dec.keywords)

    out = []
    for path in sorted((Path(__file__).resolve().parent / "model").rglob("*.py")):
        if modules is not None and not modules(path.stem):
            continue
        sub = f"{path.parent.name}_{hashlib.sha1(str(path.parent).encode()).hexdigest()}"
        for n in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(n, ast.FunctionDef) and any(cached(d) for d in n.decorator_list):
                out.append((sub, f"{path.stem}.{n.name}-{n.decorator_list[0].lineno}"))
    return out


def cached_kernels(modules=None) -> list[str]:
    """Every cached numba kernel under axdf_cli/model/ (a function decorated with
    ``cache=True``) as numba names its cache entry, ``MODULE.NAME-LINE`` (the line of its first
    decorator); ``modules``: a test on the module's stem (all when None)."""
    return [name for _, name in _kernels(modules)]


def cache_entry(kernel: str) -> str:
    """The path of ``kernel``'s (a :func:`cached_kernels` name) index file in numba's cache
    folder, relative to it."""
    sub = dict((name, sub) for sub, name in _kernels())[kernel]
    return f"{sub}/{kernel}.py{sys.version_info[0]}{sys.version_info[1]}.nbi"


def missing_kernels(cache_dir: str | None, modules=None) -> tuple[list[str], int]:
    """(the kernels with no entry in numba's cache folder ``cache_dir`` for this checkout, how
    many there are)."""
    from pathlib import Path

    kernels = _kernels(modules)
    tag = f".py{sys.version_info[0]}{sys.version_info[1]}.nbi"
    if not cache_dir or not Path(cache_dir).is_dir():
        return [name for _, name in kernels], len(kernels)
    return [name for sub, name in kernels if not (Path(cache_dir) / sub / f"{name}{tag}").exists()], len(kernels)


def compile_line(missing: int, total: int, cache_dir: str | None) -> str:
    minutes = max(1, round(missing * SECONDS_PER_KERNEL / 60))
    return (f"axdf: compiling {missing} of {total} numba kernels once (about {minutes} min of CPU); "
            f"later runs load them from {cache_dir or 'numba default cache'}")


def compile_notice(command: str) -> str | None:
    """The line to print before command ``command`` compiles numba's kernels into a cold
    cache; None when its kernels are cached (:func:`cold_kernels`)."""
    missing, total = cold_kernels(command)
    return compile_line(missing, total, os.environ.get("NUMBA_CACHE_DIR")) if missing else None


def cold_kernels(command: str) -> tuple[int, int]:
    """(how many of command ``command``'s kernels have no entry in the cache yet, how many it
    has). A kernel called only from within other kernels may never get a cache entry of its
    own, and one a command does not reach (contact's, with contact off) is not compiled by it,
    so a command that has once finished against this cache (:func:`mark_warm`) counts none."""
    from pathlib import Path

    configure()
    cache = os.environ.get("NUMBA_CACHE_DIR")
    if cache and (Path(cache) / _warm_name(command)).exists():
        return 0, 0
    if command == "pack":
        modules = None
    elif command in COMMAND_MODULES:
        modules = COMMAND_MODULES[command].__contains__
    else:
        modules = lambda m: m not in PACK_ONLY  # noqa: E731
    missing, total = missing_kernels(cache, modules)
    return len(missing), total


def _warm_name(command: str) -> str:
    """The marker of ``command`` having finished against the cache, for this checkout (numba
    keeps each checkout's entries apart: :func:`_kernels`)."""
    import hashlib

    here = os.path.dirname(os.path.abspath(__file__))
    return f".warm-{command}-{hashlib.sha1(here.encode()).hexdigest()[:12]}"


def mark_warm(command: str) -> None:
    """Record that ``command`` finished against this kernel cache (its kernels are compiled)."""
    from pathlib import Path

    cache = os.environ.get("NUMBA_CACHE_DIR")
    if cache and Path(cache).is_dir():
        try:
            (Path(cache) / _warm_name(command)).touch()
        except OSError:  # a read-only cache: the notice comes again, nothing worse
            pass


#: Seconds between two progress lines while numba compiles into a cold cache.
PROGRESS_EVERY_S = 15.0


def compile_progress(say):
    """A context in which numba's compiles into a cold cache are reported through ``say`` (a
    line of text: the command line prints it on stderr) as they finish, at most every
    :data:`PROGRESS_EVERY_S` seconds, so that a first run that
    compiles for minutes is not silent. numba
    sends its compile event on a cache miss only, so a cached kernel reports nothing; a kernel
    compiled from within another's compile is counted, and reported with the outer one."""
    import time

    from numba.core import event

    class Progress(event.Listener):
        def __init__(self):
            self.depth, self.done = 0, 0  # compiles open now, compiles finished
            self.t0 = self.last = time.perf_counter()

        def on_start(self, ev):
            self.depth += 1

        def on_end(self, ev):
            self.depth -= 1
            self.done += 1
            if self.depth:  # (a kernel another one calls: reported with it)
                return
            now = time.perf_counter()
            if now - self.last >= PROGRESS_EVERY_S:
                self.last = now
                name = getattr(getattr(ev.data.get("dispatcher"), "py_func", None), "__qualname__", "a kernel")
                say(f"axdf: {self.done} kernels compiled ({now - self.t0:.0f} s; last: {name})")

    return event.install_listener("numba:compile", Progress())
