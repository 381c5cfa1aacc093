"""``axdf import osim``: an OpenSim model (+ motion, + controls) → the neutral import model.

:func:`read_import` reads and checks every input and fills an
:class:`~axdf_cli.importers.model.ImportedModel`, which
:func:`~axdf_cli.importers.emit.build_import` turns into the bytes of every output file; the
CLI writes them (atomically) only when all inputs were good, so bad input writes nothing.

Conversions (OpenSim → axdf)
----------------------------
- World: a root bone ``ground`` with ``orient: [90, -90, 0]`` turns OpenSim's Y-up, X-forward
  ground into axdf's Z-up world; every body keeps its own OpenSim frame, so path points and
  meshes are copied unchanged.
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
- Muscles: path points, wrap surfaces and Hill numbers as the model gives them; the belly law
  and the axis control points are the emitter's (:func:`~axdf_cli.importers.emit.belly_doc`).

Motion files (``.mot``/``.sto``) and the angle-unit rule
--------------------------------------------------------
Columns are matched to coordinates by name (``knee_angle_r``, or a state path
``/jointset/knee_r/knee_angle_r/value``; ``.../speed`` columns are skipped). A column that
names no coordinate of the model is an error. Translational coordinates are metres.
Rotational coordinates follow the header's ``inDegrees``, unless the values contradict it:

- header says degrees, but every rotational value lies within ±2π, consecutive rows never
  step by more than 0.35 (20° if radians, a jerky 0.35° if degrees would still pass) and
  some rotational coordinate moves by more than 0.5 over the motion → the values are
  radians (a whole motion within ±6.3° that still moves is implausible, a 29° swing is
  not); a warning goes to stderr and into the report. ``arm26_Kinematics_q.sto`` is such
  a file.
- header says radians (or says nothing), but some rotational value exceeds 2π in
  magnitude → degrees, with a warning. With no header and values within ±2π: radians.

Frames: without ``--fps`` a uniformly sampled motion keys every row at frame
``0 .. N-1`` with ``fps = 1 / dt``; with ``--fps`` (or when the rows are not evenly spaced)
the motion is resampled by linear interpolation at ``t0 + k / fps``. Refused, at the row
that shows it (``FILE:LINE:COL``): a time column that does not advance (the median step is
0), a gap (a step more than ``GAP_FACTOR`` times the median step: a motion whose last row
jumps to 2000 s would otherwise become 200,001 interpolated frames), more than
and more than ``MAX_MOTION_FRAMES`` frames; values beyond ``MAX_ABS_NUMBER`` are refused
when the table is read (values read as radians lie within ±2π by the rule above, so the
conversion to degrees cannot push them past it). The pose written must be readable by
axdf: a pose over ``YAML_MAX_BYTES`` is refused too.

Controls (``--controls``): columns name muscles (``TRIlong``, ``glut_med1_r.excitation``,
``/forceset/TRIlong``); other columns (reserve actuators) are listed as ignored. Values are
linearly interpolated at each pose frame inside the controls' time span (outside it the pose
holds the nearest key, as every axdf pose does) and clipped to 0..1 (warning when clipped).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.yamlio import NAME_ALLOWED, check_name, is_name
from axdf_cli.importers import emit
from axdf_cli.importers.model import Bone, Coordinate, Dof, Hill, ImportedModel, Motion, Muscle, Rules
from axdf_cli.importers.osim import load_osim
from axdf_cli.importers.osim_model import Axis, FConst, FLinear, FMult, FPoly, FSpline, Model
from axdf_cli.importers.osim_model import Coordinate as OsimCoordinate
from axdf_cli.importers.osim_model import Muscle as OsimMuscle
from axdf_cli.importers.result import SIDE_SUFFIX, safe_name, strip_dirs, yaml_number
from axdf_cli.importers.storage import Table, read_storage
from axdf_cli.importers.vtp import read_vtp
from axdf_cli.model.jiggle import JiggleSpec
from axdf_cli.model.skeleton import Spline

DEG = 180.0 / math.pi
#: The angle-unit rule's thresholds (see module doc).
RADIAN_BOUND = 2.0 * math.pi
MAX_RADIAN_STEP = 0.35
MIN_RADIAN_SWING = 0.5
#: A time step larger than this many median steps is a gap (refused). OpenSim's
#: variable-step outputs (CMC controls) reach 3.5 median steps in the shipped data.
GAP_FACTOR = 20.0
#: At most this many pose frames per import: 100,000 frames are 28 minutes at 60 fps (the
#: pose file's size limit, YAML_MAX_BYTES, usually binds first: ~25 values per frame).
MAX_MOTION_FRAMES = 100_000


# ----------------------------------------------------------------------------- motion


def coordinate_columns(table: Table, model: Model) -> tuple[list[tuple[int, str]], list[str]]:
    """(column index, coordinate) pairs; skipped labels (speeds)."""
    pairs, skipped = [], []
    for i, (lab, mark) in enumerate(zip(table.labels, table.label_marks)):
        name = lab
        if "/" in lab:
            parts = [p for p in lab.split("/") if p]
            if parts and parts[-1] in ("speed", "acceleration"):
                skipped.append(lab)
                continue
            if parts and parts[-1] == "value":
                parts = parts[:-1]
            name = parts[-1] if parts else lab
        if name not in model.coordinates:
            raise InputError(mark, f"unknown coordinate {lab!r}",
                             f"coordinates of {Path(model.source).name}: " + ", ".join(model.coordinates))
        pairs.append((i, name))
    return pairs, skipped


def angle_unit(table: Table, rot_cols: list[int]) -> tuple[bool, str | None]:
    """Whether rotational columns are degrees, and a warning when the header is overruled."""
    header = table.in_degrees
    if not rot_cols:
        return bool(header), None
    v = table.data[:, rot_cols]
    within = bool(np.all(np.abs(v) <= RADIAN_BOUND))
    step = float(np.max(np.abs(np.diff(v, axis=0)))) if len(v) > 1 else 0.0
    swing = float(np.max(v.max(axis=0) - v.min(axis=0)))
    where = Mark(table.source).file
    if header is True:
        if within and step <= MAX_RADIAN_STEP and swing > MIN_RADIAN_SWING:
            return False, (f"{where}: header says inDegrees=yes but every rotational value lies within ±2π "
                           f"with steps <= {step:.3g} and a swing of {swing:.3g}: reading the values as radians")
        return True, None
    if not within:
        said = "inDegrees=no" if header is False else "no inDegrees"
        return True, (f"{where}: header says {said} but rotational values reach {float(np.abs(v).max()):.4g} "
                      f"(beyond ±2π): reading the values as degrees")
    return False, None


def _frame_times(table: Table, fps: float | None) -> tuple[np.ndarray, float, bool]:
    """Output frame times, fps, and whether rows map 1:1 to frames; InputErrors at the row
    that shows a time column that does not advance, a gap, or too many frames."""
    time = table.time
    if len(time) == 1:
        return time.copy(), float(fps or 30.0), True
    dt = np.diff(time)
    med = float(np.median(dt))
    if med <= 0:
        i = int(np.argmax(dt <= 0)) + 1  # the first row that repeats the time before it
        raise InputError(table.mark(i), f"time does not advance: {int(np.sum(dt <= 0))} of {len(dt)} steps "
                         f"are 0 (time {time[i]:g} repeats)", "time increasing from row to row")
    gaps = np.flatnonzero(dt > GAP_FACTOR * med)
    if len(gaps):
        i = int(gaps[0])
        raise InputError(table.mark(i + 1), f"time jumps from {time[i]:g} to {time[i + 1]:g} s, "
                         f"{dt[i] / med:.3g} times the median step {med:g} s (a gap)",
                         f"steps up to {GAP_FACTOR:g} times the median; split the motion at the gap or fill it")
    uniform = bool(np.all(np.abs(dt - med) <= 1e-3 * med))
    native = 1.0 / med
    if abs(native - round(native)) < 1e-3 * native:
        native = float(round(native))
    if fps is None and uniform:
        n = len(time)
    else:
        fps = float(fps or native)
        n = int(math.floor((time[-1] - time[0]) * fps + 1e-9)) + 1
    if n > MAX_MOTION_FRAMES:
        raise InputError(table.mark(len(time) - 1), f"the motion makes {n} frames "
                         f"({time[-1] - time[0]:g} s at {fps or native:g} fps)",
                         f"at most {MAX_MOTION_FRAMES} frames per import; a lower --fps or a shorter motion")
    if fps is None and uniform:
        return time.copy(), native, True
    return time[0] + np.arange(n) / fps, fps, False


def _interp(time: np.ndarray, values: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of each column of ``values`` (N, C) at ``t``; repeated times keep the last row."""
    keep = np.append(np.diff(time) > 0, True)
    time, values = time[keep], values[keep]
    return np.stack([np.interp(t, time, values[:, c]) for c in range(values.shape[1])], axis=1)


def _coupled(model: Model, c: str) -> bool:
    """Whether OpenSim writes coordinate ``c``'s motion column in radians whatever the
    header says: a rotation whose motion type is Coupled (``osim.motion_type``)."""
    coord = model.coordinates[c]
    return coord.type == "rotation" and getattr(coord, "motion", None) == "coupled"


def _axdf_function(model: Model, c: str):
    """Coupled coordinate ``c``'s function in axdf units (degrees, metres): an OpenSim
    model's is converted; a skeleton's (``axdf dataset`` motions) already is."""
    coord = model.coordinates[c]
    if not isinstance(coord, OsimCoordinate):
        return coord.function
    k_in = math.pi / 180.0 if model.coordinates[coord.follows].type == "rotation" else 1.0
    return convert_function(coord.function, k_in, DEG if coord.type == "rotation" else 1.0)


def followed_columns(model: Model, motion: Table, pairs: list[tuple[int, str]], degrees: bool,
                     warnings: list[str]) -> dict:
    """The motion's columns of coupled coordinates (not read: the skeleton computes them), each
    with the largest difference from its coupler's function of the leader's column (axdf
    units), when the motion holds the leader too; a warning beyond COUPLED_COLUMN_ATOL."""
    cols = {c: i for i, c in pairs}

    def axdf_units(k, name):  # column k of coordinate ``name`` in axdf units
        v = motion.data[:, k]
        return np.degrees(v) if model.coordinates[name].type == "rotation" and (not degrees or _coupled(model, name)) else v

    out = {}
    for i, c in pairs:
        coord = model.coordinates[c]
        if coord.follows is None:
            continue
        row = {"follows": coord.follows}
        j = cols.get(coord.follows)
        if j is not None:
            dev = float(np.max(np.abs(_axdf_function(model, c)(axdf_units(j, coord.follows)) - axdf_units(i, c))))
            row["max_deviation"] = dev
            if (math.radians(dev) if coord.type == "rotation" else dev) > tol.COUPLED_COLUMN_ATOL:
                unit = "°" if coord.type == "rotation" else " m"
                warnings.append(f"{motion.label_marks[i]}: column {c} differs from its coupler's function of "
                                f"{coord.follows} by up to {dev:.3g}{unit}; the coupler's value is used")
        out[c] = row
    return out


def motion_of(model: Model, motion: Table, controls: Table | None, pose_name: str, fps: float | None,
              muscle_names: list[str], report: dict, warnings: list[str]) -> Motion:
    """The motion of a ``.mot``/``.sto`` table (+ controls) on ``model``: its coordinates'
    columns in axdf units, the angle-unit rule, resampling at ``fps``; what it did goes into
    ``report`` and ``warnings``."""
    pairs, skipped = coordinate_columns(motion, model)
    rot = [i for i, c in pairs if model.coordinates[c].type == "rotation" and not _coupled(model, c)]
    degrees, warn = angle_unit(motion, rot)
    if warn:
        warnings.append(warn)
    followed = followed_columns(model, motion, pairs, degrees, warnings)
    pairs = [(i, c) for i, c in pairs if c not in followed]
    times, fps, direct = _frame_times(motion, fps)
    data = motion.data if direct else _interp(motion.time, motion.data, times)
    keys: dict[int, dict] = {}
    for f in range(len(times)):
        row = {}
        for i, c in pairs:
            v = float(data[f, i])
            if model.coordinates[c].type == "rotation" and (not degrees or _coupled(model, c)):
                v = math.degrees(v)
            row[c] = v
        keys[f] = row
    out = Motion(pose_name, fps, len(times), keys, f"Imported from {Path(motion.source).name} by `axdf import osim`.",
                 mark=motion.mark(len(motion.time) - 1), remedy="a lower --fps or a shorter motion")
    report["motion"] = {"file": Path(motion.source).name, "sha256": sha256_file(Path(motion.source)),
                        "rows": int(len(motion.time)), "frames": int(len(times)), "fps": yaml_number(fps),
                        "resampled": not direct, "rotations_read_as": "degrees" if degrees else "radians",
                        "header_inDegrees": motion.header.get("indegrees"), "coordinates": [c for _, c in pairs],
                        "skipped_columns": skipped}
    if followed:
        report["motion"]["coupled_columns"] = followed
    coupled = [c for _, c in pairs if _coupled(model, c)]
    if coupled:
        report["motion"]["coupled_read_as_radians"] = coupled
    if controls is not None:
        act: dict[str, dict] = {}
        names = set(muscle_names)
        ignored, clipped = [], 0
        cols = []
        for i, lab in enumerate(controls.labels):
            n = lab.split("/")[-1] if "/" in lab else lab
            for suffix in (".excitation", ".activation", "_excitation", "_activation"):
                if n.endswith(suffix) and n[: -len(suffix)] in names:
                    n = n[: -len(suffix)]
            if n in names:
                cols.append((i, n))
            else:
                ignored.append(lab)
        inside = (times >= controls.time[0] - 1e-9) & (times <= controls.time[-1] + 1e-9)
        frames = np.nonzero(inside)[0]
        if len(frames) and cols:
            vals = _interp(controls.time, controls.data[:, [i for i, _ in cols]], times[frames])
            clipped = int(np.sum((vals < 0) | (vals > 1)))
            vals = np.clip(vals, 0.0, 1.0)
            for k, (_, n) in enumerate(cols):
                act[n] = {int(f): float(vals[j, k]) for j, f in enumerate(frames)}
        if clipped:
            warnings.append(f"{controls.source}: {clipped} control values outside 0..1 were clipped")
        if cols and not len(frames):
            warnings.append(f"{controls.source}: the controls' time span "
                            f"[{controls.time[0]}, {controls.time[-1]}] misses every pose frame")
        if act:
            out.activation = {n: act[n] for n in muscle_names if n in act}
        report["controls"] = {"file": Path(controls.source).name, "sha256": sha256_file(Path(controls.source)),
                              "muscles": [n for _, n in cols], "ignored_columns": ignored, "clipped_values": clipped,
                              "keyed_frames": [int(frames[0]), int(frames[-1])] if len(frames) else []}
    return out


def motion_doc(model: Model, motion: Table, controls: Table | None, pose_name: str, skeleton_ref: str,
               fps: float | None, muscle_names: list[str], report: dict, warnings: list[str]) -> dict:
    """The pose document of a motion on ``model`` (:func:`motion_of`), as ``axdf import osim`` writes it."""
    return emit.pose_doc(motion_of(model, motion, controls, pose_name, fps, muscle_names, report, warnings),
                         skeleton_ref)


# ----------------------------------------------------------------------------- units and skeleton


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


def _is_zero(fn) -> bool:
    return (isinstance(fn, FConst) and fn.value == 0.0) or (isinstance(fn, FMult) and (fn.scale == 0.0 or _is_zero(fn.function)))


def _deg(v) -> list[float]:
    return [x * DEG for x in v]


def _dof(model: Model, a: Axis) -> Dof | None:
    """A transform axis as a DOF: None for the constant 0; a plain DOF for the identity of a
    coordinate of its own type; else the axis's function in axdf units."""
    if _is_zero(a.function):
        return None
    coord = a.coord if a.coord is not None and not isinstance(a.function, FConst) else None
    d = Dof(a.type, list(a.axis), coord)
    if coord is not None:
        ctype = model.coordinates[coord].type
        if ctype == a.type and isinstance(a.function, FLinear) and a.function.slope == 1.0 and a.function.intercept == 0.0:
            return d
        k_in = math.pi / 180.0 if ctype == "rotation" else 1.0
    else:
        k_in = 1.0
    d.function = emit.function_doc(convert_function(a.function, k_in, DEG if a.type == "rotation" else 1.0))
    return d


def coordinates(model: Model) -> list[Coordinate]:
    """The model's coordinates in axdf units; a coupler's dependent follows its independent one."""
    out = []
    for c in model.coordinates.values():
        k = DEG if c.type == "rotation" else 1.0
        if c.follows is not None:  # a CoordinateCouplerConstraint's dependent: no default, no range of its own
            k_in = math.pi / 180.0 if model.coordinates[c.follows].type == "rotation" else 1.0
            out.append(Coordinate(c.name, c.type, follows=c.follows,
                                  function=emit.function_doc(convert_function(c.function, k_in, k))))
            continue
        out.append(Coordinate(c.name, c.type, c.default * k,
                              (c.range[0] * k, c.range[1] * k) if c.range is not None else None))
    return out


def bones(model: Model) -> list[Bone]:
    """``ground`` (OpenSim's Y-up, X-forward ground in axdf's Z-up world), then a bone per joint's child body."""
    out = [Bone("ground", orient=[90.0, -90.0, 0.0])]
    for j in model.joints:
        b = Bone(j.child.body, j.parent.body, list(j.parent.translation), _deg(j.parent.orientation),
                 [d for d in (_dof(model, a) for a in j.axes) if d is not None])
        if not j.child.is_identity:
            b.post_offset, b.post_orient = list(j.child.translation), _deg(j.child.orientation)
        out.append(b)
    return out


# ----------------------------------------------------------------------------- muscles

#: Secondary motion (``jiggle:``, docs/JIGGLE.md) of the calf's and the thigh's muscles, by
#: name without the side suffix (OpenSim's gait2392/gait2354 names). Soft tissue of the leg
#: rings at 10-50 Hz after a heel strike (Wakeling & Nigg 2001, skin-mounted accelerometers);
#: animators' jiggle sits lower (a few Hz: a slow, visible sway). The bottom of the measured
#: range still shows at the library's 60 fps (6 frames per cycle; above half the frame rate a
#: ring aliases) and keeps a hard landing's sag to about 2 cm (the amplitude of a stop goes as
#: speed / (2 pi f)). The thigh's bellies are heavier: a little lower. Relaxed, damping 0.2
#: lets a stop ring for about two visible cycles (each extremum 0.53 of the last). A tensed
#: muscle rings faster and dies out sooner (frequency and damping both rise with muscle force).
JIGGLE_CALF = JiggleSpec(10.0, 0.2, tensed_frequency=16.0, tensed_damping_ratio=0.45)
JIGGLE_THIGH = JiggleSpec(8.0, 0.2, tensed_frequency=14.0, tensed_damping_ratio=0.45)
JIGGLE = {**{m: JIGGLE_CALF for m in ("med_gas", "lat_gas", "soleus", "tib_ant", "tib_post", "per_long",
                                      "per_brev", "per_tert", "ext_dig", "ext_hal", "flex_dig", "flex_hal")},
          **{m: JIGGLE_THIGH for m in ("rect_fem", "vas_med", "vas_int", "vas_lat", "bifemlh", "bifemsh",
                                       "semimem", "semiten", "sar", "grac", "add_long", "add_brev", "add_mag1",
                                       "add_mag2", "add_mag3")}}


def muscle(model: Model, m: OsimMuscle, source: str) -> Muscle:
    """An OpenSim muscle: every path point (moving ones with their functions in axdf units,
    conditional ones with their ``active`` range), its wrap surfaces (copied per muscle with the
    path wrap's range and method), its Hill numbers and the calf's and thigh's jiggle."""
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
        path.append(PathPoint(p.body, tuple(p.location), moving, active))
    wraps = []
    for pw in m.wraps:
        w = model.wrap_objects[pw.wrap]
        wraps.append(WrapSurface(w.name, w.body, w.shape, tuple(w.size) + (0.0,) * (3 - len(w.size)),
                                 tuple(w.translation), tuple(_deg(w.rotation)), w.quadrant, pw.method,
                                 tuple(pw.range), w.active))
    row = {"type": m.type, "conditional": [p.name for p in m.points if p.kind == "conditional"],
           "conditional_inactive_at_rest": [p.name for p in m.points if not p.active_at_rest],
           "moving": [p.name for p in m.points if p.kind == "moving"]}
    return Muscle(m.name, path, wraps, Hill(m.max_isometric_force, m.optimal_fiber_length, m.tendon_slack_length,
                                            m.pennation_angle),
                  f"{m.name}: imported from {source} ({m.type}) by `axdf import osim`.", row,
                  JIGGLE.get(SIDE_SUFFIX.sub("", m.name)), mark=m.mark)


# ----------------------------------------------------------------------------- meshes


def _find_mesh(model_path: Path, name: str) -> Path | None:
    for cand in (model_path.parent / "Geometry" / name, model_path.parent / name,
                 model_path.parent / "geometry" / name):
        if cand.is_file():
            return cand
    return None


def vtp_meshes(model: Model, model_path: Path, warnings: list[str], report: dict) -> dict[str, bytes]:
    """Body → binary PLY bytes (its ``.vtp`` Mesh geometry merged, scale factors baked in)."""
    out = {}
    missing = []
    for body in model.bodies.values():
        parts = []
        for ref in body.meshes:
            p = _find_mesh(model_path, ref.file)
            if p is None:
                missing.append({"body": body.name, "mesh_file": ref.file, "where": str(ref.mark)})
                continue
            if p.suffix.lower() != ".vtp":
                missing.append({"body": body.name, "mesh_file": ref.file, "where": str(ref.mark),
                                "why": "only .vtp geometry is converted"})
                continue
            v, t = read_vtp(p)
            parts.append((v * np.asarray(ref.scale), t))
            emit.check_vertices(parts[-1][0], ref.mark, f"mesh {ref.file!r} scaled by <scale_factors> "
                                f"{' '.join(f'{x:g}' for x in ref.scale)}")
        if parts:
            out[body.name] = emit.body_ply(parts, body.mark, f"the bone mesh of body {body.name!r}")
    for m in missing:
        warnings.append(f"{m['where']}: mesh {m['mesh_file']!r} of body {m['body']} "
                        f"{m.get('why', 'not found beside the model or in Geometry/')}; skipped")
    report["missing_meshes"] = missing
    return out


# ----------------------------------------------------------------------------- the model

RULES = Rules("axdf import osim", columns=("muscle", "path_points", "control_points", "rest_path", "pcsa", "fibres",
                                          "free_tendon", "belly", "belly_d", "tendon_d", "slenderness"))


def _check_names(model: Model, name: str | None, pname: str | None) -> None:
    """Names become axdf names in files that do not exist yet: checked here, at the .osim line."""
    for what, v in (("--name", name), ("--pose-name", pname)):
        if v is not None and not is_name(v):
            raise InputError(None, f"{what} {v!r}", NAME_ALLOWED)
    for what, items in (("body", model.bodies.values()), ("coordinate", model.coordinates.values()),
                        ("wrap object", model.wrap_objects.values())):
        for item in items:
            try:
                check_name(item.name, item.mark, f"{what} name")
            except InputError as e:
                raise InputError(item.mark, f"{what} name {item.name!r} cannot be an axdf name",
                                 "names use letters, digits, '_', '.', '-' (rename it in the model)") from e
    for m in model.muscles:
        if not is_name(m.name):
            raise InputError(m.mark, f"muscle name {m.name!r}", "names use letters, digits, '_', '.', '-'")


def read_import(model_path: Path | str, *, name: str | None = None, motion: Path | str | None = None,
                controls: Path | str | None = None, pose_name: str | None = None, fps: float | None = None,
                meshes: bool = True) -> ImportedModel:
    """``axdf import osim``: an OpenSim model (+ motion, + controls) read and checked into the
    neutral model, every input read before anything is emitted."""
    model_path = Path(model_path)
    if controls is not None and motion is None:
        raise InputError(None, "--controls needs --motion", "give the motion the controls belong to")
    model = load_osim(model_path)
    name = name or safe_name(model.name)
    pname = pose_name or (safe_name(Path(motion).stem) if motion is not None else None)
    _check_names(model, name, pname)
    motion_t = read_storage(motion) if motion is not None else None
    controls_t = read_storage(controls) if controls is not None else None
    warnings: list[str] = [f"{i['where']}: muscle {i['name']} skipped: {i['why']}" for i in model.ignored
                           if i["kind"] == "muscle"]
    report: dict = {"source": {"model": model_path.name, "sha256": sha256_file(model_path), "model_name": model.name},
                    "tool": "axdf import osim", "skeleton": name}
    mesh_bytes = vtp_meshes(model, model_path, warnings, report) if meshes else {}
    inputs = [Path(x) for x in (model_path, motion, controls) if x is not None]
    out = ImportedModel(name, f"Imported from {model_path.name} (OpenSim model {model.name!r}) by `axdf import osim`.\n"
                              "Regenerate with the importer rather than editing by hand.",
                        bones(model), RULES, coordinates(model), dict(sorted(mesh_bytes.items())),
                        report=report, warnings=warnings, ignored=model.ignored, inputs=inputs, strip=inputs,
                        intro=_intro, poses="the rest pose and the motion's frames")
    if motion_t is not None:
        out.motion = motion_of(model, motion_t, controls_t, pname, fps, [m.name for m in model.muscles], report,
                               warnings)
    out.muscles = [muscle(model, m, model_path.name) for m in model.muscles]
    coupled = [{"coordinate": c.name, "follows": c.follows, "constraint": c.coupler}
               for c in model.coordinates.values() if c.follows is not None]
    if coupled:
        report["coupled_coordinates"] = coupled
    report["settings"] = {"specific_tension_Pa": emit.SPECIFIC_TENSION, "tendon_stress_Pa": emit.TENDON_STRESS,
                          "free_tendon_share": emit.FREE_TENDON_SHARE,
                          "belly_profile": [list(x) for x in emit.BELLY_PROFILE],
                          "tendon_sections": list(emit.TENDON_SECTIONS),
                          "origin_tendon_share": emit.ORIGIN_TENDON_SHARE,
                          "max_tendon_fraction": emit.MAX_TENDON_FRACTION}

    def complete(r: dict) -> None:
        rows = r["muscles"]
        r["counts"] = {"bodies": len(model.bodies), "joints": len(model.joints),
                       "coordinates": len(model.coordinates), "muscles": len(rows),
                       "meshes": len(mesh_bytes), "path_points": sum(x["path_points"] for x in rows),
                       "conditional_path_points": sum(len(x["conditional"]) for x in rows),
                       "conditional_inactive_at_rest": sum(len(x["conditional_inactive_at_rest"]) for x in rows),
                       "moving_path_points": sum(len(x["moving"]) for x in rows),
                       "wrap_surfaces": sum(len(x["wraps"]) for x in rows)}
        for mm in r.get("missing_meshes", []):
            mm["where"] = strip_dirs(mm["where"], inputs)

    out.complete = complete
    return out


def _intro(r: dict) -> list[str]:
    """IMPORT.md's opening of an OpenSim import: source, counts, motion, controls, couplers."""
    c = r["counts"]
    lines = [f"Source: `{r['source']['model']}` (sha256 `{r['source']['sha256'][:16]}…`), "
             f"OpenSim model `{r['source']['model_name']}`.", "",
             f"- bodies {c['bodies']}, joints {c['joints']}, coordinates {c['coordinates']}, meshes {c['meshes']}",
             f"- muscles {c['muscles']} from {c['path_points']} path points "
             f"({c['conditional_path_points']} conditional, active within their ranges, {c['conditional_inactive_at_rest']} "
             f"of them inactive at rest; {c['moving_path_points']} moving, evaluated every frame) and "
             f"{c.get('wrap_surfaces', 0)} wrap surfaces, wrapped every frame", ""]
    if "motion" in r:
        mo = r["motion"]
        lines += [f"Motion: `{mo['file']}`, {mo['rows']} rows → {mo['frames']} frames at {mo['fps']} fps, "
                  f"rotations read as {mo['rotations_read_as']} (header inDegrees={mo['header_inDegrees']}).", ""]
    if "controls" in r:
        co = r["controls"]
        lines += [f"Controls: `{co['file']}`, {len(co['muscles'])} muscles; ignored columns: "
                  f"{', '.join(co['ignored_columns']) or 'none'}.", ""]
    if r.get("coupled_coordinates"):
        lines += ["Coupled coordinates (no pose keys them: the skeleton computes each from the coordinate it "
                  "follows, as OpenSim's constraint does; a motion's column of one is checked, not read):", ""]
        lines += [f"- `{c['coordinate']}` follows `{c['follows']}` (CoordinateCouplerConstraint `{c['constraint']}`)"
                  for c in r["coupled_coordinates"]] + [""]
    return lines
