"""The process's numeric runtime (axdf_cli/runtime.py): importing axdf changes nothing;
:func:`runtime.configure` sets the thread pools, numba's layer and its kernel cache."""
from __future__ import annotations

import json
import os
import subprocess
import sys

from conftest import REPO_ROOT

_PROBE = """
import json, os
import numpy, threadpoolctl
def blas():
    return sorted(p["num_threads"] for p in threadpoolctl.threadpool_info() if p["user_api"] == "blas")
before, threads = dict(os.environ), blas()
import axdf_cli, axdf_cli.cli.main, axdf_cli.model, axdf_cli.workers
mid, mid_threads = dict(os.environ), blas()
from axdf_cli import runtime
runtime.configure()
runtime.configure()
print(json.dumps([before == mid, threads, mid_threads, blas(),
                  {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "NUMBA_THREADING_LAYER", "NUMBA_CACHE_DIR")}]))
"""


def _probe(tmp_path) -> list:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_THREADING_LAYER",
                        "NUMBA_CACHE_DIR")}
    env["XDG_CACHE_HOME"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, check=True,
                         cwd=REPO_ROOT).stdout
    return json.loads(out)


def test_importing_axdf_changes_no_environment_and_no_thread_pool(tmp_path):
    same, threads, after_import, configured, env = _probe(tmp_path)
    assert same, "import axdf_cli changed os.environ"
    assert after_import == threads, "import axdf_cli changed the BLAS thread count"
    assert configured and all(n == 1 for n in configured)
    assert env["OMP_NUM_THREADS"] == "1" and env["NUMBA_THREADING_LAYER"] in ("omp", "workqueue")
    assert env["NUMBA_CACHE_DIR"].startswith(str(tmp_path / "axdf" / "numba"))


def test_configure_keeps_values_already_set(monkeypatch):
    from axdf_cli import runtime

    runtime.configure()  # (done by conftest: a second call changes nothing)
    before = dict(os.environ)
    runtime.configure()
    assert dict(os.environ) == before
