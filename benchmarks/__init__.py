"""``make bench``: the entry point is :mod:`benchmarks.bench`; one module per section of
docs/BENCH.md under :mod:`benchmarks.sections`, their shared helpers in :mod:`benchmarks.common`
(paths, timing, the table, the run's settings) and :mod:`benchmarks.case` (the in-memory case),
the page and its merge in :mod:`benchmarks.page`."""
from axdf_cli import runtime

runtime.configure()  # threads and numba's kernel cache as the command line sets them (before numpy)
