"""The bones' distance fields kept between runs ($XDG_CACHE_HOME/axdf/sdf, default
~/.cache/axdf/sdf) and within a process: only ever a speed-up (a missing or unwritable
cache computes again). :func:`cached` is what the contact model is handed to look a field
up by (:func:`axdf_cli.model.contact.fields.bone_field`)."""
from __future__ import annotations

import functools
import hashlib
import io
import os
from pathlib import Path

import numpy as np

from axdf_cli.errors import AxdfError
from axdf_cli.fileio import atomic

CACHE_VERSION = 1  # part of the cache key: bump when the field's computation changes


@functools.lru_cache(maxsize=1)
def igl_version() -> str:
    """libigl's installed version, part of a field's cache key: a field computed by another
    release (its distances or its winding-number sign may differ) is computed again, not read
    back (the cache outlives installs)."""
    from importlib import metadata

    try:
        return "libigl " + metadata.version("libigl")
    except metadata.PackageNotFoundError:
        return "libigl ?"


def cache_dir() -> Path:
    """Where computed bone fields are kept between runs."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "axdf" / "sdf"


_MEMO: dict = {}  # this process's fields, by key (at most _MEMO_SIZE)
_MEMO_SIZE = 64


def clear() -> None:
    """Forget this process's fields (the disk cache stays)."""
    _MEMO.clear()


def cached(key: str, compute) -> tuple:
    """The field (origin, values) of ``key`` (a digest of the mesh and the grid): this
    process's, else the disk cache's, else ``compute()``'s, then kept in both."""
    full = hashlib.sha256((key + "\0" + igl_version()).encode()).hexdigest()
    hit = _MEMO.get(full)
    if hit is not None:
        return hit
    path = cache_dir() / f"{full}-v{CACHE_VERSION}.npz"
    try:
        with np.load(path) as z:
            out = z["origin"], np.ascontiguousarray(z["values"])
    except (OSError, KeyError, ValueError):
        out = compute()
        try:
            buf = io.BytesIO()
            np.savez(buf, origin=out[0], values=out[1])
            atomic.ensure_dir(path.parent)
            atomic.write_bytes(path, buf.getvalue())
        except (OSError, AxdfError):
            pass  # the cache is only a speed-up
    if len(_MEMO) >= _MEMO_SIZE:
        _MEMO.pop(next(iter(_MEMO)))
    _MEMO[full] = out
    return out
