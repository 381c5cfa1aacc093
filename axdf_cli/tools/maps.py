"""What every map file of the tools shares (``transfer`` and ``retarget`` maps): the file read
as checked fields, the skeleton it names (``from:``, ``to:``, ``onto:``: relative to the map,
unless the command line gives one), and the ``key: NAME`` shorthand of an entry.
"""
from __future__ import annotations

from pathlib import Path

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import Fields, YMap, load_yaml
from axdf_cli.model.skeleton import Skeleton
from axdf_cli.specs import RefPolicy, load_skeleton


def open_map(path: Path | str, kind: str, keys=None) -> tuple[Path, Fields]:
    """The map file ``path`` and its fields (``kind``: "transfer map", ...)."""
    path = Path(path)
    top = Mark(str(path), 1, 1)
    doc = load_yaml(path)
    return path, (Fields(doc, top, kind) if keys is None else Fields(doc, top, kind, keys=keys))


def map_skeleton(f: Fields, key: str, given: Skeleton | None, path: Path, missing: str, flag: str,
                 policy: RefPolicy | None = None, what: str = "path") -> Skeleton:
    """The skeleton of a map's ``key``: ``given`` (the command line's ``--flag``), else the file the
    map names relative to itself; ``missing``: the error when neither names one."""
    ref = f.string(key, default=None)
    if given is not None:
        return given
    if ref is None:
        raise InputError(Mark(str(path), 1, 1), missing,
                         f"give --{flag} SKELETON, or `{key}: PATH` (relative to the map) in the map")
    p = (policy or RefPolicy()).resolve(path, ref, f.vmark(key), what)
    if not p.is_file():
        raise InputError(f.vmark(key), f"skeleton file {ref!r} not found", "a path relative to the map file")
    return load_skeleton(p, policy)


def shorthand(key: str, value: str, where: Mark) -> YMap:
    """An entry's ``NAME`` shorthand as the mapping ``{key: NAME}`` whose value sits at ``where``."""
    m = YMap({key: value})
    m.mark, m.key_marks, m.value_marks = where, {key: where}, {key: where}
    return m
