"""Where files named inside YAML files may lie (:class:`RefPolicy`), the shipped library's
roots, and muscle paths (files, folders, globs) expanded to files."""
from __future__ import annotations

import glob
import os
from dataclasses import dataclass
from pathlib import Path

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import real_path

def _library_roots() -> tuple[Path, ...]:
    """The shipped library (``poses/`` and ``muscles/`` beside the package, in a checkout or
    an editable install): trusted from any folder, so a user's own pose may name a shipped
    skeleton."""
    here = Path(__file__).resolve().parents[2]  # axdf_cli/specs/refs.py → the checkout
    return tuple(p for p in (here / "poses", here / "muscles") if p.is_dir())


LIBRARY_ROOTS = _library_roots()


def _glob_base(pattern: str) -> Path:
    """The fixed folder in front of a glob's first wildcard (``a/b/*/c.yaml`` → ``a/b``)."""
    parts = Path(pattern).parts
    for i, part in enumerate(parts):
        if glob.has_magic(part):
            return Path(*parts[:i]) if i else Path(".")
    return Path(pattern).parent


@dataclass(frozen=True)
class RefPolicy:
    """Where files read through YAML references (and a job's ``out``) may lie.

    References are resolved relative to the file that holds them. A path is allowed when its
    *real* location (symbolic links resolved: a link inside the tree to a file outside is
    refused like the file itself) lies below a root: the current folder, the folders of the
    files named on the command line (the user's own choice, see :meth:`for_command`) and the
    shipped library. ``roots`` empty (library use): the current folder and the referring
    file's own folder. ``allow_outside`` (``--allow-outside``) turns the check off.
    """

    roots: tuple[Path, ...] = ()
    allow_outside: bool = False

    @classmethod
    def for_command(cls, named=(), allow_outside: bool = False) -> "RefPolicy":
        """The policy of one command: roots are the current folder and, for every path named
        on the command line, its folder (a named folder itself; a glob's fixed part)."""
        roots = [Path.cwd()]
        for n in named:
            if n is None:
                continue
            s = str(n)
            p = _glob_base(s) if glob.has_magic(s) else Path(s)
            roots.append(p if p.is_dir() else p.parent)
        return cls(tuple(dict.fromkeys(real_path(r) for r in roots)), allow_outside)

    def roots_for(self, base: Path | None) -> list[Path]:
        own = list(self.roots) or [real_path(Path.cwd())] + ([real_path(base)] if base is not None else [])
        return own + [r for r in LIBRARY_ROOTS if r not in own]

    def check(self, path: Path | str, where: Mark, base: Path | None = None, what: str = "path",
              shown: str | None = None) -> None:
        """Refuse ``path`` unless its real location lies below a root (``base``: the folder of
        the referring file, a root when the policy has none; ``shown``: the path as written)."""
        if self.allow_outside:
            return
        real = real_path(path)
        roots = self.roots_for(base)
        if not any(real == r or r in real.parents for r in roots):
            link = "" if real == Path(os.path.abspath(path)) else f" (a link to {real})"
            raise InputError(where, f"{what} {shown or repr(str(path))}{link} leaves the project folder tree",
                             f"paths inside {', '.join(str(r) for r in roots)} (or pass --allow-outside)")

    def resolve(self, base_file: Path, ref: str, where: Mark, what: str = "path") -> Path:
        """A path written in ``base_file``, relative to its folder, checked (see the class doc)."""
        if "\x00" in ref:
            raise InputError(where, "path contains a NUL character", "plain relative paths")
        p = Path(base_file).parent / ref  # an absolute ref replaces the folder
        self.check(p, where, Path(base_file).parent, what, repr(ref))
        return p


def expand_muscle_paths(entries, policy: RefPolicy | None = None, base: Path | None = None) -> list[Path]:
    """Files, folders (every *.yaml below, sorted) or globs → sorted unique files. Every file
    found is checked against ``policy`` by its real path (``base``: the folder the entries are
    relative to, a root when the policy has none)."""
    policy = policy or RefPolicy()
    out: list[tuple[Path, Mark]] = []
    for p, mark in entries:
        p = Path(p)
        s = str(p)
        if glob.has_magic(s):
            hits = sorted(Path(h) for h in glob.glob(s, recursive=True) if Path(h).is_file())
            if not hits:
                raise InputError(mark, f"glob {s!r} matches no file", "a glob matching muscle YAML files")
        elif p.is_dir():
            hits = sorted(x for x in p.rglob("*.yaml") if x.is_file())
            if not hits:
                raise InputError(mark, f"folder {s!r} holds no .yaml file", "a folder of muscle YAML files")
        elif p.is_file():
            hits = [p]
        else:
            raise InputError(mark, f"muscle path {s!r} not found", "an existing file, folder or glob")
        for h in hits:
            if any("\udc80" <= c <= "\udcff" for c in str(h)):  # bytes that are not UTF-8 (see cli/main)
                raise InputError(mark, f"file name {os.fsencode(h)!r} is not UTF-8 text",
                                 "file and folder names in UTF-8 (axdf writes names into its text files)")
            policy.check(h, mark, base, "muscle file")
        out.extend((h, mark) for h in hits)
    seen, uniq = set(), []
    for p, _ in out:
        k = str(real_path(p))
        if k not in seen:
            seen.add(k)
            uniq.append(p)
    return uniq
