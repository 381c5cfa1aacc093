"""How much of numba's kernel cache a run will find: the compiled kernels are numba's
``cache=True`` functions under axdf_cli/model/, each cached as ``MODULE.NAME-LINE.pyXY.nbi``
(the line of its first decorator) under NUMBA_CACHE_DIR. A cold cache costs minutes on two
cores, once; this says so before it is paid."""
from __future__ import annotations

import ast
import os
import sys
from pathlib import Path

MODEL = Path(__file__).resolve().parents[1] / "axdf_cli" / "model"
#: measured: a cold compile of every kernel on an idle 2-core machine, CPU seconds per kernel
SECONDS_PER_KERNEL = 5.5


def _is_cached(dec: ast.expr) -> bool:
    return isinstance(dec, ast.Call) and any(
        k.arg == "cache" and isinstance(k.value, ast.Constant) and k.value.value is True for k in dec.keywords)


def cached_kernels() -> list[str]:
    """Every cached kernel's file name stem, ``MODULE.NAME-LINE``."""
    out = []
    for path in sorted(MODEL.rglob("*.py")):
        for n in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(n, ast.FunctionDef) and any(_is_cached(d) for d in n.decorator_list):
                out.append(f"{path.stem}.{n.name}-{n.decorator_list[0].lineno}")
    return out


def missing_kernels(cache_dir: str | None) -> tuple[list[str], int]:
    """(the kernels not in the cache, how many there are)."""
    kernels = cached_kernels()
    tag = f".py{sys.version_info[0]}{sys.version_info[1]}.nbi"
    found = set()
    if cache_dir and Path(cache_dir).is_dir():
        found = {p.name[: -len(tag)] for p in Path(cache_dir).rglob(f"*{tag}")}
    return [k for k in kernels if k not in found], len(kernels)


def cache_report() -> str | None:
    """A line when kernels will compile on this run; None when all are cached."""
    import axdf_cli  # noqa: F401  (where the package chooses numba's cache folder)

    try:
        from axdf_cli import runtime
    except ImportError:
        runtime = None
    if runtime is not None and hasattr(runtime, "configure"):
        runtime.configure()
    cache = os.environ.get("NUMBA_CACHE_DIR")
    missing, total = missing_kernels(cache)
    if not missing:
        return None
    minutes = max(1, round(len(missing) * SECONDS_PER_KERNEL / 60))
    return (f"axdf: compiling {len(missing)} of {total} numba kernels once (about {minutes} min of CPU); "
            f"later runs load them from {cache or 'numba default cache'}")
