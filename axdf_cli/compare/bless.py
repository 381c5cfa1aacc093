"""``--update``: make golden equal to actual, saying what changed.

Every file of actual that golden lacks is added, every file whose bytes differ is replaced,
and every golden file that actual lacks is removed (empty folders with it), all or nothing:
the new files are written first, then put in place at once (:func:`apply_bless`).
Ignored files and this comparison's own outputs are left alone.

Nothing is written before everything is checked (:func:`plan_bless`, exit 2 on refusal):

- one folder inside the other (``compare A A/golden --update`` would nest golden/golden one
  level deeper each time) is refused;
- golden is written only through real folders inside it: a symbolic link on the way to a
  file it would write or remove (``GOLDEN/meshes -> /elsewhere``) is refused, as is a
  non-regular file where a file would go (a FIFO, a folder);
- every file copied from actual must be a regular file inside actual (the rules of
  :mod:`axdf_cli.compare.files`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from axdf_cli.fileio.atomic import deferred_signals, temp_path, write_parts
from axdf_cli.compare.files import check_compared, list_files, nested, read_compared
from axdf_cli.compare.result import Report, Unreadable
from axdf_cli.compare.thresholds import Tolerances
from axdf_cli.errors import EnvironmentProblem, UsageError
from axdf_cli.fileio.yamlio import real_path


@dataclass(frozen=True)
class Change:
    action: str  # "added", "replaced", "removed"
    path: str  # relative path (file name in file mode)
    note: str = ""  # for "replaced": within or beyond tolerance


@dataclass(frozen=True)
class Step:
    action: str  # "add", "update" (replace when the bytes differ), "remove"
    rel: str
    src: Path | None  # the actual file (add, update)
    dst: Path  # the golden file, below the real golden folder


def refuse_nested(actual: Path, golden: Path) -> None:
    """UsageError when either folder is (or lies inside) the other, by real paths (golden
    may not exist yet)."""
    inner = nested(actual, golden)
    if inner is not None:
        outer = actual if inner is golden else golden
        raise UsageError(f"--update: {inner} is inside {outer}",
                         "ACTUAL and GOLDEN must be separate folders (each update would copy one into itself)")


def _check_target(golden: Path, rel: str, final_regular: bool) -> None:
    """Refuse a write or removal of ``golden/rel`` that would pass through a symbolic link
    or land on something that is not a regular file."""
    cur = golden
    parts = rel.split("/")
    for i, part in enumerate(parts):
        cur = cur / part
        shown = f"GOLDEN/{'/'.join(parts[:i + 1])}"
        if os.path.islink(cur):
            raise UsageError(f"--update: {shown} ({cur}) is a symbolic link",
                             "--update writes only real files and folders inside GOLDEN; replace the link by a folder")
        if not os.path.lexists(cur):
            return
        last = i == len(parts) - 1
        if not last and not cur.is_dir():
            raise UsageError(f"--update: {shown} ({cur}) is not a folder", "remove it, then update")
        if last and final_regular and not cur.is_file():
            raise UsageError(f"--update: {shown} ({cur}) is not a regular file", "remove it, then update")


def plan_bless(actual: Path, golden: Path, tolerances: Tolerances, exclude: Iterable[Path] = ()) -> list[Step]:
    """What an update would do, checked through; raises UsageError (exit 2) before anything
    is written."""
    if actual.is_file():
        try:
            check_compared(actual, None)
        except Unreadable as e:
            raise UsageError(f"--update: ACTUAL {actual}: {e}", "--update copies regular files") from None
        return [Step("update" if golden.exists() else "add", golden.name, actual, golden)]
    refuse_nested(actual, golden)
    exclude = list(exclude)
    fa = {r: p for r, p in list_files(actual, exclude).items() if not tolerances.ignored(r)}
    fg = ({r: p for r, p in list_files(golden, exclude).items() if not tolerances.ignored(r)}
          if golden.exists() else {})
    root = real_path(golden)
    steps: list[Step] = []
    for rel in sorted(set(fa) | set(fg)):
        if rel in fa:
            try:
                check_compared(fa[rel], actual)
            except Unreadable as e:
                raise UsageError(f"--update: ACTUAL/{rel} ({fa[rel]}): {e}",
                                 "--update copies regular files inside ACTUAL") from None
        _check_target(golden, rel, final_regular=rel in fa)
        action = "remove" if rel not in fa else "update" if rel in fg else "add"
        steps.append(Step(action, rel, fa.get(rel), root / rel))
    return steps


def apply_bless(steps: list[Step], actual: Path, golden: Path, report: Report | None = None) -> list[Change]:
    """Carry out :func:`plan_bless`'s steps; return what changed, in path order.

    Whole or not at all: every new or changed file is first written beside its place as a
    temporary (``.axdf-tmp-<pid>-NAME``, which compare ignores and a later command removes
    once this process is gone); only when all are written are they renamed into place and
    the removed files deleted, with Ctrl-C and SIGTERM held until that is done. An
    interruption or error before then leaves GOLDEN as it was."""
    verdicts = {f.path: f.verdict for f in report.files} if report is not None else {}
    root_a = None if actual.is_file() else actual
    changes: list[Change] = []
    staged: list[tuple[Path, Path]] = []  # (temporary, golden file)
    try:
        for s in steps:
            if s.action == "remove":
                continue
            try:
                data = read_compared(s.src, root_a)
                if s.action == "update" and s.dst.stat().st_size == len(data) and read_compared(s.dst, None) == data:
                    continue
            except Unreadable as e:  # changed since plan_bless checked it
                raise EnvironmentProblem(f"{s.src}: {e}") from None
            tmp = temp_path(s.dst)
            write_parts(tmp, (data,))
            staged.append((tmp, s.dst))
            changes.append(Change("added" if s.action == "add" else "replaced", s.rel,
                                  _note(verdicts.get(s.rel)) if s.action == "update" else ""))
    except BaseException:
        for tmp, _ in staged:
            try:
                tmp.unlink()
            except OSError:
                pass
            if golden.exists() and not golden.is_file():
                _prune(tmp.parent, real_path(golden))  # folders made for new files
        raise
    with deferred_signals():
        for tmp, dst in staged:
            try:
                os.replace(tmp, dst)
            except OSError as e:
                raise EnvironmentProblem(f"{dst}: cannot write ({e.strerror})") from None
        for s in steps:
            if s.action != "remove":
                continue
            try:
                s.dst.unlink()
            except OSError as e:
                raise EnvironmentProblem(f"{s.dst}: cannot remove ({e.strerror})") from None
            changes.append(Change("removed", s.rel))
            _prune(s.dst.parent, real_path(golden))
    return sorted(changes, key=lambda c: c.path)
def bless(actual: Path, golden: Path, tolerances: Tolerances, report: Report | None = None,
          exclude: Iterable[Path] = ()) -> list[Change]:
    """Copy ``actual`` over ``golden`` (files or folders); return what changed, in path order.
    ``golden`` may not exist yet (a first bless)."""
    return apply_bless(plan_bless(actual, golden, tolerances, exclude), actual, golden, report)


def _note(verdict: str | None) -> str:
    return {"pass": "it was within tolerance", "fail": "it differed beyond tolerance",
            "error": "it could not be read"}.get(verdict or "", "")


def _prune(folder: Path, root: Path) -> None:
    """Remove now-empty folders from ``folder`` up to (not including) ``root``."""
    folder, root = Path(os.path.abspath(folder)), Path(os.path.abspath(root))
    while folder != root and root in folder.parents:
        try:
            folder.rmdir()
        except OSError:  # not empty
            return
        folder = folder.parent
