"""A MuJoCo model (MJCF XML) → plain data: bodies, joints, meshes, sites, wrap geoms, spatial
tendons, joint couplings and muscle actuators, every item with its ``FILE:LINE:COL``.

What is read, as MuJoCo reads it (https://mujoco.readthedocs.io, "XML Reference"):

- ``<include file>``: the included file's root children replace the element (paths relative to
  the main model's folder, then the including file's); an include of a file already being read
  is refused.
- ``<compiler angle meshdir assetdir eulerseq autolimits>``: ``angle`` (default ``degree``)
  applies to joint ranges and refs, ``euler`` and ``axisangle``; ``meshdir`` (else ``assetdir``)
  is relative to the model's folder.
- ``<default>`` classes (nested; the top one is ``main``): an element takes the attributes of
  its ``class``, else of the nearest ``childclass`` of its bodies and frames, else ``main``,
  each class inheriting its parent's; its own attributes win.
- Frames: a body's, geom's or site's ``pos`` with one of ``quat`` (w x y z), ``axisangle``,
  ``euler`` (``eulerseq``: lower case rotates with the frame, upper case about fixed axes),
  ``xyaxes``, ``zaxis``; a geom's ``fromto`` (capsule, cylinder); ``<frame>`` elements (their
  transform applies to what they hold, their ``childclass`` too).
- Joints: ``hinge`` (default), ``slide``, ``ball``, ``free`` (``<freejoint/>`` too) with
  ``pos``, ``axis``, ``ref``, ``range`` and ``limited`` (``auto`` with ``autolimits``: limited
  when a range is given). A free joint must be its body's only joint, in a child of the world.
- Geoms: ``mesh`` geoms (``<asset><mesh file scale refpos refquat>``, STL/OBJ/PLY read by
  trimesh) become bone meshes; ``sphere`` and ``cylinder`` geoms named by a tendon are its wrap
  surfaces (radius ``size[0]``; MuJoCo's cylinder is infinite for wrapping).
- ``<tendon><spatial>``: ``<site>``, ``<geom geom sidesite>`` and ``<pulley>``; ``<fixed>``
  tendons are listed as not imported.
- ``<equality><joint joint1 joint2 polycoef active>``: joint1 − ref1 = Σ c_i (joint2 − ref2)^i.
  Other equalities are listed as not imported.
- Actuators whose gain is MuJoCo's muscle (``<muscle>``, or ``<general gaintype="muscle">``)
  on a tendon: force, scale, range, lengthrange and gear; other actuators are listed.

Units stay MuJoCo's here (radians, metres, quaternions w x y z); the importer converts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.importers.xmltree import Node, parse_xml

JOINT_TYPES = ("hinge", "slide", "ball", "free")
#: Geom types a spatial tendon may wrap over (MuJoCo allows these two only).
WRAP_GEOMS = ("sphere", "cylinder")
#: MuJoCo's defaults for a <muscle>: range, force, scale (the rest only shapes force).
MUSCLE_DEFAULTS = {"range": (0.75, 1.05), "force": -1.0, "scale": 200.0, "lmin": 0.5, "lmax": 1.6}
#: Elements of <default> whose attributes are kept per class (actuator shortcuts share one).
ACTUATOR_TAGS = ("general", "motor", "position", "velocity", "intvelocity", "damper", "cylinder", "muscle",
                 "adhesion", "plugin")


@dataclass
class Joint:
    name: str
    type: str  # hinge | slide | ball | free
    body: str
    pos: np.ndarray  # (3,) in the body frame
    axis: np.ndarray  # (3,) unit, in the body frame
    ref: float  # qpos0 of a hinge (rad) or slide (m)
    range: tuple[float, float] | None  # radians / metres, None when not limited
    mark: Mark


@dataclass
class Geom:
    name: str | None
    type: str
    body: str
    size: np.ndarray  # (3,)
    pos: np.ndarray  # (3,) in the body frame
    quat: np.ndarray  # (4,) w x y z, in the body frame
    mesh: str | None
    mark: Mark


@dataclass
class Site:
    name: str
    body: str
    pos: np.ndarray
    mark: Mark


@dataclass
class Body:
    name: str
    parent: str | None  # None: a child of the world
    pos: np.ndarray
    quat: np.ndarray
    joints: list[Joint] = field(default_factory=list)
    geoms: list[Geom] = field(default_factory=list)
    mark: Mark = Mark("")


@dataclass
class MeshAsset:
    name: str
    file: Path
    scale: np.ndarray
    refpos: np.ndarray
    refquat: np.ndarray
    mark: Mark


@dataclass
class TendonItem:
    kind: str  # site | geom | pulley
    name: str | None  # site or geom name
    sidesite: str | None
    mark: Mark


@dataclass
class Tendon:
    name: str
    items: list[TendonItem]
    mark: Mark


@dataclass
class Coupling:
    """joint1 − ref1 = Σ polycoef[i] (joint2 − ref2)^i (joint2 None: joint1 − ref1 = polycoef[0])."""

    name: str | None
    joint1: str
    joint2: str | None
    polycoef: tuple[float, ...]
    mark: Mark


@dataclass
class Muscle:
    name: str
    tendon: str
    force: float  # N; < 0: MuJoCo's scale / acc0 (not known without compiling)
    scale: float
    range: tuple[float, float]  # operating range of the normalized fibre length
    lengthrange: tuple[float, float] | None  # actuator length range (m); None: MuJoCo computes it
    gear: float
    kind: str  # the element: muscle | general
    mark: Mark


@dataclass
class MjcfModel:
    name: str
    source: str
    bodies: list[Body]  # parents before children (document order)
    joints: dict[str, Joint]
    sites: dict[str, Site]
    geoms: dict[str, Geom]
    meshes: dict[str, MeshAsset]
    tendons: dict[str, Tendon]
    couplings: list[Coupling]
    muscles: list[Muscle]
    ignored: list[dict] = field(default_factory=list)  # {kind, name, where, why}
    includes: list[Path] = field(default_factory=list)  # the files <include> read, in reading order


# ----------------------------------------------------------------------------- numbers


def _floats(node: Node, key: str, attrs: dict, n: int | tuple[int, ...] | None = None, default=None):
    """The attribute ``key`` (from ``attrs``: the element's with its class defaults) as floats."""
    raw = attrs.get(key)
    if raw is None:
        return default
    try:
        v = np.array([float(x) for x in raw.split()], dtype=np.float64)
    except ValueError:
        raise InputError(node.mark, f"{node.tag} {key}={raw!r} is not a list of numbers",
                         "numbers separated by spaces") from None
    counts = (n,) if isinstance(n, int) else n
    if counts is not None and len(v) not in counts:
        raise InputError(node.mark, f"{node.tag} {key}={raw!r} has {len(v)} number(s)",
                         f"{' or '.join(str(c) for c in counts)} numbers")
    if not np.all(np.isfinite(v)) or np.any(np.abs(v) > 1e9):
        raise InputError(node.mark, f"{node.tag} {key}={raw!r} holds a number that is not finite or beyond ±1e9",
                         "finite numbers within ±1e9")
    return v


def _bool(node: Node, key: str, attrs: dict, default: str) -> str:
    v = attrs.get(key, default)
    if v not in ("true", "false", "auto"):
        raise InputError(node.mark, f"{node.tag} {key}={v!r}", "true, false or auto")
    return v


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w x y z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of a unit quaternion (w x y z)."""
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2)], math.sin(angle / 2) * a])


def _from_matrix(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(m).as_quat()
    return np.array([w, x, y, z])


class Reader:
    """Reads one MJCF model (see the module doc); :meth:`model` returns the :class:`MjcfModel`."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.root_dir = self.path.parent
        self.angle = "degree"
        self.eulerseq = "xyz"
        self.autolimits = True
        self.meshdir: Path | None = None
        self.assetdir: Path | None = None
        self.defaults: dict[str, dict[str, dict]] = {}  # class -> tag -> attributes (inherited)
        self.ignored: list[dict] = []
        self.includes: list[Path] = []
        self._parsed: dict[Path, tuple[Node, frozenset]] = {}  # see _expand
        self._reached: list[Path] = []  # the files expansions have reached, in order

    # ------------------------------------------------------------------ documents
    def load(self) -> Node:
        root = parse_xml(self.path)
        if root.tag != "mujoco":
            raise InputError(root.mark, f"root element <{root.tag}>", "an MJCF model: <mujoco>")
        self._expand(root, [self.path.resolve()])
        return root

    def _expand(self, node: Node, stack: list[Path]) -> None:
        """Replace every <include file> below ``node`` by the included file's root children.

        Each file is parsed and expanded once (``self._parsed``: its resolved path → its
        expanded root and every file its expansion reaches): a diamond of includes (files
        included by several others) costs one parse per file, not one per path to it. A cached
        file whose expansion reaches a file being expanded now is parsed afresh, so the cycle
        is refused at the include that closes it, as without the cache."""
        out = []
        for c in node.children:
            if c.tag != "include":
                self._expand(c, stack)
                out.append(c)
                continue
            fname = c.attrib.get("file")
            if not fname:
                raise InputError(c.mark, "<include> without file", "<include file=\"PATH\"/>")
            cands = [self.root_dir / fname, Path(c.mark.file).parent / fname]
            target = next((p for p in cands if p.is_file()), None)
            if target is None:
                raise InputError(c.mark, f"included file {fname!r} not found",
                                 "a path relative to the model's folder")
            key = target.resolve()
            if key in stack:
                raise InputError(c.mark, f"{fname!r} includes itself", "includes without a cycle")
            cached = self._parsed.get(key)
            if cached is None or not cached[1].isdisjoint(stack):
                sub = parse_xml(target)
                if cached is None:
                    self.includes.append(target)
                before = len(self._reached)
                self._reached.append(key)
                self._expand(sub, stack + [key])
                cached = (sub, frozenset(self._reached[before:]))
                self._parsed[key] = cached
            else:
                self._reached.extend(cached[1])
            out.extend(cached[0].children)
        node.children = out

    # ------------------------------------------------------------------ defaults
    def _read_defaults(self, node: Node, parent: str | None) -> None:
        """One <default> and its nested classes, as MuJoCo reads them (xml_native_reader.cc,
        ``mjXReader::Default``): every top-level <default> of the model, in each file an
        <include> brings, is class ``main`` (a ``class`` other than main is refused) and adds
        its attributes to it, later ones over earlier ones; a nested class is a copy of its
        parent as it stands then, with its own attributes over it, and its name must be new."""
        top = parent is None
        cls = node.attrib.get("class", "main" if top else None)
        if top and cls != "main":
            raise InputError(node.mark, f"top-level default class {cls!r}", "main (MuJoCo's top-level class "
                             "cannot be renamed)")
        if not cls:
            raise InputError(node.mark, "a nested <default> without class", "<default class=\"NAME\">")
        if not top and cls in self.defaults:
            raise InputError(node.mark, f"default class {cls!r} defined twice", "unique class names")
        source = "main" if top else parent
        inherited = {t: dict(a) for t, a in self.defaults.get(source, {}).items()}
        for c in node.children:
            if c.tag == "default":
                continue
            tag = "actuator" if c.tag in ACTUATOR_TAGS else c.tag
            d = inherited.setdefault(tag, {})
            d.update(c.attrib)
            if tag == "actuator":
                d["__shortcut__"] = c.tag
        self.defaults[cls] = inherited
        for c in node.children:
            if c.tag == "default":
                self._read_defaults(c, cls)

    def attrs(self, node: Node, cls: str | None, tag: str | None = None) -> dict:
        """The element's attributes over its class's defaults."""
        name = node.attrib.get("class", cls or "main")
        if name not in self.defaults and name != "main":
            raise InputError(node.mark, f"unknown default class {name!r}",
                             "classes: " + ", ".join(sorted(self.defaults)) if self.defaults else "a <default> class")
        base = dict(self.defaults.get(name, {}).get(tag or node.tag, {}))
        base.update(node.attrib)
        return base

    # ------------------------------------------------------------------ frames
    def orientation(self, node: Node, a: dict) -> np.ndarray:
        """The element's orientation (w x y z) from quat, axisangle, euler, xyaxes or zaxis."""
        a = {**a, **node.attrib}
        given = [k for k in ("quat", "axisangle", "euler", "xyaxes", "zaxis") if k in node.attrib]
        if len(given) > 1:
            raise InputError(node.mark, f"{node.tag} has {' and '.join(given)}", "one orientation attribute")
        key = given[0] if given else next((k for k in ("quat", "axisangle", "euler", "xyaxes", "zaxis") if k in a), None)
        if key is None:
            return np.array([1.0, 0.0, 0.0, 0.0])
        unit = math.pi / 180.0 if self.angle == "degree" else 1.0
        if key == "quat":
            q = _floats(node, "quat", a, 4)
            n = np.linalg.norm(q)
            if n < 1e-12:
                raise InputError(node.mark, f"{node.tag} quat is zero", "a non-zero quaternion (w x y z)")
            return q / n
        if key == "axisangle":
            v = _floats(node, "axisangle", a, 4)
            if np.linalg.norm(v[:3]) < 1e-12:
                raise InputError(node.mark, f"{node.tag} axisangle has a zero axis", "a non-zero axis and an angle")
            return _axis_angle(v[:3], v[3] * unit)
        if key == "euler":
            v = _floats(node, "euler", a, 3) * unit
            q = np.array([1.0, 0.0, 0.0, 0.0])
            for ch, ang in zip(self.eulerseq, v):
                r = _axis_angle(np.eye(3)["xyz".index(ch.lower())], ang)
                q = quat_mul(q, r) if ch.islower() else quat_mul(r, q)
            return q
        if key == "xyaxes":
            v = _floats(node, "xyaxes", a, 6)
            x = v[:3]
            y = v[3:] - np.dot(v[3:], x) / max(np.dot(x, x), 1e-300) * x
            if np.linalg.norm(x) < 1e-12 or np.linalg.norm(y) < 1e-12:
                raise InputError(node.mark, f"{node.tag} xyaxes are parallel or zero", "two independent axes")
            x, y = x / np.linalg.norm(x), y / np.linalg.norm(y)
            return _from_matrix(np.stack([x, y, np.cross(x, y)], axis=1))
        v = _floats(node, "zaxis", a, 3)
        n = np.linalg.norm(v)
        if n < 1e-12:
            raise InputError(node.mark, f"{node.tag} zaxis is zero", "a non-zero axis")
        z = v / n
        c = np.cross([0.0, 0.0, 1.0], z)
        s = np.linalg.norm(c)
        if s < 1e-12:
            return np.array([1.0, 0.0, 0.0, 0.0]) if z[2] > 0 else np.array([0.0, 1.0, 0.0, 0.0])
        return _axis_angle(c, math.atan2(s, z[2]))

    # ------------------------------------------------------------------ the model
    def model(self) -> MjcfModel:
        root = self.load()
        for c in root.children:
            if c.tag == "compiler":
                if "angle" in c.attrib:
                    if c.attrib["angle"] not in ("degree", "radian"):
                        raise InputError(c.mark, f"compiler angle={c.attrib['angle']!r}", "degree or radian")
                    self.angle = c.attrib["angle"]
                if "eulerseq" in c.attrib:
                    seq = c.attrib["eulerseq"]
                    if len(seq) != 3 or any(ch not in "xyzXYZ" for ch in seq):
                        raise InputError(c.mark, f"compiler eulerseq={seq!r}", "three of x y z X Y Z")
                    self.eulerseq = seq
                if "autolimits" in c.attrib:
                    self.autolimits = _bool(c, "autolimits", c.attrib, "true") == "true"
                for key in ("meshdir", "assetdir"):
                    if key in c.attrib:
                        setattr(self, key, self.root_dir / c.attrib[key])
        for c in root.children:
            if c.tag == "default":
                self._read_defaults(c, None)
        self.defaults.setdefault("main", {})
        meshes: dict[str, MeshAsset] = {}
        for c in root.children:
            if c.tag == "asset":
                for m in c.children:
                    if m.tag == "mesh":
                        mesh = self._mesh(m)
                        if mesh.name in meshes:
                            raise InputError(m.mark, f"mesh {mesh.name!r} defined twice", "unique mesh names")
                        meshes[mesh.name] = mesh
        self.bodies: list[Body] = []
        self._body_by_name: dict[str, Body] = {}
        self.joints: dict[str, Joint] = {}
        self.sites: dict[str, Site] = {}
        self.geoms: dict[str, Geom] = {}
        self.unnamed = 0
        for c in root.children:
            if c.tag == "worldbody":
                self._children(c, None, np.zeros(3), np.array([1.0, 0, 0, 0]), "main")
        tendons = {}
        couplings = []
        muscles = []
        for c in root.children:
            if c.tag == "tendon":
                for t in c.children:
                    if t.tag == "spatial":
                        td = self._tendon(t)
                        if td.name in tendons:
                            raise InputError(t.mark, f"tendon {td.name!r} defined twice", "unique tendon names")
                        tendons[td.name] = td
                    elif t.tag == "fixed":
                        self._ignore("fixed tendon", t, "a fixed tendon is a sum of joint values, not a path")
            elif c.tag == "equality":
                for e in c.children:
                    if e.tag == "joint":
                        cp = self._coupling(e)
                        if cp is not None:
                            couplings.append(cp)
                    else:
                        self._ignore(f"{e.tag} equality", e, "only joint couplings move the skeleton")
        for c in root.children:
            if c.tag == "actuator":
                for a in c.children:
                    mu = self._actuator(a, tendons)
                    if mu is not None:
                        muscles.append(mu)
        return MjcfModel(root.attrib.get("model", self.path.stem), str(self.path), self.bodies, self.joints,
                         self.sites, self.geoms, meshes, tendons, couplings, muscles, self.ignored, self.includes)

    def _ignore(self, kind: str, node: Node, why: str) -> None:
        self.ignored.append({"kind": kind, "name": node.attrib.get("name", ""), "where": str(node.mark), "why": why})

    def _mesh(self, m: Node) -> MeshAsset:
        a = self.attrs(m, m.attrib.get("class"), "mesh")
        f = a.get("file")
        if not f:
            raise InputError(m.mark, "mesh without file", "<mesh file=\"PATH\"/> (meshes given by vertices are not read)")
        base = self.meshdir or self.assetdir or self.root_dir
        name = a.get("name") or Path(f).stem
        scale = _floats(m, "scale", a, 3, np.ones(3))
        if np.any(scale == 0):
            raise InputError(m.mark, f"mesh {name!r} scale has a zero", "non-zero scale factors")
        refpos = _floats(m, "refpos", a, 3, np.zeros(3))
        refquat = _floats(m, "refquat", a, 4, np.array([1.0, 0, 0, 0]))
        if np.linalg.norm(refquat) < 1e-12:
            raise InputError(m.mark, f"mesh {name!r} refquat is zero", "a non-zero quaternion (w x y z)")
        return MeshAsset(name, base / f, scale, refpos, refquat / np.linalg.norm(refquat), m.mark)

    def _children(self, node: Node, body: str | None, fpos: np.ndarray, fquat: np.ndarray, cls: str) -> None:
        """Elements under the world, a body or a frame. ``fpos``/``fquat``: the transform of the
        enclosing <frame>s in the body; ``cls``: the childclass in force."""
        rot = quat_matrix(fquat)
        for c in node.children:
            if c.tag == "body":
                self._body(c, body, fpos, fquat, cls)
            elif c.tag == "frame":
                pos = _floats(c, "pos", c.attrib, 3, np.zeros(3))
                q = self.orientation(c, {})
                self._children(c, body, fpos + rot @ pos, quat_mul(fquat, q), c.attrib.get("childclass", cls))
            elif c.tag in ("joint", "freejoint"):
                if body is None:
                    raise InputError(c.mark, "a joint in the world body", "joints inside a <body>")
                self._joint(c, body, cls)
            elif c.tag == "geom":
                g = self._geom(c, body, cls, fpos, fquat)
                if g.name:
                    if g.name in self.geoms:
                        raise InputError(c.mark, f"geom {g.name!r} defined twice", "unique geom names")
                    self.geoms[g.name] = g
                if body is not None:
                    self._body_by_name[body].geoms.append(g)
            elif c.tag == "site":
                a = self.attrs(c, cls)
                name = a.get("name")
                pos = _floats(c, "pos", a, 3, np.zeros(3))
                if name:
                    if name in self.sites:
                        raise InputError(c.mark, f"site {name!r} defined twice", "unique site names")
                    self.sites[name] = Site(name, body or "world", fpos + rot @ pos, c.mark)

    def _body(self, c: Node, parent: str | None, fpos: np.ndarray, fquat: np.ndarray, cls: str) -> None:
        name = c.attrib.get("name")
        if not name:
            self.unnamed += 1
            name = f"body{self.unnamed}"
        if name in self._body_by_name or name == "world":
            raise InputError(c.mark, f"body {name!r} defined twice", "unique body names (world is MuJoCo's own)")
        pos = _floats(c, "pos", c.attrib, 3, np.zeros(3))
        q = self.orientation(c, {})
        b = Body(name, parent, fpos + quat_matrix(fquat) @ pos, quat_mul(fquat, q), mark=c.mark)
        self.bodies.append(b)
        self._body_by_name[name] = b
        self._children(c, name, np.zeros(3), np.array([1.0, 0, 0, 0]), c.attrib.get("childclass", cls))
        free = [j for j in b.joints if j.type == "free"]
        if free and (len(b.joints) > 1 or parent is not None):
            raise InputError(free[0].mark, f"free joint {free[0].name!r} " +
                             ("is not its body's only joint" if len(b.joints) > 1 else "is not in a child of the world"),
                             "a free joint alone, in a body of the world body")

    def _joint(self, c: Node, body: str, cls: str) -> None:
        a = self.attrs(c, cls, "joint")
        jtype = "free" if c.tag == "freejoint" else a.get("type", "hinge")
        if jtype not in JOINT_TYPES:
            raise InputError(c.mark, f"joint type {jtype!r}", ", ".join(JOINT_TYPES))
        b = self._body_by_name[body]
        name = a.get("name") or f"{body}_joint{len(b.joints) + 1}"
        if name in self.joints:
            raise InputError(c.mark, f"joint {name!r} defined twice", "unique joint names")
        pos = _floats(c, "pos", a, 3, np.zeros(3))
        axis = _floats(c, "axis", a, 3, np.array([0.0, 0.0, 1.0]))
        if np.linalg.norm(axis) < 1e-12:
            raise InputError(c.mark, f"joint {name!r} axis is zero", "a non-zero axis")
        axis = axis / np.linalg.norm(axis)
        unit = math.pi / 180.0 if (self.angle == "degree" and jtype == "hinge") else 1.0
        ref = float(_floats(c, "ref", a, 1, np.zeros(1))[0]) * unit
        rng = _floats(c, "range", a, 2)
        limited = _bool(c, "limited", a, "auto")
        if limited == "auto":
            lim = rng is not None if self.autolimits else False
        else:
            lim = limited == "true"
        rng_out = None
        if lim and jtype in ("hinge", "slide"):
            if rng is None:
                raise InputError(c.mark, f"joint {name!r} is limited but has no range", "range=\"LOW HIGH\"")
            if rng[0] > rng[1]:
                raise InputError(c.mark, f"joint {name!r} range {rng[0]:g} {rng[1]:g} is empty", "LOW <= HIGH")
            rng_out = (float(rng[0]) * unit, float(rng[1]) * unit)
        j = Joint(name, jtype, body, pos, axis, ref, rng_out, c.mark)
        self.joints[name] = j
        b.joints.append(j)

    def _geom(self, c: Node, body: str | None, cls: str, fpos: np.ndarray, fquat: np.ndarray) -> Geom:
        a = self.attrs(c, cls, "geom")
        gtype = a.get("type", "sphere")
        size = _floats(c, "size", a, (1, 2, 3), np.zeros(3))
        size = np.concatenate([size, np.zeros(3 - len(size))])
        fromto = _floats(c, "fromto", a, 6)
        if fromto is not None:
            p0, p1 = fromto[:3], fromto[3:]
            d = p1 - p0
            if np.linalg.norm(d) < 1e-12:
                raise InputError(c.mark, "geom fromto has equal ends", "two different points")
            pos = 0.5 * (p0 + p1)
            z = d / np.linalg.norm(d)
            cz = np.cross([0.0, 0.0, 1.0], z)
            s = np.linalg.norm(cz)
            q = np.array([1.0, 0, 0, 0]) if s < 1e-12 and z[2] > 0 else \
                np.array([0.0, 1.0, 0, 0]) if s < 1e-12 else _axis_angle(cz, math.atan2(s, z[2]))
            size[1] = 0.5 * np.linalg.norm(d)
        else:
            pos = _floats(c, "pos", a, 3, np.zeros(3))
            q = self.orientation(c, a)
        pos = fpos + quat_matrix(fquat) @ pos
        q = quat_mul(fquat, q)
        return Geom(a.get("name"), gtype, body or "world", size, pos, q, a.get("mesh"), c.mark)

    def _tendon(self, t: Node) -> Tendon:
        name = t.attrib.get("name")
        if not name:
            self.unnamed += 1
            name = f"tendon{self.unnamed}"
        items = []
        for c in t.children:
            if c.tag == "site":
                items.append(TendonItem("site", c.attrib.get("site"), None, c.mark))
            elif c.tag == "geom":
                items.append(TendonItem("geom", c.attrib.get("geom"), c.attrib.get("sidesite"), c.mark))
            elif c.tag == "pulley":
                items.append(TendonItem("pulley", None, None, c.mark))
            else:
                raise InputError(c.mark, f"<{c.tag}> in a spatial tendon", "<site>, <geom> or <pulley>")
        for it in items:
            if it.kind == "site" and it.name not in self.sites:
                raise InputError(it.mark, f"tendon {name!r}: unknown site {it.name!r}", "a site of the model")
            if it.kind == "geom":
                g = self.geoms.get(it.name)
                if g is None:
                    raise InputError(it.mark, f"tendon {name!r}: unknown geom {it.name!r}", "a geom of the model")
                if g.type not in WRAP_GEOMS:
                    raise InputError(it.mark, f"tendon {name!r} wraps over {g.type} geom {it.name!r}",
                                     "sphere or cylinder geoms (MuJoCo wraps over these only)")
                if it.sidesite is not None and it.sidesite not in self.sites:
                    raise InputError(it.mark, f"tendon {name!r}: unknown sidesite {it.sidesite!r}", "a site of the model")
        kinds = [it.kind for it in items]
        for i, k in enumerate(kinds):
            if k == "geom" and (i == 0 or i == len(kinds) - 1 or kinds[i - 1] != "site" or kinds[i + 1] != "site"):
                raise InputError(items[i].mark, f"tendon {name!r}: a geom not between two sites",
                                 "site, geom, site (MuJoCo's rule)")
        if kinds.count("site") < 2:
            raise InputError(t.mark, f"tendon {name!r} has {kinds.count('site')} site(s)", "at least 2 sites")
        return Tendon(name, items, t.mark)

    def _coupling(self, e: Node) -> Coupling | None:
        a = self.attrs(e, None, "equality")
        j1, j2 = a.get("joint1"), a.get("joint2")
        if j1 is None:
            raise InputError(e.mark, "joint equality without joint1", "joint1=\"NAME\" (and joint2)")
        for j in (j1, j2):
            if j is not None and j not in self.joints:
                raise InputError(e.mark, f"joint equality names unknown joint {j!r}", "joints of the model")
            if j is not None and self.joints[j].type not in ("hinge", "slide"):
                raise InputError(e.mark, f"joint equality on {self.joints[j].type} joint {j!r}", "hinge or slide joints")
        if _bool(e, "active", a, "true") == "false":
            self._ignore("joint equality", e, "inactive (active=\"false\"): the joints stay independent")
            return None
        poly = _floats(e, "polycoef", a, 5, np.array([0.0, 1.0, 0.0, 0.0, 0.0]))
        return Coupling(a.get("name"), j1, j2, tuple(float(v) for v in poly), e.mark)

    def _actuator(self, a_node: Node, tendons: dict) -> Muscle | None:
        a = self.attrs(a_node, None, "actuator")
        name = a.get("name") or ""
        if a_node.tag == "muscle" or (a_node.tag == "general" and a.get("gaintype") == "muscle"):
            if "tendon" not in a:
                self._ignore(f"{a_node.tag} actuator", a_node, "a muscle on a joint or site, not on a spatial tendon")
                return None
            tname = a["tendon"]
            if tname not in tendons:
                raise InputError(a_node.mark, f"actuator {name!r} names unknown tendon {tname!r}",
                                 "a spatial tendon of the model")
            if a_node.tag == "muscle":
                rng = _floats(a_node, "range", a, 2, np.array(MUSCLE_DEFAULTS["range"]))
                force = float(_floats(a_node, "force", a, 1, np.array([MUSCLE_DEFAULTS["force"]]))[0])
                scale = float(_floats(a_node, "scale", a, 1, np.array([MUSCLE_DEFAULTS["scale"]]))[0])
                lmin = float(_floats(a_node, "lmin", a, 1, np.array([MUSCLE_DEFAULTS["lmin"]]))[0])
                lmax = float(_floats(a_node, "lmax", a, 1, np.array([MUSCLE_DEFAULTS["lmax"]]))[0])
                if not lmin < 1.0 < lmax:  # MuJoCo refuses the model too
                    raise InputError(a_node.mark, f"muscle {name!r} lmin {lmin:g} lmax {lmax:g}",
                                     "lmin < 1 < lmax (lengths relative to the optimal fibre length), as MuJoCo requires")
            else:
                g = _floats(a_node, "gainprm", a, None, np.zeros(10))
                g = np.concatenate([g, np.zeros(max(0, 4 - len(g)))])
                rng, force, scale = g[:2], float(g[2]), float(g[3])
            if not rng[0] < rng[1]:
                raise InputError(a_node.mark, f"muscle {name!r} range {rng[0]:g} {rng[1]:g}", "LOW < HIGH")
            lr = _floats(a_node, "lengthrange", a, 2)
            lr = None if lr is None or (lr[0] == 0 and lr[1] == 0) else (float(lr[0]), float(lr[1]))
            if lr is not None and not 0 <= lr[0] < lr[1]:
                raise InputError(a_node.mark, f"muscle {name!r} lengthrange {lr[0]:g} {lr[1]:g}", "0 <= LOW < HIGH")
            gear = float(_floats(a_node, "gear", a, (1, 6), np.ones(1))[0])
            if gear <= 0:
                raise InputError(a_node.mark, f"muscle {name!r} gear {gear:g}", "a positive gear")
            return Muscle(name, tname, force, scale, (float(rng[0]), float(rng[1])), lr, gear, a_node.tag,
                          a_node.mark)
        self._ignore(f"{a_node.tag} actuator", a_node, "not a muscle")
        return None


def load_mjcf(path: Path | str) -> MjcfModel:
    """Read an MJCF model; :class:`InputError` at ``FILE:LINE:COL`` for anything malformed."""
    return Reader(Path(path)).model()
