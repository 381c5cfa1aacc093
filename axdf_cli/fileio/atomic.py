"""Files appear whole or not at all: write to a temporary name in the same folder, then rename.

Errors of the machine (unwritable folder, full disk) become :class:`EnvironmentProblem`
(exit 3) and leave no temporary file behind.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import threading
from pathlib import Path
from typing import Iterator

from axdf_cli.errors import EnvironmentProblem

TMP_PREFIX = ".axdf-tmp-"

# Signal deferral: SIGINT/SIGTERM arriving while a file is being written and renamed are held
# until the file is whole (the CLI's handlers call :func:`on_signal`). A write takes
# milliseconds, so an interrupt still ends the run promptly, and never leaves a temporary.
_state = {"depth": 0, "pending": False, "signum": None}


def on_signal(signum=None, frame=None) -> None:
    """Signal handler: raise KeyboardInterrupt now, or when the current write is done."""
    _state["signum"] = signum
    if _state["depth"] > 0:
        _state["pending"] = True
        return
    raise KeyboardInterrupt


def interrupted() -> bool:
    """Whether :func:`on_signal` has run since :func:`reset_interrupt` (also where the
    KeyboardInterrupt it raised was caught and dropped by a library)."""
    return _state["signum"] is not None


def reset_interrupt() -> None:
    """Forget an earlier interrupt (the command line's start: ``main`` may be called again in
    one process)."""
    _state.update(pending=False, signum=None)


def _unraisable(hook):
    """``sys.unraisablehook``: a KeyboardInterrupt raised while Python code ran inside a C
    callback (llvmlite's object cache, loading a numba kernel) cannot propagate; Python would
    print it with a traceback and go on. Instead say nothing and send the signal again a
    moment later, when the callback has returned: once, however many times the callback ran
    into it (a second copy would land in the handling of the first)."""
    def again(signum) -> None:
        _state["resend"] = False
        os.kill(os.getpid(), signum)

    def unraisable(args) -> None:
        if not isinstance(args.exc_value, KeyboardInterrupt) or _state["signum"] is None:
            return hook(args)
        if _state.get("resend"):
            return
        _state["resend"] = True
        timer = threading.Timer(0.05, again, (_state["signum"],))
        timer.daemon = True
        timer.start()
    unraisable.axdf = True
    return unraisable


def catch_interrupts_in_callbacks() -> None:
    """Install :func:`_unraisable` (once) where :func:`on_signal` is the signal handler."""
    import sys

    if not getattr(sys.unraisablehook, "axdf", False):
        sys.unraisablehook = _unraisable(sys.unraisablehook)


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():
        yield  # signals only ever interrupt the main thread: nothing to defer here
        return
    if _state["depth"] == 0 and _state["signum"] is not None:
        raise KeyboardInterrupt  # an interrupt a library swallowed: no further file is begun
    _state["depth"] += 1
    try:
        yield
    finally:
        _state["depth"] -= 1
        if _state["depth"] == 0 and _state["pending"]:
            _state["pending"] = False
            raise KeyboardInterrupt


def environment_problem(path: Path, e: OSError) -> EnvironmentProblem:
    if e.errno == errno.ENOSPC:
        return EnvironmentProblem(f"{path}: no space left on device", "free disk space or choose another --out")
    if e.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        return EnvironmentProblem(f"{path}: cannot write ({e.strerror})",
                                  "choose a writable --out folder")
    return EnvironmentProblem(f"{path}: cannot write ({e.strerror})")


def ensure_dir(path: Path) -> None:
    try:
        Path(path).mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise environment_problem(Path(path), e) from None


def _unlink(p: Path) -> None:
    try:
        p.unlink()
    except OSError:
        pass


def write_parts(path: Path | str, parts) -> None:
    """Write the byte strings ``parts`` (bytes, bytearray, memoryview) to ``path`` atomically.

    The hot path of every mesh file: plain ``os.open``/``os.write``/``os.replace`` (cheaper
    than a Python file object or ``ndarray.tofile``), whole or absent,
    machine errors as exit 3, interrupting signals held until the file is done."""
    path = Path(path)
    tmp = temp_path(path)
    flags = os.O_WRONLY | os.O_CREAT | os.O_TRUNC
    with deferred_signals():
        try:
            try:
                fd = os.open(tmp, flags, 0o644)
            except FileNotFoundError:  # the folder does not exist yet: make it once
                ensure_dir(path.parent)
                fd = os.open(tmp, flags, 0o644)
        except OSError as e:
            raise environment_problem(path, e) from None
        try:
            try:
                for part in parts:
                    view = memoryview(part).cast("B")
                    while view:
                        view = view[os.write(fd, view):]
            finally:
                os.close(fd)
            os.replace(tmp, path)
        except OSError as e:
            _unlink(tmp)
            raise environment_problem(path, e) from None
        except BaseException:
            _unlink(tmp)
            raise


def write_bytes(path: Path | str, data: bytes) -> str:
    """Write ``data`` atomically; return its sha256 hex digest."""
    write_parts(path, (data,))
    return hashlib.sha256(data).hexdigest()


def write_text(path: Path | str, text: str) -> str:
    return write_bytes(path, text.encode("utf-8"))


def sha256_file(path: Path | str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def temp_path(path: Path) -> Path:
    """The temporary a file is written to before its rename: it names the writing process."""
    return path.with_name(f"{TMP_PREFIX}{os.getpid()}-{path.name}")


def temp_owner(name: str) -> int | None:
    """The process id in a temporary's (or staging folder's) name ``<prefix><pid>-...``."""
    digits = name.split("-", 3)[2] if name.count("-") >= 2 else ""
    return int(digits) if digits.isdigit() else None


def pid_alive(pid: int) -> bool:
    """Whether a process with this id runs (a zombie, killed but not yet reaped, does not)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except (OSError, IndexError):
        return True


def remove_stale_temporaries(folders) -> int:
    """Delete the temporaries in ``folders`` (not below them) whose writing process is gone,
    never a live process's; return how many."""
    n = 0
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except (FileNotFoundError, NotADirectoryError):
            continue
        for e in entries:
            if e.name.startswith(TMP_PREFIX) and e.is_file(follow_symlinks=False):
                pid = temp_owner(e.name)
                if pid is None or not pid_alive(pid):
                    _unlink(Path(e.path))
                    n += 1
    return n


class StreamingFile:
    """A file written in pieces (a per-sequence format: every frame of a muscle) that still
    appears whole or not at all: the pieces go to a temporary name in the target's folder
    (:data:`TMP_PREFIX`, so ``--resume`` removes what a killed run left) and :meth:`commit`
    renames it into place; :meth:`discard` removes it.

    ``pwrite(data, offset)`` places bytes anywhere (a header filled in last); the file is
    opened for each call, so many streams may be open at once without holding descriptors.
    Machine errors become :class:`EnvironmentProblem` (exit 3) and remove the temporary."""

    def __init__(self, path: Path | str):
        self.path = Path(path)
        self.tmp = temp_path(self.path)
        try:
            try:
                fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            except FileNotFoundError:
                ensure_dir(self.path.parent)
                fd = os.open(self.tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.close(fd)
        except OSError as e:
            raise environment_problem(self.path, e) from None

    def pwrite(self, data, offset: int) -> None:
        """Write ``data`` (bytes-like or a C-contiguous array) at byte ``offset``."""
        view = memoryview(data).cast("B")
        try:
            fd = os.open(self.tmp, os.O_WRONLY)
            try:
                while view:
                    n = os.pwrite(fd, view, offset)
                    view, offset = view[n:], offset + n
            finally:
                os.close(fd)
        except OSError as e:
            self.discard()
            raise environment_problem(self.path, e) from None

    def commit(self) -> None:
        """Rename the temporary into place (the file appears whole)."""
        with deferred_signals():
            try:
                os.replace(self.tmp, self.path)
            except OSError as e:
                self.discard()
                raise environment_problem(self.path, e) from None

    def discard(self) -> None:
        _unlink(self.tmp)
