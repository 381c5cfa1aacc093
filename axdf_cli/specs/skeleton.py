"""Skeleton files (``skeleton:``, ``bones:``) → a frozen :class:`~axdf_cli.model.skeleton.Skeleton`;
the coordinate functions (constant, linear, polynomial, spline, multiplier) bones' DOFs may follow.
Every check reports ``FILE:LINE:COL: what; allowed`` (docs/FORMATS.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.model.skeleton import (Bone, Constant, Coordinate, Dof, Linear, Multiplier, Polynomial,
                                     Skeleton, Spline)
from axdf_cli.specs.refs import RefPolicy
from axdf_cli.fileio.yamlio import (Fields, YMap, check_name, check_number, check_vector, did_you_mean, item_marks,
                                    load_yaml, mark_of)

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
    from axdf_cli.fileio.yamlio import parse_yaml

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
    follows: dict[str, tuple[str, object, Mark, Mark]] = {}  # coupled coordinate -> (leader, fn, marks)
    if coords_map is not None:
        for cname, cval in coords_map.items():
            km = coords_map.key_mark(cname)
            check_name(cname, km, "coordinate name")
            cf = Fields(cval, coords_map.value_mark(cname), f"coordinate {cname}",
                        keys=("type", "default", "range", "follows"))
            ctype = cf.choice("type", DOF_TYPES, required=True)
            default = cf.number("default", default=0.0)
            rng = _check_range(cf.vector("range", 2, default=None), cf.vmark("range"), f"coordinate {cname}")
            if cf.has("follows"):
                for key in ("default", "range"):
                    if cf.has(key):
                        raise InputError(cf.kmark(key), f"coupled coordinate {cname!r} has a {key}",
                                         "a coordinate with `follows` takes its value from the coordinate it "
                                         "follows: give only type and follows")
                ff = Fields(cf.raw("follows"), cf.vmark("follows"), f"follows of {cname}", keys=("coord", "function"))
                leader = ff.name("coord", required=True)
                fn = parse_function(ff.raw("function", required=True), ff.vmark("function"))
                ff.done()
                if leader == cname:
                    raise InputError(ff.vmark("coord"), f"coordinate {cname!r} follows itself",
                                     "another coordinate of the skeleton")
                follows[cname] = (leader, fn, ff.vmark("coord"), km)
            cf.done()
            declared[cname] = Coordinate(cname, ctype, float(default), None)
            if rng is not None:
                ranges.setdefault(cname, []).append((rng, cf.vmark("range")))

    bones: list[Bone] = []
    index: dict[str, int] = {}
    used: dict[str, str] = {}  # coordinate -> type inferred from direct use
    order: dict[str, None] = dict.fromkeys(declared)  # coordinates in order of appearance (a set: linear time)
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
                if coord in follows:
                    raise InputError(df.vmark("range"), f"range on a dof of coupled coordinate {coord!r}",
                                     f"a coupled coordinate has no range of its own: bound {follows[coord][0]!r}, "
                                     "the coordinate it follows")
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
                order.setdefault(coord)
            dofs.append(Dof(dtype, axis, coord, fn))
        bf.done()
        index[bname] = len(bones)
        bones.append(Bone(bname, parent, offset, orient, tuple(dofs), post_offset, post_orient, mesh))

    for cname, (leader, _, at, _) in follows.items():
        if leader not in order:
            raise InputError(at, f"coordinate {cname!r} follows unknown coordinate {leader!r}",
                             f"{did_you_mean(leader, order)}coordinates of the skeleton: {', '.join(order)}")
    _check_no_cycle(follows)
    coords = []
    for c in order:
        base = declared.get(c) or Coordinate(c, used.get(c, "rotation"), 0.0, None)
        leader, fn = follows[c][:2] if c in follows else (None, None)
        coords.append(Coordinate(base.name, base.type, base.default, _joint_range(c, ranges.get(c, [])), leader, fn))
    return Skeleton(name, tuple(bones), tuple(coords), str(path))


def _check_no_cycle(follows: dict) -> None:
    """Coupled coordinates must end at a free coordinate: ``a`` follows ``b`` follows ``a`` is
    refused at the first coordinate of the cycle."""
    for start in follows:
        seen = [start]
        c = follows[start][0]
        while c in follows:
            if c == start:
                raise InputError(follows[start][2], f"coupled coordinates follow each other in a cycle: "
                                 f"{' -> '.join(seen + [start])}", "each chain of `follows` ends at a free coordinate")
            if c in seen:
                break  # a cycle not through start: reported from its own members
            seen.append(c)
            c = follows[c][0]


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
