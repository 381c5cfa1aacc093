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
# numba's threads must survive fork (the --jobs workers are forked): GNU OpenMP's do not (a
# child that uses them stops: "fork() called from a process already using GNU OpenMP"), and
# TBB's print to stdout when a process that used them forks; numba's own work queue is safe
# (a value you set is kept).
_os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")
if "numba" in _sys.modules and _os.environ["NUMBA_THREADING_LAYER"] == "workqueue":
    # numba already loaded (an embedding program): its layer is chosen when its threads start
    _sys.modules["numba"].config.THREADING_LAYER = "workqueue"
try:  # numpy may already be loaded (an embedding program): limit its BLAS pool directly
    from threadpoolctl import threadpool_limits as _limits

    _limits(1, user_api="blas")
except ImportError:  # threadpoolctl is a dependency; tolerate its absence in odd installs
    pass
