"""The thresholds of ``axdf compare`` (what its tolerance YAML and flags set; the model's own
numeric tolerances are :mod:`axdf_cli.tolerances`): the defaults (all in one place, each with
its reason), the tolerance YAML reader, and per-file resolution of glob overrides.

Two requirements fix the image defaults (docs/COMPARE.md repeats them):

- a run rendered by llvmpipe on another CPU must pass: different SIMD widths and FMA use
  change shading by a few 8-bit steps and may flip the coverage or depth test of a few
  silhouette pixels;
- a muscle moved by 2 pixels must fail: every pixel along its outline (both sides) and most
  of its shaded interior change by far more than the per-pixel threshold.

Precedence for one file: built-in defaults < the YAML's top level < command-line flags < the
YAML's ``overrides`` whose ``match`` glob matches the file (in file order, later wins).
"""
from __future__ import annotations

import fnmatch
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import Fields, item_marks, load_yaml

# ----------------------------------------------------------------------------- the defaults
# Meshes are written as float32 in metres. A float32 step at 1 m is 6e-8 m; a float64 result
# that differs in its last bits between CPUs (numpy/BLAS kernels) can round to the next
# float32. 1e-5 m (10 micrometres) is ~170 such steps, yet 200x below one preview pixel
# (a 0.5 m field of view over 256 pixels is 2 mm per pixel).
MESH_MAX_DISTANCE = 1e-5
# RMS over all vertices catches a drift of the whole muscle that stays under the maximum.
# Rounding noise of a few float32 steps gives an RMS near 1e-7 m; 2e-6 m is 20x that.
MESH_RMS_DISTANCE = 2e-6
# Per-vertex normals are float32 unit vectors recomputed from the positions; a 1e-5 m move
# of a vertex on 5 mm edges turns a normal by ~2e-3. 0.01 (|n_a - n_g|, about 0.6 degree)
# passes that and still catches a flipped normal (difference 2).
MESH_NORMAL_MAX = 0.01

# PNG (8-bit): a pixel fails when any channel differs by more than this, in [0, 1] units
# (5/255). Cross-CPU llvmpipe shading noise is 1-2 steps of 1/255; a 2-pixel shift changes
# outline pixels by the muscle/background contrast and shaded pixels by the shading slope.
PNG_THRESHOLD = 5.0 / 255.0
# At most this fraction of pixels may fail (0.1%: 65 pixels at 256x256). Room for a few
# silhouette pixels whose coverage or depth test flips on another CPU; a muscle moved by 2
# pixels fails at least 4 pixels per row of its outline (a 20-pixel-wide muscle: ~0.4%).
FAIL_FRACTION = 1e-3
# Hard maximum per-pixel difference: off (None) by default. A silhouette pixel whose
# coverage flips on another CPU changes by the full contrast, so any hard maximum below 1
# would fail runs that must pass; the failing fraction bounds how many such pixels there are.
PNG_HARD_MAX = None

# EXR float channels: a value fails when |a - g| > atol + rtol * |g| (as numpy.isclose).
# Colour (R G B A, half floats): half has 11 significant bits (rtol 1e-3); shading noise
# across CPUs is like the PNG's, so atol matches PNG_THRESHOLD and rtol lets HDR values
# (> 1) vary by the same 2%.
EXR_COLOR_ATOL = 5.0 / 255.0
EXR_COLOR_RTOL = 0.02
# Depth Z (metres, float32): depth interpolation differs in the last bits between CPUs
# (1e-6 relative); 1 mm + 0.1% is far above that and far below a 2-pixel move of an
# outline, which changes depth from the muscle to the background.
EXR_DEPTH_ATOL = 1e-3
EXR_DEPTH_RTOL = 1e-3
# Normals N.X N.Y N.Z (unit vectors): the same bound as mesh normals.
EXR_NORMAL_ATOL = MESH_NORMAL_MAX
EXR_NORMAL_RTOL = 0.0
# Any other float channel: float32 rounding noise with room (relative 1e-4).
EXR_OTHER_ATOL = 1e-4
EXR_OTHER_RTOL = 1e-4
# `id` channels are labels: exact per pixel (3 is not close to 4). The failing-pixel
# fraction still applies, because a silhouette pixel that flips coverage flips its id too.

# stats.csv / bones.csv (and any CSV), camera.json (and any JSON but the manifest): numbers
# are printed from float64 with at least 9 significant digits, so cross-CPU differences
# are ~1e-9 relative. rtol 1e-6 is far above that; atol 1e-9 covers values printed as ~0
# (a volume in m^3 is ~1e-4, so a larger atol would hide real volume changes).
TABLE_ATOL = 1e-9
TABLE_RTOL = 1e-6
JSON_ATOL = 1e-9
JSON_RTOL = 1e-6

# How many individual differences (cells, JSON paths) one file's reasons list at most.
MAX_LISTED = 5


# ----------------------------------------------------------------------------- dataclasses
@dataclass(frozen=True)
class MeshTol:
    max_distance: float = MESH_MAX_DISTANCE
    rms_distance: float = MESH_RMS_DISTANCE
    normal_max: float = MESH_NORMAL_MAX


@dataclass(frozen=True)
class ChannelTol:
    """A value fails when ``|a - g| > atol + rtol * |g|``; the image fails when any value
    differs by more than ``hard_max`` (None: no hard maximum)."""

    atol: float
    rtol: float = 0.0
    hard_max: float | None = None


@dataclass(frozen=True)
class PngTol:
    threshold: float = PNG_THRESHOLD
    fail_fraction: float = FAIL_FRACTION
    hard_max: float | None = PNG_HARD_MAX


@dataclass(frozen=True)
class ExrTol:
    fail_fraction: float = FAIL_FRACTION
    color: ChannelTol = ChannelTol(EXR_COLOR_ATOL, EXR_COLOR_RTOL)
    depth: ChannelTol = ChannelTol(EXR_DEPTH_ATOL, EXR_DEPTH_RTOL)
    normal: ChannelTol = ChannelTol(EXR_NORMAL_ATOL, EXR_NORMAL_RTOL)
    other: ChannelTol = ChannelTol(EXR_OTHER_ATOL, EXR_OTHER_RTOL)


@dataclass(frozen=True)
class NumTol:
    atol: float
    rtol: float


@dataclass(frozen=True)
class FileTol:
    """Everything one file may need; each comparator reads its own part."""

    mesh: MeshTol = MeshTol()
    png: PngTol = PngTol()
    exr: ExrTol = ExrTol()
    table: NumTol = NumTol(TABLE_ATOL, TABLE_RTOL)
    json: NumTol = NumTol(JSON_ATOL, JSON_RTOL)


@dataclass(frozen=True)
class Override:
    pattern: str
    where: Mark
    changes: dict  # section -> {key: value} (nested for exr channel classes)


@dataclass(frozen=True)
class Tolerances:
    base: FileTol = FileTol()
    overrides: tuple[Override, ...] = ()
    ignore: tuple[str, ...] = ()  # globs of relative paths that are not compared
    source: str | None = None  # the YAML file, when one was read

    def for_path(self, rel: str) -> FileTol:
        t = self.base
        for ov in self.overrides:
            if glob_match(ov.pattern, rel):
                t = _apply(t, ov.changes)
        return t

    def ignored(self, rel: str) -> bool:
        return any(glob_match(p, rel) for p in self.ignore)

    def with_flags(self, changes: dict) -> "Tolerances":
        """Command-line flags: they replace the top level, below the per-pattern overrides."""
        return replace(self, base=_apply(self.base, changes))


def glob_match(pattern: str, rel: str) -> bool:
    """fnmatch on the path relative to the run folder ('*' also crosses '/'); a pattern
    without '/' also matches the file name alone."""
    if fnmatch.fnmatchcase(rel, pattern):
        return True
    return "/" not in pattern and fnmatch.fnmatchcase(rel.rsplit("/", 1)[-1], pattern)


def _apply(t: FileTol, changes: dict) -> FileTol:
    for section, vals in changes.items():
        sub = getattr(t, section)
        upd = {}
        for k, v in vals.items():
            upd[k] = replace(getattr(sub, k), **v) if isinstance(v, dict) else v
        t = replace(t, **{section: replace(sub, **upd)})
    return t


def as_dict(t: FileTol) -> dict:
    """JSON-able view (for the report)."""
    out = {}
    for f in fields(t):
        sub = getattr(t, f.name)
        d = {}
        for g in fields(sub):
            v = getattr(sub, g.name)
            d[g.name] = {h.name: getattr(v, h.name) for h in fields(v)} if hasattr(v, "__dataclass_fields__") else v
        out[f.name] = d
    return out


# ----------------------------------------------------------------------------- YAML reading
_SECTIONS = {"mesh": MeshTol, "png": PngTol, "exr": ExrTol, "table": NumTol, "json": NumTol}
_EXR_CLASSES = ("color", "depth", "normal", "other")


def _read_section(section: str, value, where: Mark) -> dict:
    f = Fields(value, where, section)
    out: dict[str, Any] = {}

    def num(key, lo=0.0, hi=None, nullable=False):
        if not f.has(key):
            return
        if nullable and f.raw(key) is None:
            out[key] = None
            return
        out[key] = float(f.number(key, lo=lo, hi=hi))

    if section == "mesh":
        for key in ("max_distance", "rms_distance", "normal_max"):
            num(key)
    elif section == "png":
        num("threshold", hi=1.0)
        num("fail_fraction", hi=1.0)
        num("hard_max", hi=1.0, nullable=True)
    elif section == "exr":
        num("fail_fraction", hi=1.0)
        for cls in _EXR_CLASSES:
            if f.has(cls):
                g = Fields(f.mapping(cls), f.vmark(cls), f"exr.{cls}")
                sub: dict[str, Any] = {}
                for key in ("atol", "rtol"):
                    if g.has(key):
                        sub[key] = float(g.number(key, lo=0.0))
                if g.has("hard_max"):
                    sub["hard_max"] = None if g.raw("hard_max") is None else float(g.number("hard_max", lo=0.0))
                g.done()
                out[cls] = sub
    else:  # table, json
        num("atol")
        num("rtol")
    f.done()
    return out


def load_tolerances(path: Path | str) -> Tolerances:
    """Read a tolerance YAML; any unknown key or bad value is an InputError with its position.

    Schema (every key optional)::

        mesh:  {max_distance, rms_distance, normal_max}
        png:   {threshold, fail_fraction, hard_max}
        exr:   {fail_fraction, color|depth|normal|other: {atol, rtol, hard_max}}
        table: {atol, rtol}
        json:  {atol, rtol}
        ignore: [GLOB, ...]
        overrides: [{match: GLOB, mesh: ..., png: ..., ...}, ...]
    """
    display = str(path)
    doc = load_yaml(path, display)
    where = Mark(display, 1, 1)
    if doc is None:
        doc = {}
    top = Fields(doc, where, "tolerances")
    base = FileTol()
    for section in _SECTIONS:
        if top.has(section):
            base = _apply(base, {section: _read_section(section, top.mapping(section), top.vmark(section))})
    ignore: list[str] = []
    if top.has("ignore"):
        seq = top.seq("ignore")
        for v, m in zip(seq, item_marks(seq, top.vmark("ignore"))):
            if not isinstance(v, str) or not v:
                raise InputError(m, f"ignore entry is {v!r}", "ignore is a list of glob strings")
            ignore.append(v)
    overrides: list[Override] = []
    if top.has("overrides"):
        seq = top.seq("overrides")
        for v, m in zip(seq, item_marks(seq, top.vmark("overrides"))):
            g = Fields(v, m, "override")
            pattern = g.string("match", required=True)
            changes = {}
            for section in _SECTIONS:
                if g.has(section):
                    changes[section] = _read_section(section, g.mapping(section), g.vmark(section))
            g.done()
            overrides.append(Override(pattern, getattr(v, "mark", m), changes))
    top.done()
    return Tolerances(base=base, overrides=tuple(overrides), ignore=tuple(ignore), source=display)
