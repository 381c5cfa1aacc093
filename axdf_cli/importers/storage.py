"""OpenSim storage tables (``.mot``, ``.sto``): a header ending in ``endheader``, a
tab-separated line of column labels (the first is ``time``), then rows of numbers.

Header ``key=value`` lines are kept (``inDegrees``, ``nRows``, ``nColumns``, ...). Errors name
``FILE:LINE:COL``: no ``endheader``, a row with the wrong number of values, a malformed,
non-finite or huge number (beyond ``tolerances.MAX_ABS_NUMBER``, what axdf's YAML files
accept), time that goes backwards, fewer rows than ``nRows`` says (a truncated file). Every
value's line and column are kept (:meth:`Table.mark`) for later checks to point at.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import read_input


@dataclass(frozen=True)
class Table:
    source: str
    header: dict  # key -> value text (lower-case keys)
    labels: tuple[str, ...]  # data columns (without time)
    label_marks: tuple[Mark, ...]
    time: np.ndarray  # (N,) float64
    data: np.ndarray  # (N, C) float64
    header_mark: dict  # key -> Mark of its header line
    row_lines: np.ndarray  # (N,) int: the 1-based line of each row
    cell_cols: np.ndarray  # (N, C + 1) int32: the 1-based column of each value (time first)

    def mark(self, row: int, col: int = -1) -> Mark:
        """Where value ``col`` (a data column index, -1 for time) of row ``row`` is."""
        return Mark(self.source, int(self.row_lines[row]), int(self.cell_cols[row, col + 1]))

    @property
    def in_degrees(self) -> bool | None:
        v = self.header.get("indegrees")
        if v is None:
            return None
        return v.strip().lower() in ("yes", "true", "1")

    def column(self, label: str) -> np.ndarray:
        return self.data[:, self.labels.index(label)]


def _split(line: str) -> list[tuple[str, int]]:
    """Whitespace-separated words with their 1-based columns."""
    out = []
    i, n = 0, len(line)
    while i < n:
        while i < n and line[i] in " \t\r":
            i += 1
        if i >= n:
            break
        j = i
        while j < n and line[j] not in " \t\r":
            j += 1
        out.append((line[i:j], i + 1))
        i = j
    return out


def read_storage(path: Path | str) -> Table:
    path = Path(path)
    shown = str(path)
    raw = read_input(path, shown, "an existing .mot / .sto file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[: e.start].count(b"\n") + 1
        raise InputError(Mark(shown, line, 1), "not UTF-8 text", "a text .mot / .sto table") from None
    lines = text.split("\n")
    header: dict = {}
    hmark: dict = {}
    end = None
    for i, line in enumerate(lines):
        s = line.strip()
        if s.lower() == "endheader":
            end = i
            break
        if "=" in s:
            k, v = s.split("=", 1)
            header[k.strip().lower()] = v.strip()
            hmark[k.strip().lower()] = Mark(shown, i + 1, 1)
    if end is None:
        raise InputError(Mark(shown, len(lines), 1), "no 'endheader' line", "an OpenSim .mot/.sto header ending in endheader")
    li = end + 1
    while li < len(lines) and not lines[li].strip():
        li += 1
    if li >= len(lines):
        raise InputError(Mark(shown, li, 1), "no column labels after endheader", "a line of labels starting with time")
    words = _split(lines[li].rstrip("\r"))
    if not words or words[0][0].lower() != "time":
        raise InputError(Mark(shown, li + 1, 1), f"first column is {words[0][0] if words else ''!r}", "time")
    labels = tuple(w for w, _ in words[1:])
    marks = tuple(Mark(shown, li + 1, c) for _, c in words[1:])
    seen = set()
    for lab, m in zip(labels, marks):
        if lab in seen:
            raise InputError(m, f"column {lab!r} appears twice", "unique column labels")
        seen.add(lab)
    ncol = len(words)
    rows, times, row_lines, cell_cols = [], [], [], []
    for k in range(li + 1, len(lines)):
        line = lines[k].rstrip("\r")
        if not line.strip():
            continue
        ws = _split(line)
        if len(ws) != ncol:
            col = ws[-1][1] + len(ws[-1][0]) if ws else 1
            raise InputError(Mark(shown, k + 1, col), f"row has {len(ws)} values",
                             f"{ncol} values (time and {ncol - 1} columns)")
        vals = []
        for w, c in ws:
            try:
                v = float(w)
            except ValueError:
                raise InputError(Mark(shown, k + 1, c), f"malformed number {w!r}", "decimal numbers") from None
            if not math.isfinite(v):
                raise InputError(Mark(shown, k + 1, c), f"{w!r} is not finite", "finite numbers")
            if abs(v) > tol.MAX_ABS_NUMBER:
                raise InputError(Mark(shown, k + 1, c), f"{w!r} is too large",
                                 f"|value| <= {tol.MAX_ABS_NUMBER:g}, as in every axdf file")
            vals.append(v)
        if times and vals[0] < times[-1]:
            raise InputError(Mark(shown, k + 1, ws[0][1]), f"time {vals[0]} is before the previous row's {times[-1]}",
                             "non-decreasing time")
        times.append(vals[0])
        rows.append(vals[1:])
        row_lines.append(k + 1)
        cell_cols.append([c for _, c in ws])
    if not rows:
        raise InputError(Mark(shown, len(lines), 1), "no data rows", "at least one row after the labels")
    nrows = header.get("nrows")
    if nrows is not None:
        try:
            n = int(nrows)
        except ValueError:
            raise InputError(hmark["nrows"], f"nRows is {nrows!r}", "an integer") from None
        if len(rows) < n:
            raise InputError(Mark(shown, len(lines), 1), f"file ends after {len(rows)} of nRows={n} rows (truncated?)",
                             "as many rows as nRows says")
    return Table(shown, header, labels, marks, np.array(times), np.array(rows, dtype=np.float64).reshape(len(rows), -1),
                 hmark, np.array(row_lines), np.array(cell_cols, dtype=np.int32))
