"""OpenSim 4 ``.osim`` models (XML) → small frozen model dataclasses, OpenSim units.

Everything here stays in OpenSim's units and frames (radians, metres, Y-up ground; the
dataclasses are in :mod:`axdf_cli.importers.osim_model`); the conversion to axdf (degrees,
Z-up) happens in :mod:`axdf_cli.importers.osim_import`. What the
parser does not model is listed in :attr:`Model.ignored` (wrap objects, markers,
constraints, non-muscle forces, muscles on a ``FunctionBasedPath``, ...), never dropped
silently.

Semantics (confirmed against Simbody / OpenSim sources):

- ``CustomJoint``: Simbody's ``FunctionBased`` mobilizer computes
  ``X_FM = [R(s1, a1)·R(s2, a2)·R(s3, a3),  s4·a4 + s5·a5 + s6·a6]`` with ``s_i`` the values of
  the six ``TransformAxis`` functions and all axes in the parent offset frame F: rotations
  are a body-fixed sequence, translations are summed in F (so they come *before* the
  rotations in axdf's ordered DOF list).
- Standard joints map to the same form: Pin (rotation about Z), Slider (translation along
  X), Universal (X then Y), Gimbal / Ball (body-fixed X-Y-Z), Planar (Z rotation, X and Y
  translations), Free (X-Y-Z rotations, translations in the parent), Weld (none).
- ``PhysicalOffsetFrame``: ``translation`` in the parent, ``orientation`` a body-fixed
  X-Y-Z rotation in radians. A body's transform in its parent body is
  ``X_PF · X_FM(q) · X_BM^-1`` (parent offset frame, joint, inverse child offset frame).
- Coordinates: rotational when they drive a rotation axis (in order rotation1..3, then
  translations; the first axis that names the coordinate decides), else translational.
- Functions: ``Constant``, ``LinearFunction`` (``coefficients: slope intercept``),
  ``PolynomialFunction`` (coefficients from the highest power down), ``SimmSpline``
  (Forsythe-Malcolm-Moler cubic), ``NaturalCubicSpline``, ``MultiplierFunction``.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.importers.osim_model import (FUNCTION_TAGS, Axis, Body, Coordinate, FConst, FLinear, FMult, FPoly,
                                           FSpline, Joint, MeshRef, Model, Muscle, Offset, PathPoint, PathWrap,
                                           WrapObject)
from axdf_cli.importers.xmltree import Node, parse_xml

# ----------------------------------------------------------------------------- helpers

_ALLOWED_JOINTS = ("CustomJoint", "PinJoint", "SliderJoint", "WeldJoint", "UniversalJoint", "GimbalJoint",
                   "BallJoint", "PlanarJoint", "FreeJoint")


def _numbers(node: Node, n: int | None = None, what: str | None = None) -> tuple[float, ...]:
    what = what or f"<{node.tag}>"
    words = node.text.split()
    out = []
    for w in words:
        try:
            v = float(w)
        except ValueError:
            raise InputError(node.mark, f"malformed number {w!r} in {what}", "decimal numbers separated by spaces") from None
        if not math.isfinite(v):
            raise InputError(node.mark, f"{what} holds {w!r}", "finite numbers")
        out.append(v)
    if n is not None and len(out) != n:
        raise InputError(node.mark, f"{what} has {len(out)} numbers", f"exactly {n}")
    return tuple(out)


def _need(node: Node, tag: str, owner: str) -> Node:
    child = node.find(tag)
    if child is None:
        raise InputError(node.mark, f"{owner} has no <{tag}>", f"<{node.tag}> needs a <{tag}> element")
    return child


def _opt_numbers(node: Node, tag: str, n: int, default):
    child = node.find(tag)
    return default if child is None or not child.text else _numbers(child, n)


def _bool(node: Node | None, default=False) -> bool:
    if node is None or not node.text:
        return default
    t = node.text.lower()
    if t in ("true", "1"):
        return True
    if t in ("false", "0"):
        return False
    raise InputError(node.mark, f"<{node.tag}> is {node.text!r}", "true or false")


def _last(path: str) -> str:
    return path.rstrip("/").split("/")[-1]


# ----------------------------------------------------------------------------- functions


def parse_function(node: Node, depth: int = 0):
    """A function element (``<SimmSpline>`` ...) or a ``<function>`` wrapper holding one."""
    if node.tag == "function":
        inner = [c for c in node.children if c.tag in FUNCTION_TAGS]
        if len(inner) != 1:
            raise InputError(node.mark, "<function> must hold exactly one function",
                             "one of " + ", ".join(FUNCTION_TAGS))
        node = inner[0]
    tag = node.tag
    if tag == "Constant":
        v = node.find("value")
        return FConst(_numbers(v, 1)[0] if v is not None and v.text else 0.0)
    if tag == "LinearFunction":
        c = _numbers(_need(node, "coefficients", tag), 2, "LinearFunction coefficients")
        return FLinear(c[0], c[1])
    if tag == "PolynomialFunction":
        c = _numbers(_need(node, "coefficients", tag), None, "PolynomialFunction coefficients")
        if not c:
            raise InputError(node.mark, "PolynomialFunction has no coefficients", "at least one coefficient")
        return FPoly(tuple(reversed(c)))
    if tag in ("SimmSpline", "NaturalCubicSpline"):
        xn, yn = _need(node, "x", tag), _need(node, "y", tag)
        x, y = _numbers(xn, None, f"{tag} x"), _numbers(yn, None, f"{tag} y")
        if len(x) != len(y):
            raise InputError(yn.mark, f"{tag} has {len(x)} x and {len(y)} y values", "x and y of equal length")
        if len(x) < 2:
            raise InputError(xn.mark, f"{tag} has {len(x)} points", "at least 2 points")
        if any(b <= a for a, b in zip(x, x[1:])):
            raise InputError(xn.mark, f"{tag} x values are not strictly increasing", "increasing x")
        return FSpline(x, y, "fmm" if tag == "SimmSpline" else "natural")
    if tag == "MultiplierFunction":
        if depth > 4:
            raise InputError(node.mark, "MultiplierFunction nested too deeply", "at most 4 levels")
        s = node.find("scale")
        scale = _numbers(s, 1)[0] if s is not None and s.text else 1.0
        inner = node.find("function")
        if inner is None:
            cands = [c for c in node.children if c.tag in FUNCTION_TAGS]
            if len(cands) != 1:
                raise InputError(node.mark, "MultiplierFunction has no function", "a <function> element")
            inner = cands[0]
        return FMult(scale, parse_function(inner, depth + 1))
    raise InputError(node.mark, f"unsupported function <{tag}>", "one of " + ", ".join(FUNCTION_TAGS))


def _find_function(node: Node, owner: str):
    for c in node.children:
        if c.tag in FUNCTION_TAGS or c.tag == "function":
            return parse_function(c)
    return None


def evaluate_function(fn, x: float) -> float:
    """Value of a function at ``x`` (OpenSim units)."""
    return float(fn(np.array([x]))[0])


# ----------------------------------------------------------------------------- parsing


class _Parser:
    def __init__(self, root: Node, source: str):
        self.root = root
        self.source = source
        self.ignored: list[dict] = []
        self.wrap_objects: dict[str, WrapObject] = {}

    def ignore(self, kind: str, name: str | None, node: Node, why: str):
        self.ignored.append({"kind": kind, "name": name or "", "where": f"{node.mark}", "why": why})

    def parse(self) -> Model:
        root = self.root
        if root.tag != "OpenSimDocument":
            raise InputError(root.mark, f"root element is <{root.tag}>", "an OpenSim model (<OpenSimDocument>)")
        version = root.attrib.get("Version", "0")
        try:
            v = int(version)
        except ValueError:
            raise InputError(root.mark, f"Version is {version!r}", "an integer such as 40000") from None
        if v < 30500:
            raise InputError(root.mark, f"OpenSim document version {v}",
                             "OpenSim 4 models (Version >= 30500); open and re-save older models in OpenSim 4")
        model = _need(root, "Model", "OpenSimDocument")
        name = model.name or Path(self.source).stem
        self.model_node = model
        self.bodies = self._bodies(model)
        self.joint_nodes = self._joint_nodes(model)
        joints, coords = self._joints()
        self.coords = coords
        self._couplers(model)
        muscles = self._forces(model)
        for tag, kind in (("MarkerSet", "marker"), ("ConstraintSet", "constraint"), ("ContactGeometrySet", "contact geometry"),
                          ("ControllerSet", "controller"), ("ProbeSet", "probe"), ("ComponentSet", "component")):
            s = model.find(tag)
            objs = s.find("objects") if s is not None else None
            for o in (objs.children if objs is not None else []):
                if o.tag != "CoordinateCouplerConstraint":  # _couplers has taken or listed these
                    self.ignore(kind, o.name, o, f"{o.tag}: not used by axdf")
        for c in coords.values():
            if c.locked:
                self.ignored.append({"kind": "coordinate lock", "name": c.name, "where": str(c.mark),
                                     "why": "locked coordinates are imported as free coordinates"})
        return Model(name, self.source, self.bodies, joints, coords, muscles,
                     (model.find("credits").text if model.find("credits") is not None else ""),
                     (model.find("publications").text if model.find("publications") is not None else ""),
                     self.ignored, self.wrap_objects)

    # constraints ----------------------------------------------------------

    def _couplers(self, model: Node) -> None:
        """``CoordinateCouplerConstraint``: the dependent coordinate follows
        ``scale_factor · f(independent)`` (Simbody enforces ``scale·f(q_ind) − q_dep = 0``). A
        coupler that axdf cannot follow (disabled, or a function of several coordinates) is
        listed and its dependent coordinate stays free."""
        objs = model.path("ConstraintSet", "objects")
        for c in (objs.children if objs is not None else []):
            if c.tag != "CoordinateCouplerConstraint":
                continue
            enforced = _bool(c.find("isEnforced"), True) and not _bool(c.find("isDisabled"), False)
            dn = _need(c, "dependent_coordinate_name", f"CoordinateCouplerConstraint {c.name!r}")
            dep = self._coord(dn)
            ind_node = _need(c, "independent_coordinate_names", f"CoordinateCouplerConstraint {c.name!r}")
            names = ind_node.text.split() if ind_node.text else []
            if not enforced:
                self.ignore("constraint", c.name, c, f"CoordinateCouplerConstraint not enforced: {dep.name} stays free")
                continue
            if len(names) != 1:
                self.ignore("constraint", c.name, c, f"CoordinateCouplerConstraint of {len(names)} coordinates "
                            f"({', '.join(names) or 'none'}): axdf couples to one; {dep.name} stays free")
                continue
            fnode = _need(c, "coupled_coordinates_function", f"CoordinateCouplerConstraint {c.name!r}")
            inner = [n for n in fnode.children if n.tag in FUNCTION_TAGS]
            if len(inner) != 1:
                kinds = ", ".join(n.tag for n in fnode.children) or "none"
                self.ignore("constraint", c.name, c, f"CoordinateCouplerConstraint function {kinds}: axdf follows "
                            f"one of {', '.join(FUNCTION_TAGS)}; {dep.name} stays free")
                continue
            ind = self._coord_named(names[0], ind_node.mark)
            if ind.name == dep.name:
                raise InputError(ind_node.mark, f"{c.name} couples {dep.name} to itself",
                                 "an independent coordinate other than the dependent one")
            if dep.follows is not None:
                raise InputError(dn.mark, f"coordinate {dep.name!r} is the dependent of two CoordinateCouplerConstraints",
                                 "one coupler per dependent coordinate")
            fn = parse_function(inner[0])
            sn = c.find("scale_factor")
            scale = _numbers(sn, 1)[0] if sn is not None and sn.text else 1.0
            if scale != 1.0:
                fn = FMult(scale, fn)
            self.coords[dep.name] = replace(dep, follows=ind.name, function=fn, coupler=c.name)
        # a chain of couplers must end at a free coordinate
        for name, c in self.coords.items():
            seen = [name]
            while c.follows is not None:
                if c.follows in seen:
                    raise InputError(self.coords[name].mark, f"coordinate {name!r} is coupled in a cycle "
                                     f"({' -> '.join(seen + [c.follows])})", "couplers whose chains end at a free coordinate")
                seen.append(c.follows)
                c = self.coords[c.follows]
        # rest values: a dependent coordinate's default is its function of its leader's (what
        # OpenSim's assembly makes of the model's defaults)
        done = False
        while not done:
            done = True
            for name, c in self.coords.items():
                if c.follows is not None:
                    v = evaluate_function(c.function, self.coords[c.follows].default)
                    if v != c.default:
                        self.coords[name] = replace(c, default=v)
                        done = False

    # bodies ---------------------------------------------------------------

    def _meshes(self, frame: Node, owner: str) -> list[MeshRef]:
        out = []
        ag = frame.find("attached_geometry")
        for g in (ag.children if ag is not None else []):
            if g.tag != "Mesh":
                self.ignore("geometry", g.name, g, f"{g.tag} on {owner}: only Mesh geometry is converted")
                continue
            f = g.find("mesh_file")
            if f is None or not f.text:
                raise InputError(g.mark, f"Mesh {g.name!r} has no <mesh_file>", "a mesh file name")
            sock = g.find("socket_frame")
            if sock is not None and sock.text not in ("..", ""):
                self.ignore("geometry", g.name, g, f"mesh attached to frame {sock.text!r}, not to its body")
                continue
            scale = _opt_numbers(g, "scale_factors", 3, (1.0, 1.0, 1.0))
            out.append(MeshRef(f.text, scale, g.mark))
        return out

    def _bodies(self, model: Node) -> dict[str, Body]:
        bodies: dict[str, Body] = {}
        ground = model.find("Ground")
        gmark = ground.mark if ground is not None else model.mark
        bodies["ground"] = Body("ground", (0.0, 0.0, 0.0), tuple(self._meshes(ground, "ground")) if ground is not None else (),
                                gmark)
        bs = model.path("BodySet", "objects")
        for b in (bs.children if bs is not None else []):
            if b.tag != "Body":
                self.ignore("body", b.name, b, f"{b.tag}: not a Body")
                continue
            if not b.name:
                raise InputError(b.mark, "Body without a name", "<Body name=\"...\">")
            if b.name in bodies:
                raise InputError(b.mark, f"body {b.name!r} defined twice", "unique body names")
            mc = _opt_numbers(b, "mass_center", 3, (0.0, 0.0, 0.0))
            bodies[b.name] = Body(b.name, mc, tuple(self._meshes(b, b.name)), b.mark)
            ws = b.path("WrapObjectSet", "objects")
            for w in (ws.children if ws is not None else []):
                self._wrap_object(w, b.name)
            comps = b.find("components")
            for c in (comps.children if comps is not None else []):
                if c.tag != "PhysicalOffsetFrame":
                    self.ignore("component", c.name, c, f"{c.tag} on body {b.name}")
        return bodies

    # wrap objects ---------------------------------------------------------

    _WRAP_TAGS = {"WrapCylinder": "cylinder", "WrapSphere": "sphere", "WrapEllipsoid": "ellipsoid",
                  "WrapTorus": "torus"}

    def _wrap_object(self, w: Node, body: str) -> None:
        shape = self._WRAP_TAGS.get(w.tag)
        if shape is None:
            self.ignore("wrap object", w.name, w, f"{w.tag} on body {body}: not a wrap surface axdf knows")
            return
        if not w.name or w.name in self.wrap_objects:
            raise InputError(w.mark, f"wrap object {w.name!r} unnamed or defined twice", "unique wrap object names")
        if shape == "cylinder":
            size = (_numbers(_need(w, "radius", w.name), 1)[0], _numbers(_need(w, "length", w.name), 1)[0], 0.0)
        elif shape == "sphere":
            size = (_numbers(_need(w, "radius", w.name), 1)[0], 0.0, 0.0)
        elif shape == "ellipsoid":
            size = _numbers(_need(w, "dimensions", w.name), 3, "dimensions")
        else:
            size = (_numbers(_need(w, "inner_radius", w.name), 1)[0], _numbers(_need(w, "outer_radius", w.name), 1)[0], 0.0)
        n = 3 if shape == "ellipsoid" else (2 if shape in ("cylinder", "torus") else 1)
        if any(v <= 0 for v in size[:n]):
            raise InputError(w.mark, f"{w.tag} {w.name!r} has a non-positive size {list(size[:n])}", "positive radii and lengths")
        q = w.find("quadrant")
        quadrant = (q.text.strip() if q is not None and q.text else "all")
        if quadrant.lower() in ("all", "unassigned"):
            quadrant = "all"
        self.wrap_objects[w.name] = WrapObject(
            w.name, body, shape, tuple(float(v) for v in size),
            _opt_numbers(w, "translation", 3, (0.0, 0.0, 0.0)), _opt_numbers(w, "xyz_body_rotation", 3, (0.0, 0.0, 0.0)),
            quadrant, _bool(w.find("active"), True), w.mark)

    # frames ---------------------------------------------------------------

    def _offset_frame(self, frame: Node, scope: dict[str, Node], depth: int) -> Offset:
        sp = frame.find("socket_parent")
        if sp is None or not sp.text:
            raise InputError(frame.mark, f"offset frame {frame.name!r} has no <socket_parent>", "a body path")
        base = self._resolve(sp.text, sp, scope, depth + 1)
        t = _opt_numbers(frame, "translation", 3, (0.0, 0.0, 0.0))
        o = _opt_numbers(frame, "orientation", 3, (0.0, 0.0, 0.0))
        if base.is_identity:
            return Offset(base.body, t, o)
        m = base.matrix() @ Offset(base.body, t, o).matrix()
        return _offset_from_matrix(base.body, m)

    def _resolve(self, path: str, where: Node, scope: dict[str, Node], depth: int = 0) -> Offset:
        """A frame path (``/bodyset/femur_r``, ``/ground``, ``femur_r_offset``) → Offset in a body."""
        if depth > 8:
            raise InputError(where.mark, f"frame {path!r} nests too deeply", "at most 8 levels of offset frames")
        p = path.strip()
        while p.startswith("./"):
            p = p[2:]
        parts = [s for s in p.split("/") if s]
        if p.startswith("/"):
            if parts == ["ground"]:
                return Offset("ground", (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            if len(parts) == 2 and parts[0] == "bodyset":
                if parts[1] not in self.bodies:
                    raise InputError(where.mark, f"unknown body {parts[1]!r}",
                                     "bodies of the BodySet: " + ", ".join(sorted(self.bodies)))
                return Offset(parts[1], (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
            if len(parts) == 3 and parts[0] == "bodyset" and parts[1] in self.bodies:
                frames = self._body_frames(parts[1])
                if parts[2] in frames:
                    return self._offset_frame(frames[parts[2]], frames, depth)
            if len(parts) == 3 and parts[0] == "jointset" and parts[1] in self.joint_nodes:
                jf = self._joint_frames(self.joint_nodes[parts[1]])
                if parts[2] in jf:
                    return self._offset_frame(jf[parts[2]], jf, depth)
        else:
            name = parts[-1] if parts else ""
            if len(parts) == 1 and name in scope:
                return self._offset_frame(scope[name], scope, depth)
            if len(parts) <= 2 and name in self.bodies and (len(parts) == 1 or parts[0] in ("..", "bodyset")):
                return Offset(name, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        raise InputError(where.mark, f"unknown frame {path!r}",
                         "/ground, /bodyset/BODY, or an offset frame of the joint or body")

    def _body_frames(self, body: str) -> dict[str, Node]:
        for b in self.model_node.path("BodySet", "objects").children:
            if b.name == body:
                comps = b.find("components")
                return {c.name: c for c in (comps.children if comps is not None else []) if c.tag == "PhysicalOffsetFrame"}
        return {}

    @staticmethod
    def _joint_frames(j: Node) -> dict[str, Node]:
        fr = j.find("frames")
        return {f.name: f for f in (fr.children if fr is not None else []) if f.tag == "PhysicalOffsetFrame"}

    # joints ---------------------------------------------------------------

    def _joint_nodes(self, model: Node) -> dict[str, Node]:
        out = {}
        js = model.path("JointSet", "objects")
        for j in (js.children if js is not None else []):
            if j.tag not in _ALLOWED_JOINTS:
                raise InputError(j.mark, f"unsupported joint type <{j.tag}>", "one of " + ", ".join(_ALLOWED_JOINTS))
            if not j.name:
                raise InputError(j.mark, "joint without a name", f"<{j.tag} name=\"...\">")
            if j.name in out:
                raise InputError(j.mark, f"joint {j.name!r} defined twice", "unique joint names")
            out[j.name] = j
        return out

    def _joints(self):
        coords: dict[str, Coordinate] = {}
        by_child: dict[str, Joint] = {}
        for j in self.joint_nodes.values():
            scope = self._joint_frames(j)
            sp, sc = j.find("socket_parent_frame"), j.find("socket_child_frame")
            if sp is None or sc is None or not sp.text or not sc.text:
                raise InputError(j.mark, f"joint {j.name!r} lacks socket_parent_frame or socket_child_frame",
                                 "both sockets")
            parent = self._resolve(sp.text, sp, scope)
            child = self._resolve(sc.text, sc, scope)
            if child.body == "ground":
                raise InputError(sc.mark, f"joint {j.name!r} has ground as its child", "ground is always the root")
            if child.body in by_child:
                raise InputError(j.mark, f"body {child.body!r} is the child of two joints "
                                 f"({by_child[child.body].name!r}, {j.name!r})",
                                 "a tree: one joint per body (closed loops are constraints, not joints)")
            jc = [c for c in (j.find("coordinates").children if j.find("coordinates") is not None else [])
                  if c.tag == "Coordinate"]
            axes = self._axes(j, jc)
            for c in jc:
                if c.name in coords:
                    raise InputError(c.mark, f"coordinate {c.name!r} defined twice", "unique coordinate names")
                ctype = None
                for a in sorted(axes, key=lambda a: a.type != "rotation"):  # rotations decide first
                    if a.coord == c.name:
                        ctype = a.type
                        break
                if ctype is None:
                    self.ignore("coordinate", c.name, c, f"drives no axis of joint {j.name}")
                    ctype = "rotation"
                d = c.find("default_value")
                default = _numbers(d, 1)[0] if d is not None and d.text else 0.0
                r = c.find("range")
                rng = _numbers(r, 2) if r is not None and r.text else None
                coords[c.name] = Coordinate(c.name, ctype, default, rng, _bool(c.find("locked")), j.name, c.mark,
                                            motion_type(axes, c.name))
            by_child[child.body] = Joint(j.name, j.tag, parent, child, tuple(axes), j.mark)
        # check axes name known coordinates
        for jt in by_child.values():
            for a in jt.axes:
                if a.coord is not None and a.coord not in coords:
                    raise InputError(self.joint_nodes[jt.name].mark, f"joint {jt.name!r} uses unknown coordinate {a.coord!r}",
                                     "coordinates declared in the joints' <coordinates>")
        # order: parents before children, from ground
        order: list[Joint] = []
        done = {"ground"}
        pending = dict(by_child)
        while pending:
            ready = [b for b, jt in pending.items() if jt.parent.body in done]
            if not ready:
                b, jt = next(iter(pending.items()))
                raise InputError(self.joint_nodes[jt.name].mark,
                                 f"body {b!r} is not connected to ground (parent {jt.parent.body!r})",
                                 "a tree of joints rooted at ground")
            for b in ready:  # keep JointSet order among ready joints
                order.append(pending.pop(b))
                done.add(b)
        for b in self.bodies.values():
            if b.name not in done:
                raise InputError(b.mark, f"body {b.name!r} has no joint", "every body is the child of one joint")
        return order, coords

    def _axes(self, j: Node, jc: list[Node]) -> list[Axis]:
        names = [c.name for c in jc]
        ident = FLinear(1.0, 0.0)

        def need(n):
            if len(names) != n:
                raise InputError(j.mark, f"{j.tag} {j.name!r} has {len(names)} coordinates", f"{j.tag} has {n}")

        X, Y, Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)
        t = j.tag
        if t == "WeldJoint":
            need(0)
            return []
        if t == "PinJoint":
            need(1)
            return [Axis("rotation", Z, names[0], ident)]
        if t == "SliderJoint":
            need(1)
            return [Axis("translation", X, names[0], ident)]
        if t == "UniversalJoint":
            need(2)
            return [Axis("rotation", X, names[0], ident), Axis("rotation", Y, names[1], ident)]
        if t in ("GimbalJoint", "BallJoint"):
            need(3)
            return [Axis("rotation", a, n, ident) for a, n in zip((X, Y, Z), names)]
        if t == "PlanarJoint":
            need(3)
            return [Axis("translation", X, names[1], ident), Axis("translation", Y, names[2], ident),
                    Axis("rotation", Z, names[0], ident)]
        if t == "FreeJoint":
            need(6)
            return ([Axis("translation", a, n, ident) for a, n in zip((X, Y, Z), names[3:])]
                    + [Axis("rotation", a, n, ident) for a, n in zip((X, Y, Z), names[:3])])
        # CustomJoint
        st = _need(j, "SpatialTransform", f"CustomJoint {j.name!r}")
        found = {}
        for ta in st.findall("TransformAxis"):
            if ta.name not in ("rotation1", "rotation2", "rotation3", "translation1", "translation2", "translation3"):
                raise InputError(ta.mark, f"TransformAxis named {ta.name!r}", "rotation1..3, translation1..3")
            found[ta.name] = ta
        axes = []
        for nm in ("translation1", "translation2", "translation3", "rotation1", "rotation2", "rotation3"):
            ta = found.get(nm)
            if ta is None:
                continue
            kind = "rotation" if nm.startswith("rotation") else "translation"
            an = _need(ta, "axis", f"TransformAxis {nm}")
            axis = _numbers(an, 3, f"{nm} axis")
            if math.sqrt(sum(a * a for a in axis)) < 1e-9:
                raise InputError(an.mark, f"{nm} axis is the zero vector", "a non-zero axis")
            cn = ta.find("coordinates")
            cl = cn.text.split() if cn is not None and cn.text else []
            if len(cl) > 1:
                raise InputError(cn.mark, f"{nm} is a function of {len(cl)} coordinates", "at most one coordinate per axis")
            coord = cl[0] if cl else None
            if coord is not None and coord not in names:
                raise InputError(cn.mark, f"unknown coordinate {coord!r} in {nm} of joint {j.name!r}",
                                 "this joint's coordinates: " + (", ".join(names) or "none"))
            fn = _find_function(ta, nm)
            if fn is None:
                fn = ident if coord is not None else FConst(0.0)
            axes.append(Axis(kind, tuple(axis), coord, fn))
        return axes

    # forces ---------------------------------------------------------------

    def _forces(self, model: Node) -> list[Muscle]:
        muscles = []
        fs = model.path("ForceSet", "objects")
        names = set()
        for f in (fs.children if fs is not None else []):
            gp = f.find("GeometryPath")
            if gp is None and f.find("FunctionBasedPath") is not None:
                self.ignore("muscle", f.name, f, f"{f.tag} on a FunctionBasedPath (its length a function of "
                            "coordinates, no path points to build a belly along): skipped; give it a GeometryPath")
                continue
            if gp is None or f.find("max_isometric_force") is None:
                self.ignore("force", f.name, f, f"{f.tag}: not a muscle with a path")
                continue
            if not f.name:
                raise InputError(f.mark, "muscle without a name", f"<{f.tag} name=\"...\">")
            if f.name in names:
                raise InputError(f.mark, f"muscle {f.name!r} defined twice", "unique muscle names")
            names.add(f.name)
            fmax = _numbers(f.find("max_isometric_force"), 1)[0]
            lopt = _numbers(_need(f, "optimal_fiber_length", f.name), 1)[0]
            lts = _numbers(_need(f, "tendon_slack_length", f.name), 1)[0]
            pn = f.find("pennation_angle_at_optimal")
            pen = _numbers(pn, 1)[0] if pn is not None and pn.text else 0.0
            for v, what, node in ((fmax, "max_isometric_force", f.find("max_isometric_force")),
                                  (lopt, "optimal_fiber_length", f.find("optimal_fiber_length"))):
                if v <= 0:
                    raise InputError(node.mark, f"{what} of {f.name} is {v}", f"{what} > 0")
            if lts < 0:
                raise InputError(f.find("tendon_slack_length").mark, f"tendon_slack_length of {f.name} is {lts}", ">= 0")
            pts = self._path_points(gp, f.name)
            ws = gp.path("PathWrapSet", "objects")
            wraps = []
            for w in (ws.children if ws is not None else []):
                wo = w.find("wrap_object") or w.find("socket_wrap_object")
                wname = _last(wo.text) if wo is not None and wo.text else (w.name or "")
                if wname not in self.wrap_objects:
                    raise InputError((wo or w).mark, f"path wrap of {f.name} names unknown wrap object {wname!r}",
                                     "wrap objects of the bodies: " + ", ".join(sorted(self.wrap_objects)))
                mn = w.find("method")
                method = mn.text.strip() if mn is not None and mn.text else "hybrid"
                if method not in ("hybrid", "midpoint", "axial"):
                    raise InputError(mn.mark, f"wrap method {method!r}", "hybrid, midpoint or axial")
                rn = w.find("range")
                rng = tuple(int(v) for v in _numbers(rn, 2, "range")) if rn is not None and rn.text else (-1, -1)
                npts = len(pts)
                for v in rng:
                    if v == 0 or v < -1 or v > npts:
                        raise InputError(rn.mark, f"range {list(rng)} of path wrap {wname!r} lies outside the path of "
                                         f"{f.name} ({npts} points)", f"1-based point indices 1..{npts}, or -1 for an end")
                wraps.append(PathWrap(wname, method, rng, w.mark))
            muscles.append(Muscle(f.name, f.tag, fmax, lopt, lts, pen, tuple(pts), tuple(wraps), f.mark))
        return muscles

    def _path_points(self, gp: Node, muscle: str) -> list[PathPoint]:
        ps = gp.path("PathPointSet", "objects")
        pts = []
        for p in (ps.children if ps is not None else []):
            if p.tag not in ("PathPoint", "ConditionalPathPoint", "MovingPathPoint"):
                raise InputError(p.mark, f"unsupported path point <{p.tag}> in {muscle}",
                                 "PathPoint, ConditionalPathPoint, MovingPathPoint")
            sf = p.find("socket_parent_frame") or p.find("socket_body") or p.find("body")
            if sf is None or not sf.text:
                raise InputError(p.mark, f"path point {p.name!r} of {muscle} has no <socket_parent_frame>", "a body path")
            frame = self._resolve(sf.text if "/" in sf.text else "/bodyset/" + sf.text if sf.text != "ground" else "/ground",
                                  sf, {})
            moving = None
            if p.tag == "MovingPathPoint":
                loc = []
                moving = []
                for ax, default in zip("xyz", _opt_numbers(p, "location", 3, (0.0, 0.0, 0.0))):
                    fnode = p.find(f"{ax}_location")
                    cnode = p.find(f"socket_{ax}_coordinate") or p.find(f"{ax}_coordinate")
                    if fnode is None:
                        loc.append(default)
                        moving.append(None)
                        continue
                    fn = _find_function(fnode, f"{ax}_location")
                    if fn is None:
                        raise InputError(fnode.mark, f"<{ax}_location> holds no function", "one of " + ", ".join(FUNCTION_TAGS))
                    x = 0.0
                    if not isinstance(fn, FConst):
                        if cnode is None or not cnode.text:
                            raise InputError(p.mark, f"moving point {p.name!r} has no {ax} coordinate",
                                             f"<socket_{ax}_coordinate>")
                        x = self._coord(cnode).default
                        moving.append((self._coord(cnode).name, fn))
                    else:
                        moving.append(None)
                    loc.append(evaluate_function(fn, x))
                location = tuple(loc)
                moving = tuple(moving)
                kind, active, cond = "moving", True, None
            else:
                location = _numbers(_need(p, "location", f"path point {p.name!r}"), 3, "location")
                kind, active, cond = "fixed", True, None
                if p.tag == "ConditionalPathPoint":
                    cnode = p.find("socket_coordinate") or p.find("coordinate")
                    if cnode is None or not cnode.text:
                        raise InputError(p.mark, f"conditional point {p.name!r} has no coordinate", "<socket_coordinate>")
                    c = self._coord(cnode)
                    lo, hi = _numbers(_need(p, "range", f"conditional point {p.name!r}"), 2, "range")
                    kind, cond = "conditional", (c.name, lo, hi)
                    active = lo <= c.default <= hi
            if not frame.is_identity:
                location = tuple(float(v) for v in (frame.matrix() @ np.append(location, 1.0))[:3])
            pts.append(PathPoint(p.name or "", frame.body, tuple(float(v) for v in location), kind, active, cond, p.mark,
                                 moving, None if frame.is_identity else frame))
        active = [q for q in pts if q.active_at_rest]
        if len(active) < 2:
            raise InputError(gp.mark, f"muscle {muscle!r} has {len(active)} path points active at the rest pose",
                             "at least 2 (origin and insertion)")
        return pts

    def _coord(self, node: Node) -> Coordinate:
        return self._coord_named(_last(node.text), node.mark)

    def _coord_named(self, name: str, mark: Mark) -> Coordinate:
        if name not in self.coords:
            raise InputError(mark, f"unknown coordinate {name!r}",
                             "coordinates of the model: " + ", ".join(sorted(self.coords)))
        return self.coords[name]


def motion_type(axes: list[Axis], coord: str) -> str:
    """OpenSim's motion type of a joint's coordinate (``CustomJoint::constructCoordinates``):
    over the axes in OpenSim's order (rotation1..3, translation1..3) that the coordinate
    drives, one whose function is linear with slope ±1 makes it ``rotational`` or
    ``translational`` (a later such axis wins); any other function makes it ``coupled``
    unless a pure axis decided already. OpenSim writes a ``coupled`` coordinate's motion
    column in radians whatever the header's ``inDegrees`` says."""
    mt = None
    for a in sorted(axes, key=lambda a: a.type != "rotation"):  # stable: rotations 1..3, translations 1..3
        if a.coord != coord:
            continue
        if isinstance(a.function, FLinear) and abs(a.function.slope) == 1.0:
            mt = "rotational" if a.type == "rotation" else "translational"
        elif mt is None:
            mt = "coupled"
    return mt or "rotational"


def _offset_from_matrix(body: str, m: np.ndarray) -> Offset:
    from scipy.spatial.transform import Rotation

    o = Rotation.from_matrix(m[:3, :3]).as_euler("XYZ")  # intrinsic X-Y-Z = Rx·Ry·Rz
    return Offset(body, tuple(float(v) for v in m[:3, 3]), tuple(float(v) for v in o))


def load_osim(path: Path | str) -> Model:
    """Read an OpenSim 4 model file into a :class:`Model` (OpenSim units and frames)."""
    path = Path(path)
    root = parse_xml(path)
    return _Parser(root, str(path)).parse()
