"""An OpenSim :class:`~axdf_cli.importers.osim.Model` → axdf documents and YAML text.

Output is deterministic: no timestamps, no absolute paths, keys in a fixed order. Numbers
are written rounded to what they mean (:func:`rounded`): positions (``offset``,
``post_offset``, an axis point's ``at``) to 0.1 µm, everything else to 9 significant digits.
The digits beyond come from matrix products whose last bits differ between CPUs and BLAS
builds; rounding them away keeps the files readable and (but for a rare value on a
rounding boundary) the same on every machine.

Conversions (OpenSim → axdf):

- World: a root bone ``ground`` with ``orient: [90, -90, 0]`` turns OpenSim's Y-up, X-forward ground into
  axdf's Z-up world; every body keeps its own OpenSim frame, so path points and meshes are
  copied unchanged.
- Joints: parent offset frame → ``offset``/``orient``; child offset frame →
  ``post_offset``/``post_orient``; transform axes → ordered DOFs, translations first (Simbody
  sums them in the parent frame), then rotations (a body-fixed sequence). Axes whose function
  is the constant 0 are dropped; an identity ``LinearFunction`` of a coordinate of the
  axis's own type becomes a plain DOF; anything else a coupled DOF with ``function``.
- Units: rotational coordinates and rotation outputs rad → degrees. A function
  ``y = f(x)`` in OpenSim units becomes ``y' = k_out · f(k_in · x')`` with
  ``k_in = π/180`` for a rotational coordinate and ``k_out = 180/π`` for a rotation axis:
  spline knots x / k_in and values y · k_out, linear slope · k_in · k_out, polynomial
  c_i · k_out · k_in^i, multiplier scales unchanged (its inner function converted).
- Muscles: see :func:`muscle_doc` (axis control points, sections, tendons, colour).
"""
from __future__ import annotations

import colorsys
import hashlib
import math
import re

import numpy as np
import yaml

from axdf_cli.importers.osim import Axis, FConst, FLinear, FMult, FPoly, FSpline, Model, Muscle
from axdf_cli.skeleton import Skeleton, Spline, forward_kinematics

DEG = 180.0 / math.pi

#: Specific tension σ (N/m²) turning max isometric force into PCSA. 0.6 MPa: inside the
#: 0.3-1 MPa range reported for human muscle, near the 61 N/cm² used for the lower-limb
#: model of Arnold et al. (2010). A lower σ would make every muscle thicker (PCSA ∝ 1/σ).
SPECIFIC_TENSION = 0.6e6
#: Stress in a tendon at the muscle's max isometric force (N/m²), sizing tendon sections:
#: human tendons carry roughly 30-100 MPa at maximal force; 50 MPa is the middle.
TENDON_STRESS = 50e6
#: Belly sections' radii relative to the largest: a fusiform profile.
BELLY_PROFILE = (0.75, 1.0, 1.0, 0.75)
#: Upper bound on the tendons' share of the rest axis, so a belly always remains.
MAX_TENDON_FRACTION = 0.7
#: How the tendon (tendon_slack_length) splits between origin and insertion: insertion
#: tendons are usually the longer ones (Achilles, quadriceps, biceps distal).
ORIGIN_TENDON_SHARE = 0.4
#: Half-length of the control-point pair that makes the axis pass through a via point,
#: as a fraction of the shorter neighbouring path segment.
VIA_PAIR_FRACTION = 0.25


# ----------------------------------------------------------------------------- functions


def convert_function(fn, k_in: float, k_out: float):
    """A function of OpenSim units → the same function of axdf units (see module doc)."""
    if isinstance(fn, FConst):
        return FConst(fn.value * k_out)
    if isinstance(fn, FLinear):
        return FLinear(fn.slope * k_in * k_out, fn.intercept * k_out)
    if isinstance(fn, FPoly):
        return FPoly(tuple(c * k_out * k_in ** i for i, c in enumerate(fn.coefficients)))
    if isinstance(fn, Spline):
        return FSpline(fn.x / k_in, fn.y * k_out, fn.kind)
    if isinstance(fn, FMult):
        return FMult(fn.scale, convert_function(fn.function, k_in, k_out))
    raise TypeError(f"unknown function {fn!r}")


def function_doc(fn) -> dict:
    if isinstance(fn, FConst):
        return {"constant": fn.value}
    if isinstance(fn, FLinear):
        return {"linear": [fn.slope, fn.intercept]}
    if isinstance(fn, FPoly):
        return {"polynomial": list(fn.coefficients)}
    if isinstance(fn, Spline):
        return {"spline": {"x": [float(v) for v in fn.x], "y": [float(v) for v in fn.y], "kind": fn.kind}}
    if isinstance(fn, FMult):
        return {"multiplier": {"scale": fn.scale, "function": function_doc(fn.function)}}
    raise TypeError(f"unknown function {fn!r}")


def _is_zero(fn) -> bool:
    return (isinstance(fn, FConst) and fn.value == 0.0) or (isinstance(fn, FMult) and (fn.scale == 0.0 or _is_zero(fn.function)))


# ----------------------------------------------------------------------------- skeleton


def _deg(v) -> list[float]:
    return [x * DEG for x in v]


def _dof(model: Model, a: Axis) -> dict | None:
    if _is_zero(a.function):
        return None
    d: dict = {}
    if a.coord is not None and not isinstance(a.function, FConst):
        d["coord"] = a.coord
    d["type"] = a.type
    d["axis"] = list(a.axis)
    if "coord" in d:
        ctype = model.coordinates[a.coord].type
        if ctype == a.type and isinstance(a.function, FLinear) and a.function.slope == 1.0 and a.function.intercept == 0.0:
            return d
        k_in = math.pi / 180.0 if ctype == "rotation" else 1.0
    else:
        k_in = 1.0
    k_out = DEG if a.type == "rotation" else 1.0
    d["function"] = function_doc(convert_function(a.function, k_in, k_out))
    return d


def skeleton_doc(model: Model, name: str, meshes: dict[str, str]) -> dict:
    """The skeleton YAML document. ``meshes``: body → mesh path relative to the skeleton file."""
    coords = {}
    for c in model.coordinates.values():
        k = DEG if c.type == "rotation" else 1.0
        cd = {"type": c.type, "default": c.default * k}
        if c.range is not None:
            cd["range"] = [c.range[0] * k, c.range[1] * k]
        coords[c.name] = cd
    bones = [{"name": "ground", "orient": [90.0, -90.0, 0.0]}]
    if "ground" in meshes:
        bones[0]["mesh"] = meshes["ground"]
    for j in model.joints:
        b: dict = {"name": j.child.body, "parent": j.parent.body,
                   "offset": list(j.parent.translation), "orient": _deg(j.parent.orientation)}
        dofs = [d for d in (_dof(model, a) for a in j.axes) if d is not None]
        if dofs:
            b["dofs"] = dofs
        if not j.child.is_identity:
            b["post_offset"] = list(j.child.translation)
            b["post_orient"] = _deg(j.child.orientation)
        if j.child.body in meshes:
            b["mesh"] = meshes[j.child.body]
        bones.append(b)
    doc = {"skeleton": name}
    if coords:
        doc["coordinates"] = coords
    doc["bones"] = bones
    return doc


# ----------------------------------------------------------------------------- muscles


def muscle_color(name: str) -> str:
    """A deterministic colour from the muscle's name: hue from sha256, muscle-like saturation."""
    h = hashlib.sha256(name.encode()).digest()
    hue = h[0] / 255.0
    sat = 0.45 + 0.3 * h[1] / 255.0
    val = 0.7 + 0.25 * h[2] / 255.0
    r, g, b = colorsys.hsv_to_rgb(hue, sat, val)
    return "#{:02x}{:02x}{:02x}".format(round(r * 255), round(g * 255), round(b * 255))


def _world_points(skel: Skeleton, world: np.ndarray, pts) -> np.ndarray:
    """Rest-pose world positions (n, 3) of points ``[(body, (x, y, z)), ...]``; world (B, 4, 4)."""
    bi = skel.bone_index
    return np.array([(world[bi[b]] @ np.append(p, 1.0))[:3] for b, p in pts])


def axis_control_points(skel: Skeleton, world: np.ndarray, pts: list[tuple[str, tuple]]) -> list[tuple[str, list[float]]]:
    """Path points (body, location) active at rest → clamped quadratic B-spline control points.

    - First and last control points are the origin and insertion (the clamped curve
      interpolates its end control points).
    - Each via point V (interior path point) becomes a pair ``V - h·d``, ``V + h·d`` in V's own
      body, with ``d`` the unit direction from the previous to the next path point and ``h``
      = VIA_PAIR_FRACTION × the shorter neighbouring segment. On a uniform clamped quadratic
      B-spline the curve passes through the midpoint of two consecutive control points at
      the knot between them, so the axis passes exactly through V, tangent to ``d``.
    - A two-point path gets two inner points at 1/3 (in the origin's body) and 2/3 (in the
      insertion's body) of the straight line: 4 control points, a straight rest axis.
    - Consecutive path points closer than 0.1 mm are merged (the first is kept).
    """
    bi = skel.bone_index
    w = _world_points(skel, world, pts)
    keep = [0]
    for i in range(1, len(pts)):
        if np.linalg.norm(w[i] - w[keep[-1]]) >= 1e-4:
            keep.append(i)
    if len(keep) == 1:
        keep.append(len(pts) - 1)
    elif keep[-1] != len(pts) - 1:
        keep[-1] = len(pts) - 1  # the insertion always ends the axis
    pts = [pts[i] for i in keep]
    w = w[keep]

    def local(body, xw):
        m = np.linalg.inv(world[bi[body]])
        return [float(v) for v in (m @ np.append(xw, 1.0))[:3]]

    out = [(pts[0][0], [float(v) for v in pts[0][1]])]
    if len(pts) == 2:
        out.append((pts[0][0], local(pts[0][0], w[0] + (w[1] - w[0]) / 3.0)))
        out.append((pts[1][0], local(pts[1][0], w[0] + 2.0 * (w[1] - w[0]) / 3.0)))
    for i in range(1, len(pts) - 1):
        d = w[i + 1] - w[i - 1]
        n = np.linalg.norm(d)
        h = VIA_PAIR_FRACTION * min(np.linalg.norm(w[i] - w[i - 1]), np.linalg.norm(w[i + 1] - w[i]))
        if n < 1e-9:
            out.append((pts[i][0], [float(v) for v in pts[i][1]]))
            continue
        d = d / n
        out.append((pts[i][0], local(pts[i][0], w[i] - h * d)))
        out.append((pts[i][0], local(pts[i][0], w[i] + h * d)))
    out.append((pts[-1][0], [float(v) for v in pts[-1][1]]))
    return out


def muscle_doc(m: Muscle, skel: Skeleton, world: np.ndarray) -> tuple[dict, dict]:
    """One muscle YAML document and a summary row for the import report.

    Sizing: PCSA = F_max / SPECIFIC_TENSION; belly volume V = PCSA × optimal fibre length.
    Tendons: T = min(tendon_slack_length / rest axis length, MAX_TENDON_FRACTION), split
    ORIGIN_TENDON_SHARE : (1 - ORIGIN_TENDON_SHARE) between origin and insertion. Sections:
    one thin section inside each tendon (radius from TENDON_STRESS) and four belly sections
    evenly spread over the belly with radii BELLY_PROFILE × r, r chosen so that the radius
    profile (piecewise linear along the axis, closing at the poles) holds volume V over the
    belly. Section positions are chosen as fractions of the rest arc length and written as
    curve parameters t (mapped through the rest axis). Circular sections; ``volume: exact``
    keeps the rest volume under motion.
    """
    pts = [(p.body, p.location) for p in m.points if p.active_at_rest]
    wpts = _world_points(skel, world, pts)
    path_length = float(np.sum(np.linalg.norm(np.diff(wpts, axis=0), axis=1)))
    axis = axis_control_points(skel, world, pts)
    t_of, axis_length = _arc_parameter(skel, world, axis)
    pcsa = m.max_isometric_force / SPECIFIC_TENSION
    volume = pcsa * m.optimal_fiber_length
    tendon = min(m.tendon_slack_length / axis_length, MAX_TENDON_FRACTION) if axis_length > 0 else 0.0
    t_o, t_i = ORIGIN_TENDON_SHARE * tendon, (1.0 - ORIGIN_TENDON_SHARE) * tendon
    r_t = math.sqrt(m.max_isometric_force / TENDON_STRESS / math.pi)
    belly = 1.0 - t_o - t_i
    ss = [t_o + belly * (k + 0.5) / len(BELLY_PROFILE) for k in range(len(BELLY_PROFILE))]  # arc fractions
    r = _belly_radius(volume, axis_length, t_o, 1.0 - t_i, ss, r_t)
    sections = []
    if t_o > 0.02:
        sections.append({"t": t_of(t_o / 2.0), "radii": [r_t, r_t], "angle": 0.0})
    for s_, f in zip(ss, BELLY_PROFILE):
        sections.append({"t": t_of(s_), "radii": [max(f * r, r_t), max(f * r, r_t)], "angle": 0.0})
    if t_i > 0.02:
        sections.append({"t": t_of(1.0 - t_i / 2.0), "radii": [r_t, r_t], "angle": 0.0})
    doc = {
        "muscle": m.name,
        "color": muscle_color(m.name),
        "volume": "exact",
        "axis": [{"bone": b, "at": at} for b, at in axis],
        "sections": sections,
        "tendons": [t_o, t_i],
    }
    conditional = [p.name for p in m.points if p.kind == "conditional"]
    dropped = [p.name for p in m.points if not p.active_at_rest]
    moving = [p.name for p in m.points if p.kind == "moving"]
    row = {"muscle": m.name, "type": m.type, "path_points": len(m.points), "control_points": len(axis),
           "rest_axis_length": axis_length,
           "conditional": conditional, "conditional_inactive_at_rest": dropped, "moving": moving,
           "wraps": list(m.wraps), "rest_path_length": path_length, "pcsa_m2": pcsa, "volume_m3": volume,
           "belly_radius": r, "tendon_radius": r_t, "tendons": [t_o, t_i]}
    return doc, rounded(row)


def _arc_parameter(skel: Skeleton, world: np.ndarray, axis) -> tuple:
    """The rest axis' arc-length fraction → curve parameter map, and its length.

    Sections are placed by curve parameter t, tendons by arc length (docs/FORMATS.md); via
    points crowd control points (and so parameter range) where the path turns, so belly and
    tendon positions chosen along the length are mapped to t through the rest curve."""
    from axdf_cli import bspline

    ctrl = _world_points(skel, world, axis)  # (n, 3)
    ts = np.linspace(0.0, 1.0, 2001)
    # C[s, c] = sum_i N[s, i] ctrl[i, c]
    c = np.einsum("si,ic->sc", bspline.basis_matrix(bspline.clamped_knots(len(ctrl), 2), 2, ts), ctrl)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    length = float(arc[-1])
    frac = arc / length if length > 0 else ts

    def t_of(x: float) -> float:
        return float(np.interp(x, frac, ts))

    return t_of, length


def _belly_radius(volume: float, length: float, a: float, b: float, ts: list[float], r_t: float) -> float:
    """Largest belly radius r so that the piecewise-linear radius profile through
    (a, r_t), (ts_k, BELLY_PROFILE_k·r), (b, r_t) encloses ``volume`` over [a, b]·length."""
    xs = [a] + list(ts) + [b]

    def vol(r):
        rs = [r_t] + [f * r for f in BELLY_PROFILE] + [r_t]
        v = 0.0
        for (x0, r0), (x1, r1) in zip(zip(xs, rs), zip(xs[1:], rs[1:])):
            v += math.pi * (x1 - x0) * length * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0
        return v

    lo, hi = 0.0, 1.0
    if vol(hi) < volume:
        return hi
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if vol(mid) < volume else (lo, mid)
    return 0.5 * (lo + hi)


def rest_world(skel: Skeleton) -> np.ndarray:
    """(B, 4, 4) world transforms at the rest pose."""
    return forward_kinematics(skel, skel.rest_coordinates()[None, :])[0]


# ----------------------------------------------------------------------------- YAML text

#: Positions are rounded to this many decimals of a metre (0.1 µm): OpenSim path points and
#: joint frames are given to 0.1 mm or coarser; float noise is ~1e-17 m.
POSITION_DECIMALS = 7
#: Keys whose numbers are positions in metres.
POSITION_KEYS = frozenset({"offset", "post_offset", "at"})
#: Significant digits of every other number (angles, radii, fractions, activations, function
#: values): ~1e-9 relative, far below anything the model resolves and above float noise.
SIGNIFICANT_DIGITS = 9


def round_number(v: float, key=None) -> float:
    """``v`` rounded to what it means: see POSITION_DECIMALS and SIGNIFICANT_DIGITS."""
    if key in POSITION_KEYS:
        return round(v, POSITION_DECIMALS) + 0.0  # + 0.0: no negative zero
    return float(f"{v:.{SIGNIFICANT_DIGITS}g}") + 0.0


def rounded(doc, key=None):
    """A copy of a document (dicts, lists, scalars) with every float rounded by
    :func:`round_number`; a list's numbers are rounded as its key says."""
    if isinstance(doc, dict):
        return {k: rounded(v, k) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [rounded(v, key) for v in doc]
    if isinstance(doc, float) and math.isfinite(doc):
        return round_number(doc, key)
    return doc

_PLAIN = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-/]*$")


def _scalar(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"non-finite number {v!r}")
        if v == 0.0:
            v = 0.0  # no negative zero
        s = repr(v)
        if "e" in s and "." not in s.split("e")[0]:
            m, e = s.split("e")
            s = f"{m}.0e{e}"  # YAML 1.1 (PyYAML) floats need a dot
        return s
    if v is None:
        return "null"
    s = str(v)
    if _PLAIN.match(s) and yaml.safe_load(s) == s:
        return s
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _flow(v) -> str:
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_scalar(k)}: {_flow(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_flow(x) for x in v) + "]"
    return _scalar(v)


def _simple(v) -> bool:
    if isinstance(v, (list, tuple)):
        return all(not isinstance(x, (dict, list, tuple)) for x in v)
    return not isinstance(v, dict)


def _inline_ok(v, limit: int = 120) -> bool:
    """Small mappings of simple values, and lists of scalars, go on one line."""
    if isinstance(v, (list, tuple)):
        return _simple(v)
    if isinstance(v, dict):
        return all(_simple(x) or (isinstance(x, dict) and _inline_ok(x, limit)) for x in v.values()) and \
            len(_flow(v)) <= limit
    return True


#: Mappings whose entries are always written on one line each (pose keys, activation curves).
FLOW_CHILDREN = ("keys", "activation", "coordinates")


def dump_yaml(doc, header: str = "") -> str:
    """Block-style YAML with flow-style vectors and small mappings, numbers :func:`rounded`;
    deterministic."""
    doc = rounded(doc)
    lines: list[str] = []
    if header:
        lines += ["# " + h if h else "#" for h in header.splitlines()]

    def block(x) -> bool:
        return isinstance(x, (dict, list, tuple)) and bool(x) and not _inline_ok(x)

    def emit(v, indent: int, flow_children: bool = False):
        pad = " " * indent
        if isinstance(v, dict):
            for k, x in v.items():
                key = _scalar(k)
                if block(x) and not flow_children:
                    lines.append(f"{pad}{key}:")
                    emit(x, indent + 2, k in FLOW_CHILDREN)
                else:
                    lines.append(f"{pad}{key}: {_flow(x)}")
        elif isinstance(v, (list, tuple)):
            for x in v:
                if isinstance(x, dict) and block(x):
                    saved = lines[:]
                    lines.clear()
                    emit(x, indent + 2)
                    sub = lines[:]
                    lines[:] = saved
                    lines.append(f"{pad}- {sub[0][indent + 2:]}")
                    lines.extend(sub[1:])
                else:
                    lines.append(f"{pad}- {_flow(x)}")
        else:
            lines.append(pad + _scalar(v))

    emit(doc, 0)
    return "\n".join(lines) + "\n"
