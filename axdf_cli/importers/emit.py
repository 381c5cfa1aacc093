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
- Coupled coordinates: the dependent coordinate of a ``CoordinateCouplerConstraint`` is
  written ``follows: {coord: INDEPENDENT, function: scale · f}`` (no default, no range: the
  skeleton sets it from the coordinate it follows), its function converted like a DOF's
  (input in the independent coordinate's units, output in its own).
- Units: rotational coordinates and rotation outputs rad → degrees. A function
  ``y = f(x)`` in OpenSim units becomes ``y' = k_out · f(k_in · x')`` with
  ``k_in = π/180`` for a rotational coordinate and ``k_out = 180/π`` for a rotation axis:
  spline knots x / k_in and values y · k_out, linear slope · k_in · k_out, polynomial
  c_i · k_out · k_in^i, multiplier scales unchanged (its inner function converted).
- Muscles: see :func:`muscle_doc` (axis control points, sections, tendons, colour).
"""
from __future__ import annotations

import colorsys
import functools
import hashlib
import math
import re
from dataclasses import dataclass

import numpy as np
import yaml

from axdf_cli.errors import InputError, Mark
from axdf_cli.importers.osim import Axis, FConst, FLinear, FMult, FPoly, FSpline, Model, Muscle
from axdf_cli.model.jiggle import JiggleSpec
from axdf_cli.model.skeleton import Skeleton, Spline, forward_kinematics

DEG = 180.0 / math.pi

#: Specific tension σ (N/m²) turning max isometric force into PCSA. 0.6 MPa: inside the
#: 0.3-1 MPa range reported for human muscle, the 61 N/cm² of the lower-limb model of Arnold
#: et al. (2010). A lower σ would make every muscle thicker (PCSA ∝ 1/σ).
SPECIFIC_TENSION = 0.6e6
#: Stress in a tendon at the muscle's max isometric force (N/m²), sizing tendon sections:
#: human tendons carry roughly 30-100 MPa at maximal force; 50 MPa is the middle.
TENDON_STRESS = 50e6
#: Share of OpenSim's tendon slack length that is free tendon, outside the belly. A Hill-type
#: model's tendon is the whole series elastic element, free tendon plus aponeurosis (Zajac
#: 1989); the aponeuroses lie inside the belly, along the fibres. The model does not say how
#: the slack length divides; half puts the long leg muscles' bellies at 19-27 cm (the order of
#: their cadaver lengths), where the whole slack length would leave the gastrocnemius 6 cm.
FREE_TENDON_SHARE = 0.5
#: Upper bound on the free tendons' share of the rest path, so a belly always remains.
MAX_TENDON_FRACTION = 0.7
#: How the free tendon splits between origin and insertion: insertion tendons are usually
#: the longer ones (Achilles, quadriceps, biceps distal).
ORIGIN_TENDON_SHARE = 0.4
#: The belly's radius profile: (position along the belly 0..1, radius / widest radius), a
#: spindle close to sin(πx)^0.3 (a long middle) that tapers into the tendons at both ends.
BELLY_PROFILE = ((0.04, 0.45), (0.15, 0.8), (0.32, 0.97), (0.5, 1.0), (0.68, 0.97), (0.85, 0.8), (0.96, 0.45))
#: Sections inside a free tendon, as fractions of it from its bone; a tendon shorter than
#: MIN_TENDON_FRACTION of the path gets none (the belly tapers into the attachment).
TENDON_SECTIONS = (0.3, 0.75)
MIN_TENDON_FRACTION = 0.02

#: Secondary motion (``jiggle:``, README "Jiggle") of the calf's and the thigh's muscles, by
#: name without the side suffix (OpenSim's gait2392/gait2354 names). Soft tissue of the leg
#: rings at 10-50 Hz after a heel strike (Wakeling & Nigg 2001, skin-mounted accelerometers);
#: animators' jiggle sits lower (a few Hz: a slow, visible sway). We take the bottom of the
#: measured range: it still shows at the library's 60 fps (6 frames per cycle; above half the
#: frame rate a ring aliases) and keeps a hard landing's sag to about 2 cm (the amplitude of a
#: stop goes as speed / (2 pi f)), where 5 Hz sagged the calf by 4 cm. The thigh's bellies are
#: heavier: a little lower. Relaxed, damping 0.2 lets a stop ring for about two visible cycles
#: (each extremum 0.53 of the last). A tensed muscle rings faster and dies out sooner (measured
#: frequency and damping both rise with muscle force).
JIGGLE_CALF = JiggleSpec(10.0, 0.2, tensed_frequency=16.0, tensed_damping_ratio=0.45)
JIGGLE_THIGH = JiggleSpec(8.0, 0.2, tensed_frequency=14.0, tensed_damping_ratio=0.45)
JIGGLE = {**{m: JIGGLE_CALF for m in ("med_gas", "lat_gas", "soleus", "tib_ant", "tib_post", "per_long",
                                      "per_brev", "per_tert", "ext_dig", "ext_hal", "flex_dig", "flex_hal")},
          **{m: JIGGLE_THIGH for m in ("rect_fem", "vas_med", "vas_int", "vas_lat", "bifemlh", "bifemsh",
                                       "semimem", "semiten", "sar", "grac", "add_long", "add_brev", "add_mag1",
                                       "add_mag2", "add_mag3")}}


def jiggle_doc(spec: JiggleSpec) -> dict:
    """A muscle's ``jiggle:`` mapping (docs/FORMATS.md), optional keys only when set."""
    d = {"frequency": spec.frequency, "damping_ratio": spec.damping_ratio}
    if spec.weight is not None:
        d["weight"] = list(spec.weight)
    tensed = {k: v for k, v in (("frequency", spec.tensed_frequency), ("damping_ratio", spec.tensed_damping_ratio))
              if v is not None}
    if tensed:
        d["tensed"] = tensed
    return d


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
        if c.follows is not None:  # a CoordinateCouplerConstraint's dependent: no default, no range of its own
            k_in = math.pi / 180.0 if model.coordinates[c.follows].type == "rotation" else 1.0
            coords[c.name] = {"type": c.type, "follows": {"coord": c.follows,
                                                          "function": function_doc(convert_function(c.function, k_in, k))}}
            continue
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


def _hex(rgb) -> str:
    return "#{:02x}{:02x}{:02x}".format(*(round(c * 255) for c in rgb))


def hashed_color(name: str) -> str:
    """A deterministic colour from the muscle's name: any hue (sha256), muscle-like saturation."""
    h = hashlib.sha256(name.encode()).digest()
    return _hex(colorsys.hsv_to_rgb(h[0] / 255.0, 0.45 + 0.3 * h[1] / 255.0, 0.7 + 0.25 * h[2] / 255.0))


#: Side suffixes: a muscle and its mirror image share their anatomical colour.
SIDE_SUFFIX = re.compile(r"_[lr]$")


def srgb_to_linear(c: float) -> float:
    """IEC 61966-2-1: an sRGB (display) value in [0, 1] → linear (the muscle files' colours)."""
    return c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4


def anatomical_color(name: str) -> str:
    """A muscle red, varied per muscle so that neighbours stay apart. Chosen on screen (sRGB):
    hue 352°-10° (crimson to brick), saturation 0.6-0.85, value 0.5-0.8, each from its own
    byte of sha256 of the name without its side suffix (``_r``/``_l``: left and right of a
    muscle look alike); written linear, as muscle colours are."""
    h = hashlib.sha256(SIDE_SUFFIX.sub("", name).encode()).digest()
    hue = (352.0 + 18.0 * h[0] / 255.0) / 360.0 % 1.0
    rgb = colorsys.hsv_to_rgb(hue, 0.6 + 0.25 * h[1] / 255.0, 0.5 + 0.3 * h[2] / 255.0)
    return _hex([srgb_to_linear(c) for c in rgb])


#: ``axdf import osim --palette``: how muscles are coloured.
PALETTES = {"anatomical": anatomical_color, "hashed": hashed_color}


def _world_points(skel: Skeleton, world: np.ndarray, pts) -> np.ndarray:
    """Rest-pose world positions (n, 3) of points ``[(body, (x, y, z)), ...]``; world (B, 4, 4)."""
    bi = skel.bone_index
    return np.array([(world[bi[b]] @ np.append(p, 1.0))[:3] for b, p in pts])


def point_doc(p) -> dict:
    """One path point's document (a :class:`axdf_cli.model.paths.PathPoint`, axdf units)."""
    d: dict = {"bone": p.bone, "at": [float(v) for v in p.at]}
    mv = {ax: {"coord": a.coord, "function": function_doc(a.function)}
          for ax, a in zip("xyz", p.moving or ()) if a is not None}
    if mv:
        d["moving"] = mv
    if p.active is not None:
        coord, lo, hi = p.active
        d["active"] = {"coord": coord, "range": [float(lo), float(hi)]}
    return d


def wrap_doc(w) -> dict:
    """One wrap surface's document (a :class:`axdf_cli.model.paths.WrapSurface`)."""
    from axdf_cli.specs import WRAP_SIZE_KEYS

    d = {"name": w.name, "shape": w.shape, "bone": w.bone}
    if w.shape == "ellipsoid":
        d["radii"] = [float(v) for v in w.size]
    else:
        d.update({k: float(v) for k, v in zip(WRAP_SIZE_KEYS[w.shape], w.size)})
    d["at"] = [float(v) for v in w.at]
    d["orient"] = [float(v) for v in w.orient]
    if w.side is not None:
        d["side"] = {"bone": w.side[0], "at": [float(v) for v in w.side[1]]}
    if w.shape in ("mujoco_sphere", "mujoco_cylinder"):
        if tuple(w.range) != (-1, -1):
            d["range"] = [int(v) for v in w.range]
        if not w.active:
            d["active"] = False
        return d
    d["quadrant"] = w.quadrant
    if w.shape == "ellipsoid":
        d["method"] = w.method
    if tuple(w.range) != (-1, -1):
        d["range"] = [int(v) for v in w.range]
    if not w.active:
        d["active"] = False
    return d


def path_docs(model: Model, m: Muscle) -> tuple[list, list]:
    """The muscle's ``path`` (every path point; moving ones with their functions in axdf
    units, conditional ones with their ``active`` range) and ``wrap`` (its wrap surfaces,
    copied per muscle with the path wrap's range and method) documents."""
    from axdf_cli.model.paths import Moving, PathPoint, WrapSurface

    path = []
    for p in m.points:
        moving = None
        if p.moving is not None:
            if p.frame is not None:
                raise InputError(p.mark, f"moving point {p.name!r} of {m.name} is attached to an offset frame",
                                 "moving points attached to a body")
            moving = tuple(None if a is None else
                           Moving(a[0], convert_function(a[1], math.pi / 180.0 if model.coordinates[a[0]].type
                                                         == "rotation" else 1.0, 1.0)) for a in p.moving)
        active = None
        if p.condition is not None:
            coord, lo, hi = p.condition
            k = DEG if model.coordinates[coord].type == "rotation" else 1.0
            active = (coord, lo * k, hi * k)
        path.append(point_doc(PathPoint(p.body, tuple(p.location), moving, active)))
    wraps = []
    for pw in m.wraps:
        w = model.wrap_objects[pw.wrap]
        wraps.append(wrap_doc(WrapSurface(w.name, w.body, w.shape, tuple(w.size) + (0.0,) * (3 - len(w.size)),
                                          tuple(w.translation), tuple(_deg(w.rotation)), w.quadrant, pw.method,
                                          tuple(pw.range), w.active)))
    return path, wraps


@dataclass(frozen=True)
class AxisPoints:
    """How many axis control points an imported path muscle gets (:func:`axis_points_for`)."""

    n: int  # the count to write (the default when it is within the target)
    default: int  # the path's default count (``default_control_points``)
    error: float  # the largest |shortfall| over the measured poses at ``n``
    error_default: float  # ... at the default count

    @property
    def raised(self) -> bool:
        return self.n != self.default

    def row(self) -> dict:
        """The import report's ``axis_points_raised`` entry."""
        return {"from": self.default, "to": self.n, "shortfall_at_default": self.error_default, "shortfall": self.error}


def axis_point_counts(n_default: int) -> list[int]:
    """The counts tried after the default, fewest first: steps of AXIS_POINTS_STEP up to
    AXIS_POINTS_FINE_MAX, then of AXIS_POINTS_COARSE_STEP up to AXIS_POINTS_MAX."""
    from axdf_cli import tolerances as tol

    fine = range(n_default + tol.AXIS_POINTS_STEP, tol.AXIS_POINTS_FINE_MAX + 1, tol.AXIS_POINTS_STEP)
    start = max(n_default, tol.AXIS_POINTS_FINE_MAX) + tol.AXIS_POINTS_COARSE_STEP
    return [*fine, *range(start, tol.AXIS_POINTS_MAX + 1, tol.AXIS_POINTS_COARSE_STEP)]


def axis_points_for(name: str, path: list, wraps: list, skel: Skeleton, q: np.ndarray) -> AxisPoints:
    """The axis control points a path muscle needs over the poses ``q`` (P, C) (the importer's
    choice: the imported motion's frames, poses drawn in the joints' ranges; the rest pose
    among them). The axis is a smooth fit to the wrapped path and cuts its corners, so it
    falls short of it; the measure is :meth:`PathModel.shortfall` (``1 − axis length / path
    length``, the axis's arc length by Gauss-Legendre) and the error its largest magnitude
    over the poses. The default count is kept when its error is within AXIS_SHORTFALL_MAX;
    otherwise the first of :func:`axis_point_counts` that is, or the one with the least
    error when none is (one rule for ``import osim`` and ``import mjcf``)."""
    import dataclasses

    from axdf_cli import tolerances as tol
    from axdf_cli.fileio.yamlio import Fields
    from axdf_cli.model.paths.path import PathModel
    from axdf_cli.specs import parse_muscle_path

    spec = parse_muscle_path(Fields({"path": path, "wrap": wraps}, Mark(f"<{name}>"), "muscle"))
    world = forward_kinematics(skel, q)
    n0 = PathModel(spec, skel.bone_index, skel.coord_index).n

    def error(n: int) -> float:
        pm = PathModel(dataclasses.replace(spec, control_points=n), skel.bone_index, skel.coord_index)
        return float(np.max(np.abs(pm.shortfall(world, q))))

    e0 = error(n0)
    best = (e0, n0)
    if e0 > tol.AXIS_SHORTFALL_MAX:
        for n in axis_point_counts(n0):
            best = min(best, (error(n), n))
            if best[0] <= tol.AXIS_SHORTFALL_MAX:
                break
    return AxisPoints(best[1], n0, best[0], e0)


def motion_poses(skel: Skeleton, motion_q: np.ndarray | None) -> np.ndarray:
    """The poses (P, C) an OpenSim import measures its axes on: the rest pose and the imported
    motion's frames (at most AXIS_FIT_FRAMES of them, evenly spread)."""
    from axdf_cli import tolerances as tol

    q = skel.rest_coordinates()[None]
    if motion_q is not None and len(motion_q):
        pick = np.unique(np.linspace(0, len(motion_q) - 1, min(len(motion_q), tol.AXIS_FIT_FRAMES)).astype(np.int64))
        q = np.concatenate([q, motion_q[pick]])
    return q


def muscle_doc(m: Muscle, skel: Skeleton, world: np.ndarray, model: Model | None = None,
               palette: str = "anatomical", motion_q: np.ndarray | None = None) -> tuple[dict, dict]:
    """One OpenSim muscle's YAML document and summary row for the import report: its path
    (:func:`path_docs`) sized by :func:`belly_doc` from its Hill-type parameters, with the
    calf's and thigh's jiggle (``JIGGLE``). ``axis_points`` is written when the rest pose
    and the imported motion ``motion_q`` (F, C) need more than the default
    (:func:`axis_points_for` over :func:`motion_poses`)."""
    path, wraps = path_docs(model, m)
    axis = axis_points_for(m.name, path, wraps, skel, motion_poses(skel, motion_q))
    doc, row = belly_doc(m.name, path, wraps, m.max_isometric_force, m.optimal_fiber_length, m.tendon_slack_length,
                         m.pennation_angle, skel, world, palette, axis.n if axis.raised else 0,
                         jiggle=JIGGLE.get(SIDE_SUFFIX.sub("", m.name)))
    row.update({"type": m.type, "path_points": len(m.points),
                "conditional": [p.name for p in m.points if p.kind == "conditional"],
                "conditional_inactive_at_rest": [p.name for p in m.points if not p.active_at_rest],
                "moving": [p.name for p in m.points if p.kind == "moving"], "wraps": [w.wrap for w in m.wraps]})
    if axis.raised:  # the worst shortfall over the motion at the default count and at the count written
        row["axis_points_raised"] = axis.row()
    return doc, rounded(row)


def belly_doc(name: str, path: list, wraps: list, max_force: float, fibre_length: float, tendon_slack: float,
              pennation: float, skel: Skeleton, world: np.ndarray, palette: str = "anatomical",
              axis_points: int = 0, min_slenderness: float = 0.0,
              jiggle: JiggleSpec | None = None) -> tuple[dict, dict]:
    """A path muscle's YAML document sized by its model's own numbers, and its summary row
    (unrounded): the path and wrap documents ``path``, ``wraps``, the max isometric force (N),
    optimal fibre length, tendon slack length (m) and pennation (rad).

    The belly law (README, "OpenSim models"), from the model's own numbers:

    - volume V = PCSA × optimal fibre length, PCSA = F_max / SPECIFIC_TENSION (a pennate
      muscle's fibres are short, but there are many of them side by side: V holds);
    - free tendon = FREE_TENDON_SHARE × tendon slack length, but no longer than what leaves the
      belly its fibres' projection (optimal fibre length × cos pennation) and at most
      MAX_TENDON_FRACTION of the path; split ORIGIN_TENDON_SHARE : rest between origin and
      insertion;
    - belly length = rest path length − free tendon: the belly fills the path between the free
      tendons (a pennate belly is much longer than its fibres);
    - belly sections: BELLY_PROFILE × R, R such that the written mesh's rest volume (the
      model's own surface, as ``axdf run`` builds it) is V plus the tendons' volume;
    - tendon sections (TENDON_SECTIONS inside each free tendon) of radius r_t with
      π r_t² = F_max / TENDON_STRESS; ``tendons`` are the free tendons' arc fractions.

    With ``min_slenderness`` (MuJoCo imports), a belly squatter than that at rest is thinned
    (R scaled down, the volume falls below the law's) until it is not; the row's
    ``thinned_from_radius`` keeps the law's R. ``axis_points`` (0: the path's default) is
    written into the document.

    Positions are fractions of the rest arc length written as curve parameters t (mapped
    through the rest axis); sections are circular; ``volume: exact`` keeps the rest volume.
    The row also carries the belly's slenderness (:mod:`axdf_cli.model.measure`) at rest.
    """
    from axdf_cli.model.measure import belly_slenderness

    rest_ctrl, path_length = rest_path(name, path, wraps, skel, world, axis_points)
    t_of, axis_length = _arc_parameter_of(rest_ctrl)
    pcsa = max_force / SPECIFIC_TENSION
    volume = pcsa * fibre_length
    fibres = fibre_length * math.cos(pennation)
    free = min(max(min(FREE_TENDON_SHARE * tendon_slack, path_length - fibres), 0.0),
               MAX_TENDON_FRACTION * path_length)
    belly_length = path_length - free
    t_o = ORIGIN_TENDON_SHARE * free / path_length
    t_i = free / path_length - t_o
    r_t = math.sqrt(max_force / TENDON_STRESS / math.pi)
    target = volume + math.pi * r_t * r_t * free  # the belly and the free tendons (tubes)
    fractions, factors = [], []  # (arc fraction, radius factor: None for a tendon section)
    if t_o > MIN_TENDON_FRACTION:
        fractions += [x * t_o for x in TENDON_SECTIONS]
        factors += [None] * len(TENDON_SECTIONS)
    fractions += [t_o + x * (1.0 - t_o - t_i) for x, _ in BELLY_PROFILE]
    factors += [f for _, f in BELLY_PROFILE]
    if t_i > MIN_TENDON_FRACTION:
        fractions += [1.0 - x * t_i for x in TENDON_SECTIONS[::-1]]
        factors += [None] * len(TENDON_SECTIONS)
    ts = [t_of(x) for x in fractions]

    def document(r: float) -> dict:
        sections = [{"t": t, "radii": [r_t, r_t] if f is None else [f * r, f * r], "angle": 0.0}
                    for t, f in zip(ts, factors)]
        return {"muscle": name, "color": PALETTES[palette](name), "volume": "exact", "path": path,
                **({"wrap": wraps} if wraps else {}), **({"axis_points": axis_points} if axis_points else {}),
                "sections": sections, "tendons": [t_o, t_i],
                **({"jiggle": jiggle_doc(jiggle)} if jiggle is not None else {})}

    # a first guess from the profile's mean squared radius, then the model's own exact-volume
    # solve (belly points scale, tendon points do not) gives the widest radius R
    mean_sq = float(np.mean([f * f for _, f in BELLY_PROFILE]))
    guess = math.sqrt(volume / (math.pi * belly_length * mean_sq))
    mm = _model(document(guess), name, skel, world)
    res = mm.evaluate(world[None], np.zeros(1), rest_volume=target, coords=skel.rest_coordinates()[None])
    r = guess * float(res.scale[0])
    doc = document(r)
    mm = _model(doc, name, skel, world)
    slender = belly_slenderness(mm.rest_vertices, mm.faces)
    law_radius = r
    for _ in range(6):  # a squat belly thinned to ``min_slenderness`` (its width scales with R)
        if slender.ratio >= min_slenderness:
            break
        r *= slender.ratio / min_slenderness * (1.0 - 1e-3)
        doc = document(r)
        mm = _model(doc, name, skel, world)
        slender = belly_slenderness(mm.rest_vertices, mm.faces)
    row = {"muscle": name, "control_points": len(rest_ctrl), "rest_axis_length": axis_length,
           "rest_path_length": path_length, "pcsa_m2": pcsa, "volume_m3": volume,
           "optimal_fiber_length": fibre_length, "pennation_deg": math.degrees(pennation),
           "tendon_slack_length": tendon_slack, "free_tendon": free, "belly_length": belly_length,
           "fibre_projection": fibres,
           "belly_radius": r, "tendon_radius": r_t, "tendons": [t_o, t_i], "rest_volume_m3": mm.v0,
           "slenderness": slender.ratio, "widest_diameter": slender.width}
    if r != law_radius:
        row["thinned_from_radius"] = law_radius
    return doc, row


def _model(doc: dict, name: str, skel: Skeleton, world: np.ndarray):
    """The muscle document as ``axdf run`` reads and builds it (rounded YAML text → model)."""
    from axdf_cli.specs import parse_muscle_text
    from axdf_cli.model.muscle import MuscleModel

    (spec,) = parse_muscle_text(dump_yaml(doc), f"<{name}>")
    return MuscleModel(spec, skel.bone_index, world, skel)


def rest_path(name: str, path: list, wraps: list, skel: Skeleton, world: np.ndarray, axis_points: int = 0):
    """The path documents read back through the loader, evaluated at the rest pose: the axis
    control points (n, 3) and the wrapped path's length."""
    from axdf_cli.specs import parse_muscle_path
    from axdf_cli.model.paths.path import PathModel
    from axdf_cli.fileio.yamlio import Fields

    doc = {"path": path, "wrap": wraps, **({"axis_points": axis_points} if axis_points else {})}
    spec = parse_muscle_path(Fields(doc, Mark(f"<{name}>"), "muscle"))
    pm = PathModel(spec, skel.bone_index, skel.coord_index)
    q = skel.rest_coordinates()[None]
    _, length, _ = pm.wrapped(world[None], q)
    ctrl, _ = pm.control_points(world[None], q)
    return ctrl[0], float(length[0])


def _arc_parameter_of(ctrl: np.ndarray) -> tuple:
    """The arc-length fraction → curve parameter map of the axis with control points ctrl,
    and its length."""
    from axdf_cli.model import bspline

    ts = np.linspace(0.0, 1.0, 2001)
    c = np.einsum("si,ic->sc", bspline.basis_matrix(bspline.clamped_knots(len(ctrl), 2), 2, ts), ctrl)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    length = float(arc[-1])
    frac = arc / length if length > 0 else ts

    def t_of(x: float) -> float:
        return float(np.interp(x, frac, ts))

    return t_of, length


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
    if _plain_string(s):
        return s
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


_RESOLVER = yaml.resolver.Resolver()
_STR_TAG = "tag:yaml.org,2002:str"


@functools.lru_cache(maxsize=1 << 20)
def _plain_string(s: str) -> bool:
    """Whether ``s`` may be written unquoted: it looks like a name and PyYAML's implicit
    resolvers read it back as this string (not ``true``, ``null``, ``on``, a number). The
    resolver's pattern match only: parsing every string as a document was most of an
    import's time."""
    return bool(_PLAIN.match(s)) and _RESOLVER.resolve(yaml.ScalarNode, s, (True, False)) == _STR_TAG


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


def _inline_text(v, limit: int = 120) -> str | None:
    """``v`` on one line (flow style) when it goes there: a scalar, a list of scalars, a small
    mapping of simple values (at most ``limit`` characters); else None. Each text is built
    once (it was built twice: to measure it, then to write it)."""
    if isinstance(v, (list, tuple)):
        return _flow(v) if _simple(v) else None
    if isinstance(v, dict):
        if not all(_simple(x) or isinstance(x, dict) for x in v.values()):
            return None
        parts = []
        n = 2
        for k, x in v.items():
            t = _flow(x) if _simple(x) else _inline_text(x, limit)
            if t is None:
                return None
            parts.append(f"{_scalar(k)}: {t}")
            n += len(parts[-1]) + 2
            if n > limit + 2:
                return None
        text = "{" + ", ".join(parts) + "}"
        return text if len(text) <= limit else None
    return _scalar(v)


def _inline_ok(v, limit: int = 120) -> bool:
    """Small mappings of simple values, and lists of scalars, go on one line."""
    return _inline_text(v, limit) is not None


#: Mappings whose entries are always written on one line each (pose keys, activation curves).
FLOW_CHILDREN = ("keys", "activation", "coordinates")


def dump_yaml(doc, header: str = "") -> str:
    """Block-style YAML with flow-style vectors and small mappings, numbers :func:`rounded`;
    deterministic."""
    doc = rounded(doc)
    lines: list[str] = []
    if header:
        lines += ["# " + h if h else "#" for h in header.splitlines()]

    def emit(v, indent: int, flow_children: bool = False):
        pad = " " * indent
        if isinstance(v, dict):
            for k, x in v.items():
                key = _scalar(k)
                text = _flow(x) if flow_children or not isinstance(x, (dict, list, tuple)) or not x \
                    else _inline_text(x)
                if text is None:
                    lines.append(f"{pad}{key}:")
                    emit(x, indent + 2, k in FLOW_CHILDREN)
                else:
                    lines.append(f"{pad}{key}: {text}")
        elif isinstance(v, (list, tuple)):
            for x in v:
                text = _inline_text(x) if isinstance(x, dict) and x else None
                if isinstance(x, dict) and x and text is None:
                    start = len(lines)  # the mapping's first line becomes the item's "- " line
                    emit(x, indent + 2)
                    lines[start] = f"{pad}- {lines[start][indent + 2:]}"
                else:
                    lines.append(f"{pad}- {text if text is not None else _flow(x)}")
        else:
            lines.append(pad + _scalar(v))

    emit(doc, 0)
    return "\n".join(lines) + "\n"
