"""One output rule for every command that writes: a command's files are checked whole before
the first byte, then written by one call, :func:`write_outputs`.

Commands that make a set of files at once (``axdf import osim|bvh|mjcf``, ``axdf retarget``,
``axdf transfer``) collect them in an :class:`OutputSet` and hand it over::

    files = OutputSet(out, "import bvh")           # OUT: the command's own folder (--out)
    files.add(path, data, "--pose-out")            # a path inside OUT, or a single file outside it
    write_outputs(files, inputs=[bvh_path], overwrite=args.overwrite)

An importer's CLI calls :func:`axdf_cli.cli.importer.write_imported` instead, which adds, between
the checks and the write, the importers' own promise: every YAML file read back by the file
specs (what ``axdf validate`` accepts). Give the command ``--overwrite``
(:func:`axdf_cli.cli.importer.add_overwrite_arg`). A builder that collects ``path -> bytes`` in
a dict uses :class:`UniqueFiles`, so that two outputs on one path are refused, not merged.

The rule (docs/OUTPUTS.md):

- **OUT is a folder the command owns.** It is written only when it is absent, empty, or
  holds the output of the same command (its ``manifest.json`` says ``tool: axdf`` and
  ``command: <this command>``); then only with ``--overwrite``. Anything else is refused
  (exit 2). The new output is built in ``OUT/.axdf-new-<pid>/`` and swapped in once it is
  complete: the files the old manifest lists and the new output lacks are deleted then,
  never earlier; anything else in OUT stays (:class:`~axdf_cli.fileio.runfolder.Session`), and
  a new file that would land on a file the old manifest does not list (or on a link) is refused.
- **A single file outside OUT** (``--skeleton-out``, ``--pose-out``, a muscles or meshes
  folder elsewhere): written when it does not exist; an existing file only with
  ``--overwrite`` and only when axdf wrote it: OUT's manifest lists it (``outside``: its
  path relative to OUT and its sha256) and its bytes are still those. A file you wrote, or
  edited since, is refused (exit 2) and stays. A symbolic link is never replaced or written
  through. Nothing outside OUT is ever deleted.
- **Nothing through links**: no folder below OUT on the way to a file may be a link.
- **One writer**: ``flock`` on ``OUT/.axdf-lock`` (another writer: exit 3).
- **An input is never an output**: every output's real path differs from every input's
  (and from every file ``--overwrite`` would delete), and two outputs of one command differ.
- **Every check before the first byte**: :func:`check_outputs` only reads.

Outside files are written in the swap's window (signals held), after a manifest that names
both their old and new sha256: a kill there leaves files a later ``--overwrite`` still
recognises.
"""
from __future__ import annotations

import errno
import hashlib
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path

from axdf_cli import __version__
from axdf_cli.errors import EnvironmentProblem, InputError, Mark
from axdf_cli.fileio import atomic
from axdf_cli.fileio.runfolder import (LOCK, MANIFEST, STAGING_PREFIX, Manifest, Root, Session, check_way,
                                       is_file_with, plain_relpath, prepare)


@dataclass(frozen=True)
class Output:
    path: Path  # absolute, normalised (not resolved: a link on the way is checked, not followed)
    data: bytes
    what: str  # what names it for the user: a flag (--pose-out) or a role (skeleton, muscle file)
    shown: str = ""  # the path as the command was given it (for messages)

    def __str__(self) -> str:
        return f"{self.what} {self.shown or self.path}"


@dataclass
class OutputSet:
    """The files one command writes: ``out`` (its folder, ``--out``) and every file's bytes."""

    out: Path
    command: str  # "import bvh", "transfer", ...: recorded in the manifest
    files: list = field(default_factory=list)  # [Output]
    settings: dict = field(default_factory=dict)  # recorded in the manifest (no absolute paths)

    def __post_init__(self):
        self.out = Path(self.out)
        self._seen: dict = {}

    def add(self, path: Path | str, data: bytes, what: str) -> None:
        """Add a file (inside OUT or not). The same path twice is refused, naming both."""
        p = Path(os.path.abspath(path))
        if p in self._seen:
            raise InputError(None, f"{what} and {self._seen[p]} are the same file {path}",
                             "two outputs of one command need different paths")
        self._seen[p] = what
        self.files.append(Output(p, bytes(data), what, str(path)))

    def relpath(self, path: Path) -> str | None:
        """``path`` relative to OUT when it lies inside OUT, else None."""
        rel = os.path.relpath(path, os.path.abspath(self.out))
        return None if rel == os.curdir or rel == os.pardir or rel.startswith(os.pardir + os.sep) else \
            Path(rel).as_posix()

    def __iter__(self):
        return iter(self.files)


class UniqueFiles(dict):
    """``path -> bytes`` for a builder that collects its files in a dict: the same path (after
    normalisation) twice is refused instead of silently keeping one of them."""

    def __setitem__(self, key, value) -> None:
        norm = os.path.abspath(key)
        seen = self.__dict__.setdefault("_seen", set())
        if norm in seen:
            raise InputError(None, f"two outputs would be the same file {key}",
                             "give the outputs different paths (--skeleton-out, --pose-out, ... and --out)")
        seen.add(norm)
        super().__setitem__(key, value)


@dataclass(frozen=True)
class Checked:
    """An :class:`OutputSet` that passed every check (:func:`check_outputs`): what to write where."""

    outputs: OutputSet
    target: object  # runfolder.Target
    inside: dict  # rel -> Output
    outside: dict  # rel to OUT -> (Output, sha256 of the file there now or None)
    inputs: list  # [{file, sha256}]: every input read (no absolute path: see _shown)


def _real(path: Path) -> str:
    """The real path of ``path`` (its folder resolved; a final link resolved too)."""
    return os.path.realpath(path)


def _shown(path: Path) -> str:
    """An input as the manifest names it: relative to the current folder when below it, else
    its file name (no absolute path, and none spelled out by '..' either)."""
    rel = os.path.relpath(os.path.abspath(path))
    return Path(rel).as_posix() if not rel.startswith(os.pardir) else path.name


def _sha_of(path: Path) -> str:
    return atomic.sha256_file(path)


def _recorded(previous: Manifest | None, key: str, rel: str) -> set:
    if previous is None:
        return set()
    got = previous.data.get(key)
    sha = got.get(rel) if isinstance(got, dict) else None
    return {sha} if isinstance(sha, str) else set()


def check_outputs(outputs: OutputSet, *, inputs=(), overwrite: bool = False, assets=(), input_dirs=()) -> Checked:
    """Every check of the output rule (module docstring); reads only. ``inputs``: the files
    the command read (never an output; listed in the manifest with their sha256); ``assets``:
    more files it read that are never an output either but are not listed (a MuJoCo model's
    mesh files: many, and named by wherever a package installed them); ``input_dirs``: folders
    the command read whole (every YAML file below ``transfer``'s MUSCLES folder): no output
    lies below one, or the same command run again would read its own output."""
    out = outputs.out
    inside: dict = {}
    outside_files: list = []
    top_out = Path(os.path.abspath(out))
    for o in outputs:
        if o.path == top_out or o.path in top_out.parents:
            raise InputError(None, f"{o} is the output folder {out} (or holds it)", "a file inside or beside --out")
        rel = outputs.relpath(o.path)
        if rel is None:
            outside_files.append(o)
            continue
        if not plain_relpath(rel):
            raise InputError(None, f"{o} is not a plain path inside {out}", "a file below --out")
        top = rel.split("/", 1)[0]
        if rel == MANIFEST or top == LOCK or top.startswith((atomic.TMP_PREFIX, STAGING_PREFIX)):
            raise InputError(None, f"{o} is a name axdf keeps for itself in {out}",
                             f"any name but {MANIFEST} and names starting with .axdf-")
        inside[rel] = o
    # an input is never an output; two outputs are never one file (real paths: links resolved)
    reals: dict = {}
    for o in outputs:
        r = _real(o.path)
        if r in reals:
            raise InputError(None, f"{o} and {reals[r]} are the same file",
                             "two outputs of one command need different paths")
        reals[r] = str(o)
    recorded_inputs: list = []
    for i in [*inputs, *assets]:
        if i is None:
            continue
        clash = reals.get(_real(Path(i)))
        if clash:
            raise InputError(Mark(str(i)), f"this input is also an output: {clash}",
                             "an input is never overwritten; choose another output path")
    for d in input_dirs:
        real_d = _real(Path(d))
        for o in [Output(top_out, b"", "output folder", str(out)), *outputs]:
            if _real(o.path) == real_d or _real(o.path).startswith(real_d.rstrip(os.sep) + os.sep):
                raise InputError(Mark(str(d)), f"{o} lies in this input folder, which is read whole",
                                 "an output outside the input folders (the same command run again would "
                                 "read its own output)")
    for i in inputs:
        if i is not None and os.path.isfile(i):
            recorded_inputs.append({"file": _shown(Path(i)), "sha256": _sha_of(Path(i))})
    dirs = sorted({str(Path(rel).parent.as_posix()) for rel in inside} - {"."})
    target = prepare(out, overwrite=overwrite, dirs=dirs, command=outputs.command, resumable=False)
    previous = target.previous
    old_files = previous.files() if previous is not None else {}
    for rel in inside:  # a folder of the new output where the old one has a file, or the reverse
        for f in old_files:
            if f.startswith(rel + "/") or rel.startswith(f + "/"):
                raise InputError(previous.mark(("files", f)), f"{rel} and {f} cannot both be files",
                                 "remove the old output first")
    for rel, o in inside.items():
        try:
            st = os.lstat(out / rel)
        except FileNotFoundError:
            continue
        except OSError as e:
            raise atomic.environment_problem(out / rel, e) from None
        if stat.S_ISDIR(st.st_mode):
            raise InputError(None, f"{o} is a folder", "a file; remove or rename the folder")
        if stat.S_ISLNK(st.st_mode):
            raise InputError(None, f"{o} is a symbolic link",
                             "axdf never replaces a link or writes through one; remove the link")
        if rel not in old_files:  # a file there that the old output does not list: not axdf's
            raise InputError(None, f"{o} exists and {out / MANIFEST} does not list it (axdf did not write it)",
                             "--overwrite replaces only the files the old output lists; move it away")

    deleted = {_real(out / rel): f"{rel} (listed in {out / MANIFEST}, deleted by --overwrite)"
               for rel in old_files if rel not in inside} if overwrite else {}
    for i in [*inputs, *assets]:
        if i is not None and _real(Path(i)) in deleted:
            raise InputError(Mark(str(i)), f"this input would be deleted: {deleted[_real(Path(i))]}",
                             "an input is never overwritten or deleted; choose another output folder")
    for d in input_dirs:  # a folder read whole (axdf atlas --muscles OUT/muscles) is not emptied either
        real_d = _real(Path(d)).rstrip(os.sep) + os.sep
        gone = sorted(v for r, v in deleted.items() if r.startswith(real_d))
        if gone:
            raise InputError(Mark(str(d)), f"this input folder's files would be deleted: {gone[0]}"
                             + (f" and {len(gone) - 1} more" if len(gone) > 1 else ""),
                             "an input is never overwritten or deleted; choose another output folder, or copy "
                             "the input out of it first")
    outside: dict = {}
    for o in outside_files:
        rel = Path(os.path.relpath(o.path, os.path.abspath(out))).as_posix()
        try:
            st = os.lstat(o.path)
        except FileNotFoundError:
            check_way(o.path, o.what)
            outside[rel] = (o, None)
            continue
        except NotADirectoryError:
            check_way(o.path, o.what)
            raise
        except OSError as e:
            raise atomic.environment_problem(o.path, e) from None
        if stat.S_ISLNK(st.st_mode):
            raise InputError(None, f"{o} is a symbolic link",
                             "axdf never replaces a link or writes through one; give the file's own path")
        if not stat.S_ISREG(st.st_mode):
            raise InputError(None, f"{o} exists and is not a regular file", "a new or axdf-written file")
        if not overwrite:
            raise InputError(None, f"{o} exists",
                             f"pass --overwrite to replace a file axdf wrote (listed in {out / MANIFEST}), "
                             "or choose another path")
        sha = _sha_of(o.path)
        if sha not in _recorded(previous, "outside", rel) | _recorded(previous, "outside_previous", rel) | \
                _recorded(previous, "outside_earlier", rel):
            listed = bool(_recorded(previous, "outside", rel))
            raise InputError(None, f"{o} " + ("was changed since axdf wrote it" if listed else
                             f"was not written by this command into {out} (its manifest does not list it)"),
                             "--overwrite replaces only files axdf wrote and nobody changed since; "
                             "move it away or choose another path")
        outside[rel] = (o, sha)

    _writable(top_out, f"output folder {out}")
    for o, _ in outside.values():
        _writable(o.path.parent, str(o))
    return Checked(outputs, target, inside, outside, sorted(recorded_inputs, key=lambda d: (d["file"], d["sha256"])))


def _writable(folder: Path, what: str) -> None:
    """The folder (or, where it is still to be made, its nearest existing parent) takes new
    files: a read-only file system or folder is exit 3 here, before OUT's manifest is written
    (a file outside OUT is written after it)."""
    p = Path(folder)
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    if os.path.isdir(p) and not os.access(p, os.W_OK):
        raise EnvironmentProblem(f"{what}: cannot write in {p} (a read-only file system or folder)",
                                 "choose a writable output path")


def write_checked(checked: Checked) -> dict:
    """Write what :func:`check_outputs` accepted: the files inside OUT staged and swapped in,
    the files outside OUT beside it; return the manifest written."""
    o = checked.outputs
    with Session(checked.target, stage=True) as session:
        root = Root(session.root)
        files: dict = {}
        for rel, out in sorted(checked.inside.items()):
            files[rel] = atomic.write_bytes(root.path(rel), out.data)
        new_outside = {rel: hashlib.sha256(x.data).hexdigest() for rel, (x, _) in sorted(checked.outside.items())}
        old_outside = {rel: sha for rel, (_, sha) in sorted(checked.outside.items()) if sha is not None}
        manifest = {"tool": "axdf", "version": __version__, "command": o.command, "complete": True,
                    "inputs": checked.inputs, "settings": o.settings, "files": files, "outside": new_outside}
        earlier = _earlier_outside(checked, new_outside)
        if earlier:
            manifest["outside_earlier"] = earlier

        def write_outside() -> None:
            for rel, (x, sha) in sorted(checked.outside.items()):
                _still(x, sha)
                atomic.write_bytes(x.path, x.data)

        session.commit(manifest, interim={"outside": new_outside, "outside_previous": old_outside},
                       during=write_outside)
    return manifest


def _earlier_outside(checked: Checked, new_outside: dict) -> dict:
    """Files outside OUT that an earlier output wrote and this one does not (never deleted:
    they stay where they are): still recognised as axdf's while their bytes are unchanged, so
    that a later ``--overwrite`` writing them again may replace them (an import with another
    ``--name``, then the first one again, replaces its own earlier files)."""
    previous = checked.target.previous
    out = os.path.abspath(checked.outputs.out)
    earlier: dict = {}
    for key in ("outside", "outside_earlier"):
        got = previous.data.get(key) if previous is not None else None
        for rel, sha in (got.items() if isinstance(got, dict) else ()):
            if isinstance(rel, str) and rel not in new_outside and isinstance(sha, str) and rel not in earlier \
                    and "\x00" not in rel and is_file_with(Path(os.path.normpath(os.path.join(out, rel))), sha):
                earlier[rel] = sha
    return dict(sorted(earlier.items()))


def _still(o: Output, sha: str | None) -> None:
    """An outside file is still what :func:`check_outputs` saw (absent, or those bytes)."""
    try:
        st = os.lstat(o.path)
    except FileNotFoundError:
        if sha is None:
            return
        st = None
    if sha is None or st is None or not stat.S_ISREG(st.st_mode) or _sha_of(o.path) != sha:
        raise InputError(None, f"{o} changed while axdf was writing", "run again")


def write_outputs(outputs: OutputSet, *, inputs=(), overwrite: bool = False, input_dirs=()) -> dict:
    """The one call: :func:`check_outputs` (every check, nothing written), then
    :func:`write_checked`. Returns the manifest written into OUT."""
    return write_checked(check_outputs(outputs, inputs=inputs, overwrite=overwrite, input_dirs=input_dirs))


def check_file_output(path: Path | str, what: str, recognise) -> None:
    """A single file a command writes afresh on each call, without a manifest (``compare
    --report``, ``--junit``): absent, or a regular file that ``recognise(head)`` (its first
    :data:`HEAD_BYTES` bytes) says this command wrote; then it is replaced. A link (even to
    a report), a FIFO, a folder, or any other file (a golden file, a run's manifest, your
    YAML) is refused (exit 2) before anything is written: it is never replaced."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except (FileNotFoundError, NotADirectoryError):
        check_way(path, what)
        return
    except OSError as e:
        if e.errno == errno.ELOOP:
            check_way(path, what)
        raise atomic.environment_problem(path, e) from None
    if stat.S_ISLNK(st.st_mode):
        raise InputError(None, f"{what} {path} is a symbolic link",
                         "axdf never replaces a link or writes through one; give the file's own path")
    if stat.S_ISDIR(st.st_mode):
        raise InputError(None, f"{what} {path} is a folder", f"{what} takes a file name")
    if not stat.S_ISREG(st.st_mode):
        raise InputError(None, f"{what} {path} exists and is not a regular file", "a new file, or one axdf wrote")
    try:
        with open(path, "rb") as f:
            head = f.read(HEAD_BYTES)
    except OSError as e:
        raise atomic.environment_problem(path, e) from None
    if not recognise(head):
        raise InputError(None, f"{what} {path} exists and was not written by axdf",
                         "a new path, or an earlier output of the same option (axdf replaces only those); "
                         "move the file away")


HEAD_BYTES = 512  # what check_file_output reads of an existing file to recognise it
