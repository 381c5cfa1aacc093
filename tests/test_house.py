"""The house rules of the package, enforced on its source (an ast walk over axdf_cli, every
import counted, those inside functions too):

- the rooms, bottom to top, written down here once (:data:`ROOMS`): a module imports only its
  own room and the rooms below it (so there is no import cycle between rooms);
- only the command line prints or exits: no ``print``, ``sys.exit`` or write to
  ``sys.stdout``/``sys.stderr`` in the library outside ``cli/`` and ``__main__.py`` (the rule
  ruff's T20 makes, without the tool).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from conftest import REPO_ROOT

PACKAGE = REPO_ROOT / "axdf_cli"

#: The rooms of axdf_cli, bottom to top: a room's modules import only rooms at its level or
#: below. A room is a sub-package or a top-level module ("__init__" is the package's own).
ROOMS = (
    ("__init__", "errors", "tolerances"),  # the version, the error hierarchy, every numeric tolerance
    ("fileio",),  # atomic writes, bounded reads, YAML with positions, the run folder's rules
    ("workers", "runtime"),  # process pools whose workers die with the parent; threads and kernel cache
    ("formats",),  # mesh formats: one entry per format in FORMATS
    ("model",),  # skeleton + FK, poses, the muscle model, paths, kernels
    ("specs",),  # YAML file specs by kind
    ("render",),  # the EGL renderer: a scene and array chunks in, never evaluates
    ("compare",),  # axdf compare
    ("pipeline",),  # plan, stages, evaluate, execute, the sinks
    ("importers",),  # OpenSim, BVH, transfer
    ("dataset",),  # axdf dataset
    ("cli", "__main__"),  # one module per subcommand; the only room that prints or exits
)
LEVEL = {room: k for k, rooms in enumerate(ROOMS) for room in rooms}
TALKERS = {"cli", "__main__"}  # may print and exit


def room_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def imported_rooms(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, room) of every axdf_cli import in the module."""
    out = []
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.level == 0 and n.module and n.module.split(".")[0] == "axdf_cli":
            parts = n.module.split(".")
            if len(parts) > 1:
                out.append((n.lineno, parts[1]))
            else:  # from axdf_cli import x: a room, or a name of the package's own __init__
                out += [(n.lineno, a.name if a.name in LEVEL else "__init__") for a in n.names]
        elif isinstance(n, ast.ImportFrom) and n.level > 0:
            raise AssertionError(f"line {n.lineno}: a relative import (the rooms are checked on absolute ones)")
        elif isinstance(n, ast.Import):
            out += [(n.lineno, a.name.split(".")[1] if "." in a.name else "__init__") for a in n.names
                    if a.name.split(".")[0] == "axdf_cli"]
    return out


MODULES = sorted(PACKAGE.rglob("*.py"))


def test_every_room_is_listed():
    rooms = {room_of(p) for p in MODULES}
    assert rooms == set(LEVEL), f"unlisted: {sorted(rooms - set(LEVEL))}; gone: {sorted(set(LEVEL) - rooms)}"


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_a_room_imports_only_rooms_below_it(path):
    here = room_of(path)
    wrong = [f"line {line}: {here} (level {LEVEL[here]}) imports {room} (level {LEVEL[room]})"
             for line, room in imported_rooms(ast.parse(path.read_text(), str(path)))
             if LEVEL[room] > LEVEL[here]]
    assert not wrong, "\n".join(wrong)


def _talks(tree: ast.AST) -> list[str]:
    found = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in ("print", "exit", "quit"):
            found.append(f"line {n.lineno}: {n.func.id}()")
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "sys" \
                and n.attr in ("exit", "stdout", "stderr"):
            found.append(f"line {n.lineno}: sys.{n.attr}")
    return sorted(found, key=lambda t: int(t.split(":")[0].split()[1]))


@pytest.mark.parametrize("path", [p for p in MODULES if room_of(p) not in TALKERS],
                         ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_only_the_command_line_prints_or_exits(path):
    found = _talks(ast.parse(path.read_text(), str(path)))
    assert not found, "\n".join(found)


def test_the_rules_catch_what_they_forbid():
    """The checks themselves: an upward import, a print and sys.exit are found."""
    tree = ast.parse("import sys\nfrom axdf_cli.pipeline import plan\nfrom axdf_cli import dataset, __version__\n"
                     "def f():\n    print('x')\n    sys.stderr.write('y')\n    sys.exit(1)\n")
    assert imported_rooms(tree) == [(2, "pipeline"), (3, "dataset"), (3, "__init__")]
    assert _talks(tree) == ["line 5: print()", "line 6: sys.stderr", "line 7: sys.exit"]
