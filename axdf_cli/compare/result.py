"""What a comparison finds: one :class:`FileResult` per file, gathered in a :class:`Report`."""
from __future__ import annotations

from dataclasses import dataclass, field

from axdf_cli.formats import MeshReadError

# verdicts of one file; every one but PASS fails the comparison
PASS = "pass"  # equal within tolerance (identical bytes included)
FAIL = "fail"  # differs beyond tolerance (or topology, size, channels differ)
MISSING = "missing"  # in golden, not in actual
EXTRA = "extra"  # in actual, not in golden
ERROR = "error"  # a file could not be read (truncated, not the format its name says)
VERDICTS = (PASS, FAIL, MISSING, EXTRA, ERROR)


class Unreadable(MeshReadError):
    """A file cannot be read as the format its name says; becomes an ERROR verdict."""


@dataclass(frozen=True)
class Outcome:
    """What one comparator says about one pair of files."""

    ok: bool
    reasons: tuple[str, ...] = ()  # why it fails, one line each
    metrics: dict = field(default_factory=dict)  # JSON-able numbers
    notes: tuple[str, ...] = ()  # worth saying, not a failure (manifest differences)
    picture: object = None  # (H, 3W, 3) uint8 actual | golden | heat map, for failing images
    mask: object = None  # (H, W) bool the failing pixels of a failing image (whose parts they show)


@dataclass(frozen=True)
class FileResult:
    path: str  # relative to the run folders (posix), or the file name when comparing files
    kind: str  # mesh, png, exr, table, json, manifest, bytes
    verdict: str  # one of VERDICTS
    reasons: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    metrics: dict = field(default_factory=dict)
    tolerance: dict | None = None  # the tolerances applied to this file
    diff_picture: str | None = None  # where its actual | golden | heat map PNG was written
    seconds: float = 0.0

    @property
    def failed(self) -> bool:
        return self.verdict != PASS


@dataclass(frozen=True)
class Report:
    actual: str
    golden: str
    files: tuple[FileResult, ...]
    likely_causes: tuple[str, ...] = ()  # manifest input/settings differences
    seconds: float = 0.0
    parts: tuple[tuple[str, tuple[str, ...]], ...] = ()  # (part name, what of it differs): compare.parts
    bordering: tuple[tuple[str, int], ...] = ()  # (part whose meshes are the same, failing pixels on it)

    @property
    def passed(self) -> bool:
        return not any(f.failed for f in self.files)

    def counts(self) -> dict:
        out = {v: 0 for v in VERDICTS}
        for f in self.files:
            out[f.verdict] += 1
        out["total"] = len(self.files)
        return out


def read_side(side: str, reader, *args):
    """Call ``reader(*args)``; an :class:`Unreadable` names the side ("actual"/"golden")."""
    try:
        return reader(*args)
    except MeshReadError as e:
        raise Unreadable(f"{side}: {e}") from None
