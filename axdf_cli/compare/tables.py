"""Comparison of text data: CSV tables (``stats.csv``, ``bones.csv``), JSON (``camera.json``),
the run manifest (only its inputs and settings), and any other file byte for byte."""
from __future__ import annotations

import csv
import io
import json
import math

import numpy as np

from axdf_cli.compare.result import Outcome, Unreadable, read_side
from axdf_cli.compare.thresholds import MAX_LISTED, NumTol

# ----------------------------------------------------------------------------- CSV
#: columns that name a row's part (stats.csv's muscle, bones.csv's bone): the report says whose rows differ
NAME_COLUMNS = ("muscle", "bone", "part")


def read_csv(data: bytes) -> list[list[str]]:
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise Unreadable("CSV is not UTF-8 text") from None
    try:
        return [row for row in csv.reader(io.StringIO(text)) if row]
    except csv.Error as e:
        raise Unreadable(f"bad CSV ({e})") from None


def _numbers(col: list[str]) -> np.ndarray:
    """Cells -> float64, NaN where a cell is not a number. ``(R,)``."""
    try:
        return np.array(col, np.float64)
    except ValueError:
        out = np.full(len(col), np.nan)
        for i, c in enumerate(col):
            try:
                out[i] = float(c)
            except ValueError:
                pass
        return out


def compare_csv(a_bytes: bytes, g_bytes: bytes, tol: NumTol) -> Outcome:
    """Same header, same number of rows and columns; cells that are numbers on both sides
    within ``atol + rtol*|golden|``, all other cells equal as text."""
    a = read_side("actual", read_csv, a_bytes)
    g = read_side("golden", read_csv, g_bytes)
    if not g or not a:
        ok = len(a) == len(g)
        return Outcome(ok, () if ok else (f"{len(a)} rows vs golden {len(g)}",), {"rows": len(g)})
    header = g[0]
    metrics: dict = {"rows": len(g) - 1, "columns": len(header)}
    if a[0] != header:
        return Outcome(False, (f"header {','.join(a[0])!r} vs golden {','.join(header)!r}",), metrics)
    if len(a) != len(g):
        return Outcome(False, (f"{len(a) - 1} rows vs golden {len(g) - 1}",), metrics)
    widths = {len(r) for r in a[1:] + g[1:]}
    if widths - {len(header)}:
        bad = next(i for i in range(1, len(g)) if len(a[i]) != len(header) or len(g[i]) != len(header))
        return Outcome(False, (f"row {bad} has {len(a[bad])} cells vs golden {len(g[bad])}; header has "
                               f"{len(header)}",), metrics)
    ca = list(zip(*a[1:])) if len(a) > 1 else [()] * len(header)
    cg = list(zip(*g[1:])) if len(g) > 1 else [()] * len(header)
    bad_cells: list[tuple[int, int, str]] = []  # (row, col, text), at most MAX_LISTED per column
    bad_rows = np.zeros(len(g) - 1, bool)  # (R,) rows with a differing cell
    n_bad = 0
    max_abs: dict = {}
    for j, name in enumerate(header):
        xa, xg = _numbers(list(ca[j])), _numbers(list(cg[j]))  # (R,) each
        numeric = ~np.isnan(xa) & ~np.isnan(xg)
        with np.errstate(invalid="ignore"):
            d = np.abs(xa - xg)  # inf - inf is NaN
        d = np.where(xa == xg, 0.0, d)  # equal infinities
        d = np.where(numeric, np.where(np.isnan(d), np.inf, d), 0.0)
        allowed = tol.atol + tol.rtol * np.abs(np.where(np.isfinite(xg), xg, 0.0))
        over = numeric & (d > allowed)
        text_diff = ~numeric & (np.array(ca[j], object) != np.array(cg[j], object))
        if numeric.any():
            max_abs[name] = float(d[numeric].max())
        bad = np.flatnonzero(over | text_diff)
        bad_rows[bad] = True
        n_bad += len(bad)
        for i in bad[:MAX_LISTED]:
            bad_cells.append((int(i), j, f"{ca[j][i]} vs golden {cg[j][i]}"))
    metrics["max_abs_difference"] = max_abs
    metrics["differing_cells"] = n_bad
    named = next((j for j, name in enumerate(header) if name in NAME_COLUMNS), None)
    if named is not None and bad_rows.any():  # whose rows differ: {muscle or bone: rows}
        names = [g[i + 1][named] for i in np.flatnonzero(bad_rows)]
        metrics["differing_names"] = {n: names.count(n) for n in sorted(set(names))}
    reasons: list[str] = []
    if bad_cells:
        bad_cells.sort()
        reasons.append(f"{n_bad} cells differ beyond atol {tol.atol:g} + rtol {tol.rtol:g}:")
        for i, j, text in bad_cells[:MAX_LISTED]:
            reasons.append(f"row {i + 1} ({header[0]}={g[i + 1][0]}) column {header[j]}: {text}")
        if n_bad > MAX_LISTED:
            reasons.append(f"... and {n_bad - MAX_LISTED} more")
    return Outcome(not reasons, tuple(reasons), metrics)


# ----------------------------------------------------------------------------- JSON


def read_json(data: bytes):
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise Unreadable(f"not valid JSON ({e})") from None
    except ValueError as e:  # an integer of more digits than Python converts (4300)
        raise Unreadable(f"JSON holds a number too long to read ({str(e).split(';')[0]})") from None
    except RecursionError:
        raise Unreadable("JSON nested too deeply to read") from None


def _float(x) -> float:
    """A JSON number as a float; integers beyond float's range become +-inf."""
    try:
        return float(x)
    except OverflowError:
        return math.inf if x > 0 else -math.inf


def json_differences(a, g, tol: NumTol | None, path: str = "$", out: list | None = None,
                     stats: dict | None = None) -> list[str]:
    """Every difference between two JSON values as ``path: actual vs golden`` lines. Numbers
    pass within ``atol + rtol*|golden|`` (exact when ``tol`` is None); dict keys, list
    lengths, strings, booleans and null must be equal."""
    out = [] if out is None else out
    if stats is not None and isinstance(a, (int, float)) and isinstance(g, (int, float)) \
            and not isinstance(a, bool) and not isinstance(g, bool):
        d = 0.0 if a == g else _float(abs(a - g))  # exact for integers of any size
        if math.isnan(d):
            d = math.inf
        stats["max_abs_difference"] = max(stats.get("max_abs_difference", 0.0), d)
        allowed = 0.0 if tol is None else tol.atol + tol.rtol * abs(_float(g))
        if d > allowed or (d == allowed == math.inf):
            out.append(f"{path}: {_short(a)} vs golden {_short(g)}")
        return out
    if isinstance(a, dict) and isinstance(g, dict):
        for k in g:
            if k not in a:
                out.append(f"{path}.{k}: missing (golden {_short(g[k])})")
        for k in a:
            if k not in g:
                out.append(f"{path}.{k}: {_short(a[k])} (not in golden)")
            else:
                json_differences(a[k], g[k], tol, f"{path}.{k}", out, stats)
        return out
    if isinstance(a, list) and isinstance(g, list):
        if len(a) != len(g):
            out.append(f"{path}: {len(a)} items vs golden {len(g)}")
        for i, (x, y) in enumerate(zip(a, g)):
            json_differences(x, y, tol, f"{path}[{i}]", out, stats)
        return out
    if stats is None and _is_num(a) and _is_num(g):
        return json_differences(a, g, tol, path, out, {})
    if type(a) is not type(g) or a != g:
        out.append(f"{path}: {_short(a)} vs golden {_short(g)}")
    return out


def _is_num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _short(v) -> str:
    s = json.dumps(v, sort_keys=True)
    return s if len(s) <= 80 else s[:77] + "..."


def compare_json(a_bytes: bytes, g_bytes: bytes, tol: NumTol) -> Outcome:
    a = read_side("actual", read_json, a_bytes)
    g = read_side("golden", read_json, g_bytes)
    stats: dict = {"max_abs_difference": 0.0}
    diffs = json_differences(a, g, tol, stats=stats)
    metrics = {"max_abs_difference": stats["max_abs_difference"], "differences": len(diffs)}
    if not diffs:
        return Outcome(True, (), metrics)
    reasons = [f"{len(diffs)} values differ beyond atol {tol.atol:g} + rtol {tol.rtol:g}:"] + diffs[:MAX_LISTED]
    if len(diffs) > MAX_LISTED:
        reasons.append(f"... and {len(diffs) - MAX_LISTED} more")
    return Outcome(False, tuple(reasons), metrics)


# ----------------------------------------------------------------------------- manifest
# Sections of manifest.json that explain a mismatch: what went in and how it was set up.
# Outputs (sha256 of every file), the GL renderer and timings are not compared: they change
# with the machine, and the outputs are compared file by file anyway.
MANIFEST_SECTIONS = ("inputs", "settings", "frames")


def compare_manifest(a_bytes: bytes, g_bytes: bytes) -> Outcome:
    """Differences of the manifests' ``inputs``, ``settings``, ``frames`` and any top-level key
    naming a version become notes (likely causes of other files' mismatches); the manifest
    itself passes when both sides can be read."""
    a = read_side("actual", read_json, a_bytes)
    g = read_side("golden", read_json, g_bytes)
    if not isinstance(a, dict) or not isinstance(g, dict):
        raise Unreadable("manifest.json is not a JSON object")
    keys = [k for k in MANIFEST_SECTIONS if k in a or k in g]
    keys += sorted(k for k in set(a) | set(g) if "version" in k.lower() and k not in keys)
    notes: list[str] = []
    for k in keys:
        if k not in a or k not in g:
            notes.append(f"manifest {k}: {'only in golden' if k not in a else 'only in actual'}")
            continue
        diffs = json_differences(_keyed(a[k]), _keyed(g[k]), None, f"{k}")
        notes += [f"manifest {d}" for d in diffs]
    return Outcome(True, (), {"compared_sections": keys, "differences": len(notes)}, tuple(notes))


def _keyed(v):
    """A list of objects each naming a ``path`` or ``name`` becomes a dict by that name, so
    that inputs compare by file rather than by position."""
    if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
        for key in ("path", "name", "file"):
            names = [x.get(key) for x in v]
            if all(isinstance(n, str) for n in names) and len(set(names)) == len(names):
                return {n: {kk: _keyed(vv) for kk, vv in x.items() if kk != key} for n, x in zip(names, v)}
    if isinstance(v, dict):
        return {k: _keyed(x) for k, x in v.items()}
    return v


# ----------------------------------------------------------------------------- bytes


def compare_bytes(a_bytes: bytes, g_bytes: bytes) -> Outcome:
    """Any other file: equal bytes or a failure naming the first differing offset."""
    metrics = {"size": len(g_bytes), "actual_size": len(a_bytes)}
    if a_bytes == g_bytes:
        return Outcome(True, (), metrics)
    n = min(len(a_bytes), len(g_bytes))
    av = np.frombuffer(a_bytes, np.uint8, n)
    gv = np.frombuffer(g_bytes, np.uint8, n)
    neq = np.flatnonzero(av != gv)
    first = int(neq[0]) if neq.size else n
    return Outcome(False, (f"bytes differ from offset {first} ({len(a_bytes)} bytes vs golden {len(g_bytes)})",),
                   metrics | {"first_difference": first})
