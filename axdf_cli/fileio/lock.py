"""One writer per output folder: ``flock``, refused at once when another process holds it.

Two holders of the one rule (refusal: exit 3, "another axdf process is writing ..."):

- a lock *file* (:func:`lock_file`): a run's ``.axdf-lock``, holding the writer's pid so that
  a refusal names it, removed when released;
- a lock on a *folder* itself (:func:`lock_folder`): a data set's, exclusive or shared, which
  leaves nothing behind when its holder is killed.

The lock file is never opened through a symbolic link.
"""
from __future__ import annotations

import errno
import os
from pathlib import Path

from axdf_cli.errors import EnvironmentProblem, InputError, UsageError
from axdf_cli.fileio import atomic

#: Tries at taking a lock file whose holder removes it as we open it.
LOCK_TRIES = 8


def link_refused(path: Path) -> InputError:
    """The refusal of a symbolic link where axdf writes (exit 2, naming it)."""
    return InputError(None, f"{path} is a symbolic link",
                      "axdf never writes through a link out of its output folder; remove the link or choose "
                      "another output folder")


def held(what, owner: str = "") -> EnvironmentProblem:
    """The refusal of a second writer of ``what`` (``owner``: the holder's pid, when known)."""
    return EnvironmentProblem(f"another axdf process{f' (pid {owner})' if owner.isdigit() else ''} is writing {what}",
                              "wait for it to finish, or choose another output folder")


def try_flock(fd: int, shared: bool = False) -> bool:
    """Take ``flock`` on ``fd`` without waiting (exclusive, or ``shared``); whether it was taken."""
    import fcntl

    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except OSError:
        return False
    return True


def lock_file(path: Path, folder: Path) -> int:
    """Take ``flock`` on the lock file ``path`` (created, never through a link) for the one
    writer of ``folder``, and write our pid in it; return its descriptor. Another holder:
    exit 3 naming its pid."""
    for _ in range(LOCK_TRIES):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        except OSError as e:
            if e.errno == errno.ELOOP:
                raise link_refused(path) from None
            if e.errno == errno.EISDIR:  # not ours: a folder where the lock goes
                raise UsageError(f"{path} is a folder", f"axdf keeps its lock file there ({Path(path).name}); "
                                 "move the folder away") from None
            raise atomic.environment_problem(path, e) from None
        if not try_flock(fd):
            owner = os.read(fd, 32).decode("ascii", "replace").strip()
            os.close(fd)
            raise held(folder, owner)
        try:
            same = os.fstat(fd).st_ino == os.stat(path, follow_symlinks=False).st_ino
        except FileNotFoundError:
            same = False
        if same:
            try:
                os.ftruncate(fd, 0)
                os.write(fd, f"{os.getpid()}\n".encode())
            except OSError as e:  # a full disk takes the lock's inode, not its pid's block
                unlock_file(path, fd)
                raise atomic.environment_problem(path, e) from None
            return fd
        os.close(fd)  # its holder removed it as we opened it: lock the file there now
    raise EnvironmentProblem(f"cannot lock {path}", "try again")


def unlock_file(path: Path, fd: int) -> None:
    """Release :func:`lock_file`'s lock and remove the file (a waiting writer locks anew)."""
    try:
        os.unlink(path)
    except OSError:
        pass
    os.close(fd)


def remove_stale_lock(path: Path) -> None:
    """A lock file left by a killed process (nobody holds it): removed; a live holder's stays."""
    try:
        fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return
    try:
        if try_flock(fd):
            try:
                os.unlink(path)
            except OSError:
                pass
    finally:
        os.close(fd)


def lock_folder(path: Path, shared: bool = False, what: str | None = None) -> int:
    """``flock`` on the folder ``path`` itself (no lock file: nothing is left behind when the
    holder is killed); exclusive, or ``shared``. Another holder: exit 3. Returns the
    descriptor (:func:`unlock_folder`)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError as e:
        raise atomic.environment_problem(Path(path), e) from None
    if not try_flock(fd, shared):
        os.close(fd)
        raise held(what or path)
    return fd


def relock_folder(fd: int, shared: bool, what: str) -> None:
    """Turn :func:`lock_folder`'s lock shared or exclusive (refused, exit 3, when another holds it)."""
    if not try_flock(fd, shared):
        raise held(what)


def unlock_folder(fd: int | None) -> None:
    if fd is not None:
        os.close(fd)
