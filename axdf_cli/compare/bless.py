"""``--update``: make golden equal to actual, saying what changed.

Every file of actual that golden lacks is added, every file whose bytes differ is replaced
(atomically), and every golden file that actual lacks is removed (empty folders with it).
Ignored files and this comparison's own outputs are left alone.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable

from axdf_cli.atomic import write_parts
from axdf_cli.compare import list_files
from axdf_cli.compare.result import Report
from axdf_cli.compare.tolerances import Tolerances
from axdf_cli.errors import EnvironmentProblem


@dataclass(frozen=True)
class Change:
    action: str  # "added", "replaced", "removed"
    path: str  # relative path (file name in file mode)
    note: str = ""  # for "replaced": within or beyond tolerance


def _copy(src: Path, dst: Path) -> None:
    write_parts(dst, (src.read_bytes(),))


def _same_bytes(a: Path, b: Path) -> bool:
    if a.stat().st_size != b.stat().st_size:
        return False
    return a.read_bytes() == b.read_bytes()


def bless(actual: Path, golden: Path, tolerances: Tolerances, report: Report | None = None,
          exclude: Iterable[Path] = ()) -> list[Change]:
    """Copy ``actual`` over ``golden`` (files or folders); return what changed, in path order.
    ``golden`` may not exist yet (a first bless)."""
    verdicts = {f.path: f.verdict for f in report.files} if report is not None else {}
    changes: list[Change] = []
    if actual.is_file():
        if golden.exists() and _same_bytes(actual, golden):
            return []
        action = "replaced" if golden.exists() else "added"
        _copy(actual, golden)
        return [Change(action, golden.name, _note(verdicts.get(golden.name)))]
    exclude = list(exclude)
    fa = {r: p for r, p in list_files(actual, exclude).items() if not tolerances.ignored(r)}
    fg = ({r: p for r, p in list_files(golden, exclude).items() if not tolerances.ignored(r)}
          if golden.exists() else {})
    for rel in sorted(set(fa) | set(fg)):
        if rel not in fa:
            try:
                fg[rel].unlink()
            except OSError as e:
                raise EnvironmentProblem(f"{fg[rel]}: cannot remove ({e.strerror})") from None
            changes.append(Change("removed", rel))
            _prune(fg[rel].parent, golden)
        elif rel not in fg:
            _copy(fa[rel], golden / rel)
            changes.append(Change("added", rel))
        elif not _same_bytes(fa[rel], fg[rel]):
            _copy(fa[rel], fg[rel])
            changes.append(Change("replaced", rel, _note(verdicts.get(rel))))
    return changes


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
