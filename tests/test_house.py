"""The house rules of the package, enforced on its source (an ast walk over axdf_cli, every
import counted, those inside functions too; the size and coupling rules, and no import cycle,
hold for the bench, benchmarks/, too):

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
    ("__init__", "errors", "tolerances", "parts"),  # the version, the errors, every numeric tolerance, the part kinds
    ("fileio",),  # atomic writes, bounded reads, YAML with positions, the run folder's rules
    ("workers", "runtime"),  # process pools whose workers die with the parent; threads and kernel cache
    ("formats",),  # mesh formats: one entry per format in FORMATS
    ("model",),  # skeleton + FK, poses, the muscle model, paths, kernels
    ("geometry",),  # closed meshes once: inside by winding number, push-out, caps, bone meshes at rest
    ("specs",),  # YAML file specs by kind
    ("importers",),  # OpenSim, MuJoCo and BVH readers, one neutral model, one emitter
    ("render",),  # the EGL renderer: a scene and array chunks in, never evaluates
    ("compare",),  # axdf compare
    ("pipeline",),  # plan, stages, evaluate, execute, the sinks
    ("tools",),  # commands that rewrite axdf files: transfer, retarget, pack
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


# --- size and coupling: what keeps a module readable and its insides its own ---

MAX_LINES = 800  # a module longer than this does more than one job
MAX_PARAMS = 12  # a function with more takes named groups (a NamedTuple, a params object)
#: what model/ may import of axdf: it is pure functions of arrays and small specs
MODEL_MAY_IMPORT = {"model", "errors", "tolerances"}
#: what model/ never touches: files, the environment, the process
MODEL_FORBIDDEN_CALLS = {"open", "getenv", "getpid", "savez", "savez_compressed", "save", "load", "mkdir",
                         "write_bytes", "write_text", "read_bytes", "read_text"}


def _params(fn: ast.AST) -> int:
    a = fn.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)


def _too_many_params(tree: ast.AST) -> list[str]:
    return [f"line {n.lineno}: {n.name}() takes {_params(n)} parameters (at most {MAX_PARAMS})"
            for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))
            and _params(n) > MAX_PARAMS]


def _is_module(dotted: str) -> bool:
    rel = PACKAGE.parent.joinpath(*dotted.split("."))
    return rel.with_suffix(".py").is_file() or (rel / "__init__.py").is_file()


def _private_uses(tree: ast.AST, roots: tuple[str, ...] = ("axdf_cli",)) -> list[str]:
    """Another axdf module's ``_private`` names used here: ``from axdf_cli.m import _x``, or
    ``m._x`` where ``m`` names an axdf module imported into this one (``roots``: the packages
    whose modules count; the bench's checks add ``benchmarks``)."""
    found, modules = [], set()
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.level == 0 and n.module and n.module.split(".")[0] in roots:
            for a in n.names:
                if a.name.startswith("_") and not a.name.startswith("__"):
                    found.append(f"line {n.lineno}: from {n.module} import {a.name}")
                elif _is_module(f"{n.module}.{a.name}"):
                    modules.add(a.asname or a.name)
        elif isinstance(n, ast.Import):
            for a in n.names:
                if a.name.split(".")[0] in roots and a.asname:
                    modules.add(a.asname)
    for n in ast.walk(tree):
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in modules \
                and n.attr.startswith("_") and not n.attr.startswith("__"):
            found.append(f"line {n.lineno}: {n.value.id}.{n.attr}")
    return found


def _model_touches(tree: ast.AST) -> list[str]:
    found = []
    for n in ast.walk(tree):
        if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id == "os" and n.attr == "environ":
            found.append(f"line {n.lineno}: os.environ")
        if isinstance(n, ast.Call):
            name = n.func.attr if isinstance(n.func, ast.Attribute) else getattr(n.func, "id", "")
            if name in MODEL_FORBIDDEN_CALLS:
                found.append(f"line {n.lineno}: {name}()")
    return found


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_a_module_stays_small_and_keeps_its_insides(path):
    text = path.read_text()
    tree = ast.parse(text, str(path))
    lines = text.count("\n")
    found = [f"{lines} lines (at most {MAX_LINES})"] if lines > MAX_LINES else []
    found += _too_many_params(tree) + _private_uses(tree)
    assert not found, "\n".join(found)


@pytest.mark.parametrize("path", [p for p in MODULES if room_of(p) == "model"],
                         ids=lambda p: p.relative_to(PACKAGE).as_posix())
def test_the_model_imports_nothing_above_it_and_touches_no_file(path):
    """model/ is pure: it imports only its own room, errors and tolerances, and neither reads
    the environment nor opens, loads or saves a file (caches and threads are decided by its
    callers)."""
    tree = ast.parse(path.read_text(), str(path))
    found = [f"line {line}: imports {room}" for line, room in imported_rooms(tree) if room not in MODEL_MAY_IMPORT]
    found += _model_touches(tree)
    assert not found, "\n".join(found)


def test_the_size_and_coupling_rules_catch_what_they_forbid():
    tree = ast.parse("import os\nfrom axdf_cli.model import contact\nfrom axdf_cli.model.kernels import _x\n"
                     "import axdf_cli.model.pack as pk\n"
                     "def f(a, b, c, d, e, f, g, h, i, j, k, l, m):\n    return contact._y + pk._z + contact.ok\n"
                     "def g(*a, **k):\n    return os.environ, open('f'), os.getpid()\n")
    assert _too_many_params(tree) == ["line 5: f() takes 13 parameters (at most 12)"]
    assert _private_uses(tree) == ["line 3: from axdf_cli.model.kernels import _x", "line 6: contact._y",
                                   "line 6: pk._z"]
    assert _model_touches(tree) == ["line 8: os.environ", "line 8: open()", "line 8: getpid()"]


# --- the bench (benchmarks/): one module per section, under the same size and coupling rules ---

BENCH = REPO_ROOT / "benchmarks"
BENCH_MODULES = sorted(BENCH.rglob("*.py"))


def _bench_name(path: Path) -> str:
    rel = path.relative_to(REPO_ROOT).with_suffix("")
    return ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)


def _bench_imports(tree: ast.AST) -> set[str]:
    """The benchmarks modules this one imports (``from benchmarks.sections import x`` counts as
    ``benchmarks.sections.x`` where that is a module)."""
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.ImportFrom) and n.level == 0 and n.module and n.module.split(".")[0] == "benchmarks":
            subs = [f"{n.module}.{a.name}" for a in n.names if _is_module(f"{n.module}.{a.name}")]
            out |= set(subs) if len(subs) == len(n.names) else {n.module, *subs}
        elif isinstance(n, ast.Import):
            out |= {a.name for a in n.names if a.name.split(".")[0] == "benchmarks"}
    return out


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every import cycle, as the modules along it (a package's own __init__ is left out of the
    edges from its submodules: Python imports it first anyway)."""
    found, state = [], {}

    def visit(m, path):
        state[m] = 1
        for d in sorted(graph.get(m, ())):
            if state.get(d) == 1:
                found.append(path[path.index(d):] + [d])
            elif d not in state:
                visit(d, path + [d])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])
    return found


def test_the_bench_has_no_import_cycle():
    graph = {_bench_name(p): {d for d in _bench_imports(ast.parse(p.read_text(), str(p)))
                              if not _bench_name(p).startswith(d + ".")} for p in BENCH_MODULES}
    assert "benchmarks.bench" in graph and "benchmarks.sections.skin" in graph
    assert not _cycles(graph), _cycles(graph)


@pytest.mark.parametrize("path", BENCH_MODULES, ids=lambda p: p.relative_to(BENCH).as_posix())
def test_a_bench_module_stays_small_and_keeps_its_insides(path):
    text = path.read_text()
    tree = ast.parse(text, str(path))
    lines = text.count("\n")
    found = [f"{lines} lines (at most {MAX_LINES})"] if lines > MAX_LINES else []
    found += _too_many_params(tree) + _private_uses(tree, ("axdf_cli", "benchmarks"))
    assert not found, "\n".join(found)


def test_the_bench_rules_catch_what_they_forbid():
    tree = ast.parse("from benchmarks.sections import writers, render\nfrom benchmarks.common import _x, Table\n"
                     "import benchmarks.page as pg\ndef f():\n    return writers._y + pg._z\n")
    assert _bench_imports(tree) == {"benchmarks.sections.writers", "benchmarks.sections.render",
                                    "benchmarks.common", "benchmarks.page"}
    assert _private_uses(tree, ("axdf_cli", "benchmarks")) == ["line 2: from benchmarks.common import _x",
                                                               "line 5: writers._y", "line 5: pg._z"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c", "a"]]
    assert _cycles({"a": {"b"}, "b": {"c"}, "d": {"a", "c"}}) == []
