"""A data set's output folder under the output rule (axdf_cli/fileio/outputs.py,
docs/OUTPUTS.md).

- OUT is written only when it is absent, empty, or holds an axdf data set (``dataset.json``
  with ``tool: axdf``); anything else is refused (exit 2), before anything is written.
- **The same data set** (the same ``dataset.json`` bytes: inputs, settings, seed): its
  sequences are finished (``--resume``) or made again (``--overwrite``) in place; each
  sequence is an ``axdf run`` folder (staged and swapped by the run's own rules) plus its
  views, labels and ``sequence.json``. Files a sequence's earlier record lists and the new
  one lacks are deleted once the new record is written; anything else in a sequence folder
  (your annotations, other views) stays.
- **Another data set** (other seed, inputs or settings) with ``--overwrite``: the new one is
  built whole in ``OUT/.axdf-new-<pid>/`` and swapped in only once it is complete (index
  included); then the files the old data set lists (its ``dataset.json``, ``index.parquet``,
  bone meshes, and each sequence's listed files) are deleted and the new ones moved in. An
  interrupted or failed build leaves the old data set as it was. Shards (``--shard K/N``,
  N > 1) of another data set are refused: each shard would replace the folder alone.
- Nothing is written or deleted through a link: OUT's sequence folders, ``views``,
  ``views/<view>``, ``meshes``, ``bones`` are checked to be real folders first.
- One writer (axdf_cli/fileio/lock.py, the run's rule): ``flock`` on OUT (the folder itself,
  so a killed build leaves no lock file):
  exclusive for a build of the whole data set and for ``merge``, shared between the shards
  of one data set (after an exclusive claim of ``dataset.json``); each sequence is locked
  exclusively by the worker that makes it. A second writer is refused (exit 3).
"""
from __future__ import annotations

import json
import os
import shutil
import stat
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio import atomic
from axdf_cli.fileio.runfolder import (MANIFEST, STAGING_PREFIX, Manifest, check_dirs, check_way, own_entry, prepare,
                                       plain_relpath, swap_in)
from axdf_cli.fileio.yamlio import is_name
from axdf_cli.tolerances import MAX_SEED

DATASET_JSON = "dataset.json"
INDEX = "index.parquet"
RECORD = "sequence.json"
BONES = "bones"


# ----------------------------------------------------------------------------- dataset.json, read back


def read_dataset_json(path: Path, required: bool = True) -> Manifest | None:
    """An axdf data set's ``dataset.json`` (positions kept for messages), checked for what the
    commands read from it: ``tool: axdf``, ``dataset``, ``seed``, ``shards``, ``image.passes``,
    ``sequences`` (a list of ``{name, ...}`` with axdf names), ``bones`` (name -> path).
    Not one (``required``): exit 2 at its line and column; else None."""
    try:
        m = Manifest.read(path)
    except InputError:
        if required:
            raise
        return None
    try:
        if m.data.get("tool") != "axdf" or "dataset" not in m.data:
            raise m.error(("tool",), "not a data set written by axdf", "a dataset.json with tool 'axdf' and dataset: NAME")
        if not 0 <= m.get(("seed",), int, "a whole number") <= MAX_SEED:
            raise m.error(("seed",), f"{m.data['seed']} is out of range", f"a seed in 0..{MAX_SEED}")
        if m.get(("shards",), int, "a whole number") < 1:
            raise m.error(("shards",), f"{m.data['shards']} shards", "a data set is built in 1 or more shards")
        passes = m.get(("image", "passes"), list, "a list of image passes")
        for i, p in enumerate(passes):
            m.get(("image", "passes", i), str, "a pass name")
        seqs = m.get(("sequences",), list, "a list of {name, source, frames}")
        for i, _ in enumerate(seqs):
            m.get(("sequences", i), dict, "an object {name, source, frames}")
            name = m.get(("sequences", i, "name"), str, "a sequence name")
            if not is_name(name):
                raise m.error(("sequences", i, "name"), f"{name!r} is not a sequence name", "an axdf name")
        bones = m.get(("bones",), dict, "an object of bone -> bones/<bone>.ply", required=False, default={})
        for b, rel in bones.items():
            if not isinstance(rel, str) or not plain_relpath(rel):
                raise m.error(("bones", b), f"{rel!r} is not a plain relative path", "bones/<bone>.ply")
    except InputError:
        if required:
            raise
        return None
    return m


def sequence_names(m: Manifest) -> list[str]:
    return [s["name"] for s in m.data["sequences"]]


def listed_files(out: Path, m: Manifest) -> dict:
    """What an old data set in ``out`` lists as its own, relative to ``out``: dataset.json,
    index.parquet, its bone meshes, and per sequence its record's files (or, for a sequence
    that never completed, its run manifest's)."""
    files = {DATASET_JSON: None, INDEX: None}
    files.update({rel: None for rel in m.data.get("bones", {}).values()})
    for name in sequence_names(m):
        rec = _json_object(out / name / RECORD)
        listed = rec.get("files") if isinstance(rec, dict) else None
        if isinstance(listed, dict):
            files[f"{name}/{RECORD}"] = None
        else:
            man = _json_object(out / name / MANIFEST)
            listed = man.get("files") if isinstance(man, dict) and man.get("tool") == "axdf" else None
            if isinstance(listed, dict):
                files[f"{name}/{MANIFEST}"] = None
        for rel in listed or {}:
            if plain_relpath(rel):
                files[f"{name}/{rel}"] = None
    return files


def _json_object(path: Path):
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_size > (256 << 20):
            return None
        return json.loads(Path(path).read_bytes())
    except (OSError, ValueError, RecursionError):
        return None


# ----------------------------------------------------------------------------- the checks


@dataclass
class DatasetTarget:
    """A data-set folder, checked: how this build writes it."""

    out: Path
    mode: str  # "new" (absent or empty), "same" (this data set), "replace" (another one, --overwrite)
    old: Manifest | None = None  # the dataset.json there now
    root: Path = None  # where this build writes: OUT, or its staging folder (replace)
    old_files: dict = field(default_factory=dict)  # replace: what the old data set lists

    def __post_init__(self):
        self.root = self.out / f"{STAGING_PREFIX}{os.getpid()}" if self.mode == "replace" else self.out


def sequence_dirs(names, views, muscles, fmt: str) -> list[str]:
    """The folders below OUT a data set's sequences write into."""
    from axdf_cli.fileio.runfolder import mesh_relpath

    dirs = []
    for n in names:
        dirs += [f"{n}/views/{v}" for v in views]
        dirs += [f"{n}/{PurePosixPath(mesh_relpath(m, 0, fmt)).parent}" for m in muscles]
    return dirs


def check(out: Path, dataset_json: bytes, names: list[str], dirs: list[str], *, resume: bool, overwrite: bool,
          shards: int) -> DatasetTarget:
    """Every check of a build's output folder (reads only). ``names``: this build's
    sequences; ``dirs``: folders below OUT it writes into; ``shards``: N of ``--shard K/N``."""
    out = Path(out)
    try:
        st = os.stat(out)
    except (FileNotFoundError, NotADirectoryError):
        if os.path.lexists(out):  # a dangling link: nothing is made at its far end
            raise InputError(None, f"--out {out} is a symbolic link to nothing", "give a folder") from None
        check_way(out, "--out")
        return DatasetTarget(out, "new")
    except OSError as e:
        raise atomic.environment_problem(out, e) from None
    if not stat.S_ISDIR(st.st_mode):
        raise InputError(None, f"--out {out} exists and is not a folder", "give a folder")
    try:
        entries = [n for n in os.listdir(out) if not own_entry(n)]
    except OSError as e:
        raise atomic.environment_problem(out, e) from None
    if not entries:
        return DatasetTarget(out, "new")
    dj = out / DATASET_JSON
    if os.path.islink(dj):
        raise InputError(None, f"{dj} is a symbolic link", "a data set's dataset.json is a file axdf wrote")
    old = read_dataset_json(dj, required=False) if dj.is_file() else None
    if old is None:
        if dj.is_file() and (resume or overwrite):
            read_dataset_json(dj)  # a damaged dataset.json: say where
        raise InputError(None, f"output folder {out} is not empty and holds no axdf data set (no dataset.json "
                         "written by axdf)", "--overwrite and --resume only replace or finish axdf's own data "
                         "sets; choose an empty or new output folder")
    for f in (INDEX,):
        if os.path.islink(out / f) or (os.path.lexists(out / f) and not os.path.isfile(out / f)):
            raise InputError(None, f"{out / f} is not a regular file", "the data set's index is a file axdf writes")
    if dj.read_bytes() == dataset_json:
        check_dirs(out, [BONES] + list(names) + dirs)
        present = [n for n in names if os.path.lexists(out / n)]
        if present and not (resume or overwrite):
            raise InputError(None, f"{len(present)} sequence folder(s) of this run exist in {out} "
                             f"(first: {present[0]})",
                             "pass --resume to finish them, --overwrite to make them again, or another --out")
        for n in present:  # each is an axdf run folder, finished or made again by the run's rule: its
            # refusals (a damaged manifest, files but no run) come now, not after other sequences were made
            prepare(out / n, resume=resume, overwrite=not resume)
        return DatasetTarget(out, "same", old)
    if not overwrite:
        raise InputError(old.mark(("seed",)), f"output folder {out} holds another data set (its dataset.json differs: "
                         "other inputs, settings or seed)",
                         "pass --overwrite to replace it, or another --out (shards of one data set share one --out)")
    if shards > 1:
        raise InputError(old.mark(("seed",)), f"output folder {out} holds another data set; --overwrite with "
                         f"--shard K/{shards} would replace it shard by shard",
                         "build the new data set's shards into a new --out (or build it whole, without --shard, "
                         "to replace the old one once the new one is complete)")
    old_files = listed_files(out, old)
    check_dirs(out, sorted({str(PurePosixPath(r).parent) for r in old_files} - {"."}) + [BONES] + list(names)
               + dirs)
    return DatasetTarget(out, "replace", old, old_files=old_files)


def check_dry(out: Path, *, resume: bool, overwrite: bool) -> None:
    """``--dry-run``'s checks of OUT, which do not need the list of sequences: OUT is absent,
    empty or an axdf data set (its dataset.json readable)."""
    out = Path(out)
    if os.path.lexists(out) and not out.is_dir():
        raise InputError(None, f"--out {out} exists and is not a folder", "give a folder")
    if not os.path.lexists(out):
        check_way(out, "--out")
    if not out.is_dir() or not [n for n in os.listdir(out) if not own_entry(n)]:
        return
    dj = out / DATASET_JSON
    if os.path.islink(dj) or not dj.is_file():
        raise InputError(None, f"output folder {out} is not empty and holds no axdf data set (no dataset.json "
                         "written by axdf)", "choose an empty or new output folder")
    read_dataset_json(dj)


# ----------------------------------------------------------------------------- the swap


def staged_files(root: Path) -> list[str]:
    """Every file below a staging folder, relative to it (axdf's own temporaries aside)."""
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [d for d in dirnames if not own_entry(d)]
        rel = Path(dirpath).relative_to(root)
        out += [(rel / f).as_posix() for f in filenames if not own_entry(f)]
    return sorted(out)


def commit_replace(target: DatasetTarget) -> None:
    """Swap a complete new data set from its staging folder into OUT (signals held): the old
    data set's listed files are deleted, the new ones moved in, ``dataset.json`` last."""
    with atomic.deferred_signals():
        swap_in(target.root, target.out, target.old_files, staged_files(target.root), last=DATASET_JSON)


def discard_staging(target: DatasetTarget) -> None:
    if target.mode == "replace":
        shutil.rmtree(target.root, ignore_errors=True)


def check_merge(out: Path) -> Manifest:
    """``axdf dataset merge OUT``: OUT holds an axdf data set (exit 2 at the position in its
    dataset.json otherwise); the index may be written (not a link, not a folder)."""
    out = Path(out)
    dj = out / DATASET_JSON
    if not out.is_dir():
        raise InputError(Mark(str(out)), "not a folder", "give a folder written by axdf dataset build")
    if os.path.islink(dj):
        raise InputError(Mark(str(dj)), "a symbolic link", "a dataset.json written by axdf dataset build")
    if not os.path.lexists(dj):
        raise InputError(Mark(str(dj)), "no dataset.json", "give a folder written by axdf dataset build")
    m = read_dataset_json(dj)
    if os.path.islink(out / INDEX) or (os.path.lexists(out / INDEX) and not os.path.isfile(out / INDEX)):
        raise InputError(Mark(str(out / INDEX)), "not a regular file", "the data set's index is a file axdf writes")
    return m
