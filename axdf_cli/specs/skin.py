"""Skin files (``skin:``, written by ``axdf skin``; docs/SKIN.md) → a frozen :class:`Skin`.

A skin file names its rest mesh (PLY or OBJ triangles), its weights (NPZ: the skeleton bones
and sparse per-vertex weights) and its fat map (NPZ: per-vertex thickness and region), each
relative to the file. Every check reports ``FILE:LINE:COL: what; allowed``: unknown keys, bad
values, missing or unreadable files, vertex counts that disagree with the mesh, weights that
do not sum to one, regions the table lacks and, given the skeleton, bones it does not have.
The rest mesh must be a body (:func:`check_rest_mesh`: finite, closed, wound outward, of a
sane size); every NPZ array its dtype and shape, read from the NPZ's headers before any array
is (:func:`npz_headers`), so that a small file cannot claim gigabytes; bone names are unique.

An optional ``segments: {SEGMENT: metres}`` records the skeleton's segment lengths the skin
was fitted to (``axdf skin`` writes it; :func:`axdf_cli.pipeline.plan.plan_skin` refuses a
skeleton they do not fit).

An optional ``jiggle: {frequency, damping_ratio, amount}`` gives the skin secondary motion
(:mod:`axdf_cli.pipeline.skin_stage`): soft tissue lagging and ringing behind its bones.
"""
from __future__ import annotations

import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import Fields, load_yaml
from axdf_cli.geometry.mesh import surface_problem
from axdf_cli.model.skinning import SKINNING
from axdf_cli.specs.refs import RefPolicy

SKIN_KEYS = ("skin", "skeleton", "family", "mesh", "weights", "fat", "stature", "height", "fat_source", "regions",
             "jiggle", "segments", "skinning")
JIGGLE_KEYS = ("frequency", "damping_ratio", "amount")
#: Bounds of a skin's ``jiggle:``: an underdamped spring (it rings, and its ring has died away
#: within a few seconds of frames), at most 100 Hz (soft tissue wobbles at a few Hz to tens).
SKIN_JIGGLE_DAMPING = (0.05, 1.0)
SKIN_JIGGLE_MAX_HZ = 100.0
REGION_KEYS = ("fat_mm", "site")
SEGMENT_KEYS = ("from", "to", "length")
#: Each NPZ array: name -> (dimensions, dtype kinds (numpy's ``dtype.kind``), what it is).
WEIGHT_ARRAYS = {"vertex_count": (0, "iu", "an integer"), "bones": (1, "U", "a list of bone names"),
                 "vertex": (1, "iu", "integer vertex indices"), "bone": (1, "iu", "integer bone indices"),
                 "weight": (1, "f", "float weights")}
FAT_ARRAYS = {"vertex_count": (0, "iu", "an integer"), "fat": (1, "f", "float thicknesses (metres), one per vertex"),
              "region": (1, "iu", "integer region indices, one per vertex"),
              "regions": (1, "U", "a list of region names")}
#: How far a vertex's weights may sum from one (they are stored as float32).
WEIGHT_SUM_TOLERANCE = 1e-4


@dataclass(frozen=True)
class Skin:
    name: str
    skeleton: str
    family: str | None
    vertices: np.ndarray  # (V, 3) float64, the skin at the skeleton's rest pose
    faces: np.ndarray  # (F, 3) int64
    bones: tuple  # the skeleton bones the weights name
    weights: np.ndarray  # (V, len(bones)) float64, rows sum to 1
    fat: np.ndarray  # (V,) metres
    region: np.ndarray  # (V,) index into regions
    regions: dict  # region -> fat thickness (mm)
    stature: float | None
    height: float | None
    files: tuple  # every file read (the skin file first)
    jiggle: "SkinJiggle | None" = None
    segments: dict | None = None  # segment -> (from bone, to bone, length (m)) of the skeleton it was fitted to
    marks: dict | None = None  # key -> Mark of its value in the skin file (skeleton, stature, segments)
    skinning: str | None = None  # the skin stage's method (axdf_cli.model.skinning.SKINNING); None: the default


@dataclass(frozen=True)
class SkinJiggle:
    """A skin's secondary motion: each vertex a damped spring behind where its bones put it."""

    frequency: float  # Hz, the spring's undamped natural frequency
    damping_ratio: float  # in SKIN_JIGGLE_DAMPING, [lo, hi)
    amount: float  # scale of the lag, at the thickest fat (a vertex's share: its fat over the thickest)


def npz_headers(path: Path, where: Mark, spec: dict) -> dict:
    """name -> (shape, dtype) of each array ``spec`` names, from the NPZ's member headers (nothing
    else is read): each of its dtype kind and dimensions, and each member holding as many bytes
    as its header claims (a truncated file is refused here, not when it is read)."""
    out = {}
    try:
        with zipfile.ZipFile(path) as zf:
            members = {i.filename[:-4]: i for i in zf.infolist() if i.filename.endswith(".npy")}
            missing = [n for n in spec if n not in members]
            if missing:
                raise InputError(where, f"{path.name} lacks the arrays {', '.join(missing)}",
                                 f"an NPZ with {', '.join(spec)} (docs/SKIN.md)")
            for name, (ndim, kinds, what) in spec.items():
                info = members[name]
                with zf.open(info) as fp:
                    version = np.lib.format.read_magic(fp)
                    if version not in ((1, 0), (2, 0)):
                        raise ValueError(f"array {name} has npy format {version}")
                    read = np.lib.format.read_array_header_1_0 if version == (1, 0) else \
                        np.lib.format.read_array_header_2_0
                    shape, _, dtype = read(fp)
                    start = fp.tell()
                if dtype.kind not in kinds or len(shape) != ndim:
                    raise InputError(where, f"{path.name}: array {name} is {dtype.str} of shape {tuple(shape)}",
                                     f"{what}: {'a single value' if ndim == 0 else f'{ndim}-dimensional'}, "
                                     f"dtype kind {' or '.join(kinds)} (docs/SKIN.md)")
                if dtype.kind == "U" and dtype.itemsize > 4 * tol.SKIN_MAX_NAME:
                    raise InputError(where, f"{path.name}: array {name} holds names of up to "
                                     f"{dtype.itemsize // 4} characters", f"names of at most {tol.SKIN_MAX_NAME}")
                need = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
                if info.file_size < start + need:
                    raise InputError(where, f"{path.name}: array {name} is cut short ({info.file_size - start} of "
                                     f"the {need} bytes its header claims)", "an NPZ written whole by axdf skin")
                out[name] = (tuple(int(x) for x in shape), dtype)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(where, f"{path.name} is not a readable NPZ ({e})", "an NPZ written by axdf skin") from None
    return out


def _arrays(path: Path, where: Mark, spec: dict, sizes) -> dict:
    """The arrays ``spec`` names, each checked by :func:`npz_headers` and then by ``sizes(headers)``
    (it raises where a claimed size exceeds what the mesh or skeleton allows) before it is read."""
    sizes(npz_headers(path, where, spec))
    try:
        with np.load(path, allow_pickle=False) as z:
            return {n: z[n] for n in spec}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as e:
        raise InputError(where, f"{path.name} is not a readable NPZ ({e})", "an NPZ written by axdf skin") from None


def check_rest_mesh(v: np.ndarray, faces: np.ndarray, where: Mark, name: str) -> float:
    """A skin's rest mesh is a body: finite vertices, every one on a triangle; closed and
    manifold (every edge of exactly two triangles, which run along it in opposite directions:
    consistently wound); wound outward (positive volume); its extent and fullness in
    ``tol.SKIN_MIN_EXTENT``..``tol.SKIN_MAX_EXTENT`` and ``tol.SKIN_MIN_FILL``. → its volume (m^3)."""
    allowed = "a closed triangle mesh of a body, wound outward (as axdf skin writes it)"
    bad = np.flatnonzero(~np.isfinite(v).all(axis=1)) if len(faces) >= 4 else ()
    if len(bad):
        raise InputError(where, f"{name} has {len(bad)} non-finite vertices (the first, vertex {int(bad[0])}: "
                         f"{np.asarray(v[bad[0]]).tolist()})", "finite coordinates (metres)")
    faces = np.asarray(faces, np.int64)
    problem = surface_problem(faces, len(v))
    if problem:
        raise InputError(where, f"{name} {problem}", allowed)
    extent = float(np.ptp(v, axis=0).max())
    if not tol.SKIN_MIN_EXTENT <= extent <= tol.SKIN_MAX_EXTENT:
        raise InputError(where, f"{name} is {extent:.4g} m across", f"a body between {tol.SKIN_MIN_EXTENT:g} and "
                         f"{tol.SKIN_MAX_EXTENT:g} m across (metres)")
    c = np.asarray(v, np.float64) - np.asarray(v, np.float64).mean(axis=0)
    p, q, r = c[faces[:, 0]], c[faces[:, 1]], c[faces[:, 2]]
    volume = float(np.einsum("ij,ij->", p, np.cross(q, r)) / 6.0)  # a . (b x c) / 6 per triangle
    if abs(volume) < tol.SKIN_MIN_FILL * extent ** 3:
        raise InputError(where, f"{name} encloses {abs(volume):.4g} m^3, under {tol.SKIN_MIN_FILL:g} of the cube of "
                         f"its {extent:.3g} m extent: a flat or folded surface", allowed)
    if volume < 0.0:
        raise InputError(where, f"{name} is inside out (its volume is {volume:.4g} m^3: its triangles are wound "
                         "inward)", allowed)
    return volume


def _file(f: Fields, key: str, path: Path, policy: RefPolicy) -> Path:
    ref = f.string(key, required=True)
    p = policy.resolve(path, ref, f.vmark(key), key)
    if not p.is_file():
        raise InputError(f.vmark(key), f"{key} file {ref} not found", f"a file relative to {path.name}")
    return p


def load_skin(path: Path | str, skeleton=None, policy: RefPolicy | None = None) -> Skin:
    """Read and check a skin file; with ``skeleton`` (a :class:`~axdf_cli.model.skeleton.Skeleton`)
    also that it is the skin's skeleton and has every bone the weights name."""
    from axdf_cli.formats import load_triangles_and_bytes

    path = Path(path)
    policy = policy or RefPolicy()
    doc = load_yaml(path)
    f = Fields(doc, Mark(str(path)), "skin file", SKIN_KEYS)
    name = f.name("skin", required=True)
    skel_name = f.name("skeleton", required=True)
    family = f.string("family")
    stature = f.number("stature", lo=0.0, lo_open=True)
    height = f.number("height", lo=0.0, lo_open=True)
    f.string("fat_source")
    regions = {}
    table = f.mapping("regions", required=True)
    for key, value in table.items():
        r = Fields(value, table.value_mark(key) if hasattr(table, "value_mark") else f.vmark("regions"),
                   f"region {key}", REGION_KEYS)
        regions[str(key)] = r.number("fat_mm", required=True, lo=0.0, hi=100.0)
        r.string("site")
        r.done()
    mesh_p, weights_p, fat_p = (_file(f, k, path, policy) for k in ("mesh", "weights", "fat"))
    jiggle = _jiggle(f) if f.has("jiggle") else None
    skinning = f.choice("skinning", SKINNING)
    marks = {k: f.vmark(k) for k in ("skeleton", "stature", "segments") if f.has(k)}
    segments = _segments(f, marks) if f.has("segments") else None
    f.done()
    (v, _, faces), _ = load_triangles_and_bytes(mesh_p)
    n = len(v)
    check_rest_mesh(v, faces, f.vmark("mesh"), mesh_p.name)
    if skeleton is not None and skeleton.name != skel_name:
        raise InputError(f.vmark("skeleton"), f"the skin is for skeleton {skel_name!r}, not {skeleton.name!r}",
                         f"a skin made by axdf skin for {skeleton.name!r}")

    wm = f.vmark("weights")
    max_bones = len(skeleton.bones) if skeleton is not None else tol.SKIN_MAX_BONES
    w = _arrays(weights_p, wm, WEIGHT_ARRAYS, lambda h: _weight_sizes(h, weights_p.name, wm, n, max_bones))
    if int(w["vertex_count"]) != n:
        raise InputError(wm, f"{weights_p.name} weighs {int(w['vertex_count'])} vertices, the mesh "
                         f"{mesh_p.name} has {n}", "weights made for this mesh")
    bones = tuple(str(b) for b in w["bones"])
    _check_names(bones, weights_p.name, wm, "bone")
    twice = sorted({b for b in bones if bones.count(b) > 1})
    if twice:
        raise InputError(wm, f"{weights_p.name} names bone{'s' if len(twice) > 1 else ''} {', '.join(twice[:5])} "
                         "more than once", "each bone once (its weights in one column)")
    vi, bi, ww = (np.asarray(w[k]) for k in ("vertex", "bone", "weight"))
    if len(vi) and (vi.min() < 0 or vi.max() >= n or bi.min() < 0 or bi.max() >= len(bones)):
        raise InputError(wm, f"{weights_p.name} has weights of vertices or bones it does not have",
                         "vertex indices below the mesh's count, bone indices below the bones' count")
    if not np.isfinite(ww).all() or (ww < 0).any():
        raise InputError(wm, f"{weights_p.name} has negative or non-finite weights", "weights in 0..1")
    dense = np.zeros((n, len(bones)))
    np.add.at(dense, (vi.astype(np.int64), bi.astype(np.int64)), ww.astype(np.float64))
    off = np.abs(dense.sum(axis=1) - 1.0)
    if (off > WEIGHT_SUM_TOLERANCE).any():
        raise InputError(wm, f"the weights of {int((off > WEIGHT_SUM_TOLERANCE).sum())} vertices do not sum to 1 "
                         f"(vertex {int(np.argmax(off))} sums to {dense.sum(axis=1)[np.argmax(off)]:.4g})",
                         "every vertex's weights summing to 1")
    if skeleton is not None:
        lacking = [b for b in bones if b not in skeleton.bone_index]
        if lacking:
            raise InputError(wm, f"{weights_p.name} weighs bones skeleton {skeleton.name!r} lacks: "
                             f"{', '.join(lacking[:5])}", "bones of the skin's skeleton")

    fm = f.vmark("fat")
    a = _arrays(fat_p, fm, FAT_ARRAYS, lambda h: _fat_sizes(h, fat_p.name, mesh_p.name, fm, n))
    fat, region, names = np.asarray(a["fat"], dtype=np.float64), np.asarray(a["region"]), [str(r) for r in a["regions"]]
    if int(a["vertex_count"]) != n:
        raise InputError(fm, f"{fat_p.name} has the fat of {int(a['vertex_count'])} vertices, the mesh "
                         f"{mesh_p.name} has {n}", "a fat map made for this mesh")
    if not np.isfinite(fat).all() or (fat < 0).any() or (fat > tol.SKIN_MAX_FAT).any():
        worst = fat[np.argmax(~np.isfinite(fat) | (fat < 0) | (fat > tol.SKIN_MAX_FAT))]
        raise InputError(fm, f"{fat_p.name} has thicknesses out of range (one is {float(worst):.4g} m)",
                         f"thicknesses 0 to {tol.SKIN_MAX_FAT:g} m (metres)")
    _check_names(names, fat_p.name, fm, "region")
    twice = sorted({r for r in names if names.count(r) > 1})
    if twice:
        raise InputError(fm, f"{fat_p.name} names region{'s' if len(twice) > 1 else ''} {', '.join(twice[:5])} "
                         "more than once", "each region once (its vertices under one index)")
    if len(region) and (region.min() < 0 or region.max() >= len(names)):
        raise InputError(fm, f"{fat_p.name} names regions it does not list", "region indices below its regions' count")
    unknown = [r for r in names if r not in regions]
    if unknown:
        raise InputError(f.vmark("regions"), f"regions lacks {', '.join(unknown)}, which {fat_p.name} uses",
                         "a fat_mm for every region of the fat map")
    skin = Skin(name, skel_name, family, np.asarray(v, dtype=np.float64), np.asarray(faces, dtype=np.int64),
                bones, dense, fat, region.astype(np.int64), regions, stature, height,
                (path, mesh_p, weights_p, fat_p), jiggle, segments, marks, skinning)
    if skeleton is not None:
        check_fitted(skin, skeleton, Mark(str(path)))
    return skin


def check_fitted(skin: Skin, skeleton, where: Mark) -> None:
    """The skin fits ``skeleton``'s proportions (docs/SKIN.md, worn on its skeleton): each of
    its ``segments:`` (from one bone's origin to another's at rest) within
    ``tol.SKIN_SEGMENT_TOLERANCE`` of the length it was fitted to; without ``segments:`` (a skin
    made before axdf skin wrote them), every bone the skin weighs has its origin, and the middle of
    the way to each of its children, inside the rest mesh or less than ``tol.SKIN_FIT_OUTSIDE`` outside it (a skeleton of other proportions puts
    its joints outside: gait2392 with 1.6 times longer shanks, its feet's 6 joints). Refused with
    the command that refits the skin."""
    from axdf_cli.model.skeleton import forward_kinematics

    refit = f"fit the skin to this skeleton: axdf skin --skeleton {skeleton.source or skeleton.name} --out NEW_DIR"
    world = forward_kinematics(skeleton, skeleton.rest_coordinates()[None])[0, :, :3, 3]
    bi = skeleton.bone_index
    if skin.segments is not None:
        marks = skin.marks or {}
        off, first = [], None
        for seg, (a, b, length) in skin.segments.items():
            if a not in bi or b not in bi:
                raise InputError(marks.get(f"segments.{seg}", where), f"segment {seg} runs from {a} to {b}, bones skeleton {skeleton.name!r} lacks",
                                 "segments between bones of the skin's skeleton")
            now = float(np.linalg.norm(world[bi[b]] - world[bi[a]]))
            if abs(now / length - 1.0) > tol.SKIN_SEGMENT_TOLERANCE:
                off.append(f"{seg} ({a} to {b}) {length:.3f} m, here {now:.3f} m ({100 * (now / length - 1):+.0f}%)")
                first = first or marks.get(f"segments.{seg}", where)
        if off:
            raise InputError(first, f"the skin was fitted to other proportions than skeleton {skeleton.name!r}'s: "
                             + "; ".join(off[:4]) + (f" and {len(off) - 4} more" if len(off) > 4 else ""),
                             f"segments within {100 * tol.SKIN_SEGMENT_TOLERANCE:g}% of the fit's; {refit}")
        return
    from axdf_cli.geometry.winding import inside

    labels, points = [], []
    for b in skin.bones:
        i = bi[b]
        labels.append(b)
        points.append(world[i])
        for j, child in enumerate(skeleton.bones):
            if child.parent == i:
                labels.append(f"{b}-{child.name}")
                points.append((world[i] + world[j]) / 2.0)
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    within = inside(skin.vertices, skin.faces, points)
    depth = cKDTree(skin.vertices).query(points)[0]  # how far outside (the nearest vertex: within an edge)
    out = [f"{lab} {1000 * d:.0f} mm" for lab, x, d in zip(labels, within, depth) if not x and d > tol.SKIN_FIT_OUTSIDE]
    if out:
        raise InputError((skin.marks or {}).get("skeleton", where),
                         f"{len(out)} of skeleton {skeleton.name!r}'s joints and bones the skin wears lie outside "
                         f"its rest mesh ({', '.join(out[:6])}): it was fitted to other proportions", refit)


def _check_names(names, file: str, where: Mark, what: str) -> None:
    """Every bone or region name an NPZ lists is a name (``[A-Za-z0-9_.-]+``, as in YAML files)."""
    from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name

    bad = next((n for n in names if not is_name(n)), None)
    if bad is not None:
        raise InputError(where, f"{file} lists the {what} name {bad!r}", f"{what} names: {NAME_ALLOWED}")


def _weight_sizes(h: dict, name: str, where: Mark, n: int, max_bones: int) -> None:
    """The weights' claimed sizes against the mesh's ``n`` vertices and at most ``max_bones``
    bones (the skeleton's count, else ``tol.SKIN_MAX_BONES``), before any array is read."""
    k = h["bones"][0][0]
    if k > max_bones:
        raise InputError(where, f"{name} names {k} bones", f"at most {max_bones} (each a bone of the skeleton, once)")
    lens = {a: h[a][0][0] for a in ("vertex", "bone", "weight")}
    if len(set(lens.values())) > 1:
        raise InputError(where, f"{name} has {lens['vertex']} vertex, {lens['bone']} bone and {lens['weight']} weight "
                         "entries", "as many of each (one per weight)")
    if lens["weight"] > n * k:
        raise InputError(where, f"{name} claims {lens['weight']} weights, more than its {k} bones on the mesh's "
                         f"{n} vertices have", f"at most one weight per vertex and bone ({n * k})")


def _fat_sizes(h: dict, name: str, mesh: str, where: Mark, n: int) -> None:
    """The fat map's claimed sizes: one thickness and one region per mesh vertex, at most
    ``tol.SKIN_MAX_BONES`` region names."""
    for a in ("fat", "region"):
        if h[a][0][0] != n:
            raise InputError(where, f"{name} has the {a} of {h[a][0][0]} vertices, the mesh {mesh} has {n}",
                             f"a fat map made for this mesh: {a} of shape ({n},)")
    if h["regions"][0][0] > tol.SKIN_MAX_BONES:
        raise InputError(where, f"{name} lists {h['regions'][0][0]} regions", f"at most {tol.SKIN_MAX_BONES}")


def _segments(f: Fields, marks: dict) -> dict:
    """``segments: {SEGMENT: {from: BONE, to: BONE, length: m}}``: the skeleton's segments the
    skin was fitted to, each from one bone's origin to another's at rest → segment -> (from,
    to, length); each entry's position in ``marks`` (``segments.NAME``)."""
    sf = Fields(f.raw("segments"), f.vmark("segments"), "segments")
    out = {}
    for key in sf.m:
        e = Fields(sf.m[key], sf.vmark(key), f"segment {key}", SEGMENT_KEYS)
        out[str(key)] = (e.name("from", required=True), e.name("to", required=True),
                         float(e.number("length", required=True, lo=0.0, hi=tol.SKIN_MAX_EXTENT, lo_open=True)))
        e.done()
        marks[f"segments.{key}"] = sf.vmark(key)
    return out


def _jiggle(f: Fields) -> SkinJiggle:
    jf = Fields(f.raw("jiggle"), f.vmark("jiggle"), "jiggle", keys=JIGGLE_KEYS)
    freq = jf.number("frequency", required=True, lo=0.0, hi=SKIN_JIGGLE_MAX_HZ, lo_open=True)
    lo, hi = SKIN_JIGGLE_DAMPING
    zeta = jf.number("damping_ratio", required=True, lo=lo, hi=hi)
    if zeta >= hi:
        raise InputError(jf.vmark("damping_ratio"), f"damping_ratio {zeta:g} does not ring",
                         f"an underdamped skin: {lo:g} <= damping_ratio < {hi:g}")
    amount = jf.number("amount", default=1.0, lo=0.0, hi=10.0)
    jf.done()
    return SkinJiggle(float(freq), float(zeta), float(amount))
