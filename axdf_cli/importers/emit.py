"""The one emitter of every importer: a neutral :class:`~axdf_cli.importers.model.ImportedModel`
→ the bytes of its skeleton, bone meshes, muscles, pose, ``import_report.json`` and
``IMPORT.md`` (:func:`build_import`), and the deterministic YAML text they are written in.

Output is deterministic: no timestamps, no absolute paths, keys in a fixed order. Numbers
are written rounded to what they mean (:func:`rounded`): positions (``offset``,
``post_offset``, an axis point's ``at``) to 0.1 µm, everything else to 9 significant digits.
The digits beyond come from matrix products whose last bits differ between CPUs and BLAS
builds; rounding them away keeps the files readable and (but for a rare value on a
rounding boundary) the same on every machine.

Muscles are sized by one belly law (:func:`belly_doc`) from their Hill numbers, their axis
control points chosen by one rule (:func:`axis_points_for`), whatever format they came from.
"""
from __future__ import annotations

import colorsys
import functools
import hashlib
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.outputs import UniqueFiles
from axdf_cli.formats.ply import PlyWriter
from axdf_cli.importers.model import Hill, ImportedModel, Motion, Outputs
from axdf_cli.importers.volumes import Sized, Subject, regression_volumes
from axdf_cli.importers.result import SIDE_SUFFIX, ImportResult, import_markdown, relative_ref, strip_dirs, yaml_number
from axdf_cli.model.jiggle import JiggleSpec
from axdf_cli.model.skeleton import Constant, Linear, Multiplier, Polynomial, Skeleton, Spline, forward_kinematics

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


# ----------------------------------------------------------------------------- muscles


def _hex(rgb) -> str:
    return "#{:02x}{:02x}{:02x}".format(*(round(c * 255) for c in rgb))


def hashed_color(name: str) -> str:
    """A deterministic colour from the muscle's name: any hue (sha256), muscle-like saturation."""
    h = hashlib.sha256(name.encode()).digest()
    return _hex(colorsys.hsv_to_rgb(h[0] / 255.0, 0.45 + 0.3 * h[1] / 255.0, 0.7 + 0.25 * h[2] / 255.0))


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


def function_doc(fn) -> dict:
    """A skeleton function (:mod:`axdf_cli.model.skeleton`) as the axdf file writes it."""
    if isinstance(fn, Constant):
        return {"constant": fn.value}
    if isinstance(fn, Linear):
        return {"linear": [fn.slope, fn.intercept]}
    if isinstance(fn, Polynomial):
        return {"polynomial": list(fn.coefficients)}
    if isinstance(fn, Spline):
        return {"spline": {"x": [float(v) for v in fn.x], "y": [float(v) for v in fn.y], "kind": fn.kind}}
    if isinstance(fn, Multiplier):
        return {"multiplier": {"scale": fn.scale, "function": function_doc(fn.function)}}
    raise TypeError(f"unknown function {fn!r}")


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


def belly_doc(name: str, path: list, wraps: list, hill: Hill, skel: Skeleton, world: np.ndarray,
              palette: str = "anatomical", axis_points: int = 0, min_slenderness: float = 0.0,
              jiggle: JiggleSpec | None = None, volume: float | None = None) -> tuple[dict, dict]:
    """A path muscle's YAML document sized by its model's own numbers, and its summary row
    (unrounded): the path and wrap documents ``path``, ``wraps``, and the muscle's Hill numbers.

    The belly law (docs/IMPORTERS.md), from the model's own numbers:

    - volume V = PCSA × optimal fibre length, PCSA = F_max / SPECIFIC_TENSION (a pennate
      muscle's fibres are short, but there are many of them side by side: V holds), unless
      ``volume`` (m³) is given (the subject's regression, :mod:`axdf_cli.importers.volumes`);
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

    max_force, fibre_length, tendon_slack, pennation = hill.max_force, hill.fibre_length, hill.tendon_slack, \
        hill.pennation
    rest_ctrl, path_length = rest_path(name, path, wraps, skel, world, axis_points)
    t_of, axis_length = _arc_parameter_of(rest_ctrl)
    pcsa = max_force / SPECIFIC_TENSION
    volume = pcsa * fibre_length if volume is None else volume
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


# ----------------------------------------------------------------------------- the import


def skeleton_doc(model: ImportedModel, meshes: dict[str, str]) -> dict:
    """The skeleton YAML document. ``meshes``: bone → mesh path relative to the skeleton file."""
    doc: dict = {"skeleton": model.name}
    if model.coordinates:
        doc["coordinates"] = {c.name: c.doc() for c in model.coordinates}
    doc["bones"] = [b.doc(meshes.get(b.name)) for b in model.bones]
    return doc


def pose_doc(motion: Motion, skeleton_ref: str) -> dict:
    """The pose YAML document of a motion, referring to its skeleton by ``skeleton_ref``."""
    doc = {"pose": motion.name, "skeleton": skeleton_ref, "fps": yaml_number(motion.fps),
           "frames": [0, motion.frames - 1], "interpolation": "linear", "keys": motion.keys}
    if motion.activation:
        doc["activation"] = motion.activation
    return doc


def check_vertices(v: np.ndarray, where, what: str) -> None:
    """Bone mesh vertices (metres) as a PLY may hold them: finite and within ±MAX_ABS_NUMBER
    (a PLY stores float32: 1e300 would become inf, which ``axdf validate`` refuses), and not
    collapsed to a point (a scale of 0, or one that underflows float32).
    ``where``: the mark of the mesh in its model; ``what`` names it."""
    v = np.asarray(v, dtype=np.float64)
    bad = ~np.isfinite(v) | (np.abs(v) > tol.MAX_ABS_NUMBER)
    if bad.any():
        i, k = (int(x) for x in np.argwhere(bad)[0])
        raise InputError(where, f"{what}: vertex {i} has {'xyz'[k]} = {float(v[i, k]):g} m once placed",
                         f"finite coordinates within ±{tol.MAX_ABS_NUMBER:g} m (check the mesh file, its scale "
                         "and its frame)")
    size = float(np.ptp(v.astype(np.float32), axis=0).max()) if len(v) > 1 else 0.0  # (as the PLY holds it)
    if len(v) > 1 and size < tol.IMPORT_MIN_MESH_SIZE:
        raise InputError(where, f"{what}: {size:g} m across once placed (scaled to a point)",
                         f"a mesh at least {tol.IMPORT_MIN_MESH_SIZE:g} m across (check its scale: 0 or a "
                         "vanishing scale collapses it)")


def body_ply(parts: list[tuple[np.ndarray, np.ndarray]], where=None, what: str = "bone mesh") -> bytes:
    """One body's meshes (vertices, faces) merged into the bytes of one binary PLY; vertices
    are checked (:func:`check_vertices`) as a backstop of the readers' own checks."""
    vs, ts, base = [], [], 0
    for v, f in parts:
        vs.append(v)
        ts.append(f + base)
        base += len(v)
    verts = np.concatenate(vs)
    check_vertices(verts, where, what)
    return PlyWriter(np.concatenate(ts)).encode(verts)


def motion_coordinates(skel: Skeleton, motion: Motion) -> np.ndarray:
    """The coordinates (F, C) of every frame of a motion on ``skel`` (keyed ones as given, the
    others at rest, coupled ones following): what ``axdf run`` samples there."""
    q = np.broadcast_to(skel.rest_coordinates(), (len(motion.keys), len(skel.coordinates))).copy()
    cidx = skel.coord_index
    for f, row in enumerate(motion.keys.values()):
        for c, v in row.items():
            q[f, cidx[c]] = v
    return skel.couple(q)


def probe_poses(skel: Skeleton, motion_q: np.ndarray | None = None) -> np.ndarray:
    """Coordinates (P, C) of the poses the axes are measured on besides the motion: the rest
    pose and AXIS_PROBE_POSES poses with every ranged coordinate uniform in its range (seeded:
    the same poses every import), then the motion's frames ``motion_q`` (:func:`motion_poses`)."""
    rng = np.random.default_rng(tol.AXIS_PROBE_SEED)
    q = np.tile(skel.rest_coordinates(), (tol.AXIS_PROBE_POSES + 1, 1))
    for i, c in enumerate(skel.coordinates):
        if c.range is not None:
            q[1:, i] = rng.uniform(c.range[0], c.range[1], size=tol.AXIS_PROBE_POSES)
    q = skel.couple(q)
    return q if motion_q is None else np.concatenate([q, motion_poses(skel, motion_q)[1:]])


def muscle_docs(model: ImportedModel, skel: Skeleton, world: np.ndarray, palette: str,
                motion_q: np.ndarray | None, subject: Subject | None = None) -> list[tuple]:
    """(muscle, document, rounded report row) of every muscle, sized by :func:`belly_doc`;
    with a ``subject``, the lower limb muscles' volumes by its regression
    (:func:`~axdf_cli.importers.volumes.regression_volumes`)."""
    rules = model.rules
    probe = probe_poses(skel, motion_q) if rules.probe_ranges else motion_poses(skel, motion_q)
    by_regression = {} if subject is None else regression_volumes(
        [(m.name, m.hill.max_force if m.hill is not None else m.force) for m in model.muscles], subject)
    out = []
    for m in model.muscles:
        given = by_regression.get(m.name)
        try:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a non-finite result is refused below
                sized = _sized_muscle(m, skel, world, palette, probe, rules, given)
            if sized is not None and not all(math.isfinite(v) for v in sized[4].values() if isinstance(v, float)):
                raise ValueError("a size is not finite")
        except InputError as e:  # a generated document: name the muscle in its model, not "<name>"
            raise InputError(m.mark, f"muscle {m.name!r}: the belly sized from the model's numbers would not pass "
                             f"axdf validate ({e})", "a path and Hill numbers of a real muscle") from None
        except (ArithmeticError, ValueError) as e:  # a number beyond what the belly law can size
            raise InputError(m.mark, f"muscle {m.name!r}: its numbers cannot size a belly ({type(e).__name__}: {e})",
                             "a path and Hill numbers of a real muscle") from None
        if sized is None:
            why = (f"its path is shorter than {tol.IMPORT_MIN_PATH_LENGTH * 1000:g} mm at rest (a path through one "
                   "point twice, or through coincident points): no belly to build along it")
            model.ignored.append({"kind": "muscle", "name": m.name, "where": str(m.mark or ""), "why": why})
            model.warnings.append(f"{_where(m)}muscle {m.name!r} skipped: {why}")
            continue
        path, wraps, axis, doc, row = sized
        if given is not None:
            row.update({"volume_law": "handsfield2014", "volume_group": given.group, "volume_share": given.share,
                        "pcsa_volume_m3": row["pcsa_m2"] * row["optimal_fiber_length"]})
        elif subject is not None:
            row["volume_law"] = "pcsa"
        row.update(m.row)
        row.update({"path_points": len(path), "wraps": [w["name"] for w in wraps]})
        if rules.shortfall:
            row["axis_shortfall"] = axis.error
        if axis.raised:  # the worst shortfall over the poses at the default count and at the count written
            row["axis_points_raised"] = axis.row()
        out.append((m, doc, rounded(row)))
        size = max(row["rest_path_length"], 2.0 * row["belly_radius"])
        if size > min(tol.IMPORT_PLAUSIBLE_PATH, 2.0 * tol.IMPORT_PLAUSIBLE_BELLY) and (
                row["rest_path_length"] > tol.IMPORT_PLAUSIBLE_PATH or 2.0 * row["belly_radius"] > tol.IMPORT_PLAUSIBLE_BELLY):
            model.warnings.append(f"{_where(m)}muscle {m.name!r} is {row['rest_path_length']:.3g} m long with a belly "
                                  f"{2.0 * row['belly_radius']:.3g} m across: beyond any human or animal muscle "
                                  f"(paths up to {tol.IMPORT_PLAUSIBLE_PATH:g} m, bellies up to "
                                  f"{tol.IMPORT_PLAUSIBLE_BELLY:g} m); is the model in other units than metres?")
    if model.rules.report and not out:
        model.warnings.append(f"{_where_model(model)}no muscle with a path to import: only the skeleton"
                              + (" and its bone meshes are" if model.meshes else " is") + " written")
    return out


def _where(m) -> str:
    return f"{m.mark}: " if m.mark is not None else ""


def _where_model(model: ImportedModel) -> str:
    return f"{model.inputs[0]}: " if model.inputs else ""


def _sized_muscle(m, skel: Skeleton, world: np.ndarray, palette: str, probe: np.ndarray, rules,
                  given: Sized | None = None) -> tuple | None:
    """(path, wraps, axis points, document, row) of one muscle, or None when its path is too
    short at rest to hold a belly (then listed as not imported, with a warning)."""
    path = [point_doc(p) for p in m.path]
    wraps = [wrap_doc(w) for w in m.wraps]
    rest = rest_path(m.name, path, wraps, skel, world)[1]
    if not rest >= tol.IMPORT_MIN_PATH_LENGTH:
        return None
    hill = m.hill
    if hill is None:  # fibres a share of the rest path, the rest of it tendon slack
        hill = Hill(m.force, m.fibre_share * rest, rest - m.fibre_share * rest)
    axis = axis_points_for(m.name, path, wraps, skel, probe)
    doc, row = belly_doc(m.name, path, wraps, hill, skel, world, palette, axis.n if axis.raised else 0,
                         rules.min_slenderness, m.jiggle, None if given is None else given.volume)
    return path, wraps, axis, doc, row


def build_import(model: ImportedModel, outputs: Outputs, palette: str = "anatomical", files: dict | None = None,
                 subject: Subject | None = None) -> ImportResult:
    """Every output file's bytes of an imported model (nothing is written here).

    Layout (defaults under ``outputs.out``): ``skeletons/NAME.yaml``, ``skeletons/meshes/NAME/*.ply``,
    ``muscles/MUSCLE.yaml``, ``POSE.yaml`` (with a motion), and with the rules' report
    ``import_report.json`` and ``IMPORT.md``. Paths written inside the files are relative to
    the file holding them. ``palette``: muscle colours, a key of :data:`PALETTES`. ``files``:
    the mapping the files go into (default: one that refuses a path twice). ``subject``: size
    the lower limb muscles by its height and mass (:mod:`axdf_cli.importers.volumes`; None:
    every muscle by PCSA × optimal fibre length).
    """
    out_dir = Path(outputs.out)
    motion = model.motion
    skel_path = Path(outputs.skeleton) if outputs.skeleton else out_dir / "skeletons" / f"{model.name}.yaml"
    mesh_dir = Path(outputs.meshes) if outputs.meshes else skel_path.parent / "meshes" / model.name
    mus_dir = Path(outputs.muscles) if outputs.muscles else out_dir / "muscles"
    pose_path = (Path(outputs.pose) if outputs.pose else out_dir / f"{motion.name}.yaml") if motion else None
    files = UniqueFiles() if files is None else files  # a path twice: exit 2, never one file lost
    mesh_refs = {}
    for bone, data in model.meshes.items():
        p = mesh_dir / f"{bone}.ply"
        files[str(p)] = data
        mesh_refs[bone] = relative_ref(p, skel_path.parent)
    text = dump_yaml(skeleton_doc(model, mesh_refs), model.header)
    files[str(skel_path)] = text.encode()
    if motion is not None:
        pose = dump_yaml(pose_doc(motion, relative_ref(skel_path, pose_path.parent)), motion.header).encode()
        if motion.mark is not None and len(pose) > tol.YAML_MAX_BYTES:
            raise InputError(motion.mark, f"the pose would be {len(pose)} bytes ({motion.frames} frames)",
                             f"axdf reads YAML files up to {tol.YAML_MAX_BYTES} bytes; {motion.remedy}")
        files[str(pose_path)] = pose
    report = model.report
    layout = {"muscles": mus_dir, "skeleton": skel_path, "pose": pose_path}
    if not model.rules.report:
        return ImportResult(files, report, model.warnings, model.inputs, model.assets, layout)
    from axdf_cli.specs import RefPolicy, parse_skeleton_text

    try:  # the file as axdf will read it back; its mesh references name files this import writes
        skel = parse_skeleton_text(text, skel_path, RefPolicy(allow_outside=True))
    except InputError as e:  # a limit of the file format that the model's numbers exceed
        if model.refuse_at is None:
            raise
        raise InputError(model.refuse_at, f"the skeleton {skel_path.name} would not pass axdf validate ({e})",
                         "numbers and names within what axdf files hold") from None
    world = rest_world(skel)
    motion_q = motion_coordinates(skel, motion) if motion is not None else None
    rows = []
    for m, doc, row in muscle_docs(model, skel, world, palette, motion_q, subject):
        rows.append(row)
        files[str(mus_dir / f"{m.name}.yaml")] = dump_yaml(doc, m.header).encode()
    report["muscles"] = rows
    report.setdefault("settings", {})["palette"] = palette
    if subject is not None:
        report["settings"]["volumes"] = {"law": "handsfield2014", "height_m": subject.height, "mass_kg": subject.mass,
                                         "lower_limb_total_cm3": round(subject.total_cm3, 3)}
    model.complete(report)
    report["ignored"] = [dict(i, where=strip_dirs(i["where"], model.strip)) for i in model.ignored]
    report["warnings"] = [strip_dirs(w, model.strip) for w in model.warnings]
    report["files"] = sorted(relative_ref(Path(p), out_dir) for p in files)
    files[str(out_dir / "import_report.json")] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[str(out_dir / "IMPORT.md")] = import_markdown(report, model.intro(report), model.poses,
                                                        model.rules).encode()
    return ImportResult(files, report, model.warnings, model.inputs, model.assets, layout)


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

_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-/]*")  # (fullmatch: "a\n" is no plain scalar)


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
    return bool(_PLAIN.fullmatch(s)) and _RESOLVER.resolve(yaml.ScalarNode, s, (True, False)) == _STR_TAG


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
