"""Skin files (``skin:``, written by ``axdf skin``; docs/SKIN.md) → a frozen :class:`Skin`.

A skin file names its rest mesh (PLY or OBJ triangles), its weights (NPZ: the skeleton bones
and sparse per-vertex weights) and its fat map (NPZ: per-vertex thickness and region), each
relative to the file. Every check reports ``FILE:LINE:COL: what; allowed``: unknown keys, bad
values, missing or unreadable files, vertex counts that disagree with the mesh, weights that
do not sum to one, regions the table lacks and, given the skeleton, bones it does not have.

An optional ``jiggle: {frequency, damping_ratio, amount}`` gives the skin secondary motion
(:mod:`axdf_cli.pipeline.skin_stage`): soft tissue lagging and ringing behind its bones.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import Fields, load_yaml
from axdf_cli.specs.refs import RefPolicy

SKIN_KEYS = ("skin", "skeleton", "family", "mesh", "weights", "fat", "stature", "height", "fat_source", "regions",
             "jiggle")
JIGGLE_KEYS = ("frequency", "damping_ratio", "amount")
#: Bounds of a skin's ``jiggle:``: an underdamped spring (it rings, and its ring has died away
#: within a few seconds of frames), at most 100 Hz (soft tissue wobbles at a few Hz to tens).
SKIN_JIGGLE_DAMPING = (0.05, 1.0)
SKIN_JIGGLE_MAX_HZ = 100.0
REGION_KEYS = ("fat_mm", "site")
WEIGHT_ARRAYS = ("vertex_count", "bones", "vertex", "bone", "weight")
FAT_ARRAYS = ("vertex_count", "fat", "region", "regions")
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


@dataclass(frozen=True)
class SkinJiggle:
    """A skin's secondary motion: each vertex a damped spring behind where its bones put it."""

    frequency: float  # Hz, the spring's undamped natural frequency
    damping_ratio: float  # in SKIN_JIGGLE_DAMPING, [lo, hi)
    amount: float  # scale of the lag, at the thickest fat (a vertex's share: its fat over the thickest)


def _arrays(path: Path, where: Mark, names: tuple) -> dict:
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [n for n in names if n not in z.files]
            if missing:
                raise InputError(where, f"{path.name} lacks the arrays {', '.join(missing)}",
                                 f"an NPZ with {', '.join(names)} (docs/SKIN.md)")
            return {n: z[n] for n in names}
    except (OSError, ValueError, EOFError) as e:
        raise InputError(where, f"{path.name} is not a readable NPZ ({e})", "an NPZ written by axdf skin") from None


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
    f.done()
    (v, _, faces), _ = load_triangles_and_bytes(mesh_p)
    n = len(v)
    if skeleton is not None and skeleton.name != skel_name:
        raise InputError(f.vmark("skeleton"), f"the skin is for skeleton {skel_name!r}, not {skeleton.name!r}",
                         f"a skin made by axdf skin for {skeleton.name!r}")

    wm = f.vmark("weights")
    w = _arrays(weights_p, wm, WEIGHT_ARRAYS)
    if int(w["vertex_count"]) != n:
        raise InputError(wm, f"{weights_p.name} weighs {int(w['vertex_count'])} vertices, the mesh "
                         f"{mesh_p.name} has {n}", "weights made for this mesh")
    bones = tuple(str(b) for b in w["bones"])
    vi, bi, ww = (np.asarray(w[k]) for k in ("vertex", "bone", "weight"))
    if not (len(vi) == len(bi) == len(ww)) or (len(vi) and (vi.min() < 0 or vi.max() >= n or bi.min() < 0
                                                             or bi.max() >= len(bones))):
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
    a = _arrays(fat_p, fm, FAT_ARRAYS)
    fat, region, names = np.asarray(a["fat"], dtype=np.float64), np.asarray(a["region"]), [str(r) for r in a["regions"]]
    if int(a["vertex_count"]) != n or len(fat) != n or len(region) != n:
        raise InputError(fm, f"{fat_p.name} has the fat of {len(fat)} vertices, the mesh {mesh_p.name} has {n}",
                         "a fat map made for this mesh")
    if not np.isfinite(fat).all() or (fat < 0).any():
        raise InputError(fm, f"{fat_p.name} has negative or non-finite thicknesses", "thicknesses >= 0 (metres)")
    if len(region) and (region.min() < 0 or region.max() >= len(names)):
        raise InputError(fm, f"{fat_p.name} names regions it does not list", "region indices below its regions' count")
    unknown = [r for r in names if r not in regions]
    if unknown:
        raise InputError(f.vmark("regions"), f"regions lacks {', '.join(unknown)}, which {fat_p.name} uses",
                         "a fat_mm for every region of the fat map")
    return Skin(name, skel_name, family, np.asarray(v, dtype=np.float64), np.asarray(faces, dtype=np.int64),
                bones, dense, fat, region.astype(np.int64), regions, stature, height,
                (path, mesh_p, weights_p, fat_p), jiggle)


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
