"""axdf: AxDf axial-deformation muscles (Zuo, Li, Wang) as a headless command-line tool."""

__version__ = "0.1.0"

# The muscle engine's matrix products are small (tens of control points by a few thousand
# vertices): multi-threaded BLAS only adds start-up and contention cost there (measured 5x
# slower on 2 busy cores). axdf parallelises with processes (--jobs) instead.
import os as _os

for _var in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS"):
    _os.environ.setdefault(_var, "1")
try:  # numpy may already be loaded (an embedding program): limit its BLAS pool directly
    from threadpoolctl import threadpool_limits as _limits

    _limits(1, user_api="blas")
except ImportError:  # threadpoolctl is a dependency; tolerate its absence in odd installs
    pass
