"""YAML files → small frozen specs. Every check reports ``FILE:LINE:COL: what; allowed``.

File kinds: skeleton (``skeleton:``), pose (``pose:``), muscle (``muscle:`` or ``muscles:``)
and job (``muscles:`` + ``pose:`` + ...). See docs/FORMATS.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.skeleton import (Bone, Constant, Coordinate, Dof, Linear, Multiplier, Polynomial,
                               Skeleton, Spline)
from axdf_cli.yamlio import Fields, YMap, check_name, check_number, check_vector, item_marks, load_yaml, mark_of

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
        f = Fields(arg, at, "spline")
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
        f = Fields(arg, at, "multiplier")
        scale = f.number("scale", required=True)
        inner = parse_function(f.raw("function", required=True), f.vmark("function"), depth + 1)
        f.done()
        return Multiplier(scale, inner)
    raise InputError(value.key_mark(kind) if isinstance(value, YMap) else where,
                     f"unknown function {kind!r}", allowed)


# ----------------------------------------------------------------------------- skeleton


def load_skeleton(path: Path | str) -> Skeleton:
    path = Path(path)
    doc = load_yaml(path)
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "skeleton file")
    name = f.name("skeleton", required=True)
    bones_seq = f.seq("bones", required=True, min_len=1)
    coords_map = f.mapping("coordinates", default=None)
    f.done()

    declared: dict[str, Coordinate] = {}
    if coords_map is not None:
        for cname, cval in coords_map.items():
            km = coords_map.key_mark(cname)
            check_name(cname, km, "coordinate name")
            cf = Fields(cval, coords_map.value_mark(cname), f"coordinate {cname}")
            ctype = cf.choice("type", DOF_TYPES, required=True)
            default = cf.number("default", default=0.0)
            rng = cf.vector("range", 2, default=None)
            cf.done()
            declared[cname] = Coordinate(cname, ctype, float(default), rng)

    bones: list[Bone] = []
    index: dict[str, int] = {}
    used: dict[str, str] = {}  # coordinate -> type inferred from direct use
    order: list[str] = list(declared)
    for bval, bm in zip(bones_seq, item_marks(bones_seq, top)):
        bf = Fields(bval, bm, "bone")
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
                             f"parents come before children; defined so far: {', '.join(index) or 'none'}")
        else:
            parent = index[parent_name]
        offset = bf.vector("offset", 3, default=(0.0, 0.0, 0.0))
        orient = bf.vector("orient", 3, default=(0.0, 0.0, 0.0))
        post_offset = bf.vector("post_offset", 3, default=(0.0, 0.0, 0.0))
        post_orient = bf.vector("post_orient", 3, default=(0.0, 0.0, 0.0))
        mesh = bf.string("mesh", default=None)
        if mesh is not None:
            mesh = str(resolve_ref(path, mesh, bf.vmark("mesh")))
        dofs = []
        dof_seq = bf.seq("dofs", default=[])
        for dval, dm in zip(dof_seq, item_marks(dof_seq, bf.vmark("dofs"))):
            df = Fields(dval, dm, "dof")
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
            rng = df.vector("range", 2, default=None)
            df.done()
            if coord is not None:
                if fn is None:
                    if coord in used and used[coord] != dtype:
                        raise InputError(df.vmark("coord"), f"coordinate {coord!r} drives both a rotation and a translation",
                                         "one type per coordinate, or a function")
                    used[coord] = dtype
                    if coord in declared and declared[coord].type != dtype:
                        raise InputError(df.vmark("coord"), f"coordinate {coord!r} is declared {declared[coord].type}",
                                         f"use it on a {declared[coord].type} dof or through a function")
                    if rng is not None and coord not in declared:
                        declared[coord] = Coordinate(coord, dtype, 0.0, rng)
                if coord not in order:
                    order.append(coord)
            dofs.append(Dof(dtype, axis, coord, fn))
        bf.done()
        index[bname] = len(bones)
        bones.append(Bone(bname, parent, offset, orient, tuple(dofs), post_offset, post_orient, mesh))

    coords = []
    for c in order:
        if c in declared:
            coords.append(declared[c])
        else:
            coords.append(Coordinate(c, used.get(c, "rotation"), 0.0, None))
    return Skeleton(name, tuple(bones), tuple(coords), str(path))


class RefPolicy:
    """Where paths written inside YAML files may point.

    References are resolved relative to the file that holds them. Absolute paths, and paths
    whose resolved location is outside every root (the current folder and the folder of the
    file given on the command line), are refused unless ``allow_outside`` is set
    (``--allow-outside``).
    """

    def __init__(self, roots=(), allow_outside: bool = False):
        self.roots = [Path(r).resolve() for r in roots] or [Path.cwd().resolve()]
        self.allow_outside = allow_outside


POLICY = RefPolicy()


def set_ref_policy(roots, allow_outside: bool) -> None:
    global POLICY
    POLICY = RefPolicy(roots, allow_outside)


def resolve_ref(base_file: Path, ref: str, where: Mark) -> Path:
    """Resolve a path written in a YAML file, relative to that file's folder."""
    if "\x00" in ref:
        raise InputError(where, "path contains a NUL character", "plain relative paths")
    p = Path(ref)
    if POLICY.allow_outside:
        return (base_file.parent / p) if not p.is_absolute() else p
    if p.is_absolute():
        raise InputError(where, f"absolute path {ref!r}",
                         "paths relative to the file that names them (or pass --allow-outside)")
    full = (base_file.parent / p).resolve()
    if not any(full == r or r in full.parents for r in POLICY.roots):
        raise InputError(where, f"path {ref!r} leaves the project folder tree",
                         f"paths inside {', '.join(str(r) for r in POLICY.roots)} (or pass --allow-outside)")
    return base_file.parent / p


def finite_or_raise(arr: np.ndarray, where: Mark, what: str) -> None:
    if not np.all(np.isfinite(arr)):
        raise InputError(where, f"{what} is not finite", "finite numbers only")


__all__ = ["load_skeleton", "parse_function", "math"]
