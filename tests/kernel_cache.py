"""How much of numba's kernel cache a test run will find (the counting lives in
:mod:`axdf_cli.runtime`, which the command line uses for its own notice). A cold cache costs
minutes on two cores, once; this says so before it is paid."""
from __future__ import annotations

import os

from axdf_cli import runtime
from axdf_cli.runtime import SECONDS_PER_KERNEL, cached_kernels, missing_kernels  # noqa: F401  (for callers)


def cache_report() -> str | None:
    """A line when kernels will compile on this run; None when all are cached."""
    runtime.configure()
    cache = os.environ.get("NUMBA_CACHE_DIR")
    missing, total = missing_kernels(cache)
    return runtime.compile_line(len(missing), total, cache) if missing else None
