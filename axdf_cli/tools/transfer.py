"""Muscle transfer: muscles defined on skeleton A re-expressed on skeleton B through a bone map.

Each map entry pairs a bone ``a`` of A with a bone ``b`` of B and gives each a *segment*:
an anchor P0 and, usually, a tip P1 (rest-pose world positions; by default the bone's own
joint and the joint of its only child away from it). A point's rest-pose world position P on
``a`` goes to

    P' = P0_b + k · R · (P - P0_a)

and is stored in ``b``'s local frame. So a point keeps its fraction along the segment (joint
to child joint) and its perpendicular offset is scaled by the same ratio of bone lengths:

- ``k = |P1_b - P0_b| / |P1_a - P0_a|``, the ratio of the segment lengths, unless the entry
  gives ``scale``; an entry without a segment on both sides (a leaf bone, a joint whose
  children all sit on it) takes the median ``k`` of the entries that have one;
- ``R`` the shortest rotation turning A's segment direction into B's (rest poses that differ,
  a T-pose against an A-pose, are aligned bone by bone), then ``roll`` degrees about B's
  segment; an entry's ``rotate: [rx, ry, rz]`` (world, body-fixed XYZ degrees, the rest
  rotation from A's bone to B's) replaces the shortest rotation; without a segment and
  without ``rotate``, R is the identity (both skeletons share axdf's world: Z-up, facing -Y).

Muscles given by a ``path`` go the same way: every path point's ``at`` through its bone's
map; a moving point's location functions are recombined per axis of B (B's axis i is
``sum_j L_ij f_j(q) + c_i`` with L the bone-local linear part k·R', written exactly as one
function when the axes it gathers follow one coordinate and are polynomials, or splines on
the same knots; a plain scaling or an axis permutation always is); conditional points keep
their coordinate range; wrap surfaces move with their bone: position mapped, orientation
turned by R', sizes (radii, length, torus radii) times k, quadrant (the surface's own axes),
range, method and flag kept. The path's coordinates must be coordinates of B (same names).

Section sizes: radii and outline points are multiplied by the geometric mean of ``k`` over
the muscle's axis control points, or its path points and wrap surfaces (each weighs as much
as the others); with the rest length scaled by about the same factor, the rest volume scales
by about its cube. Section positions ``t``, tendon fractions, twist, colour, tension,
strength, volume mode, resolution and ``axis_points`` are kept. A muscle with a point or
surface on a bone the map does not name, a path coordinate B lacks, or a moving point whose
functions cannot be recombined, is skipped and listed with the reason in the report. Files are written by the importers' emitter (numbers rounded as
it rounds them: positions to 0.1 µm, the rest to 9 significant digits). The map format: docs/FORMATS.md, "Transfer map".
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.importers import emit
from axdf_cli.specs import RefPolicy
from axdf_cli.model.muscle import AxisPoint, MuscleModel, MuscleSpec
from axdf_cli.model.skeleton import Constant, Linear, Multiplier, Polynomial, Skeleton, Spline, axis_angle, euler_xyz
from axdf_cli.fileio.outputs import UniqueFiles
from axdf_cli.fileio.yamlio import Fields, check_name, check_vector, item_marks
from axdf_cli.tools.maps import map_skeleton, open_map, shorthand
from axdf_cli.tools.muscle_files import file_doc, load_muscle_files

#: A segment shorter than this (metres) has no direction: the entry is treated as segment-less.
MIN_SEGMENT = 1e-6
#: A map's bone scale k (given, or the ratio of the segment lengths) lies in
#: [1/MAX_BONE_SCALE, MAX_BONE_SCALE]: a muscle a thousand times longer or shorter is a unit
#: mistake or a degenerate segment (a 1 µm segment once made a 164 km muscle).
MAX_BONE_SCALE = 1000.0
#: An explicit segment (``segment:``, ``to_segment:``) is at least this long (m).
MIN_SEGMENT_LENGTH = 1e-3


# ----------------------------------------------------------------------------- the map


@dataclass(frozen=True)
class BonePair:
    src: str  # bone of A
    dst: str  # bone of B
    src_segment: tuple | None  # (end, ...) with end a bone name or an (x, y, z) in src; None: default
    dst_segment: tuple | None
    scale: float | None
    rotate: tuple[float, float, float] | None
    roll: float
    mark: Mark
    segment_marks: tuple = (None, None)  # where segment / to_segment are written


@dataclass(frozen=True)
class BoneMap:
    name: str
    pairs: dict  # src bone -> BonePair
    source: str
    skel_a: Skeleton
    skel_b: Skeleton


def _segment_spec(v, where: Mark, skel: Skeleton, what: str) -> tuple:
    if not isinstance(v, list) or not 1 <= len(v) <= 2:
        raise InputError(where, f"{what} is not a list of 1 or 2 ends",
                         f"{what}: [ANCHOR] or [ANCHOR, TIP], each a bone name or [x, y, z] in the entry's bone")
    out = []
    for x, m in zip(v, item_marks(v, where)):
        if isinstance(x, str):
            check_name(x, m, f"{what} bone")
            if x not in skel.bone_index:
                raise InputError(m, f"unknown bone {x!r} in {what}", f"bones of skeleton {skel.name}: "
                                 + ", ".join(skel.bone_index))
            out.append(x)
        else:
            out.append(check_vector(x, m, f"{what} point", 3))
    return tuple(out)


def load_map(path: Path | str, skel_a: Skeleton | None = None, skel_b: Skeleton | None = None,
             policy: RefPolicy | None = None) -> BoneMap:
    """Read and check a transfer map against both skeletons (unknown bones: FILE:LINE:COL).

    A skeleton not given here (``--from`` / ``--to``) is the one the map names (``from:`` /
    ``to:``, relative to the map file)."""
    path, f = open_map(path, "transfer map")
    name = f.name("transfer", required=True)
    skels = [map_skeleton(f, key, given, path, f"transfer map names no {key!r} skeleton", key, policy)
             for key, given in (("from", skel_a), ("to", skel_b))]
    skel_a, skel_b = skels
    bones = f.mapping("bones", required=True)
    f.done()
    pairs = {}
    for src, val in bones.items():
        km, vm = bones.key_mark(src), bones.value_mark(src)
        check_name(src, km, "bone name")
        if src not in skel_a.bone_index:
            raise InputError(km, f"unknown bone {src!r} of skeleton {skel_a.name} (--from)",
                             "bones of " + skel_a.name + ": " + ", ".join(skel_a.bone_index))
        e = Fields(shorthand("to", val, vm) if isinstance(val, str) else val, vm, f"bone {src}")
        dst = e.name("to", required=True)
        if dst not in skel_b.bone_index:
            raise InputError(e.vmark("to"), f"unknown bone {dst!r} of skeleton {skel_b.name} (--to)",
                             "bones of " + skel_b.name + ": " + ", ".join(skel_b.bone_index))
        seg_a = _segment_spec(e.raw("segment"), e.vmark("segment"), skel_a, "segment") if e.has("segment") else None
        seg_b = _segment_spec(e.raw("to_segment"), e.vmark("to_segment"), skel_b, "to_segment") \
            if e.has("to_segment") else None
        scale = e.number("scale", default=None, lo=1.0 / MAX_BONE_SCALE, hi=MAX_BONE_SCALE)
        rotate = e.vector("rotate", 3, default=None)
        roll = e.number("roll", default=0.0, lo=-360.0, hi=360.0)
        e.done()
        pairs[src] = BonePair(src, dst, seg_a, seg_b, scale, rotate, float(roll), km,
                              (e.vmark("segment") if seg_a else None, e.vmark("to_segment") if seg_b else None))
    return BoneMap(name, pairs, str(path), skel_a, skel_b)


# ----------------------------------------------------------------------------- geometry


def shortest_rotation(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) by the smallest angle taking unit ``u`` to unit ``v`` (identity when equal)."""
    c = float(np.dot(u, v))
    w = np.cross(u, v)
    if c < -1.0 + 1e-12:  # opposite: half a turn about any axis perpendicular to u
        a = np.cross(u, [1.0, 0.0, 0.0])
        if np.linalg.norm(a) < 1e-6:
            a = np.cross(u, [0.0, 1.0, 0.0])
        return axis_angle(a / np.linalg.norm(a), np.array([math.pi]))[0]
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    return np.eye(3) + k + k @ k / (1.0 + c)


@dataclass(frozen=True)
class PairTransform:
    src: str
    dst: str
    matrix: np.ndarray  # (4, 4): A-bone-local homogeneous point → B-bone-local
    scale: float  # k
    rotation: np.ndarray  # (3, 3) world R
    lengths: tuple[float, float] | None  # segment lengths on A and B, when both exist


def _segment(skel: Skeleton, world: np.ndarray, bone: str, spec: tuple | None) -> tuple[np.ndarray, np.ndarray | None]:
    """Anchor and tip (world, rest) of a bone's segment; the tip is None when there is none."""
    bi = skel.bone_index
    i = bi[bone]
    if spec is None:
        p0 = world[i, :3, 3]
        away = [c for c, b in enumerate(skel.bones)
                if b.parent == i and np.linalg.norm(world[c, :3, 3] - p0) > MIN_SEGMENT]
        return p0, (world[away[0], :3, 3] if len(away) == 1 else None)
    ends = [world[bi[e], :3, 3] if isinstance(e, str) else (world[i] @ np.append(e, 1.0))[:3] for e in spec]
    return ends[0], (ends[1] if len(ends) == 2 else None)


def pair_transforms(bmap: BoneMap, skel_a: Skeleton, skel_b: Skeleton) -> dict[str, PairTransform]:
    """Every map entry's affine map from A-bone-local to B-bone-local coordinates (module doc)."""
    wa, wb = emit.rest_world(skel_a), emit.rest_world(skel_b)
    segs = {}
    for p in bmap.pairs.values():
        a0, a1 = _segment(skel_a, wa, p.src, p.src_segment)
        b0, b1 = _segment(skel_b, wb, p.dst, p.dst_segment)
        la = float(np.linalg.norm(a1 - a0)) if a1 is not None else 0.0
        lb = float(np.linalg.norm(b1 - b0)) if b1 is not None else 0.0
        for given, length, where, side in ((p.src_segment, la, p.segment_marks[0], skel_a.name),
                                           (p.dst_segment, lb, p.segment_marks[1], skel_b.name)):
            if given is not None and len(given) == 2 and length < MIN_SEGMENT_LENGTH:
                raise InputError(where or p.mark, f"bone {p.src}: this segment on {side} is {length:.3g} m long",
                                 f"a segment (anchor to tip) of at least {MIN_SEGMENT_LENGTH:g} m, or only an anchor")
        both = la > MIN_SEGMENT and lb > MIN_SEGMENT
        segs[p.src] = (a0, b0, (a1 - a0) / la if both else None, (b1 - b0) / lb if both else None,
                       (la, lb) if both else None)
    ratios = [s[4][1] / s[4][0] for s in segs.values() if s[4] is not None]
    median = float(np.median(ratios)) if ratios else 1.0
    out = {}
    for p in bmap.pairs.values():
        a0, b0, ua, ub, lengths = segs[p.src]
        k = p.scale if p.scale is not None else (lengths[1] / lengths[0] if lengths else median)
        if not 1.0 / MAX_BONE_SCALE <= k <= MAX_BONE_SCALE:
            why = (f"its segments are {lengths[0]:.3g} m on {skel_a.name} and {lengths[1]:.3g} m on {skel_b.name}"
                   if lengths else "the median of the other entries' scales")
            raise InputError(p.mark, f"bone {p.src} -> {p.dst} would scale by {k:.3g} ({why})",
                             f"a scale in [{1.0 / MAX_BONE_SCALE:g}, {MAX_BONE_SCALE:g}]: give `segment`/`to_segment` "
                             "ends that span the bones, or `scale`")
        if p.rotate is not None:
            r = euler_xyz(p.rotate)
        elif ua is not None:
            r = shortest_rotation(ua, ub)
        else:
            r = np.eye(3)
        if p.roll and ub is not None:
            r = axis_angle(ub, np.radians([p.roll]))[0] @ r
        m = np.eye(4)
        m[:3, :3] = k * r
        m[:3, 3] = b0 - k * r @ a0
        ia, ib = skel_a.bone_index[p.src], skel_b.bone_index[p.dst]
        out[p.src] = PairTransform(p.src, p.dst, np.linalg.inv(wb[ib]) @ m @ wa[ia], float(k), r, lengths)
    return out


def muscle_bones(spec: MuscleSpec) -> list[str]:
    """The bones a muscle uses: its axis points', or its path points' and wrap surfaces'."""
    if spec.path is None:
        return [p.bone for p in spec.axis]
    return [p.bone for p in spec.path.points] + [w.bone for w in spec.path.wraps] + \
        [w.side[0] for w in spec.path.wraps if w.side is not None]


class NotCarried(Exception):
    """A muscle the map cannot carry onto B (the message says why); it is skipped and listed."""


def _flatten(weight: float, fn) -> tuple[float, object]:
    """``weight · fn`` with multipliers folded into the weight; a spline of one value is a constant."""
    while isinstance(fn, Multiplier):
        weight, fn = weight * fn.scale, fn.function
    if isinstance(fn, Spline) and np.all(fn.y == fn.y[0]):
        fn = Constant(float(fn.y[0]))
    return weight, fn


def combine_functions(terms: list[tuple[float, object]], offset: float):
    """The function ``sum(w · f(x)) + offset`` of one coordinate, exactly, as one function of
    the muscle format, or None when it has none: polynomials (constants, lines) add up into a
    polynomial; splines on the same knots and of the same kind add up into a spline (spline
    interpolation is linear in the values, and a constant shifts every value)."""
    terms = [_flatten(w, f) for w, f in terms]
    for w, f in terms:
        if isinstance(f, Constant):
            offset += w * f.value
    terms = [(w, f) for w, f in terms if not isinstance(f, Constant) and w != 0.0]
    if all(isinstance(f, (Linear, Polynomial)) for _, f in terms):
        c = np.zeros(1)
        for w, f in terms:
            fc = np.array([f.intercept, f.slope]) if isinstance(f, Linear) else np.asarray(f.coefficients, float)
            c = np.pad(c, (0, max(0, len(fc) - len(c)))) + w * np.pad(fc, (0, max(0, len(c) - len(fc))))
        c[0] += offset
        return Polynomial(tuple(float(v) for v in c)) if len(c) > 2 else Linear(float(c[1]), float(c[0])) \
            if len(c) == 2 else Constant(float(c[0]))
    if all(isinstance(f, Spline) for _, f in terms) and \
            all(f.kind == terms[0][1].kind and np.array_equal(f.x, terms[0][1].x) for _, f in terms):
        return Spline(terms[0][1].x.copy(), sum(w * f.y for w, f in terms) + offset, terms[0][1].kind)
    return None


def _carry_point(p, t: PairTransform, index: int):
    """A path point on B: ``at`` through the bone's map; a moving point's location functions
    recombined per B axis (an axis of B gathers the A axes the rest rotation turns onto it)."""
    from axdf_cli.model.paths import Moving

    lin, off = t.matrix[:3, :3], t.matrix[:3, 3]
    at = lin @ np.asarray(p.at) + off
    moving = None
    if p.moving is not None:
        axes = []
        for i in range(3):
            src = [j for j in range(3) if abs(lin[i, j]) > 1e-12 * t.scale]
            driven = [j for j in src if p.moving[j] is not None]
            if not driven:
                axes.append(None)
                continue
            coords = {p.moving[j].coord for j in driven}
            fn = None
            if len(coords) == 1:
                static = sum(lin[i, j] * p.at[j] for j in src if p.moving[j] is None)
                fn = combine_functions([(lin[i, j], p.moving[j].function) for j in driven], static + off[i])
            if fn is None:
                raise NotCarried(f"path point {index + 1} moves along axes that bone {t.dst}'s rest rotation mixes "
                                 "into functions the muscle format cannot write (different coordinates, or splines "
                                 "on different knots)")
            axes.append(Moving(coords.pop(), fn))
        moving = tuple(axes) if any(axes) else None
    return replace(p, bone=t.dst, at=tuple(float(x) for x in at), moving=moving)


def _carry_wrap(w, t: PairTransform, side: PairTransform | None = None):
    """A wrap surface on B: its frame through the bone's map (position mapped, orientation turned
    by the rest rotation), its sizes times k; quadrant, range, method and flag kept (the quadrant
    names the surface's own axes, which turn with it); a side point through its own bone's map
    (``side``)."""
    from scipy.spatial.transform import Rotation

    lin, off = t.matrix[:3, :3], t.matrix[:3, 3]
    turn = (lin / t.scale) @ euler_xyz(w.orient)
    orient = Rotation.from_matrix(turn).as_euler("XYZ", degrees=True)  # intrinsic X-Y-Z: Rx·Ry·Rz
    side_b = None
    if w.side is not None:
        side_b = (side.dst, tuple(float(x) for x in side.matrix[:3, :3] @ np.asarray(w.side[1]) + side.matrix[:3, 3]))
    return replace(w, bone=t.dst, at=tuple(float(x) for x in lin @ np.asarray(w.at) + off),
                   orient=tuple(float(x) for x in orient), size=tuple(v * t.scale for v in w.size), side=side_b)


def transfer_spec(spec: MuscleSpec, tf: dict[str, PairTransform],
                  coordinates_b: dict | None = None) -> tuple[MuscleSpec | None, list[str], float]:
    """The muscle on B, the bones of A it uses that the map lacks (then None), and its radial scale.
    A path muscle's coordinates must exist in B (``coordinates_b``, name → index); a muscle that
    cannot be carried raises :class:`NotCarried`."""
    bones = muscle_bones(spec)
    missing = sorted({b for b in bones if b not in tf})
    if missing:
        return None, missing, 1.0
    k = math.exp(sum(math.log(tf[b].scale) for b in bones) / len(bones))
    secs = []
    for s in spec.sections:
        radii = None if s.radii is None else tuple(r * k for r in s.radii)
        outline = None if s.outline is None else tuple(tuple(c * k for c in pt) for pt in s.outline)
        secs.append(replace(s, radii=radii, outline=outline))
    if spec.path is not None:
        lacking = sorted(c for c in spec.path.coordinates if c not in (coordinates_b or {}))
        if lacking:
            raise NotCarried("coordinates its path points follow are not coordinates of the target skeleton: "
                             + ", ".join(lacking))
        points = tuple(_carry_point(p, tf[p.bone], i) for i, p in enumerate(spec.path.points))
        wraps = tuple(_carry_wrap(w, tf[w.bone], tf[w.side[0]] if w.side is not None else None)
                      for w in spec.path.wraps)
        spec = replace(spec, path=replace(spec.path, points=points, wraps=wraps))
        if not spec.axis:
            return replace(spec, sections=tuple(secs)), [], k
    axis = []
    for p in spec.axis:
        t = tf[p.bone]
        at = t.matrix[:3, :3] @ np.asarray(p.at) + t.matrix[:3, 3]
        axis.append(AxisPoint(t.dst, tuple(float(x) for x in at), p.mark))
    return replace(spec, axis=tuple(axis), sections=tuple(secs)), [], k


# ----------------------------------------------------------------------------- all


@dataclass
class TransferResult:
    files: dict[str, bytes]  # output path -> bytes
    report: dict
    skipped: list[dict]
    inputs: list = field(default_factory=list)  # every file read (the map, both skeletons, the muscles)


def build_transfer(muscle_files: list[Path], skel_a: Skeleton | None, skel_b: Skeleton | None,
                   map_path: Path | str, out_dir: Path | str, policy: RefPolicy | None = None) -> TransferResult:
    """Transfer every muscle of ``muscle_files``; the output files' bytes (nothing is written here).
    A skeleton given as None is the one the map names (read with ``policy``)."""
    out_dir = Path(out_dir)
    bmap = load_map(map_path, skel_a, skel_b, policy)
    skel_a, skel_b = bmap.skel_a, bmap.skel_b
    tf = pair_transforms(bmap, skel_a, skel_b)
    wa, wb = emit.rest_world(skel_a), emit.rest_world(skel_b)
    files: dict[str, bytes] = UniqueFiles()
    rows, skipped = [], []
    for path, specs in load_muscle_files(muscle_files, "transferred"):
        kept = []
        for spec in specs:
            try:
                new, missing, k = transfer_spec(spec, tf, skel_b.coord_index)
            except NotCarried as e:
                skipped.append({"muscle": spec.name, "file": path.name, "bones_without_counterpart": [],
                                "why": str(e)})
                continue
            if new is None:
                skipped.append({"muscle": spec.name, "file": path.name, "bones_without_counterpart": missing,
                                "why": "bones without a counterpart in the map: " + ", ".join(missing)})
                continue
            ma = MuscleModel(spec, skel_a.bone_index, wa, skel_a)
            mb = MuscleModel(new, skel_b.bone_index, wb, skel_b)
            rows.append({"muscle": spec.name, "file": path.name, "bones": sorted({f"{b}->{tf[b].dst}"
                                                                               for b in muscle_bones(spec)}),
                         "radius_scale": k, "rest_length_from": ma.l0, "rest_length_to": mb.l0,
                         "length_ratio": mb.l0 / ma.l0, "rest_volume_from": ma.v0, "rest_volume_to": mb.v0})
            kept.append(new)
        if kept:
            header = (f"{path.name}: transferred from skeleton {skel_a.name} to {skel_b.name} by `axdf transfer` "
                      f"(map {bmap.name}).\nRegenerate with axdf transfer rather than editing by hand.")
            files[str(out_dir / path.name)] = emit.dump_yaml(file_doc(kept), header).encode()
    report = {"tool": "axdf transfer", "map": bmap.name, "map_file": Path(bmap.source).name,
              "from": skel_a.name, "to": skel_b.name,
              "bones": [{"from": t.src, "to": t.dst, "scale": t.scale,
                         "segment_lengths": list(t.lengths) if t.lengths else None,
                         "rotation_deg": math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(t.rotation) - 1) / 2))))}
                        for t in tf.values()],
              "muscles": rows, "skipped": skipped,
              "files": sorted(Path(p).name for p in files)}
    report = emit.rounded(report)  # as the YAML files: no CPU-dependent last digits
    files[str(out_dir / "transfer_report.json")] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[str(out_dir / "TRANSFER.md")] = transfer_markdown(report).encode()
    return TransferResult(files, report, skipped, [Path(map_path), Path(skel_a.source), Path(skel_b.source),
                                                   *muscle_files])


def transfer_markdown(r: dict) -> str:
    lines = [f"# Transfer `{r['map']}`: {r['from']} → {r['to']}", "",
             f"Map `{r['map_file']}`; rules: `axdf_cli/tools/transfer.py` and docs/FORMATS.md (Transfer map).", "",
             "| bone (from) | bone (to) | scale k | segment lengths (m) | rest rotation (°) |", "|---|---|---|---|---|"]
    for b in r["bones"]:
        seg = "–" if b["segment_lengths"] is None else f"{b['segment_lengths'][0]:.4f} → {b['segment_lengths'][1]:.4f}"
        lines.append(f"| {b['from']} | {b['to']} | {b['scale']:.4f} | {seg} | {b['rotation_deg']:.1f} |")
    lines += ["", "## Muscles", "", "| muscle | file | radius scale | rest length (m) | length ratio |",
              "|---|---|---|---|---|"]
    for m in r["muscles"]:
        lines.append(f"| {m['muscle']} | {m['file']} | {m['radius_scale']:.4f} | "
                     f"{m['rest_length_from']:.4f} → {m['rest_length_to']:.4f} | {m['length_ratio']:.4f} |")
    lines += ["", "## Skipped", ""]
    lines += [f"- {s['muscle']} ({s['file']}): " + (f"{', '.join(s['bones_without_counterpart'])} (no counterpart "
                                                    "in the map)" if s["bones_without_counterpart"] else s["why"])
              for s in r["skipped"]] or ["- none"]
    return "\n".join(lines) + "\n"
