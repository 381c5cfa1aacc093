"""Muscle files (``muscle:`` or a ``muscles:`` list of heads) → frozen
:class:`~axdf_cli.model.muscle.MuscleSpec` s, with their paths and wrap surfaces
(docs/FORMATS.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.model.jiggle import JiggleSpec
from axdf_cli.model.muscle import OCT, VOLUME_MODES, AxisPoint, ContactSpec, MuscleSpec, Section, outline_area
from axdf_cli.specs.kinds import kind_error
from axdf_cli.specs.skeleton import parse_function
from axdf_cli.fileio.yamlio import Fields, check_name, check_vector, item_marks, load_yaml



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
               "sections", "tendons", "twist", "resolution", "weights", "jiggle", "contact")
CONTACT_KEYS = ("group", "ignore", "yield")


def _parse_muscle(value, where: Mark, file: str, group: str = "") -> MuscleSpec:
    f = Fields(value, where, "muscle", keys=MUSCLE_KEYS)
    name = f.name("muscle", required=True)
    color = parse_color(f.raw("color"), f.vmark("color"), name)
    strength = f.number("strength", default=1.0, lo=0.0, hi=100.0, lo_open=True)
    tension = f.number("tension", default=0.0, lo=0.0, hi=1.0)
    volume = f.choice("volume", VOLUME_MODES, default="exact")
    path = parse_muscle_path(f) if f.has("path") else None
    axis_seq = f.seq("axis", required=path is None, default=[])
    # both: the axis is the belly's shape, the path its line of action (the length, as OpenSim's)
    if (path is None or axis_seq) and len(axis_seq) < 3:
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
    jiggle = parse_jiggle(f) if f.has("jiggle") else None
    contact = parse_contact(f) if f.has("contact") else ContactSpec()
    f.done()
    return MuscleSpec(name, color, tuple(axis), tuple(sections), strength, tension, volume,
                      tendons, twist, resolution, weights, file, group, path, jiggle, contact)


def parse_contact(f: Fields) -> ContactSpec:
    """A muscle's ``contact: {group: NAME, ignore: [NAMES], yield: LAYERS}`` (docs/FORMATS.md)."""
    cf = Fields(f.mapping("contact"), f.vmark("contact"), "contact", keys=CONTACT_KEYS)
    group = cf.name("group", default="")
    seq = cf.seq("ignore", default=[])
    ignore = tuple(check_name(v, m, "ignore") for v, m in zip(seq, item_marks(seq, cf.vmark("ignore"))))
    yld = cf.number("yield", default=None, lo=-100.0, hi=100.0)
    cf.done()
    return ContactSpec(group, ignore, None if yld is None else float(yld))


#: Bounds of ``jiggle:`` (docs/FORMATS.md): an exact step is stable at any frequency; these
#: only keep the numbers physical (soft tissue rings at 10-50 Hz; 1 kHz is far above any
#: frame rate) and the step's exponentials finite.
JIGGLE_MAX_HZ = 1000.0
JIGGLE_MAX_DAMPING = 100.0


def parse_jiggle(f: Fields):
    """The muscle's ``jiggle: {frequency, damping_ratio, weight, tensed: {frequency,
    damping_ratio}}`` → :class:`~axdf_cli.model.jiggle.JiggleSpec`."""
    jf = Fields(f.raw("jiggle"), f.vmark("jiggle"), "jiggle", keys=("frequency", "damping_ratio", "weight", "tensed"))
    freq = jf.number("frequency", required=True, lo=0.0, hi=JIGGLE_MAX_HZ, lo_open=True)
    zeta = jf.number("damping_ratio", required=True, lo=0.0, hi=JIGGLE_MAX_DAMPING)
    weight = jf.vector("weight", default=None, lo=0.0, hi=1.0, min_len=2)
    if weight is not None:
        if len(weight) > 64:
            raise InputError(jf.vmark("weight"), f"weight profile has {len(weight)} values", "at most 64")
        marks = item_marks(jf.m["weight"], jf.vmark("weight"))
        for i in (0, len(weight) - 1):
            if weight[i] != 0.0:
                raise InputError(marks[i], f"weight[{i}] is {weight[i]:g}",
                                 "the origin and insertion are held by their bones: the first and last weights are 0")
    tensed_f = tensed_z = None
    if jf.has("tensed"):
        tf = Fields(jf.mapping("tensed"), jf.vmark("tensed"), "jiggle tensed", keys=("frequency", "damping_ratio"))
        tensed_f = tf.number("frequency", default=None, lo=0.0, hi=JIGGLE_MAX_HZ, lo_open=True)
        tensed_z = tf.number("damping_ratio", default=None, lo=0.0, hi=JIGGLE_MAX_DAMPING)
        tf.done()
    jf.done()
    return JiggleSpec(float(freq), float(zeta), weight, None if tensed_f is None else float(tensed_f),
                      None if tensed_z is None else float(tensed_z))


# ----------------------------------------------------------------------------- muscle paths and wrap surfaces
# (a block of its own: ``path:``, ``wrap:`` and ``axis_points:`` of a muscle; docs/FORMATS.md)

WRAP_SIZE_KEYS = {"cylinder": ("radius", "length"), "sphere": ("radius",), "ellipsoid": ("radii",),
                  "torus": ("inner", "outer"), "mujoco_sphere": ("radius",), "mujoco_cylinder": ("radius",)}


def parse_muscle_path(f: Fields):
    """The muscle's ``path`` (points: fixed, ``moving``, ``active``), ``wrap`` (surfaces) and
    ``axis_points`` → :class:`~axdf_cli.model.paths.PathSpec`."""
    from axdf_cli.model.paths import Moving, PathPoint, PathSpec, WrapSurface
    from axdf_cli.model.paths.wrap import METHODS, MUJOCO_SHAPES, QUADRANTS

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
        side = None
        if wf.has("side"):
            if shape not in MUJOCO_SHAPES:
                raise InputError(wf.kmark("side"), f"a {shape} has no side point",
                                 "side: {bone, at} on " + " or ".join(MUJOCO_SHAPES))
            sf = Fields(wf.raw("side"), wf.vmark("side"), "side point", keys=("bone", "at"))
            side = (sf.name("bone", required=True), tuple(float(v) for v in sf.vector("at", 3, default=(0.0, 0.0, 0.0))))
            sf.done()
        if shape in MUJOCO_SHAPES:
            for key, default in (("quadrant", "all"), ("method", "hybrid")):
                if wf.has(key) and (quadrant if key == "quadrant" else method) != default:
                    raise InputError(wf.vmark(key), f"{key} does not apply to a {shape}",
                                     "leave it out: MuJoCo's shapes pick their side by the side point or the shorter way")
        wf.done()
        wraps.append(WrapSurface(name, bone, shape, size, at, orient, quadrant, method, rng, active, wf.vmark("shape"),
                                 side))
    n = f.number("axis_points", default=0, lo=0, hi=tol.AXIS_POINTS_MAX, integer=True)
    if n and n < 4:
        raise InputError(f.vmark("axis_points"), f"axis_points is {n}",
                         f"4..{tol.AXIS_POINTS_MAX} (or leave it out for the default)")
    return PathSpec(tuple(points), tuple(wraps), int(n))


def load_muscle_file(path: Path | str) -> list[MuscleSpec]:
    """One muscle (``muscle:``) or several heads (``muscles:`` list, optional ``group:``)."""
    path = Path(path)
    return muscles_from_document(load_yaml(path), path)


def parse_muscle_text(text: str, path: Path | str) -> list[MuscleSpec]:
    """The muscles of YAML text that will live at ``path`` (as :func:`load_muscle_file` reads it)."""
    from axdf_cli.fileio.yamlio import parse_yaml

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
