"""YAML files → small frozen specs. Every check reports ``FILE:LINE:COL: what; allowed``.

File kinds: skeleton (``skeleton:``), pose (``pose:``), muscle (``muscle:`` or ``muscles:``)
and job (``muscles:`` + ``pose:`` + ...). See docs/FORMATS.md.

Paths written inside YAML files are resolved relative to the file that holds them and
checked against a :class:`RefPolicy`, passed down explicitly (no global state).
"""
from __future__ import annotations

import glob
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.muscle import OCT, VOLUME_MODES, AxisPoint, MuscleSpec, Section, outline_area
from axdf_cli.skeleton import (Bone, Constant, Coordinate, Dof, Linear, Multiplier, Polynomial,
                               Skeleton, Spline)
from axdf_cli.yamlio import (Fields, YMap, check_name, check_number, check_vector, did_you_mean, item_marks,
                             load_yaml, mark_of, real_path)

DOF_TYPES = ("rotation", "translation")


def _unit_axis(v, where: Mark, what: str = "axis") -> tuple[float, float, float]:
    a = np.array(check_vector(v, where, what, 3))
    n = float(np.linalg.norm(a))
    if n < 1e-9:
        raise InputError(where, f"{what} is the zero vector", f"{what} must have non-zero length")
    return tuple(float(x) for x in a / n)


# ----------------------------------------------------------------------------- functions


FUNCTION_KINDS = ("constant", "linear", "polynomial", "spline", "multiplier")


def parse_function(value, where: Mark, depth: int = 0):
    """``{constant: c}``, ``{linear: [slope, intercept]}``, ``{polynomial: [c0, c1, ...]}``,
    ``{spline: {x: [...], y: [...], kind: fmm|natural}}``, ``{multiplier: {scale, function}}``."""
    allowed = "function is one of " + ", ".join(f"{{{k}: ...}}" for k in FUNCTION_KINDS)
    if not isinstance(value, dict) or len(value) != 1:
        raise InputError(mark_of(value, where), "function must be a mapping with one key", allowed)
    (kind, arg), = value.items()
    at = value.value_mark(kind) if isinstance(value, YMap) else where
    if kind == "constant":
        return Constant(float(check_number(arg, at, "constant")))
    if kind == "linear":
        s, i = check_vector(arg, at, "linear", 2)
        return Linear(s, i)
    if kind == "polynomial":
        return Polynomial(check_vector(arg, at, "polynomial", min_len=1))
    if kind == "spline":
        f = Fields(arg, at, "spline", keys=("x", "y", "kind"))
        x = f.vector("x", required=True, min_len=2)
        y = f.vector("y", required=True, min_len=2)
        k = f.choice("kind", ("fmm", "natural"), default="fmm")
        f.done()
        if len(x) != len(y):
            raise InputError(f.vmark("y"), f"spline has {len(x)} x and {len(y)} y values", "x and y of equal length")
        if np.any(np.diff(x) <= 0):
            raise InputError(f.vmark("x"), "spline x values are not strictly increasing", "increasing x")
        return Spline(np.array(x), np.array(y), k)
    if kind == "multiplier":
        if depth > 4:
            raise InputError(at, "multiplier nested too deeply", "at most 4 levels")
        f = Fields(arg, at, "multiplier", keys=("scale", "function"))
        scale = f.number("scale", required=True)
        inner = parse_function(f.raw("function", required=True), f.vmark("function"), depth + 1)
        f.done()
        return Multiplier(scale, inner)
    raise InputError(value.key_mark(kind) if isinstance(value, YMap) else where,
                     f"unknown function {kind!r}", allowed)


# ----------------------------------------------------------------------------- skeleton


def load_skeleton(path: Path | str, policy: RefPolicy | None = None) -> Skeleton:
    path = Path(path)
    return skeleton_from_document(load_yaml(path), path, policy)


def parse_skeleton_text(text: str, path: Path | str, policy: RefPolicy | None = None) -> Skeleton:
    """A skeleton from YAML text that will live at ``path`` (mesh paths resolve from there)."""
    from axdf_cli.yamlio import parse_yaml

    return skeleton_from_document(parse_yaml(text, str(path)), Path(path), policy)


def _check_range(rng, where: Mark, what: str):
    if rng is not None and rng[0] > rng[1]:
        raise InputError(where, f"{what} range is {list(rng)}", "[min, max] with min <= max")
    return rng


def skeleton_from_document(doc, path: Path, policy: RefPolicy | None = None) -> Skeleton:
    policy = policy or RefPolicy()
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "skeleton file", keys=("skeleton", "bones", "coordinates"))
    name = f.name("skeleton", required=True)
    bones_seq = f.seq("bones", required=True, min_len=1)
    coords_map = f.mapping("coordinates", default=None)
    f.done()

    declared: dict[str, Coordinate] = {}
    ranges: dict[str, list] = {}  # coordinate -> [(range, mark)] from its declaration and its dofs
    if coords_map is not None:
        for cname, cval in coords_map.items():
            km = coords_map.key_mark(cname)
            check_name(cname, km, "coordinate name")
            cf = Fields(cval, coords_map.value_mark(cname), f"coordinate {cname}", keys=("type", "default", "range"))
            ctype = cf.choice("type", DOF_TYPES, required=True)
            default = cf.number("default", default=0.0)
            rng = _check_range(cf.vector("range", 2, default=None), cf.vmark("range"), f"coordinate {cname}")
            cf.done()
            declared[cname] = Coordinate(cname, ctype, float(default), None)
            if rng is not None:
                ranges.setdefault(cname, []).append((rng, cf.vmark("range")))

    bones: list[Bone] = []
    index: dict[str, int] = {}
    used: dict[str, str] = {}  # coordinate -> type inferred from direct use
    order: list[str] = list(declared)
    for bval, bm in zip(bones_seq, item_marks(bones_seq, top)):
        bf = Fields(bval, bm, "bone", keys=("name", "parent", "offset", "orient", "post_offset", "post_orient",
                                            "mesh", "dofs"))
        bname = bf.name("name", required=True)
        if bname in index:
            raise InputError(bf.vmark("name"), f"bone {bname!r} defined twice", "bone names are unique")
        parent_name = bf.name("parent", default=None)
        if parent_name is None:
            parent = -1
            if bones:
                raise InputError(bf.kmark("name"), f"bone {bname!r} has no parent but is not the first bone",
                                 "one root bone, listed first")
        elif parent_name not in index:
            raise InputError(bf.vmark("parent"), f"parent {parent_name!r} is not defined before {bname!r}",
                             f"parents come before children; {did_you_mean(parent_name, index)}"
                             f"defined so far: {', '.join(index) or 'none'}")
        else:
            parent = index[parent_name]
        offset = bf.vector("offset", 3, default=(0.0, 0.0, 0.0))
        orient = bf.vector("orient", 3, default=(0.0, 0.0, 0.0))
        post_offset = bf.vector("post_offset", 3, default=(0.0, 0.0, 0.0))
        post_orient = bf.vector("post_orient", 3, default=(0.0, 0.0, 0.0))
        mesh = bf.string("mesh", default=None)
        if mesh is not None:
            mesh = str(policy.resolve(path, mesh, bf.vmark("mesh")))
        dofs = []
        dof_seq = bf.seq("dofs", default=[])
        for dval, dm in zip(dof_seq, item_marks(dof_seq, bf.vmark("dofs"))):
            df = Fields(dval, dm, "dof", keys=("type", "axis", "coord", "function", "range"))
            dtype = df.choice("type", DOF_TYPES, required=True)
            axis = _unit_axis(df.raw("axis", required=True), df.vmark("axis"))
            coord = df.name("coord", default=None)
            fn = None
            if df.has("function"):
                fn = parse_function(df.raw("function"), df.vmark("function"))
            elif coord is None:
                raise InputError(dm, "dof has neither coord nor function", "give coord, function, or both")
            if coord is None and not isinstance(fn, Constant):
                raise InputError(df.vmark("function"), "a function of no coordinate must be constant",
                                 "give coord: NAME")
            rng = _check_range(df.vector("range", 2, default=None), df.vmark("range"), "dof")
            df.done()
            if rng is not None:
                if coord is None:
                    raise InputError(df.vmark("range"), "range on a dof of no coordinate",
                                     "a dof's range is its coordinate's range: give coord: NAME")
                ranges.setdefault(coord, []).append((rng, df.vmark("range")))
            if coord is not None:
                if fn is None:
                    if coord in used and used[coord] != dtype:
                        raise InputError(df.vmark("coord"), f"coordinate {coord!r} drives both a rotation and a translation",
                                         "one type per coordinate, or a function")
                    used[coord] = dtype
                    if coord in declared and declared[coord].type != dtype:
                        raise InputError(df.vmark("coord"), f"coordinate {coord!r} is declared {declared[coord].type}",
                                         f"use it on a {declared[coord].type} dof or through a function")
                if coord not in order:
                    order.append(coord)
            dofs.append(Dof(dtype, axis, coord, fn))
        bf.done()
        index[bname] = len(bones)
        bones.append(Bone(bname, parent, offset, orient, tuple(dofs), post_offset, post_orient, mesh))

    coords = []
    for c in order:
        base = declared.get(c) or Coordinate(c, used.get(c, "rotation"), 0.0, None)
        coords.append(Coordinate(base.name, base.type, base.default, _joint_range(c, ranges.get(c, []))))
    return Skeleton(name, tuple(bones), tuple(coords), str(path))


def _joint_range(coord: str, given: list) -> tuple[float, float] | None:
    """A coordinate's range: where every range given for it (declaration, dofs) overlaps."""
    if not given:
        return None
    lo, hi = given[0][0]
    for (a, b), where in given[1:]:
        lo, hi = max(lo, a), min(hi, b)
        if lo > hi:
            raise InputError(where, f"range {[a, b]} of coordinate {coord!r} does not overlap its other ranges",
                             "ranges of one coordinate (declared and on its dofs) must overlap; the tightest applies")
    return (float(lo), float(hi))


def _library_roots() -> tuple[Path, ...]:
    """The shipped library (``poses/`` and ``muscles/`` beside the package, in a checkout or
    an editable install): trusted from any folder, so a user's own pose may name a shipped
    skeleton."""
    here = Path(__file__).resolve().parent.parent
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


# ----------------------------------------------------------------------------- muscles



def parse_color(v, where: Mark, name: str) -> tuple[float, float, float]:
    if v is None:
        return default_color(name)
    if isinstance(v, str):
        s = v.strip()
        if len(s) == 7 and s[0] == "#":
            try:
                return tuple(int(s[i:i + 2], 16) / 255.0 for i in (1, 3, 5))
            except ValueError:
                pass
        raise InputError(where, f"color is {v!r}", "color is [r, g, b] in 0..1 or \"#rrggbb\"")
    return check_vector(v, where, "color", 3, 0.0, 1.0)


def default_color(name: str) -> tuple[float, float, float]:
    """A deterministic muscle-red hue from the name (no randomness)."""
    import hashlib
    import colorsys

    h = int(hashlib.sha256(name.encode()).hexdigest()[:8], 16) / 0xFFFFFFFF
    return tuple(round(c, 4) for c in colorsys.hsv_to_rgb(0.97 + 0.08 * h - (1.0 if 0.97 + 0.08 * h > 1 else 0),
                                                           0.55 + 0.2 * h, 0.65 + 0.2 * (1 - h)))


MUSCLE_KEYS = ("muscle", "color", "strength", "tension", "volume", "axis", "path", "wrap", "axis_points",
               "sections", "tendons", "twist", "resolution", "weights")


def _parse_muscle(value, where: Mark, file: str, group: str = "") -> MuscleSpec:
    f = Fields(value, where, "muscle", keys=MUSCLE_KEYS)
    name = f.name("muscle", required=True)
    color = parse_color(f.raw("color"), f.vmark("color"), name)
    strength = f.number("strength", default=1.0, lo=0.0, hi=100.0, lo_open=True)
    tension = f.number("tension", default=0.0, lo=0.0, hi=1.0)
    volume = f.choice("volume", VOLUME_MODES, default="exact")
    path = parse_muscle_path(f) if f.has("path") else None
    axis_seq = f.seq("axis", required=path is None, default=[])
    if path is not None and axis_seq:
        raise InputError(f.kmark("axis"), "muscle has both axis and path", "give one of them")
    if path is None and len(axis_seq) < 3:
        raise InputError(f.vmark("axis"), f"axis has {len(axis_seq)} control points",
                         "a quadratic B-spline axis needs at least 3 (default 5)")
    if len(axis_seq) > 64:
        raise InputError(f.vmark("axis"), f"axis has {len(axis_seq)} control points", "at most 64")
    axis = []
    for av, am in zip(axis_seq, item_marks(axis_seq, f.vmark("axis"))):
        af = Fields(av, am, "axis point", keys=("bone", "at"))
        bone = af.name("bone", required=True)
        at = af.vector("at", 3, required=True)
        af.done()
        axis.append(AxisPoint(bone, at, af.vmark("bone")))
    sections = []
    sec_seq = f.seq("sections", default=None)
    if sec_seq is None:
        sections = [Section((k + 1) / 5.0, None) for k in range(4)]
    else:
        if len(sec_seq) < 2:
            raise InputError(f.vmark("sections"), f"{len(sec_seq)} section(s)", "at least 2 sections")
        if len(sec_seq) > 64:
            raise InputError(f.vmark("sections"), f"{len(sec_seq)} sections", "at most 64")
        prev = 0.0
        for sv, sm in zip(sec_seq, item_marks(sec_seq, f.vmark("sections"))):
            sf = Fields(sv, sm, "section", keys=("t", "radii", "angle", "outline"))
            t = sf.number("t", required=True, lo=0.0, hi=1.0, lo_open=True)
            if t >= 1.0 or t <= prev:
                raise InputError(sf.vmark("t"), f"section t is {t!r}",
                                 f"section t values increase strictly inside (0, 1) (previous {prev})")
            prev = t
            if sf.has("outline"):
                if sf.has("radii") or sf.has("angle"):
                    raise InputError(sm, "section has both outline and radii/angle", "give one of them")
                ol = sf.seq("outline")
                if len(ol) != OCT:
                    raise InputError(sf.vmark("outline"), f"outline has {len(ol)} points",
                                     f"an outline has exactly {OCT} [v, w] points")
                pts = [check_vector(pv, pm, "outline point", 2)
                       for pv, pm in zip(ol, item_marks(ol, sf.vmark("outline")))]
                area = outline_area(np.array(pts))
                if abs(area) < 1e-12:
                    raise InputError(sf.vmark("outline"), "outline encloses no area",
                                     "8 points around the axis, counter-clockwise")
                if area < 0:  # clockwise: reverse so that the surface faces outwards
                    pts = [pts[0]] + pts[:0:-1]
                sections.append(Section(t, None, 0.0, tuple(pts)))
            else:
                radii = sf.vector("radii", 2, required=True, lo=0.0, lo_open=True)
                angle = sf.number("angle", default=0.0)
                sections.append(Section(t, radii, angle))
            sf.done()
    tendons = f.vector("tendons", 2, default=(0.0, 0.0), lo=0.0, hi=0.95)
    if sum(tendons) >= 0.95:
        raise InputError(f.vmark("tendons"), f"tendon fractions add up to {sum(tendons):.3g}",
                         "origin + insertion fractions < 0.95 (a belly must remain)")
    twist = f.number("twist", default=0.0, lo=-3600.0, hi=3600.0)
    res = f.raw("resolution")
    if res is None:
        resolution = (40, 24)
    else:
        r = check_vector(res, f.vmark("resolution"), "resolution", 2)
        if not (3 <= r[0] <= 4096 and 3 <= r[1] <= 4096 and all(float(x).is_integer() for x in r)):
            raise InputError(f.vmark("resolution"), f"resolution is {list(res)}",
                             "[along, around] integers in 3..4096")
        resolution = (int(r[0]), int(r[1]))
        if resolution[0] * resolution[1] > 1_000_000:
            raise InputError(f.vmark("resolution"), f"resolution {resolution[0]}x{resolution[1]} is too fine",
                             "at most 1,000,000 vertices per muscle")
    weights = f.vector("weights", default=None, lo=0.0, lo_open=True)
    if weights is not None and len(weights) != len(sections):
        raise InputError(f.vmark("weights"), f"{len(weights)} weights for {len(sections)} sections",
                         "one weight per section")
    f.done()
    return MuscleSpec(name, color, tuple(axis), tuple(sections), strength, tension, volume,
                      tendons, twist, resolution, weights, file, group, path)


# ----------------------------------------------------------------------------- muscle paths and wrap surfaces
# (a block of its own: ``path:``, ``wrap:`` and ``axis_points:`` of a muscle; docs/FORMATS.md)

WRAP_SIZE_KEYS = {"cylinder": ("radius", "length"), "sphere": ("radius",), "ellipsoid": ("radii",),
                  "torus": ("inner", "outer")}


def parse_muscle_path(f: Fields):
    """The muscle's ``path`` (points: fixed, ``moving``, ``active``), ``wrap`` (surfaces) and
    ``axis_points`` → :class:`~axdf_cli.paths.PathSpec`."""
    from axdf_cli.paths import Moving, PathPoint, PathSpec, WrapSurface
    from axdf_cli.paths.wrap import METHODS, QUADRANTS

    seq = f.seq("path", required=True)
    if len(seq) < 2:
        raise InputError(f.vmark("path"), f"path has {len(seq)} point(s)", "at least 2 (origin and insertion)")
    if len(seq) > 64:
        raise InputError(f.vmark("path"), f"path has {len(seq)} points", "at most 64")
    points = []
    for k, (pv, pm) in enumerate(zip(seq, item_marks(seq, f.vmark("path")))):
        pf = Fields(pv, pm, "path point")
        bone = pf.name("bone", required=True)
        at = pf.vector("at", 3, default=(0.0, 0.0, 0.0))
        moving = None
        mv = pf.mapping("moving")
        if mv is not None:
            mf = Fields(mv, pf.vmark("moving"), "moving point")
            axes = []
            for ax in "xyz":
                a = mf.mapping(ax)
                if a is None:
                    axes.append(None)
                    continue
                af = Fields(a, mf.vmark(ax), f"moving {ax}")
                coord = af.name("coord", required=True)
                fn = parse_function(af.raw("function", required=True), af.vmark("function"))
                af.done()
                axes.append(Moving(coord, fn))
            mf.done()
            if not any(axes):
                raise InputError(pf.vmark("moving"), "moving point moves along no axis", "x, y and/or z: {coord, function}")
            moving = tuple(axes)
        active = None
        av = pf.mapping("active")
        if av is not None:
            if k in (0, len(seq) - 1):
                raise InputError(pf.kmark("active"), "the origin or insertion is conditional",
                                 "only interior path points may have `active`")
            af = Fields(av, pf.vmark("active"), "active range")
            coord = af.name("coord", required=True)
            lo, hi = af.vector("range", 2, required=True)
            if hi < lo:
                raise InputError(af.vmark("range"), f"range [{lo}, {hi}] is empty", "[low, high] with low <= high")
            af.done()
            active = (coord, lo, hi)
        pf.done()
        points.append(PathPoint(bone, at, moving, active, pf.vmark("bone")))
    wraps = []
    wseq = f.seq("wrap", default=[])
    names = set()
    for wv, wm in zip(wseq, item_marks(wseq, f.vmark("wrap"))):
        wf = Fields(wv, wm, "wrap surface")
        shape = wf.choice("shape", tuple(WRAP_SIZE_KEYS), required=True)
        name = wf.name("name", default=f"{shape}{len(wraps) + 1}")
        if name in names:
            raise InputError(wf.vmark("name"), f"wrap surface {name!r} named twice", "unique names within a muscle")
        names.add(name)
        bone = wf.name("bone", required=True)
        if shape == "ellipsoid":
            size = wf.vector("radii", 3, required=True, lo=0.0, lo_open=True)
        else:
            size = tuple(wf.number(key, required=True, lo=0.0, lo_open=True) for key in WRAP_SIZE_KEYS[shape])
        size = tuple(float(v) for v in size) + (0.0,) * (3 - len(size))
        for key in sorted({k for ks in WRAP_SIZE_KEYS.values() for k in ks} - set(WRAP_SIZE_KEYS[shape])):
            if wf.has(key):
                raise InputError(wf.kmark(key), f"{key!r} is not a size of a {shape}",
                                 f"a {shape} takes " + ", ".join(WRAP_SIZE_KEYS[shape]))
        at = wf.vector("at", 3, default=(0.0, 0.0, 0.0))
        orient = wf.vector("orient", 3, default=(0.0, 0.0, 0.0))
        quadrant = wf.choice("quadrant", tuple(QUADRANTS), default="all")
        method = wf.choice("method", tuple(METHODS), default="hybrid")
        rng = wf.vector("range", 2, default=(-1, -1))
        for v in rng:
            if not float(v).is_integer() or not (v == -1 or 1 <= v <= len(points)):
                raise InputError(wf.vmark("range"), f"range {list(rng)} lies outside the path ({len(points)} points)",
                                 f"1-based path point indices 1..{len(points)}, or -1 for the path's end")
        rng = (int(rng[0]), int(rng[1]))
        if rng[0] > 0 and rng[1] > 0 and rng[1] <= rng[0]:
            raise InputError(wf.vmark("range"), f"range {list(rng)} holds no segment", "first < last")
        active = wf.boolean("active", default=True)
        wf.done()
        wraps.append(WrapSurface(name, bone, shape, size, at, orient, quadrant, method, rng, active, wf.vmark("shape")))
    n = f.number("axis_points", default=0, lo=0, hi=64, integer=True)
    if n and n < 4:
        raise InputError(f.vmark("axis_points"), f"axis_points is {n}", "4..64 (or leave it out for the default)")
    return PathSpec(tuple(points), tuple(wraps), int(n))


def load_muscle_file(path: Path | str) -> list[MuscleSpec]:
    """One muscle (``muscle:``) or several heads (``muscles:`` list, optional ``group:``)."""
    path = Path(path)
    return muscles_from_document(load_yaml(path), path)


def parse_muscle_text(text: str, path: Path | str) -> list[MuscleSpec]:
    """The muscles of YAML text that will live at ``path`` (as :func:`load_muscle_file` reads it)."""
    from axdf_cli.yamlio import parse_yaml

    return muscles_from_document(parse_yaml(text, str(path)), Path(path))


def muscles_from_document(doc, path: Path) -> list[MuscleSpec]:
    top = Mark(str(path), 1, 1)
    if isinstance(doc, dict) and "muscles" in doc and "muscle" not in doc:
        f = Fields(doc, top, "multi-head muscle file", keys=("group", "muscles"))
        group = f.name("group", default=path.stem)
        seq = f.seq("muscles", required=True, min_len=1)
        f.done()
        return [_parse_muscle(v, m, str(path), group) for v, m in zip(seq, item_marks(seq, f.vmark("muscles")))]
    if not isinstance(doc, dict) or "muscle" not in doc:
        raise kind_error(doc, top, "not a muscle file", "a muscle file has `muscle: NAME` or `muscles: [...]`",
                         ("muscle", "muscles"))
    return [_parse_muscle(doc, top, str(path))]


# ----------------------------------------------------------------------------- poses


INTERPOLATIONS = ("linear", "step", "cubic")
POSE_KEYS = ("pose", "skeleton", "fps", "frames", "interpolation", "clamp_ranges", "keys", "activation")


@dataclass(frozen=True)
class Pose:
    name: str
    skeleton: Skeleton
    fps: float
    first: int
    last: int
    interpolation: str
    keys: dict  # coord -> ((frames...), (values...))
    activation: dict  # muscle -> ((frames...), (values...))
    activation_marks: dict  # muscle -> Mark (to report unknown muscles)
    source: str = ""
    skeleton_path: str = ""
    clamp_ranges: bool = False  # hold coordinates inside their skeleton ranges (else: warn)
    key_marks: dict = field(default_factory=dict)  # coord -> Mark of its first key (for range warnings)

    @property
    def frames(self) -> np.ndarray:
        return np.arange(self.first, self.last + 1)


def _frame_key(frame, where: Mark, what: str, first: int, last: int) -> int:
    f = check_number(frame, where, what, 0, 10_000_000, integer=True)
    if not first <= f <= last:
        raise InputError(where, f"{what} {f} is outside the pose's frames [{first}, {last}]",
                         f"keys at frames {first}..{last} (widen `frames` to key more)")
    return int(f)


#: Motion files that are not poses → the command that turns them into one.
MOTION_IMPORTS = {".bvh": "axdf import bvh FILE.bvh --out DIR",
                  ".mot": "axdf import osim MODEL.osim --motion FILE --out DIR",
                  ".sto": "axdf import osim MODEL.osim --motion FILE --out DIR"}


def load_pose(path: Path | str, policy: RefPolicy | None = None) -> Pose:
    policy = policy or RefPolicy()
    path = Path(path)
    if path.suffix.lower() in MOTION_IMPORTS:
        raise InputError(Mark(str(path)), f"a {path.suffix} motion is not an axdf pose",
                         f"import it first ({MOTION_IMPORTS[path.suffix.lower()]}) and pass the pose YAML it writes")
    doc = load_yaml(path)
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "pose file", keys=POSE_KEYS)
    name = f.name("pose", required=True)
    skel_ref = f.string("skeleton", required=True)
    skel_path = policy.resolve(path, skel_ref, f.vmark("skeleton"))
    if not skel_path.is_file():
        raise InputError(f.vmark("skeleton"), f"skeleton file {skel_ref!r} not found",
                         "a path relative to the pose file")
    skel = load_skeleton(skel_path, policy)
    fps = f.number("fps", default=30.0, lo=0.0, hi=100000.0, lo_open=True)
    fr = f.raw("frames", required=True)
    first, last = check_vector(fr, f.vmark("frames"), "frames", 2, 0, 10_000_000)
    if not (float(first).is_integer() and float(last).is_integer()) or last < first:
        raise InputError(f.vmark("frames"), f"frames is {list(fr)}", "[first, last] integers with first <= last")
    first, last = int(first), int(last)
    interp = f.choice("interpolation", INTERPOLATIONS, default="linear")
    clamp = f.boolean("clamp_ranges", default=False)
    keys_map = f.mapping("keys", required=True)
    cidx = skel.coord_index
    series: dict[str, list] = {}
    key_marks: dict[str, Mark] = {}
    for frame, values in keys_map.items():
        fnum = _frame_key(frame, keys_map.key_mark(frame), "key frame", first, last)
        vm = keys_map.value_mark(frame)
        if not isinstance(values, dict):
            raise InputError(vm, f"key {frame} is not a mapping", "keys: {FRAME: {COORD: value}}")
        for coord, val in values.items():
            cm = values.key_mark(coord) if isinstance(values, YMap) else vm
            if coord not in cidx:
                raise InputError(cm, f"unknown coordinate {coord!r}",
                                 f"{did_you_mean(coord, cidx)}coordinates of skeleton {skel.name}: {', '.join(cidx)}")
            x = check_number(val, values.value_mark(coord) if isinstance(values, YMap) else vm, coord)
            series.setdefault(coord, []).append((fnum, float(x)))
            key_marks.setdefault(coord, cm)
    act_map = f.mapping("activation", default=None)
    activation, act_marks = {}, {}
    if act_map is not None:
        for muscle, curve in act_map.items():
            mm = act_map.key_mark(muscle)
            check_name(muscle, mm, "muscle name")
            if not isinstance(curve, dict):
                raise InputError(act_map.value_mark(muscle), f"activation of {muscle} is not a mapping",
                                 "activation: {MUSCLE: {FRAME: 0..1}}")
            pts = []
            for frame, val in curve.items():
                fnum = _frame_key(frame, curve.key_mark(frame), "activation frame", first, last)
                pts.append((fnum, float(check_number(val, curve.value_mark(frame), "activation", 0.0, 1.0))))
            pts.sort()
            activation[muscle] = (tuple(p[0] for p in pts), tuple(p[1] for p in pts))
            act_marks[muscle] = mm
    f.done()
    keys = {}
    for coord, pts in series.items():
        pts.sort()
        keys[coord] = (tuple(p[0] for p in pts), tuple(p[1] for p in pts))
    return Pose(name, skel, float(fps), first, last, interp, keys, activation, act_marks, str(path), str(skel_path),
                clamp, key_marks)


# ----------------------------------------------------------------------------- jobs

JOB_KEYS = ("muscles", "pose", "out", "format", "frames", "render")


@dataclass(frozen=True)
class Job:
    source: str
    muscles: tuple  # ((Path, Mark), ...) files, folders or globs, resolved against the job's folder
    pose: tuple | None  # (Path, Mark)
    out: Path | None  # resolved against the job's folder
    format: tuple | None  # the formats, parsed (axdf_cli.formats.parse_formats), or None
    frames: object  # raw frames spec or None
    frames_mark: Mark | None
    render: object  # RenderSettings (disabled when the job has no `render:`)
    policy: RefPolicy = RefPolicy()  # the policy the job was read with (its muscles are read with it)


def load_job(path: Path | str, policy: RefPolicy | None = None) -> Job:
    from axdf_cli.formats import parse_formats
    from axdf_cli.render.settings import parse_render_settings

    policy = policy or RefPolicy()
    path = Path(path)
    doc = load_yaml(path)
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "job file", keys=JOB_KEYS)
    raw = f.raw("muscles", required=True)
    entries = [raw] if isinstance(raw, str) else raw
    if not isinstance(entries, list) or not entries:
        raise InputError(f.vmark("muscles"), "muscles is empty or not a list", "a path, folder or glob, or a list of them")
    marks = item_marks(entries, f.vmark("muscles")) if isinstance(raw, list) else [f.vmark("muscles")]
    muscles = []
    for e, m in zip(entries, marks):
        if not isinstance(e, str) or not e:
            raise InputError(m, f"muscle path is {e!r}", "a path, folder or glob relative to the job file")
        muscles.append((policy.resolve(path, e, m), m))
    pose_ref = f.string("pose", required=True)
    pose = (policy.resolve(path, pose_ref, f.vmark("pose")), f.vmark("pose"))
    out = f.string("out", default=None)
    if out is not None:
        out = Path(os.path.normpath(policy.resolve(path, out, f.vmark("out"), "out")))
    fmt = parse_formats(f.raw("format"), f.vmark("format")) if f.has("format") else None
    frames = f.raw("frames")
    frames_mark = f.vmark("frames") if frames is not None else None
    render = parse_render_settings(f.raw("render"), f.vmark("render") if f.has("render") else top)
    f.done()
    return Job(str(path), tuple(muscles), pose, out, fmt, frames, frames_mark, render, policy)


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
            policy.check(h, mark, base, "muscle file")
        out.extend((h, mark) for h in hits)
    seen, uniq = set(), []
    for p, _ in out:
        k = str(real_path(p))
        if k not in seen:
            seen.add(k)
            uniq.append(p)
    return uniq


# ----------------------------------------------------------------------------- file kinds

#: The keys that tell a file's kind (see :func:`detect_kind`).
KIND_KEYS = ("skeleton", "bones", "pose", "keys", "muscle", "muscles", "transfer")
KINDS_ALLOWED = ("a skeleton (skeleton:, bones:), pose (pose:, keys:), muscle (muscle:), job (muscles:, pose:) "
                 "or transfer map (transfer:, bones:)")


def detect_kind(doc) -> str | None:
    if not isinstance(doc, dict):
        return None
    if "transfer" in doc:
        return "transfer"
    if "skeleton" in doc and "bones" in doc:
        return "skeleton"
    if "pose" in doc and "keys" in doc:
        return "pose"
    if "muscle" in doc or ("muscles" in doc and "pose" not in doc):
        return "muscle"
    if "muscles" in doc and "pose" in doc:
        return "job"
    return None


def kind_error(doc, top: Mark, problem: str = "unknown kind of file", allowed: str = KINDS_ALLOWED,
               kind_keys=KIND_KEYS) -> InputError:
    """The error for a file whose kind cannot be told: a top-level key close to a kind key
    (``muscel:``) is named, with its position and the key it probably means."""
    if isinstance(doc, dict):
        for key in doc:
            if key in KIND_KEYS:
                continue
            hint = did_you_mean(key, kind_keys)
            if hint:
                where = doc.key_mark(key) if isinstance(doc, YMap) else top
                return InputError(where, f"{problem}: unknown key {key!r}", f"{hint}{allowed}")
    return InputError(mark_of(doc, top), problem, allowed)
