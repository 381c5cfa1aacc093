"""Biovision hierarchy (``.bvh``) motion capture → an axdf skeleton and pose, in memory.

:func:`read_bvh` parses the file (``HIERARCHY`` then ``MOTION``) and checks it; every error
names ``FILE:LINE:COL``: unbalanced braces, a ``CHANNELS`` count that does not match the
channel names after it, an unknown keyword, a malformed number, a motion row with the wrong
number of values, a ``Frames:`` count that the rows contradict (fewer rows: truncated; more
rows: the count lies). :func:`read_import` turns a parsed file into the neutral model of a
skeleton and its motion, which :func:`axdf_cli.importers.emit.build_import` writes; the CLI
writes the files only when everything was good.

Conversions (BVH → axdf):

- World: BVH is Y-up with the character facing +Z (its left on +X). A root bone ``ground``
  with ``orient: [90, 0, 0]`` turns that into axdf's Z-up world with the character facing
  -Y (BVH X → X, Y → Z, Z → -Y), like the OpenSim importer's ``ground``. Every joint keeps
  the BVH's own axes, so offsets and channel axes are copied unchanged.
- Joints: each JOINT (and the ROOT) is a bone at its ``OFFSET`` (times ``--scale``) in the
  parent, ``orient`` 0. Its channels become DOFs driven by one coordinate each, named
  ``<joint>_<channel>`` (``LeftKnee_Zrotation``, ``Hips_Xposition``): position channels
  first (a translation along the parent's X/Y/Z, added to the offset, in metres: value times
  ``--scale``), then the rotation channels in the file's order (``Zrotation Yrotation
  Xrotation`` is ``Rz·Ry·Rx``, each about the axis left by the previous one), in degrees.
- End sites: an ``End Site`` becomes a child bone ``<joint>_end`` at its offset with no DOFs:
  the tip that gives the last bone of a chain its extent.
- Names: characters outside ``[A-Za-z0-9_.-]`` become ``_``; a name already taken (also
  ``ground``) gets a ``_2``, ``_3`` ... suffix.
- Motion: frame ``k`` of the pose is row ``k * step``; ``fps = 1 / (Frame Time * step)``, where
  a Frame Time that is ``1/n`` rounded to the digits written (``0.008333`` → 120) gives the
  whole ``n``. A coordinate that never changes is keyed once, at frame 0 (poses hold a
  coordinate's value outside its keys): a lossless, much smaller file.
- Units: ``--scale`` (metres per file unit) or ``--units`` multiplies lengths (offsets,
  position channels) into metres. Without them the unit comes from the body's height
  (:func:`choose_unit`): the rest joint span (joints and end sites, along BVH Y) divided by
  ``tolerances.STATURE_SPAN_RATIO`` (0.86: the top end site lies inside the head, a rest pose
  may splay the legs) estimates the person's stature, and the unit among metres, centimetres,
  millimetres, inches and CMU's (1/0.45 inch: the CMU database's conversions, whose 24-unit
  span is a 1.6 m person) whose stature lands in ``tolerances.STATURE_BAND`` (1.4-2.1 m) is
  taken; a 170-unit skeleton is in centimetres, a 67-unit one in inches. When no unit makes
  a person, lengths are scaled to a ``TYPICAL_STATURE`` (1.7 m) person, with a warning. The
  unit and the stature are printed.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.importers.model import Bone, Dof, ImportedModel, Motion, Rules
from axdf_cli.importers.result import safe_name
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name, read_text, unique_names

#: channel name (lower case) → (DOF type, axis index). BVH writes them capitalised.
CHANNELS = {"xposition": ("translation", 0), "yposition": ("translation", 1), "zposition": ("translation", 2),
            "xrotation": ("rotation", 0), "yrotation": ("rotation", 1), "zrotation": ("rotation", 2)}
CHANNEL_NAMES = "Xposition, Yposition, Zposition, Xrotation, Yrotation, Zrotation"
#: BVH (Y-up, facing +Z) → axdf (Z-up, facing -Y): the root bone's orient (body-fixed XYZ, degrees).
GROUND_ORIENT = (90.0, 0.0, 0.0)
#: Length units a BVH may be in: name → metres per unit (``--units``; ``--scale`` takes them too).
#: ``cmu``: the CMU Graphics Lab database's BVH conversions, whose lengths are inches times 0.45.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
UNIT_WORDS = {"m": "metres", "cm": "centimetres", "mm": "millimetres", "in": "inches",
              "cmu": "CMU units (1/0.45 inch)"}
#: Deepest joint nesting read (a guard against hostile files; real skeletons nest < 30 deep).
MAX_DEPTH = 256

_TOKEN = re.compile(r"[{}]|[^\s{}]+")


@dataclass(frozen=True)
class Joint:
    name: str  # as written in the file (End Site: its parent's name + " End Site")
    parent: int  # index into BVH.joints, -1 for the root
    offset: tuple[float, float, float]  # file units
    channels: tuple[str, ...]  # canonical capitalisation, file order
    end_site: bool
    mark: Mark


@dataclass(frozen=True)
class BVH:
    source: str
    joints: tuple[Joint, ...]  # parents before children
    frame_time: float
    frame_time_text: str
    data: np.ndarray  # (N, n_channels) float64, columns in joint order, channel order
    frames_mark: Mark
    frame_time_mark: Mark = Mark("")
    row_lines: tuple = ()  # (N,) the 1-based line of each motion row

    def value_mark(self, row: int, col: int) -> Mark:
        """Where motion value ``col`` of row ``row`` is in the file (read again: only on error)."""
        if row >= len(self.row_lines):
            return self.frames_mark
        line = self.row_lines[row]
        with open(self.source, "rb") as f:
            for k, text in enumerate(f, 1):
                if k == line:
                    cols = [m.start() + 1 for m in re.finditer(rb"\S+", text)]
                    return Mark(self.source, line, cols[col] if col < len(cols) else 1)
        return Mark(self.source, line, 1)

    @property
    def columns(self) -> list[tuple[int, str]]:
        """(joint index, channel) of every motion column, in file order."""
        return [(j, c) for j, joint in enumerate(self.joints) for c in joint.channels]


# ----------------------------------------------------------------------------- parsing


@dataclass
class _Tokens:
    """The HIERARCHY section's words with their positions; ``next`` at the end gives None."""

    shown: str
    words: list[tuple[str, int, int]]  # (word, line, col)
    end: Mark  # where the hierarchy ends (the MOTION line, or the end of the file)
    i: int = 0

    def peek(self):
        return self.words[self.i] if self.i < len(self.words) else None

    def next(self, what: str, allowed: str):
        w = self.peek()
        if w is None:
            raise InputError(self.end, f"the hierarchy ends where {what} was expected", allowed)
        self.i += 1
        return w

    def mark(self, w) -> Mark:
        return Mark(self.shown, w[1], w[2])

    def number(self, what: str) -> float:
        w = self.next(what, "a number")
        try:
            v = float(w[0])
        except ValueError:
            raise InputError(self.mark(w), f"{what} is {w[0]!r}", "a decimal number") from None
        if not math.isfinite(v) or abs(v) > tol.MAX_ABS_NUMBER:
            raise InputError(self.mark(w), f"{what} is {w[0]!r}", f"a finite number within ±{tol.MAX_ABS_NUMBER:g}")
        return v


@dataclass
class _Open:
    """A joint whose braces are open while parsing."""

    name: str
    parent: int
    end_site: bool
    mark: Mark  # of the JOINT / ROOT / End keyword
    brace: Mark
    offset: tuple | None = None
    channels: tuple = ()
    index: int = -1


def _hierarchy(tok: _Tokens) -> list[Joint]:
    w = tok.next("HIERARCHY", "a BVH file starts with HIERARCHY")
    if w[0] != "HIERARCHY":
        raise InputError(tok.mark(w), f"file starts with {w[0]!r}", "a BVH file starts with HIERARCHY")
    joints: list[Joint] = []
    stack: list[_Open] = []
    seen: dict[str, Mark] = {}
    kinds = "ROOT, JOINT, End Site, OFFSET, CHANNELS or '}'"
    while True:
        w = tok.peek()
        if w is None:
            if stack:
                o = stack[-1]
                raise InputError(tok.end, f"the '{{' of {o.name!r} (line {o.brace.line}) is never closed",
                                 "every '{' needs a matching '}' before MOTION")
            break
        tok.i += 1
        word = w[0]
        if word in ("ROOT", "JOINT"):
            if word == "ROOT" and (stack or joints):
                raise InputError(tok.mark(w), "a second ROOT" if not stack else "ROOT inside a joint",
                                 "one ROOT; the other joints are JOINTs inside its braces")
            if word == "JOINT" and not stack:
                raise InputError(tok.mark(w), "JOINT outside the ROOT's braces", "JOINTs nest inside ROOT { ... }")
            if stack and stack[-1].end_site:
                raise InputError(tok.mark(w), "a JOINT inside an End Site", "End Site { OFFSET x y z } only")
            parts = []
            while tok.peek() is not None and tok.peek()[0] != "{" and tok.peek()[1] == w[1]:
                parts.append(tok.next("a joint name", "")[0])
            if not parts:
                raise InputError(tok.mark(w), f"{word} without a name", f"{word} NAME {{ ... }}")
            name = " ".join(parts)
            if name in seen:
                raise InputError(tok.mark(w), f"joint {name!r} is defined twice (first at line {seen[name].line})",
                                 "unique joint names")
            seen[name] = tok.mark(w)
            kind = word
        elif word == "End":
            s = tok.next("Site", "End Site { OFFSET x y z }")
            if s[0] != "Site":
                raise InputError(tok.mark(s), f"'End' followed by {s[0]!r}", "End Site { OFFSET x y z }")
            if not stack:
                raise InputError(tok.mark(w), "End Site outside the ROOT's braces", "End Site inside a joint")
            if stack[-1].end_site:
                raise InputError(tok.mark(w), "an End Site inside an End Site", "End Site { OFFSET x y z } only")
            name = stack[-1].name
            kind = "End Site"
        elif word == "OFFSET":
            if not stack:
                raise InputError(tok.mark(w), "OFFSET outside any joint", "OFFSET inside ROOT, JOINT or End Site braces")
            if stack[-1].offset is not None:
                raise InputError(tok.mark(w), f"a second OFFSET in {stack[-1].name!r}", "one OFFSET per joint")
            stack[-1].offset = tuple(tok.number(f"OFFSET {a}") for a in "xyz")
            continue
        elif word == "CHANNELS":
            if not stack:
                raise InputError(tok.mark(w), "CHANNELS outside any joint", "CHANNELS inside ROOT or JOINT braces")
            o = stack[-1]
            if o.end_site:
                raise InputError(tok.mark(w), "CHANNELS in an End Site", "End Site { OFFSET x y z } only")
            if o.channels:
                raise InputError(tok.mark(w), f"a second CHANNELS in {o.name!r}", "one CHANNELS line per joint")
            nw = tok.next("the channel count", "CHANNELS N name1 ... nameN")
            if not re.fullmatch(r"[0-9]+", nw[0]) or int(nw[0]) > 6:
                raise InputError(tok.mark(nw), f"channel count {nw[0]!r}", "CHANNELS N with N in 0..6")
            n = int(nw[0])
            chans = []
            for k in range(n):
                c = tok.peek()
                if c is None or c[0].lower() not in CHANNELS:
                    where = tok.end if c is None else tok.mark(c)
                    got = "the end of the hierarchy" if c is None else repr(c[0])
                    raise InputError(where, f"CHANNELS {n} (line {w[1]}) lists {k} channel names, then {got}",
                                     f"{n} names from {CHANNEL_NAMES}")
                tok.i += 1
                name_c = c[0][0].upper() + c[0][1:].lower()
                if name_c in chans:
                    raise InputError(tok.mark(c), f"channel {c[0]} twice in {o.name!r}", "each channel once per joint")
                chans.append(name_c)
            extra = tok.peek()
            if extra is not None and extra[0].lower() in CHANNELS:
                raise InputError(tok.mark(extra), f"CHANNELS {n} (line {w[1]}) is followed by more channel names",
                                 f"exactly {n} names, or a count that matches them")
            o.channels = tuple(chans)
            continue
        elif word == "}":
            if not stack:
                raise InputError(tok.mark(w), "'}' without a matching '{'", "balanced braces")
            o = stack.pop()
            if o.offset is None:
                raise InputError(o.mark, f"{o.name!r} has no OFFSET", "OFFSET x y z inside every joint's braces")
            joints[o.index] = Joint(o.name if not o.end_site else f"{o.name} End Site", o.parent, o.offset,
                                    o.channels, o.end_site, o.mark)
            if not stack:
                nxt = tok.peek()
                if nxt is not None and nxt[0] == "}":
                    raise InputError(tok.mark(nxt), "'}' without a matching '{'", "balanced braces")
                if nxt is not None and nxt[0] == "ROOT":
                    raise InputError(tok.mark(nxt), "a second ROOT", "one ROOT; the other joints are JOINTs inside it")
                if nxt is not None:
                    raise InputError(tok.mark(nxt), f"{nxt[0]!r} where MOTION was expected",
                                     "MOTION after the ROOT's closing '}'")
            continue
        elif word == "{":
            raise InputError(tok.mark(w), "'{' without ROOT, JOINT or End Site before it", "balanced braces")
        else:
            raise InputError(tok.mark(w), f"unexpected {word!r}", kinds)
        # a new joint (ROOT, JOINT or End Site): its '{' follows
        b = tok.next("'{'", f"'{{' after {kind}")
        if b[0] != "{":
            raise InputError(tok.mark(b), f"{b[0]!r} after {kind} {name}", f"'{{' after {kind}")
        if len(stack) >= MAX_DEPTH:
            raise InputError(tok.mark(w), "joints nested too deeply", f"at most {MAX_DEPTH} levels")
        o = _Open(name, stack[-1].index if stack else -1, kind == "End Site", tok.mark(w), tok.mark(b))
        o.index = len(joints)
        joints.append(None)  # filled in at its '}' (parents keep their place before children)
        stack.append(o)
    if not joints:
        raise InputError(tok.end, "no ROOT in the hierarchy", "HIERARCHY ROOT NAME { ... }")
    return joints


def _frame_line(lines: list[str], i: int, shown: str, key: str) -> tuple[str, int, int]:
    """``Frames: N`` / ``Frame Time: T`` at line index i → (value text, line, col)."""
    m = re.fullmatch(rf"\s*{key}\s*:\s*(\S*)\s*", lines[i]) if i < len(lines) else None
    if m is None:
        where = Mark(shown, i + 1, 1) if i < len(lines) else Mark(shown, len(lines), 1)
        got = repr(lines[i].strip()[:40]) if i < len(lines) else "the end of the file"
        raise InputError(where, f"{got} where '{key}:' was expected", f"'{key}: VALUE' after MOTION")
    return m.group(1), i + 1, m.start(1) + 1


def read_bvh(path: Path | str) -> BVH:
    path = Path(path)
    shown = str(path)
    text = read_text(path, shown, allowed="an existing .bvh file", max_bytes=tol.BVH_MAX_BYTES)
    lines = text.split("\n")
    words = []
    motion = None
    for i, line in enumerate(lines):
        for m in _TOKEN.finditer(line):
            if m.group() == "MOTION":
                motion = i
                break
            words.append((m.group(), i + 1, m.start() + 1))
        if motion is not None:
            break
    end = Mark(shown, motion + 1, 1) if motion is not None else Mark(shown, len(lines), len(lines[-1]) + 1)
    joints = _hierarchy(_Tokens(shown, words, end))
    if motion is None:
        raise InputError(end, "no MOTION section", "MOTION, Frames: N, Frame Time: T and N rows after the hierarchy")
    rest = lines[motion].split("MOTION", 1)[1]
    if rest.strip():
        raise InputError(Mark(shown, motion + 1, lines[motion].index("MOTION") + 7), f"{rest.strip()!r} after MOTION",
                         "MOTION alone on its line")
    i = motion + 1
    while i < len(lines) and not lines[i].strip():
        i += 1
    ntext, nline, ncol = _frame_line(lines, i, shown, "Frames")
    if not re.fullmatch(r"[0-9]+", ntext) or int(ntext) < 1:
        raise InputError(Mark(shown, nline, ncol), f"Frames is {ntext!r}", "a whole number of frames >= 1")
    n_frames = int(ntext)
    ttext, tline, tcol = _frame_line(lines, i + 1, shown, "Frame Time")
    try:
        ft = float(ttext)
    except ValueError:
        ft = float("nan")
    if not (math.isfinite(ft) and 1.0 / tol.MAX_FPS <= ft <= 3600):
        raise InputError(Mark(shown, tline, tcol), f"Frame Time is {ttext!r}",
                         f"seconds per frame, in [{1.0 / tol.MAX_FPS:g}, 3600] (at most {tol.MAX_FPS:g} fps, "
                         "what a pose may have)")
    n_cols = sum(len(j.channels) for j in joints)
    rows: list[str] = []
    row_lines: list[int] = []
    for k in range(i + 2, len(lines)):
        if not lines[k].strip():
            continue
        if len(rows) == n_frames:
            raise InputError(Mark(shown, k + 1, 1), f"more motion rows than 'Frames: {n_frames}' (line {nline}) says",
                             "exactly as many rows as Frames says")
        rows.append(lines[k])
        row_lines.append(k + 1)
    if len(rows) < n_frames:
        last = len(lines) if lines[-1] else max(len(lines) - 1, 1)
        raise InputError(Mark(shown, last, 1), f"the file ends after {len(rows)} of {n_frames} motion rows "
                         f"('Frames: {n_frames}' at line {nline}; truncated?)", "as many rows as Frames says")
    data = _motion(rows, row_lines, n_cols, shown)
    return BVH(shown, tuple(joints), ft, ttext, data, Mark(shown, nline, ncol), Mark(shown, tline, tcol),
               tuple(row_lines))


def _motion(rows: list[str], row_lines: list[int], n_cols: int, shown: str) -> np.ndarray:
    """Motion rows → (N, n_cols) float64; a bad row or value is reported where it is."""
    flat: list[str] = []
    for r, ln in zip(rows, row_lines):
        w = r.split()
        if len(w) != n_cols:
            col = len(r.rstrip()) + 1 if len(w) < n_cols else [m.start() + 1 for m in re.finditer(r"\S+", r)][n_cols]
            raise InputError(Mark(shown, ln, col), f"motion row has {len(w)} values",
                             f"{n_cols} values, one per channel of the hierarchy")
        flat.extend(w)
    try:
        data = np.array(flat, dtype=np.float64).reshape(len(rows), n_cols)
        bad = ~np.isfinite(data) | (np.abs(data) > tol.MAX_ABS_NUMBER)
    except ValueError:
        data, bad = None, None
    if data is not None and not bad.any():
        return data
    for r, ln in zip(rows, row_lines):  # find the first bad value (rare: only on error)
        for m in re.finditer(r"\S+", r):
            try:
                v = float(m.group())
            except ValueError:
                raise InputError(Mark(shown, ln, m.start() + 1), f"motion value {m.group()!r} is not a number",
                                 "decimal numbers") from None
            if not math.isfinite(v) or abs(v) > tol.MAX_ABS_NUMBER:
                raise InputError(Mark(shown, ln, m.start() + 1), f"motion value {m.group()!r}",
                                 f"finite numbers within ±{tol.MAX_ABS_NUMBER:g}")
    raise AssertionError("unreachable: a bad value was detected but not found")


# ----------------------------------------------------------------------------- units and rates


def rest_positions(bvh: BVH) -> np.ndarray:
    """(J, 3) rest positions of every joint and end site, file units, BVH axes."""
    pos = np.zeros((len(bvh.joints), 3))
    for k, j in enumerate(bvh.joints):
        pos[k] = np.asarray(j.offset) + (pos[j.parent] if j.parent >= 0 else 0.0)
    return pos


def rest_span(bvh: BVH) -> float:
    """The rest joint span: the extent along BVH Y (up) of every joint and end site at rest, file units."""
    y = rest_positions(bvh)[:, 1]
    return float(y.max() - y.min())


def stature(span: float, scale: float) -> float:
    """The person's estimated stature (metres) from a rest joint span in file units."""
    return span * scale / tol.STATURE_SPAN_RATIO


def guess_unit(bvh: BVH) -> tuple[str | None, float]:
    """(unit name, rest joint span in file units): the unit whose estimated stature lies in
    tolerances.STATURE_BAND (the one nearest TYPICAL_STATURE should several), None when none does."""
    span = rest_span(bvh)
    if span <= 0:
        return None, span
    lo, hi = tol.STATURE_BAND
    fits = [u for u in UNITS if lo <= stature(span, UNITS[u]) <= hi]
    if not fits:
        return None, span
    return min(fits, key=lambda u: abs(math.log(stature(span, UNITS[u]) / tol.TYPICAL_STATURE))), span


@dataclass(frozen=True)
class UnitChoice:
    """How a BVH's lengths become metres: ``scale`` metres per file unit, ``unit`` its name
    (None: a number), ``how`` "given" (--scale/--units), "height" (a unit whose person is in
    the band) or "typical" (no unit was: scaled to TYPICAL_STATURE)."""

    scale: float
    unit: str | None
    how: str
    span: float  # rest joint span, file units

    @property
    def stature(self) -> float:
        return stature(self.span, self.scale)

    def notes(self, person: bool = True) -> list[str]:
        """The lines that say which unit was taken and the person's height (``person`` False:
        the unit alone, for a command that states the subject's height by
        :func:`axdf_cli.model.stature.stature`, as ``axdf retarget`` does)."""
        word = UNIT_WORDS[self.unit] if self.unit else f"{self.scale:g} m per unit"
        if not person and self.how != "typical":
            return [f"BVH unit: {word} ({'given' if self.how == 'given' else 'its rest joint span fits a person'}; "
                    f"--units or --scale to override)"]
        person = (f"rest joint span {self.span:.4g} units = {self.span * self.scale:.3g} m: a {self.stature:.2f} m "
                  f"person (span / {tol.STATURE_SPAN_RATIO:g})")
        if self.how == "given":
            return [f"BVH unit: {word} (given); {person}"]
        if self.how == "typical":
            return [f"{person}: no unit ({', '.join(UNITS)}) makes a {tol.STATURE_BAND[0]:g}-{tol.STATURE_BAND[1]:g} "
                    f"m person, so lengths are scaled to a {tol.TYPICAL_STATURE:g} m person (--scale {self.scale:.6g})"]
        return [f"rest skeleton height {self.span:.4g} units: looks like {word} "
                f"(a {self.stature:.2f} m person, span / {tol.STATURE_SPAN_RATIO:g})",
                f"using --scale {self.scale:g} (pass --units or --scale to override)"]

    def warnings(self) -> list[str]:
        """A scale that is no unit's: what the user should check (stderr)."""
        if self.how != "typical":
            return []
        return [f"no length unit makes this BVH a {tol.STATURE_BAND[0]:g}-{tol.STATURE_BAND[1]:g} m person "
                f"(rest joint span {self.span:.4g} units): scaled to {tol.TYPICAL_STATURE:g} m; "
                f"give --units ({', '.join(UNITS)}) or --scale if that is wrong"]


def choose_unit(bvh: BVH, scale: float | None = None) -> UnitChoice:
    """The scale of ``bvh``: ``scale`` when given (named when it is a unit's), else the unit
    from the body's height (see the module doc)."""
    span = rest_span(bvh)
    if scale is not None:
        unit = next((u for u, v in UNITS.items() if v == scale), None)
        return UnitChoice(float(scale), unit, "given", span)
    unit, _ = guess_unit(bvh)
    if unit is not None:
        return UnitChoice(UNITS[unit], unit, "height", span)
    if span <= 0:
        return UnitChoice(1.0, "m", "given", span)
    return UnitChoice(tol.TYPICAL_STATURE * tol.STATURE_SPAN_RATIO / span, None, "typical", span)


def frame_rate(frame_time: float, text: str) -> float:
    """fps from Frame Time: a whole n when ``1/n`` rounds to the digits written, else ``1/T``."""
    n = round(1.0 / frame_time)
    try:
        digits = -Decimal(text).as_tuple().exponent
    except InvalidOperation:
        digits = 15
    if n >= 1 and abs(1.0 / n - frame_time) <= 0.5 * 10.0 ** -digits * (1 + 1e-9):
        return float(n)
    return 1.0 / frame_time


# ----------------------------------------------------------------------------- documents


def bone_names(bvh: BVH) -> list[str]:
    """Unique axdf bone names: joint names made safe, end sites ``<joint>_end``; ``ground`` is taken."""
    return unique_names((safe_name(bvh.joints[j.parent].name) + "_end" if j.end_site else safe_name(j.name)
                         for j in bvh.joints), taken=("ground",))


def coordinate_name(bone: str, channel: str) -> str:
    return f"{bone}_{channel}"


def _dofs(bone: str, channels: tuple[str, ...]) -> list[Dof]:
    """Position channels first (translations in the parent frame), then rotations in file order."""
    dofs = []
    for want in ("translation", "rotation"):
        for c in channels:
            kind, ax = CHANNELS[c.lower()]
            if kind == want:
                axis = [0, 0, 0]
                axis[ax] = 1
                dofs.append(Dof(kind, axis, coordinate_name(bone, c)))
    return dofs


def bvh_bones(bvh: BVH, scale: float) -> list[Bone]:
    """``ground`` (BVH's Y-up world in axdf's Z-up one), then a bone per joint and end site."""
    names = bone_names(bvh)
    bones = [Bone("ground", orient=list(GROUND_ORIENT))]
    for j, bname in zip(bvh.joints, names):
        bones.append(Bone(bname, names[j.parent] if j.parent >= 0 else "ground",
                          [float(v) * scale for v in j.offset], dofs=_dofs(bname, j.channels)))
    return bones


def motion_of(bvh: BVH, name: str, scale: float, step: int) -> Motion:
    """The motion of every ``step``-th row; a coordinate that never changes is keyed at frame 0 only."""
    names = bone_names(bvh)
    rows = bvh.data[::step]
    fps = frame_rate(bvh.frame_time, bvh.frame_time_text) / step
    cols = []
    for (j, c), values in zip(bvh.columns, rows.T):
        kind = CHANNELS[c.lower()][0]
        cols.append((coordinate_name(names[j], c), values * scale if kind == "translation" else values))
    keys: dict[int, dict] = {}
    for f in range(len(rows)):
        keys[f] = {cname: float(v[f]) for cname, v in cols if f == 0 or not np.all(v == v[0])}
    return Motion(name, fps, len(rows), keys, f"Imported from {Path(bvh.source).name} by `axdf import bvh` "
                                              f"(every {step} of {len(bvh.data)} rows).")


def check_limits(bvh: BVH, scale: float) -> None:
    """What the skeleton and pose files may hold, checked at the BVH's own line and column:
    names (bones, and coordinates ``<bone>_<channel>``), lengths times ``scale`` within
    ±MAX_ABS_NUMBER metres."""
    names = bone_names(bvh)
    for j, bname in zip(bvh.joints, names):
        longest = max([bname] + [coordinate_name(bname, c) for c in j.channels], key=len)
        if not is_name(longest):
            raise InputError(j.mark, f"joint {j.name[:40]!r}{'...' if len(j.name) > 40 else ''} becomes the name "
                             f"{longest[:40]!r}... ({len(longest)} characters)", f"{NAME_ALLOWED}; rename the joint")
        far = [abs(v) * scale > tol.MAX_ABS_NUMBER for v in j.offset]
        if any(far):
            raise InputError(j.mark, f"OFFSET {j.offset[far.index(True)]:g} x --scale {scale:g} is beyond "
                             f"{tol.MAX_ABS_NUMBER:g} m", f"lengths within ±{tol.MAX_ABS_NUMBER:g} m after --scale")
    cols = [k for k, (_, c) in enumerate(bvh.columns) if CHANNELS[c.lower()][0] == "translation"]
    if cols and len(bvh.data):
        far = np.abs(bvh.data[:, cols]) * scale > tol.MAX_ABS_NUMBER
        if far.any():
            row, k = map(int, np.argwhere(far)[0])
            raise InputError(bvh.value_mark(row, cols[k]), f"position {bvh.data[row, cols[k]]:g} x --scale {scale:g} "
                             f"is beyond {tol.MAX_ABS_NUMBER:g} m", f"positions within ±{tol.MAX_ABS_NUMBER:g} m "
                             "after --scale")


RULES = Rules("axdf import bvh", report=False)


def read_import(bvh_path: Path | str, *, name: str | None = None, scale: float | None = None, step: int = 1,
                pose_name: str | None = None) -> ImportedModel:
    """``axdf import bvh``: a BVH file read and checked into the neutral model (a skeleton and
    its motion; ``scale`` None: the guessed unit). The model's ``warnings`` are the lines that
    tell the user the unit guess."""
    bvh_path = Path(bvh_path)
    bvh = read_bvh(bvh_path)
    name = name or safe_name(bvh_path.stem)
    pname = pose_name or name
    for what, v in (("--name", name), ("--pose-name", pname)):
        if not is_name(v):
            raise InputError(None, f"{what} {v!r}", NAME_ALLOWED)
    units = choose_unit(bvh, scale)
    scale = units.scale
    check_limits(bvh, scale)
    motion = motion_of(bvh, pname, scale, step)
    report = {"source": {"file": bvh_path.name, "sha256": sha256_file(bvh_path)}, "tool": "axdf import bvh",
              "skeleton": name, "pose": pname, "scale": scale, "unit": units.unit, "unit_from": units.how,
              "rest_height_units": units.span, "stature_m": units.stature, "unit_warnings": units.warnings(),
              "joints": sum(not j.end_site for j in bvh.joints), "end_sites": sum(j.end_site for j in bvh.joints),
              "channels": int(bvh.data.shape[1]), "rows": int(len(bvh.data)), "step": step,
              "frames": int(len(bvh.data[::step])), "fps": motion.fps}
    return ImportedModel(name, f"Imported from {bvh_path.name} by `axdf import bvh` (--scale {scale:g}).\n"
                               "Regenerate with the importer rather than editing by hand.",
                         bvh_bones(bvh, scale), RULES, motion=motion, report=report, warnings=units.notes(),
                         inputs=[bvh_path])


#: The steps of ``axdf import bvh`` (its progress bar's units).
STEPS = ("read", "skeleton", "pose")
