"""The run folder: where each file of a run lives, its manifest, and the rules that keep a
user's files safe.

One module for everything that knows the layout (docs/OUTPUTS.md), shared by
``axdf run`` (:mod:`axdf_cli.pipeline`), ``axdf render`` and reading a run back
(:mod:`axdf_cli.render.runio`)::

    manifest.json                 MANIFEST_KEYS, in that order
    meshes/<m>/<m>_<frame:04d>.<fmt>
    meshes/<frame:04d>.<fmt>      --mesh-files frame: every muscle of a frame in one file
    bones/<bone>.ply
    stats.csv, bones.csv
    frames/<frame:04d>.png|exr, camera.json
    <folder>/<m>.<ext>            per-sequence formats (each format's folder: its FORMATS entry):
                                  usd/<m>.usdc, pc2/<m>.pc2, mdd/<m>.mdd, npz/<m>.npz;
                                  pc2/<m>.ply, mdd/<m>.ply rest meshes
    scene.usda, usd/bones.usdc    the USD stage of the run and its bone meshes
    .axdf-lock                    while a run or render writes (flock); never in the manifest
    .axdf-new-<pid>/              --overwrite builds the new run here, then swaps it in
    .axdf-tmp-<pid>-<name>        a file being written (renamed when whole)

The rules:

- A folder is a *run* when its ``manifest.json`` is a JSON object with ``tool: axdf``. Only a
  run is resumed, re-rendered or overwritten; any other non-empty folder is refused (exit 2).
- Every check comes before the first byte is written: :func:`prepare` only reads.
- One writer at a time: :class:`Session` holds ``flock`` on ``.axdf-lock`` (:mod:`.lock`) for the whole run;
  a second writer is refused (exit 3).
- ``--overwrite`` deletes only the files the old manifest lists, and only once the new run
  is complete (built in ``.axdf-new-<pid>/``, then :meth:`Session.commit` swaps it in).
  Anything else in the folder stays.
- No write or deletion goes through a symbolic link: every folder written into is checked
  to be a real folder below OUT (:class:`Root`); a link is refused (exit 2) and named.
- Temporaries and staging folders are removed only when the process named in them is gone.
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import shutil
import stat
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from axdf_cli import tolerances as tol
from axdf_cli.fileio import atomic
from axdf_cli.fileio.lock import link_refused, lock_file, unlock_file
from axdf_cli.errors import EnvironmentProblem, InputError, Mark
from axdf_cli.fileio.yamlio import FileRefused, read_regular

MANIFEST = "manifest.json"
STATS = "stats.csv"
BONES_CSV = "bones.csv"
CAMERA = "camera.json"
FRAME_EXTENSIONS = ("png", "exr")
MAX_PENDING_WRITES = 64  # files queued for the writer thread (bounds memory)
MANIFEST_INTERVAL_S = 1.0  # an in-progress manifest is rewritten at most this often
LOCK = ".axdf-lock"
STAGING_PREFIX = ".axdf-new-"
LAYOUT_DIRS = ("meshes", "bones", "frames")

# the manifest's keys, in the one order every writer uses (unknown keys follow, sorted)
MANIFEST_KEYS = ("tool", "version", "command", "complete", "inputs", "settings", "identity", "frames", "muscles", "bones",
                 "warnings", "ranges", "files", "outside", "outside_previous", "outside_earlier", "bounds", "gl")
#: The command that wrote a folder (``command`` in its manifest; a run's manifest has none).
RUN_COMMAND = "run"


def command_of(manifest: "Manifest") -> str:
    """The command whose output a manifest describes: ``run`` unless it says otherwise."""
    c = manifest.data.get("command", RUN_COMMAND)
    return c if isinstance(c, str) else repr(c)




def mesh_relpath(muscle: str, frame: int, fmt: str) -> str:
    return f"meshes/{muscle}/{muscle}_{frame:04d}.{fmt}"


def frame_mesh_relpath(frame: int, fmt: str) -> str:
    """One frame's file holding every muscle (``--mesh-files frame``)."""
    return f"meshes/{frame:04d}.{fmt}"


def sequence_relpath(muscle: str, folder: str, extension: str) -> str:
    """A per-sequence file: one muscle, every frame (``folder``: its format's)."""
    return f"{folder}/{muscle}.{extension}"


def rest_mesh_relpath(muscle: str, folder: str) -> str:
    """The rest mesh a point cache (pc2, mdd) applies to, beside it in its format's ``folder``."""
    return f"{folder}/{muscle}.ply"


USD_STAGE = "scene.usda"
USD_BONES = "usd/bones.usdc"


def bone_mesh_relpath(bone: str) -> str:
    """Bone meshes are copied into the run, so that a run folder renders on its own."""
    return f"bones/{bone}.ply"


def frame_relpath(frame: int, ext: str) -> str:
    return f"frames/{frame:04d}.{ext}"


def gl_record(renderer: str, version: str) -> dict:
    """The manifest's ``gl`` entry: the GL renderer that drew the frames."""
    return {"renderer": renderer, "version": version}


def manifest_text(manifest: dict) -> str:
    ordered = {k: manifest[k] for k in MANIFEST_KEYS if k in manifest}
    ordered.update(sorted((k, v) for k, v in manifest.items() if k not in ordered))
    if isinstance(ordered.get("files"), dict):
        ordered["files"] = dict(sorted(ordered["files"].items()))
    return json.dumps(ordered, indent=1) + "\n"


def write_manifest(folder: Path, manifest: dict) -> None:
    atomic.write_text(Path(folder) / MANIFEST, manifest_text(manifest))


def try_write_manifest(folder: Path, manifest: dict) -> None:
    """Record an interrupted writer's progress when the disk still takes it (the error that
    stopped the writer is the one reported)."""
    try:
        write_manifest(folder, manifest)
    except (OSError, EnvironmentProblem):
        pass


def check_dirs(root: Path, rel_dirs) -> bool:
    """Every existing folder on the way from ``root`` to each of ``rel_dirs`` is a real folder
    (not a symbolic link, not a file). Reads only; the rest will be created below ``root``.
    Returns whether every one of them exists already."""
    whole = True
    for rel in rel_dirs:
        p = Path(root)
        for part in PurePosixPath(rel).parts:
            p = p / part
            try:
                st = os.lstat(p)
            except FileNotFoundError:
                whole = False
                break
            if stat.S_ISLNK(st.st_mode):
                raise link_refused(p)
            if not stat.S_ISDIR(st.st_mode):
                raise InputError(None, f"{p} is not a folder", "the run folder's layout needs a folder there")
    return whole


def check_way(path: Path, what: str) -> None:
    """A path still to be made (``path`` absent): the nearest of its parents that exists is a
    folder. A file there (``--out walk.bvh/x``) or a link loop is bad input (exit 2), not a
    machine that cannot write (exit 3)."""
    p = Path(os.path.abspath(path)).parent
    while True:
        try:
            st = os.stat(p)
        except (FileNotFoundError, NotADirectoryError):
            if p == p.parent:
                return
            p = p.parent
            continue
        except OSError as e:
            if e.errno == errno.ELOOP:
                raise InputError(None, f"{what} {path}: {_shown_path(p)} is a symbolic link loop",
                                 "a path to a folder") from None
            return  # (permissions and the like: the write reports them, exit 3)
        if not stat.S_ISDIR(st.st_mode):
            raise InputError(None, f"{what} {path}: {_shown_path(p)} is not a folder", "a path whose parents are folders")
        return


def _shown_path(p: Path) -> str:
    """``p`` relative to the current folder when below it (messages name what the user typed)."""
    rel = os.path.relpath(p)
    return rel if not rel.startswith(os.pardir) else str(p)


class Root:
    """A folder written into. :meth:`path` gives the path of a file below it after checking
    that the way there is made of real folders only (once per folder that exists; one that
    does not is checked again until it does, so a link made later is still caught)."""

    def __init__(self, path: Path):
        self.root = Path(path)
        self._checked: set = set()

    def path(self, rel: str) -> Path:
        parent = PurePosixPath(rel).parent.as_posix()
        if parent not in self._checked and check_dirs(self.root, [parent]):
            self._checked.add(parent)
        return self.root / rel


class OutputWriter:
    """Writes files atomically on a background thread (so writing overlaps evaluation),
    records their sha256, and skips files whose bytes already match on resume.

    :meth:`write` queues the bytes (at most MAX_PENDING_WRITES wait); :meth:`flush` waits
    for all and re-raises a failed write's error (full disk: EnvironmentProblem) in the
    caller. ``files`` lists what is on disk, in the order written."""

    def __init__(self, out: Path, previous: dict):
        from concurrent.futures import ThreadPoolExecutor

        self.root = Root(out)
        self.previous = previous
        self.files: dict[str, str] = {}
        self.skipped = 0
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="axdf-writer")
        self._pending: list = []

    def write(self, rel: str, data: bytes) -> None:
        self._pending.append(self._pool.submit(self._write_now, rel, data))
        if len(self._pending) > MAX_PENDING_WRITES:
            self._collect(len(self._pending) - MAX_PENDING_WRITES)

    def _write_now(self, rel: str, data: bytes):
        sha = hashlib.sha256(data).hexdigest()
        path = self.root.path(rel)
        if self.previous.get(rel) == sha and is_file_with(path, sha, len(data)):
            return rel, sha, True
        atomic.write_parts(path, (data,))
        return rel, sha, False

    def _collect(self, n: int) -> None:
        done, self._pending = self._pending[:n], self._pending[n:]
        for fut in done:
            rel, sha, skipped = fut.result()
            self.files[rel] = sha
            self.skipped += skipped

    def flush(self) -> None:
        self._collect(len(self._pending))

    def close(self, cancel: bool = False) -> None:
        """Stop the thread: after :meth:`flush`, or (cancel) dropping queued writes; a write
        in progress always finishes (files are whole or absent)."""
        if cancel:
            for fut in self._pending:
                fut.cancel()
        self._pool.shutdown(wait=True)
        done, self._pending = self._pending, []
        for fut in done:  # (cancelled) the files that were written all the same are on disk: list them
            if not fut.cancelled() and fut.exception() is None:
                rel, sha, _ = fut.result()
                self.files[rel] = sha


def is_file_with(path: Path, sha: str, size: int | None = None) -> bool:
    """Whether ``path`` is a regular file (not a link) holding bytes with this sha256."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    return stat.S_ISREG(st.st_mode) and (size is None or st.st_size == size) and atomic.sha256_file(path) == sha


# ----------------------------------------------------------------------------- the manifest, read back

_WS = re.compile(r"[ \t\n\r]*")
_HEX64 = re.compile(r"[0-9a-f]{64}")  # (fullmatch)


class Manifest:
    """A manifest.json read back: ``data`` and, for error messages, the line and column of
    any value (:meth:`mark`: located in the text only when an error needs it)."""

    def __init__(self, path: Path, text: str, data: dict, sha: str = ""):
        self.path = Path(path)
        self.text = text
        self.data = data
        self.sha = sha  # of the file's bytes: unchanged bytes, unchanged run

    @classmethod
    def read(cls, path: Path) -> "Manifest":
        where = Mark(str(path))
        try:
            raw = read_regular(path, tol.INPUT_MAX_BYTES)  # (bounded, regular files only: a FIFO there would block the reader)
        except FileNotFoundError:
            raise InputError(where, "no manifest.json", "a folder written by axdf run") from None
        except FileRefused as e:
            raise InputError(where, e.problem, f"a {Path(path).name} written by axdf") from None
        except OSError as e:
            raise InputError(where, f"cannot read ({e.strerror})", "a readable manifest.json") from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            line = raw.count(b"\n", 0, e.start) + 1
            col = e.start - (raw.rfind(b"\n", 0, e.start) + 1) + 1
            raise InputError(Mark(str(path), line, col), "not UTF-8 text", "a manifest.json written by axdf") from None
        try:
            data = json.loads(text)
        except json.JSONDecodeError as e:
            raise InputError(Mark(str(path), e.lineno, e.colno), f"not valid JSON ({e.msg})",
                             "a manifest.json written by axdf") from None
        except RecursionError:
            raise InputError(where, "nested too deeply", "a manifest.json written by axdf") from None
        m = cls(path, text, data, hashlib.sha256(raw).hexdigest())
        if not isinstance(data, dict):
            raise m.error((), f"the manifest is a JSON {_json_type(data)}", "a JSON object written by axdf")
        return m

    @property
    def is_run(self) -> bool:
        return self.data.get("tool") == "axdf"

    def mark(self, keys=()) -> Mark:
        """Where the value at ``keys`` (or its nearest enclosing value) starts in the file."""
        pos = _locate(self.text, tuple(keys))
        line = self.text.count("\n", 0, pos) + 1
        return Mark(str(self.path), line, pos - (self.text.rfind("\n", 0, pos) + 1) + 1)

    def error(self, keys, problem: str, allowed: str) -> InputError:
        path = _key_text(keys)
        return InputError(self.mark(keys), f"{path}: {problem}" if path else problem, allowed)

    def get(self, keys, kind, what: str, required: bool = True, default=None):
        """The value at ``keys`` when it has the JSON type ``kind`` (a type or tuple of types;
        bool is never a number here), else an error naming its position."""
        value = self.data
        for i, k in enumerate(keys):
            if isinstance(k, int):
                missing = not isinstance(value, list) or not 0 <= k < len(value)
            else:
                missing = not isinstance(value, dict) or k not in value
            if missing:
                if not required:
                    return default
                raise self.error(keys[:i], f"no {k!r}", f"{_key_text(keys) or 'the manifest'} is {what}")
            value = value[k]
        if not _is_kind(value, kind):
            raise self.error(keys, f"is a JSON {_json_type(value)}", f"{_key_text(keys)} is {what}")
        return value

    def files(self) -> dict:
        """``files``: relative path -> sha256, every path a plain relative path inside the folder."""
        files = self.get(("files",), dict, "an object of relative path -> sha256", required=False, default={})
        for rel, sha in files.items():
            if not plain_relpath(rel):
                raise self.error(("files", rel), f"{rel!r} is not a plain relative path inside the folder",
                                 "relative paths without '..', '.', links or absolute parts")
            if not isinstance(sha, str) or not _HEX64.fullmatch(sha):
                raise self.error(("files", rel), f"sha256 {sha!r}", "64 lowercase hex digits")
        return dict(files)

    def frames(self) -> list[int]:
        frames = self.get(("frames",), list, "a non-empty list of frame numbers")
        if not frames:
            raise self.error(("frames",), "is empty", "frames is a non-empty list of frame numbers")
        for i, f in enumerate(frames):
            if not _is_kind(f, int):
                raise self.error(("frames", i), f"{f!r} is not a frame number", "frames are whole numbers")
        return [int(f) for f in frames]


def _is_kind(value, kind) -> bool:
    kinds = kind if isinstance(kind, tuple) else (kind,)
    if isinstance(value, bool):
        return bool in kinds
    if type(value) is int and float in kinds:
        return True
    return isinstance(value, kinds)


def _json_type(v) -> str:
    return {dict: "object", list: "array", str: "string", bool: "boolean", int: "number", float: "number",
            type(None): "null"}.get(type(v), type(v).__name__)


def _key_text(keys) -> str:
    out = ""
    for k in keys:
        out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else str(k))
    return out


def plain_relpath(rel) -> bool:
    if not isinstance(rel, str) or not rel or "\\" in rel or "\x00" in rel or rel.startswith("/"):
        return False
    return all(part not in ("", ".", "..") for part in rel.split("/"))


def _locate(text: str, keys: tuple) -> int:
    """Character offset of the value at ``keys`` in JSON ``text`` (of the deepest one found)."""
    dec = json.JSONDecoder()
    i = _WS.match(text, 0).end()
    try:
        for key in keys:
            start = i
            if isinstance(key, str) and text.startswith("{", i):
                i = _WS.match(text, i + 1).end()
                while text.startswith('"', i):
                    k, i = json.decoder.scanstring(text, i + 1)
                    i = _WS.match(text, i).end() + 1  # the ':'
                    i = _WS.match(text, i).end()
                    if k == key:
                        break
                    i = _WS.match(text, dec.raw_decode(text, i)[1]).end()
                    i = _WS.match(text, i + 1).end() if text.startswith(",", i) else i
                else:
                    return start
            elif isinstance(key, int) and text.startswith("[", i):
                i = _WS.match(text, i + 1).end()
                for _ in range(key):
                    i = _WS.match(text, dec.raw_decode(text, i)[1]).end()
                    i = _WS.match(text, i + 1).end() if text.startswith(",", i) else i
                if text.startswith("]", i):
                    return start
            else:
                return start
    except (ValueError, IndexError):
        return 0
    return i


# what makes two runs the same run (--resume refuses to mix runs that differ in any)
RUN_IDENTITY = ("version", "inputs", "settings", "frames")


def describe_differences(old: Manifest, new: dict, keys=RUN_IDENTITY) -> list[str]:
    """What differs between an earlier manifest and a new one, key by key, in words."""
    out = []
    for key in keys:
        a, b = old.data.get(key), new.get(key)
        if a == b:
            continue
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if a.get(k) != b.get(k):
                    if key == "inputs":
                        out.append(f"input {k} " + ("is new" if k not in a else "is gone" if k not in b
                                                     else "changed (sha256 differs)"))
                    else:
                        out.append(f"{key}.{k}: {_short(a.get(k))} -> {_short(b.get(k))}")
        elif key == "frames" and isinstance(a, list) and isinstance(b, list):
            out.append(f"frames: {_frames_text(a)} -> {_frames_text(b)}")
        else:
            out.append(f"{key}: {_short(a)} -> {_short(b)}")
    return out


def _short(v) -> str:
    t = json.dumps(v)
    return t if len(t) <= 60 else t[:57] + "..."


def _frames_text(frames: list) -> str:
    return f"{len(frames)} frames {frames[0]}..{frames[-1]}" if frames else "no frames"


# ----------------------------------------------------------------------------- the folder: checks, lock, swap


def own_entry(name: str) -> bool:
    """Entries axdf makes while it writes (the lock, temporaries, a staging folder)."""
    return name == LOCK or name.startswith(atomic.TMP_PREFIX) or name.startswith(STAGING_PREFIX)


@dataclass(frozen=True)
class Target:
    """An output folder, checked: what it holds now and how it will be written."""

    out: Path
    previous: Manifest | None  # the run already there (None: the folder is absent or empty)
    replace: bool  # --overwrite of an earlier run: build the new one beside it, swap at the end
    dirs: tuple = ()  # the folders below OUT the writer writes into (stale temporaries are removed there)


def read_run_manifest(folder: Path) -> Manifest:
    """The manifest of an axdf run folder (exit 2 with its position when it is not one)."""
    path = Path(folder) / MANIFEST
    if os.path.islink(path):
        raise link_refused(path)
    m = Manifest.read(path)
    if not m.is_run:
        raise m.error(("tool",), "not written by axdf", "a manifest.json with tool 'axdf' (written by axdf run)")
    m.files()
    return m


def prepare(out: Path, *, resume: bool = False, overwrite: bool = False, dirs=(), command: str = RUN_COMMAND,
            resumable: bool = True) -> Target:
    """Check an output folder before anything is written (this only reads).

    Absent or empty: a new run. Holding the output of ``command`` (its manifest says
    ``tool: axdf`` and that command): refused unless ``resume`` or ``overwrite``. The output
    of another axdf command, or anything else that is not empty: refused. ``dirs``: the
    folders below OUT that will be written into; none of them may be a link. ``resumable``:
    whether the command has ``--resume`` (the messages say what to pass)."""
    out = Path(out)
    what = "axdf run" if command == RUN_COMMAND else f"axdf {command}"
    try:
        is_dir = out.is_dir()
        entries = [n for n in os.listdir(out) if not own_entry(n)] if is_dir else None
    except FileNotFoundError:
        check_way(out, "output folder")
        return Target(out, None, False, tuple(dirs))
    except OSError as e:
        raise atomic.environment_problem(out, e) from None
    if entries is None:
        if not os.path.lexists(out):
            check_way(out, "output folder")
            return Target(out, None, False, tuple(dirs))
        raise InputError(None, f"output folder {out} exists and is not a folder", "give a folder")
    if not entries:
        check_dirs(out, dirs)
        return Target(out, None, False, tuple(dirs))
    try:
        previous = read_run_manifest(out)
    except InputError:
        if (resume or overwrite) and (out / MANIFEST).is_file():
            raise  # a damaged manifest of what may be a run: say where
        previous = None
    if previous is None:
        raise InputError(None, f"output folder {out} is not empty and holds no "
                         f"{'axdf run' if command == RUN_COMMAND else 'axdf output'} (no manifest.json with tool 'axdf')",
                         f"{'--overwrite and --resume only replace or finish' if resumable else '--overwrite only replaces'}"
                         " axdf's own output; choose an empty or new output folder")
    if command_of(previous) != command:
        theirs = command_of(previous)
        raise InputError(previous.mark(("command",) if "command" in previous.data else ("tool",)),
                         f"output folder {out} holds the output of "
                         f"{'axdf run' if theirs == RUN_COMMAND else 'axdf ' + theirs}, not of {what}",
                         f"{what} writes only into an empty or new folder or one it wrote; choose another output folder")
    if not (resume or overwrite):
        raise InputError(None, f"output folder {out} is not empty (it holds an earlier {what})",
                         ("pass --resume to finish an interrupted run, --overwrite to replace it, or another --out"
                          if resumable else "pass --overwrite to replace it, or another --out"))
    # --overwrite deletes the old output's listed files that the new one lacks: the way to each
    # must be made of real folders now, not found to be a link in the middle of the swap
    old_dirs = sorted({PurePosixPath(rel).parent.as_posix() for rel in previous.files()} - {"."}) if overwrite else []
    check_dirs(out, [*dirs, *old_dirs])
    return Target(out, previous, overwrite, tuple(dirs))


def check_inputs_outside(target: Target, inputs) -> None:
    """No input of a run is a file the run would replace (reads only): an input whose real path
    lies in the output folder and that its earlier manifest lists, or below a folder the run
    writes into (``target.dirs``), is refused, naming the file (``--skin OUT/meshes/skin/skin.yaml``
    whose mesh is the run's own ``skin_0000.ply`` changed its own rest mesh on every run)."""
    real_out = os.path.realpath(target.out)
    listed = set(target.previous.files()) if target.previous is not None else set()
    for i in inputs:
        rel = os.path.relpath(os.path.realpath(i), real_out)
        if rel == os.curdir or rel == os.pardir or rel.startswith(os.pardir + os.sep):
            continue
        rel = PurePosixPath(Path(rel).as_posix())
        if str(rel) in listed or str(rel) == MANIFEST or any(
                PurePosixPath(d) in rel.parents for d in (*target.dirs, *LAYOUT_DIRS)):
            raise InputError(Mark(str(i)), f"this input lies in the output folder {target.out}, where the run "
                             f"would replace it ({rel})",
                             "inputs outside what a run writes: copy it elsewhere, or choose another --out")


def remove_stale(out: Path, dirs=()) -> None:
    """Temporaries and staging folders in OUT's layout (and in ``dirs`` below it: the folders
    of a run's formats) whose process is gone (never a live one's, never below a link)."""
    out = Path(out)
    folders = [out] + [out / d for d in LAYOUT_DIRS + tuple(dirs)]
    try:
        folders += [Path(e.path) for e in os.scandir(out / "meshes") if e.is_dir(follow_symlinks=False)]
    except OSError:
        pass
    atomic.remove_stale_temporaries(folders)
    remove_stale_staging(out)


def remove_stale_staging(out: Path) -> None:
    """Staging folders (``OUT/.axdf-new-<pid>``) whose process is gone (a killed
    ``--overwrite``): removed; a live process's stays."""
    for e in os.scandir(out):
        if e.name.startswith(STAGING_PREFIX) and e.is_dir(follow_symlinks=False):
            pid = atomic.temp_owner(e.name)
            if pid is None or not atomic.pid_alive(pid):
                shutil.rmtree(e.path, ignore_errors=True)


class Session:
    """The one writer in an output folder, from the lock to the final manifest.

    ``with Session(target) as s``: creates OUT, takes the lock (another writer: exit 3),
    checks that OUT is still what :func:`prepare` saw, removes stale temporaries; ``s.root``
    is where to write (a staging folder when replacing a run, or always with ``stage``: a
    one-shot command's output appears whole). :meth:`commit` writes the final manifest (and
    swaps a staged output in); leaving the block releases the lock and, without a commit,
    removes the staging folder (the old output stays as it was)."""

    def __init__(self, target: Target, stage: bool = False):
        self.target = target
        self.out = target.out
        self.staged = target.replace or stage
        self.root = self.out / f"{STAGING_PREFIX}{os.getpid()}" if self.staged else self.out
        self.previous_files = target.previous.files() if target.previous is not None and not target.replace else {}
        self._fd = None
        self._made = False  # OUT made by this session: removed again when it fails and leaves it empty
        self._committed = False

    def __enter__(self) -> "Session":
        self._made = not os.path.lexists(self.out)
        atomic.ensure_dir(self.out)
        try:
            self._fd = lock_file(self.out / LOCK, self.out)
            self._verify()
            remove_stale(self.out, self.target.dirs)
            if self.staged:
                shutil.rmtree(self.root, ignore_errors=True)
                atomic.ensure_dir(self.root)
        except BaseException:
            self._unlock()
            self._remove_made()
            raise
        return self

    def __exit__(self, *exc) -> None:
        try:
            if self.staged:
                shutil.rmtree(self.root, ignore_errors=True)
        finally:
            self._unlock()
            if not self._committed:
                self._remove_made()

    def _remove_made(self) -> None:
        if self._made:
            try:
                os.rmdir(self.out)  # only when empty: a failed command leaves no folder it made
            except OSError:
                pass

    def _unlock(self) -> None:
        if self._fd is not None:
            unlock_file(self.out / LOCK, self._fd)
            self._fd = None

    def _verify(self) -> None:
        prev = self.target.previous
        if prev is None:
            changed = any(not own_entry(n) for n in os.listdir(self.out))
        else:
            try:
                changed = hashlib.sha256(read_regular(self.out / MANIFEST, tol.INPUT_MAX_BYTES)).hexdigest() != prev.sha
            except (OSError, FileRefused):
                changed = True
        if changed:
            raise InputError(None, f"output folder {self.out} changed while axdf was checking it",
                             "another process wrote there; run again")

    def commit(self, manifest: dict, interim: dict | None = None, during=None) -> None:
        """Write the final manifest; when the output was staged, swap it in: the old
        output's listed files that the new one lacks are deleted, the new files renamed into
        place, the manifest last. Signals wait until the swap is done.

        ``interim``: keys added to the manifest OUT holds while swapping; ``during()``: work
        done in that window, before the files move (a command's files outside OUT)."""
        write_manifest(self.root, manifest)
        self._committed = True
        if not self.staged:
            return
        old = self.target.previous if self.target.replace else None
        old_data = old.data if old is not None else {k: manifest[k] for k in ("tool", "version", "command")
                                                     if k in manifest}
        old_files = old.files() if old is not None else {}
        new_files = manifest.get("files", {})
        with atomic.deferred_signals():
            # while swapping, the manifest says "incomplete" and lists both outputs' files: a
            # kill here leaves a folder that --overwrite replaces again
            write_manifest(self.out, dict(old_data, **(interim or {}), complete=False,
                                          files={**old_files, **new_files}))
            if during is not None:
                during()
            swap_in(self.root, self.out, old_files, new_files)


def swap_in(staging: Path, out: Path, old_files, new_files, last: str = MANIFEST) -> None:
    """Replace an output by a complete one built in ``staging``: delete ``old_files`` (the
    old manifest's) that ``new_files`` lacks, rename every new file into place (never
    through a link), ``last`` (the manifest) last; remove ``staging`` and the folders the old files
    leave empty. Machine errors are exit 3."""
    staging, out = Path(staging), Path(out)
    dest = Root(out)
    emptied = set()
    try:
        for rel in old_files:
            if rel not in new_files:
                remove_listed(dest, rel)
                emptied.add(PurePosixPath(rel).parent)
        for rel in [r for r in new_files if r != last] + [last]:
            path = dest.path(rel)
            atomic.ensure_dir(path.parent)
            os.replace(staging / rel, path)
    except OSError as e:
        raise atomic.environment_problem(out, e) from None
    shutil.rmtree(staging, ignore_errors=True)
    for d in sorted(emptied, key=lambda p: -len(p.parts)):
        while d.parts:  # folders the old files leave empty
            try:
                os.rmdir(out / d)
            except OSError:
                break
            d = d.parent


def remove_listed(root: Root, rel: str) -> None:
    """Delete one file a manifest lists (a link is removed, never followed)."""
    path = root.path(rel)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if not stat.S_ISDIR(st.st_mode):
        os.unlink(path)
