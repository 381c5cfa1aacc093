"""Which files a comparison sees, and reading them without being led astray.

Policy (docs/COMPARE.md):

- Every entry under ACTUAL and GOLDEN that is not a folder is listed: regular files, symbolic
  links (to anything), FIFOs, devices. Folders are descended; a symbolic link to a folder is
  listed, never descended.
- Only regular files are read, after a ``stat`` and up to :data:`MAX_FILE_BYTES`
  (``yamlio.read_regular``): a FIFO, a device, a link to a folder, a symlink loop or an
  oversize file is an ERROR verdict for that file, never a hang.
- A symbolic link is followed only when its target lies inside the same compared folder; a
  link that leaves the folder is an ERROR (a comparison reads nothing outside ACTUAL and
  GOLDEN).
- A folder that cannot be listed is an ERROR named by its path with a trailing ``/``.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from axdf_cli.compare.result import Unreadable
from axdf_cli.fileio.runfolder import own_entry
from axdf_cli.fileio.yamlio import FileRefused, not_regular, read_regular, real_path

# The largest file a comparison reads (each side is held in memory, plus its decoded form).
# A 4K EXR frame with every pass is ~250 MB uncompressed and far less compressed.
MAX_FILE_BYTES = 1 << 30


def inside(path: Path, root: Path) -> bool:
    """Whether ``path`` is ``root`` or below it (both real paths)."""
    return path == root or root in path.parents


def nested(actual: Path, golden: Path) -> Path | None:
    """The folder of the two that is, or lies inside, the other (by real paths; either may
    not exist yet), else None."""
    ra, rg = real_path(actual), real_path(golden)
    if inside(rg, ra):
        return golden
    if inside(ra, rg):
        return actual
    return None


def list_files(root: Path, exclude: Iterable[Path] = (), errors: dict[str, str] | None = None) -> dict[str, Path]:
    """Every non-folder entry under ``root`` by its posix path relative to ``root``, sorted;
    ``exclude`` (this comparison's own report, JUnit file and picture folder, or the other
    run folder when one holds the other) is left out. Folders that cannot be listed go into
    ``errors`` as ``"rel/": why``. What axdf itself leaves while it writes (the lock,
    temporaries, a staging folder: :func:`axdf_cli.fileio.runfolder.own_entry`) is not part of a run
    and is left out too."""
    skip = {Path(os.path.abspath(p)) for p in exclude}
    out: dict[str, Path] = {}

    def onerror(e: OSError) -> None:
        if errors is not None and e.filename is not None:
            rel = Path(e.filename).relative_to(root).as_posix()
            errors["" if rel == "." else rel + "/"] = f"cannot list this folder ({e.strerror})"

    for dirpath, dirnames, filenames in os.walk(root, onerror=onerror):
        d = Path(dirpath)
        keep = []
        for n in sorted(dirnames):
            if own_entry(n) or Path(os.path.abspath(d / n)) in skip:
                continue
            if os.path.islink(d / n):
                filenames.append(n)  # a link to a folder: listed, not descended
            else:
                keep.append(n)
        dirnames[:] = keep
        for n in sorted(filenames):
            if own_entry(n):
                continue
            p = d / n
            if Path(os.path.abspath(p)) not in skip:
                out[p.relative_to(root).as_posix()] = p
    return dict(sorted(out.items()))


def check_compared(path: Path, root: Path | None) -> None:
    """Raise :class:`Unreadable` unless ``path`` is a regular file of at most
    :data:`MAX_FILE_BYTES` and, when it is a symbolic link, its target lies inside ``root``
    (None: a file named on the command line, no containment). Reads nothing."""
    if root is not None and os.path.islink(path):
        if not inside(real_path(path), real_path(root)):
            raise Unreadable(f"symbolic link to {os.readlink(path)!r} leaves the compared folder; "
                             "links are followed only to files inside it")
    try:
        st = os.stat(path)
    except OSError as e:
        raise Unreadable(f"cannot read ({e.strerror or e})") from None
    problem = not_regular(st.st_mode)
    if problem:
        raise Unreadable(problem)
    if st.st_size > MAX_FILE_BYTES:
        raise Unreadable(f"file is {st.st_size} bytes; at most {MAX_FILE_BYTES} bytes are compared")


def read_compared(path: Path, root: Path | None) -> bytes:
    """The bytes of a compared file; :class:`Unreadable` (an ERROR verdict) for anything
    :func:`check_compared` refuses, or when reading fails."""
    check_compared(path, root)
    try:
        return read_regular(path, MAX_FILE_BYTES)
    except FileRefused as e:
        raise Unreadable(str(e)) from None
    except OSError as e:
        raise Unreadable(f"cannot read ({e.strerror or e})") from None
