"""Arrays of an ``.npz`` motion read with their cost known first: each member's ``.npy``
header (shape, dtype) is read through :mod:`zipfile` and checked against the caller's limits
and NPZ_MAX_ARRAY_BYTES before any of its data is decompressed. A compressed archive can
expand a thousandfold, and a header can claim any shape: a 3 MB file must not cost gigabytes.
"""
from __future__ import annotations

import io
import zipfile
from dataclasses import dataclass

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark


@dataclass(frozen=True)
class Header:
    """A member's ``.npy`` header: its key (the file name without ``.npy``), shape and dtype."""

    key: str
    shape: tuple[int, ...]
    dtype: np.dtype
    info: zipfile.ZipInfo

    @property
    def nbytes(self) -> int:
        return int(np.prod(self.shape, dtype=object)) * self.dtype.itemsize


def open_archive(data: bytes, where: Mark, allowed: str) -> zipfile.ZipFile:
    """The zip archive of an ``.npz`` file's bytes; a file that is none is an InputError."""
    try:
        return zipfile.ZipFile(io.BytesIO(data))
    except (zipfile.BadZipFile, ValueError, OSError) as e:
        raise InputError(where, f"not a numpy .npz archive ({e})", allowed) from None


def header(archive: zipfile.ZipFile, info: zipfile.ZipInfo, where: Mark | str, key: str) -> Header:
    """The member's header, read without its data; an unreadable one is an InputError at
    ``where`` (messages begin with the key unless ``where`` already ends with it)."""
    fmt = np.lib.format
    try:
        with archive.open(info) as f:
            version = fmt.read_magic(f)
            read = fmt.read_array_header_1_0 if version == (1, 0) else fmt.read_array_header_2_0
            shape, _, dtype = read(f)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, RuntimeError) as e:
        raise InputError(where, f"{_said(where, key)}cannot be read ({e})", "an array written by np.savez") from None
    return Header(key, tuple(int(s) for s in shape), dtype, info)


def read(archive: zipfile.ZipFile, h: Header, where: Mark | str) -> np.ndarray:
    """The member's data, once its header is known to fit: objects (pickles) and arrays over
    NPZ_MAX_ARRAY_BYTES are refused first."""
    if h.dtype.hasobject:
        raise InputError(where, f"{_said(where, h.key)}holds Python objects (pickled)", "numbers or fixed-width strings")
    if h.nbytes > tol.NPZ_MAX_ARRAY_BYTES:
        raise InputError(where, f"{_said(where, h.key)}has shape {h.shape} of {h.dtype} ({h.nbytes} bytes once read)",
                         f"arrays of at most {tol.NPZ_MAX_ARRAY_BYTES} bytes")
    try:
        with archive.open(h.info) as f:
            return np.lib.format.read_array(f, allow_pickle=False)
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, RuntimeError) as e:
        raise InputError(where, f"{_said(where, h.key)}cannot be read ({e})", "an array written by np.savez") from None


def _said(where: Mark | str, key: str) -> str:
    """``KEY `` to begin a message with, or nothing when ``where`` names the key already."""
    return "" if isinstance(where, str) and where.endswith(f": {key}") else f"{key} "


def members(archive: zipfile.ZipFile) -> dict[str, zipfile.ZipInfo]:
    """Every member by key (``qpos.npy`` → ``qpos``); nothing is read."""
    return {(i.filename[:-4] if i.filename.endswith(".npy") else i.filename): i for i in archive.infolist()}
