"""axdf: AxDf axial-deformation muscles (Zuo, Li, Wang) as a headless command-line tool."""

__version__ = "0.1.0"

# The muscle engine's matrix products are small (tens of control points by a few thousand
# vertices): multi-threaded BLAS only adds start-up and contention cost there (measured 5x
# slower on 2 busy cores). axdf parallelises with processes (--jobs), and runs the contact
# stage's kernels (and axdf pack's) on numba's threads, muscle by muscle, the same bytes for
# any number of threads; a worker process gets its share of the cores (axdf_cli.workers).
import os as _os
import sys as _sys

for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")
# numba's threads must survive fork (the --jobs workers are forked): GNU OpenMP's do not (a
# child that uses them stops: "fork() called from a process already using GNU OpenMP"), so
# TBB (a dependency; as fast as OpenMP here), else numba's own work queue (safe, but 1.4x
# slower on the contact stage: measured). A value you set is kept. pip puts TBB's library in
# the environment's lib/, where numba's TBB module does not look: loaded from there first.
_os.environ.setdefault("NUMBA_THREADING_LAYER", "forksafe")
if _os.environ["NUMBA_THREADING_LAYER"] in ("forksafe", "safe", "tbb", "default"):
    _tbb = _os.path.join(_sys.prefix, "lib", "libtbb.so.12")
    if _os.path.isfile(_tbb):
        try:
            import ctypes as _ctypes

            _ctypes.CDLL(_tbb, mode=_ctypes.RTLD_GLOBAL)
        except OSError:  # an unusable TBB: numba falls back to its work queue
            pass
if "numba" in _sys.modules and _os.environ["NUMBA_THREADING_LAYER"] == "forksafe":
    # numba already loaded (an embedding program): its layer is chosen when its threads start
    _sys.modules["numba"].config.THREADING_LAYER = "forksafe"
try:  # numpy may already be loaded (an embedding program): limit its BLAS pool directly
    from threadpoolctl import threadpool_limits as _limits

    _limits(1, user_api="blas")
except ImportError:  # threadpoolctl is a dependency; tolerate its absence in odd installs
    pass
