"""``axdf import osim``: an OpenSim model (+ motion, + controls) → axdf files, in memory.

:func:`build_import` reads and checks every input first and returns an :class:`ImportResult`
holding the bytes of every output file; the CLI writes them (atomically) only when all
inputs were good, so bad input writes nothing.

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

import json
import math
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.formats.ply import PlyWriter
from axdf_cli.importers import emit
from axdf_cli.specs import RefPolicy, parse_skeleton_text
from axdf_cli.fileio.atomic import sha256_file
from axdf_cli.fileio.outputs import UniqueFiles
from axdf_cli.fileio.yamlio import NAME_ALLOWED, check_name, is_name
from axdf_cli.importers.osim import Coordinate as OsimCoordinate
from axdf_cli.importers.osim import Model, load_osim
from axdf_cli.importers.result import (ImportResult, axis_markdown, belly_markdown, relative_ref, safe_name,
                                      strip_dirs, yaml_number)
from axdf_cli.importers.storage import Table, read_storage
from axdf_cli.importers.vtp import read_vtp

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
    return emit.convert_function(coord.function, k_in, emit.DEG if coord.type == "rotation" else 1.0)


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


def pose_doc(model: Model, motion: Table, controls: Table | None, pose_name: str, skeleton_ref: str,
             fps: float | None, muscle_names: list[str], report: dict, warnings: list[str]) -> dict:
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
    doc = {"pose": pose_name, "skeleton": skeleton_ref, "fps": yaml_number(fps), "frames": [0, len(times) - 1],
           "interpolation": "linear", "keys": keys}
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
            doc["activation"] = {n: act[n] for n in muscle_names if n in act}
        report["controls"] = {"file": Path(controls.source).name, "sha256": sha256_file(Path(controls.source)),
                              "muscles": [n for _, n in cols], "ignored_columns": ignored, "clipped_values": clipped,
                              "keyed_frames": [int(frames[0]), int(frames[-1])] if len(frames) else []}
    return doc


def pose_coordinates(skel, pdoc: dict) -> np.ndarray:
    """The coordinates (F, C) of every frame of a pose document on ``skel`` (keyed ones as
    written, the others at rest, coupled ones following): what ``axdf run`` samples there."""
    q = np.broadcast_to(skel.rest_coordinates(), (len(pdoc["keys"]), len(skel.coordinates))).copy()
    cidx = skel.coord_index
    for f, row in enumerate(pdoc["keys"].values()):
        for c, v in row.items():
            q[f, cidx[c]] = v
    return skel.couple(q)


# ----------------------------------------------------------------------------- meshes


def _find_mesh(model_path: Path, name: str) -> Path | None:
    for cand in (model_path.parent / "Geometry" / name, model_path.parent / name,
                 model_path.parent / "geometry" / name):
        if cand.is_file():
            return cand
    return None


def body_meshes(model: Model, model_path: Path, warnings: list[str], report: dict) -> dict[str, bytes]:
    """Body → binary PLY bytes (its Mesh geometry merged, scale factors baked in)."""
    out = {}
    missing = []
    for body in model.bodies.values():
        vs, ts, base = [], [], 0
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
            vs.append(v * np.asarray(ref.scale))
            ts.append(t + base)
            base += len(v)
        if vs:
            out[body.name] = PlyWriter(np.concatenate(ts)).encode(np.concatenate(vs))
    for m in missing:
        warnings.append(f"{m['where']}: mesh {m['mesh_file']!r} of body {m['body']} "
                        f"{m.get('why', 'not found beside the model or in Geometry/')}; skipped")
    report["missing_meshes"] = missing
    return out


# ----------------------------------------------------------------------------- all


def build_import(model_path: Path | str, out_dir: Path | str, *, name: str | None = None,
                 motion: Path | str | None = None, controls: Path | str | None = None,
                 skeleton_out: Path | str | None = None, muscles_out: Path | str | None = None,
                 pose_out: Path | str | None = None, meshes_out: Path | str | None = None,
                 pose_name: str | None = None, fps: float | None = None, meshes: bool = True,
                 palette: str = "anatomical") -> ImportResult:
    """Read ``model_path`` (+ motion, controls) and build every output file's bytes.

    Layout (defaults under ``out_dir``): ``skeletons/NAME.yaml``, ``skeletons/meshes/NAME/*.ply``,
    ``muscles/MUSCLE.yaml``, ``POSE.yaml`` (when a motion is given), ``import_report.json``
    and ``IMPORT.md``. Paths written inside the files are relative to the file holding them.
    ``palette``: muscle colours, a key of :data:`emit.PALETTES`.
    """
    model_path = Path(model_path)
    out_dir = Path(out_dir)
    if controls is not None and motion is None:
        raise InputError(None, "--controls needs --motion", "give the motion the controls belong to")
    model = load_osim(model_path)
    name = name or safe_name(model.name)
    pname = pose_name or (safe_name(Path(motion).stem) if motion is not None else None)
    for what, v in (("--name", name), ("--pose-name", pname)):
        if v is not None and not is_name(v):
            raise InputError(None, f"{what} {v!r}", NAME_ALLOWED)
    # names become axdf names in files that do not exist yet: check them here, at the .osim line
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
    motion_t = read_storage(motion) if motion is not None else None
    controls_t = read_storage(controls) if controls is not None else None

    skel_path = Path(skeleton_out) if skeleton_out else out_dir / "skeletons" / f"{name}.yaml"
    mesh_dir = Path(meshes_out) if meshes_out else skel_path.parent / "meshes" / name
    mus_dir = Path(muscles_out) if muscles_out else out_dir / "muscles"
    pose_path = (Path(pose_out) if pose_out else out_dir / f"{pname}.yaml") if motion is not None else None

    warnings: list[str] = [f"{i['where']}: muscle {i['name']} skipped: {i['why']}" for i in model.ignored
                           if i["kind"] == "muscle"]
    report: dict = {"source": {"model": model_path.name, "sha256": sha256_file(model_path), "model_name": model.name},
                    "tool": "axdf import osim", "skeleton": name}
    files: dict[str, bytes] = UniqueFiles()  # a path twice: exit 2, never one file lost
    mesh_bytes = body_meshes(model, model_path, warnings, report) if meshes else {}
    mesh_refs = {}
    for body, data in sorted(mesh_bytes.items()):
        p = mesh_dir / f"{body}.ply"
        files[str(p)] = data
        mesh_refs[body] = relative_ref(p, skel_path.parent)

    sdoc = emit.skeleton_doc(model, name, mesh_refs)
    header = (f"Imported from {model_path.name} (OpenSim model {model.name!r}) by `axdf import osim`.\n"
              "Regenerate with the importer rather than editing by hand.")
    text = emit.dump_yaml(sdoc, header)
    files[str(skel_path)] = text.encode()
    # the file as axdf will read it back; its mesh references name files this import writes
    skel = parse_skeleton_text(text, skel_path, RefPolicy(allow_outside=True))
    world = emit.rest_world(skel)

    motion_q = None
    if motion_t is not None:
        pdoc = pose_doc(model, motion_t, controls_t, pname, relative_ref(skel_path, pose_path.parent), fps,
                        [m.name for m in model.muscles], report, warnings)
        text = emit.dump_yaml(pdoc, f"Imported from {Path(motion).name} by `axdf import osim`.").encode()
        if len(text) > tol.YAML_MAX_BYTES:
            raise InputError(motion_t.mark(len(motion_t.time) - 1),
                             f"the pose would be {len(text)} bytes ({len(pdoc['keys'])} frames)",
                             f"axdf reads YAML files up to {tol.YAML_MAX_BYTES} bytes; a lower --fps or a shorter motion")
        files[str(pose_path)] = text
        motion_q = pose_coordinates(skel, pdoc)
    rows = []
    for m in model.muscles:
        mdoc, row = emit.muscle_doc(m, skel, world, model, palette, motion_q)
        rows.append(row)
        files[str(mus_dir / f"{m.name}.yaml")] = emit.dump_yaml(mdoc, f"{m.name}: imported from {model_path.name} "
                                                                      f"({m.type}) by `axdf import osim`.").encode()
    report["muscles"] = rows
    coupled = [{"coordinate": c.name, "follows": c.follows, "constraint": c.coupler}
               for c in model.coordinates.values() if c.follows is not None]
    if coupled:
        report["coupled_coordinates"] = coupled
    report["counts"] = {"bodies": len(model.bodies), "joints": len(model.joints), "coordinates": len(model.coordinates),
                        "muscles": len(model.muscles), "meshes": len(mesh_bytes),
                        "path_points": sum(r["path_points"] for r in rows),
                        "conditional_path_points": sum(len(r["conditional"]) for r in rows),
                        "conditional_inactive_at_rest": sum(len(r["conditional_inactive_at_rest"]) for r in rows),
                        "moving_path_points": sum(len(r["moving"]) for r in rows),
                        "wrap_surfaces": sum(len(r["wraps"]) for r in rows)}
    inputs = [Path(x) for x in (model_path, motion, controls) if x is not None]
    report["ignored"] = [dict(i, where=strip_dirs(i["where"], inputs)) for i in model.ignored]
    report["warnings"] = [strip_dirs(w, inputs) for w in warnings]
    for mm in report.get("missing_meshes", []):
        mm["where"] = strip_dirs(mm["where"], inputs)
    report["settings"] = {"specific_tension_Pa": emit.SPECIFIC_TENSION, "tendon_stress_Pa": emit.TENDON_STRESS,
                          "free_tendon_share": emit.FREE_TENDON_SHARE,
                          "belly_profile": [list(x) for x in emit.BELLY_PROFILE],
                          "tendon_sections": list(emit.TENDON_SECTIONS),
                          "origin_tendon_share": emit.ORIGIN_TENDON_SHARE,
                          "max_tendon_fraction": emit.MAX_TENDON_FRACTION, "palette": palette}
    report["files"] = sorted(relative_ref(Path(p), out_dir) for p in files)
    files[str(out_dir / "import_report.json")] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[str(out_dir / "IMPORT.md")] = import_markdown(report).encode()
    return ImportResult(files, report, warnings, model, inputs,
                        layout={"muscles": mus_dir, "skeleton": skel_path, "pose": pose_path})


def import_markdown(r: dict) -> str:
    c = r["counts"]
    lines = [f"# Import of {r['source']['model']} (`{r['skeleton']}`)", "",
             f"Source: `{r['source']['model']}` (sha256 `{r['source']['sha256'][:16]}…`), "
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
    lines += axis_markdown(r, "the rest pose and the motion's frames")
    lines += ["## Warnings", ""] + ([f"- {w}" for w in r["warnings"]] or ["- none"]) + [""]
    lines += ["## Not imported", "", "| kind | name | where | why |", "|---|---|---|---|"]
    lines += [f"| {i['kind']} | {i['name']} | {i['where']} "
              f"| {i['why']} |" for i in r["ignored"]] or ["| – | – | – | nothing |"]
    lines += belly_markdown(r)
    lines += ["", "## Muscles", "", "| muscle | path points | control points | rest path (cm) | PCSA (cm²) | "
              "fibres (cm) | free tendon (cm) | belly (cm) | belly Ø (mm) | tendon Ø (mm) | slenderness |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for m in r["muscles"]:
        lines.append(f"| {m['muscle']} | {m['path_points']} | {m['control_points']} | {m['rest_path_length'] * 100:.1f} | "
                     f"{m['pcsa_m2'] * 1e4:.2f} | {m['optimal_fiber_length'] * 100:.1f} | {m['free_tendon'] * 100:.1f} | "
                     f"{m['belly_length'] * 100:.1f} | {m['belly_radius'] * 2e3:.1f} | {m['tendon_radius'] * 2e3:.1f} | "
                     f"{m['slenderness']:.2f} |")
    return "\n".join(lines) + "\n"
