"""The dataset file (``dataset: NAME``) → a frozen :class:`DatasetSpec`; every check reports
``FILE:LINE:COL: what is wrong; what is allowed`` (docs/FORMATS.md, "Data sets").

Nothing here samples: :func:`expand_sequences` lists the data set's sequences (name, entry,
number of frames) from the file alone, so every worker and every shard sees the same list.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from axdf_cli.dataset.door import motion_pose, qpos_pose, retarget_pose
from axdf_cli.pipeline.plan import load_muscle_specs
from axdf_cli.render.passes import FRAME_WRITERS
from axdf_cli.specs.render import RenderSettings, parse_camera, parse_render_settings
from axdf_cli.errors import InputError, Mark
from axdf_cli.tolerances import MAX_ABS_NUMBER, MAX_FPS, MAX_SEED
from axdf_cli.formats import WRITERS
from axdf_cli.specs import Pose, RefPolicy, expand_muscle_paths, load_pose, load_skeleton
from axdf_cli.specs.job import STAGE_KEYS
from axdf_cli.fileio.yamlio import Fields, check_name, check_number, check_vector, item_marks, load_yaml, mark_of

SAMPLE_MODES = ("uniform", "perturb")
MOTION_KINDS = ("pose", "motion", "retarget")
ACTIVATION_MODES = ("motion", "uniform", "none")
CAMERA_PER = ("sequence", "frame")
MAX_SEQUENCES = 10_000_000
MAX_FRAMES = 100_000
MAX_VIEWS = 64
#: A sphere camera's nearest distance to its target (m): closer, the view matrix loses its
#: precision (1e-300 gave NaN cameras and labels); 1 mm is far below any useful view.
MIN_CAMERA_DISTANCE = 1e-3
#: At most this many shards (a data-set file's `shards:`, `--shard K/N`): more than any cluster
#: runs, far fewer than the sequences a file may hold.
MAX_SHARDS = 1_000_000
DEFAULT_VISIBILITY_TOLERANCE = 0.1  # metres; see labels.visibility
RENDER_KEYS_ELSEWHERE = ("enabled", "view", "camera", "orbit", "fov")
DATASET_KEYS = ("dataset", "seed", "skeleton", "muscles", "fps", "coordinates", "motions", "sequences", "activation",
                "cameras", "render", "format", "shards", "labels", "skin") + STAGE_KEYS


@dataclass(frozen=True)
class CoordinateRule:
    """How the sampler treats one coordinate: drawn within ``range`` or held at ``fixed``."""

    range: tuple[float, float] | None = None
    fixed: float | None = None
    mark: Mark = field(default=Mark(""), compare=False)


@dataclass(frozen=True)
class Motion:
    """A named motion: a pose file, an OpenSim motion (.mot/.sto), a MuJoCo qpos motion (.npz,
    on a skeleton from ``axdf import mjcf``), or motion capture (BVH, npz joints) retargeted onto
    the data set's skeleton through a map; optionally a frame subset."""

    name: str
    kind: str  # "pose" | "motion" | "retarget"
    path: str
    frames: object  # raw frames spec (parse_frames) or None
    fps: float | None  # OpenSim motions: resample to this rate; qpos: its rows' rate (None: the file's own)
    mark: Mark = field(default=Mark(""), compare=False)
    map: str | None = None  # retarget: the map file
    step: int = 1  # retarget: every step-th frame of the take
    scale: float | None = None  # retarget: metres per unit of the take (None: as axdf retarget)


@dataclass(frozen=True)
class Entry:
    """One item of ``sequences:``: a motion as it is, or ``count`` sampled sequences."""

    kind: str  # "motion" | "uniform" | "perturb"
    count: int
    motion: str | None  # motion name (kind motion, or perturb's base)
    frames: int | None  # sampled sequences: frames per sequence (uniform)
    keys: int | None  # key poses per sequence (None: every frame)
    spread: dict  # perturb: coordinate -> standard deviation (axdf units); "default" for the rest
    mark: Mark = field(default=Mark(""), compare=False)

    @property
    def label(self) -> str:
        return self.kind if self.motion is None else f"{self.kind}:{self.motion}"


@dataclass(frozen=True)
class Activation:
    mode: str  # motion | uniform | none
    range: tuple[float, float] = (0.0, 1.0)
    muscles: dict = field(default_factory=dict)  # muscle -> (lo, hi)


@dataclass(frozen=True)
class RigCamera:
    name: str
    position: tuple[float, float, float]
    target: tuple[float, float, float] | None  # None: the subject's centre (as target: auto)
    up: tuple[float, float, float]
    fov: float


@dataclass(frozen=True)
class Sphere:
    views: int
    distance: tuple[float, float]
    elevation: tuple[float, float]  # degrees
    azimuth: tuple[float, float]  # degrees
    fov: float
    target: object  # "auto" | ("bone", NAME) | (x, y, z)
    per: str  # sequence | frame
    whole: bool = True  # a drawn distance too near to show the whole subject backs off until it does


@dataclass(frozen=True)
class DatasetSpec:
    name: str
    source: str  # the dataset file
    seed: int
    skeleton_path: str
    muscle_files: tuple[str, ...]
    motions: dict  # name -> Motion
    entries: tuple[Entry, ...]
    coordinates: dict  # coordinate -> CoordinateRule
    activation: Activation
    rig: tuple[RigCamera, ...] | None
    sphere: Sphere | None
    render: object  # RenderSettings (enabled)
    passes: tuple[str, ...]  # image files per view and frame: png, exr
    format: str  # mesh format
    shards: int
    visibility_tolerance: float
    fps: float
    policy: RefPolicy = field(default=RefPolicy(), compare=False)  # where referenced files may lie
    stages: tuple = ()  # ((stage, True | False), ...): the file's stage keys (`contact: true`), as a job's
    skin: str | None = None  # the skin file every sequence wears (`skin:`, docs/SKIN.md), or None

    @property
    def views(self) -> tuple[str, ...]:
        if self.rig is not None:
            return tuple(c.name for c in self.rig)
        return tuple(f"view{v:02d}" for v in range(self.sphere.views))


@dataclass(frozen=True)
class Sequence:
    """One sequence of the data set: its number, folder name, entry and frame count."""

    index: int
    name: str
    entry: int  # index into DatasetSpec.entries
    n_frames: int


def load_dataset(path: Path | str, seed: int | None = None, policy: RefPolicy | None = None,
                 fit: bool = True) -> DatasetSpec:
    """Read and check a dataset file (and the skeleton, muscles and motions it names).
    ``seed`` overrides the file's seed (``--seed``); ``policy``: where referenced files may lie;
    ``fit`` False (``--dry-run``): a motion-capture take is read and its map checked, but not
    fitted (the fit takes a minute or more a take; the build makes it)."""
    path = Path(path)
    policy = policy or RefPolicy()
    doc = load_yaml(path)
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "dataset file", keys=DATASET_KEYS)
    name = f.name("dataset", required=True)
    file_seed = int(f.number("seed", default=0, lo=0, hi=MAX_SEED, integer=True))
    skel_ref = f.string("skeleton", required=True)
    skel_path = policy.resolve(path, skel_ref, f.vmark("skeleton"), "skeleton")
    if not skel_path.is_file():
        raise InputError(f.vmark("skeleton"), f"skeleton file {skel_ref!r} not found",
                         "a skeleton YAML relative to the dataset file")
    skel = load_skeleton(skel_path, policy)

    raw = f.raw("muscles", required=True)
    items = [raw] if isinstance(raw, str) else raw
    if not isinstance(items, list) or not items:
        raise InputError(f.vmark("muscles"), "muscles is empty or not a list",
                         "a path, folder or glob, or a list of them")
    marks = item_marks(items, f.vmark("muscles")) if isinstance(raw, list) else [f.vmark("muscles")]
    entries_paths = []
    for e, m in zip(items, marks):
        if not isinstance(e, str) or not e:
            raise InputError(m, f"muscle path is {e!r}", "a path, folder or glob relative to the dataset file")
        entries_paths.append((policy.resolve(path, e, m, "muscle path"), m))
    files = expand_muscle_paths(entries_paths, policy, path.parent)
    muscle_names = [m.name for m in load_muscle_specs(files)]

    fps = float(f.number("fps", default=30.0, lo=0.0, hi=MAX_FPS, lo_open=True))
    coords = _parse_coordinates(f.mapping("coordinates", default=None), f.vmark("coordinates"), skel)
    motions = _parse_motions(f.mapping("motions", default=None), f.vmark("motions"), path, policy)
    seq_raw = f.seq("sequences", required=True, min_len=1)
    entries = tuple(_parse_entry(v, m, motions, skel, coords)
                    for v, m in zip(seq_raw, item_marks(seq_raw, f.vmark("sequences"))))
    activation = _parse_activation(f.raw("activation"), f.vmark("activation"), muscle_names)
    rig, sphere = _parse_cameras(f.mapping("cameras", required=True), f.vmark("cameras"), skel)
    render_doc = f.mapping("render", default=None)
    render, passes = _parse_render(render_doc, f.vmark("render"))
    skin = _parse_skin(f, path, skel, policy)
    if skin is not None and (render_doc is None or "skin" not in render_doc):
        render = replace(render, skin="opaque")  # a data set's skin is the body its images show
    fmt = f.choice("format", tuple(WRITERS), default="ply")
    shards = int(f.number("shards", default=1, lo=1, hi=MAX_SHARDS, integer=True))
    lab = f.mapping("labels", default=None)
    tol = DEFAULT_VISIBILITY_TOLERANCE
    if lab is not None:
        lf = Fields(lab, f.vmark("labels"), "labels")
        tol = float(lf.number("visibility_tolerance", default=tol, lo=0.0, hi=100.0))
        lf.done()
    stages = tuple((k, f.boolean(k)) for k in STAGE_KEYS if f.has(k))
    f.done()
    total = sum(e.count for e in entries)
    if total > MAX_SEQUENCES:
        raise InputError(f.vmark("sequences"), f"{total} sequences", f"at most {MAX_SEQUENCES}")
    spec = DatasetSpec(name, str(path), file_seed if seed is None else int(seed), str(skel_path),
                       tuple(str(p) for p in files), motions, entries, coords, activation, rig, sphere, render,
                       passes, fmt, shards, tol, fps, policy, stages, skin)
    # every motion must load (and match the skeleton) before anything is written; the frame
    # selections are checked first, before any take is fitted
    check_motion_frames(spec)
    for m in motions.values():
        if fit or m.kind != "retarget":
            load_motion(spec, m.name)
        else:
            check_take(spec, m.name)
    return spec


def _parse_skin(f, path: Path, skel, policy: RefPolicy) -> str | None:
    """The ``skin:`` key: a skin file (``axdf skin``) relative to the dataset file, read and
    checked against the data set's skeleton; its path, or None without the key."""
    from axdf_cli.specs.skin import load_skin

    if not f.has("skin"):
        return None
    ref = f.string("skin")
    where = f.vmark("skin")
    skin_path = policy.resolve(path, ref, where, "skin file")
    if not skin_path.is_file():
        raise InputError(where, f"skin file {ref!r} not found",
                         "a skin file written by axdf skin, relative to the dataset file (docs/SKIN.md)")
    load_skin(skin_path, skel, policy)
    return str(skin_path)


def _parse_coordinates(value, where: Mark, skel) -> dict:
    out = {}
    if value is None:
        return out
    for cname, cval in value.items():
        km = value.key_mark(cname)
        if cname not in skel.coord_index:
            raise InputError(km, f"unknown coordinate {cname!r}",
                             f"coordinates of skeleton {skel.name}: {', '.join(skel.coord_index)}")
        leader = skel.coordinates[skel.coord_index[cname]].follows
        if leader is not None:
            raise InputError(km, f"coordinate {cname!r} is coupled: it follows {leader!r}",
                             f"set {leader!r} instead; coupled coordinates are never drawn")
        cf = Fields(cval, value.value_mark(cname), f"coordinate {cname}")
        rng = cf.vector("range", 2, default=None)
        fixed = cf.number("fixed", default=None)
        cf.done()
        if (rng is None) == (fixed is None):
            raise InputError(value.value_mark(cname), f"coordinate {cname} needs one of range or fixed",
                             "{range: [lo, hi]} or {fixed: value}")
        if rng is not None and rng[1] < rng[0]:
            raise InputError(cf.vmark("range"), f"range is {list(rng)}", "[lo, hi] with lo <= hi")
        declared = skel.coordinates[skel.coord_index[cname]].range
        if declared is not None:
            lo, hi = declared
            vals = rng if rng is not None else (fixed, fixed)
            if vals[0] < lo - 1e-9 or vals[1] > hi + 1e-9:
                raise InputError(cf.vmark("range" if rng is not None else "fixed"),
                                 f"{cname} {list(vals) if rng is not None else fixed} leaves the skeleton's range "
                                 f"[{lo:g}, {hi:g}]", "values inside the skeleton's range")
        out[cname] = CoordinateRule(rng, fixed, value.value_mark(cname))
    return out


def _parse_motions(value, where: Mark, path: Path, policy: RefPolicy) -> dict:
    out = {}
    if value is None:
        return out
    for mname, mval in value.items():
        km = value.key_mark(mname)
        check_name(mname, km, "motion name")
        mf = Fields(mval, value.value_mark(mname), f"motion {mname}")
        kinds = [k for k in MOTION_KINDS if mf.has(k)]
        if len(kinds) != 1:
            raise InputError(value.value_mark(mname), f"motion {mname} needs one of pose, motion or retarget",
                             "{pose: FILE.yaml}, {motion: FILE.mot|.sto|.npz} or {retarget: FILE.bvh|.npz, map: MAP.yaml}")
        key = kinds[0]
        ref = mf.string(key, required=True)
        p = policy.resolve(path, ref, mf.vmark(key), f"{key} file")
        if not p.is_file():
            raise InputError(mf.vmark(key), f"{key} file {ref!r} not found", "a path relative to the dataset file")
        frames = mf.raw("frames")
        fps = mf.number("fps", default=None, lo=0.0, hi=100000.0, lo_open=True)
        if fps is not None and key != "motion":
            raise InputError(mf.kmark("fps"), "fps is for OpenSim and MuJoCo motions",
                             "a pose file has its own fps; a retargeted take's is its own / step")
        map_path, step, scale = None, 1, None
        for k in ("map", "step", "scale"):
            if key != "retarget" and mf.has(k):
                raise InputError(mf.kmark(k), f"{k} is for retargeted motion capture", "{retarget: FILE, map: MAP, ...}")
        if key == "retarget":
            mref = mf.string("map", required=True)
            map_path = policy.resolve(path, mref, mf.vmark("map"), "map file")
            if not map_path.is_file():
                raise InputError(mf.vmark("map"), f"map file {mref!r} not found", "a path relative to the dataset file")
            step = int(mf.number("step", default=1, lo=1, hi=10000, integer=True))
            scale = mf.number("scale", default=None, lo=0.0, hi=1e6, lo_open=True)
        mf.done()
        out[mname] = Motion(mname, key, str(p), frames, fps, mf.vmark("frames") if frames is not None
                            else value.value_mark(mname), None if map_path is None else str(map_path), step,
                            None if scale is None else float(scale))
    return out


def _parse_entry(value, where: Mark, motions: dict, skel, coords: dict) -> Entry:
    allowed = "{motion: NAME} or {sample: uniform|perturb, count: N, ...}"
    f = Fields(value, where, "sequences entry")
    if f.has("motion") == f.has("sample"):
        raise InputError(mark_of(value, where), "a sequences entry needs one of motion or sample", allowed)
    if f.has("motion"):
        name = f.name("motion")
        if name not in motions:
            raise InputError(f.vmark("motion"), f"unknown motion {name!r}",
                             f"motions defined under motions: {', '.join(motions) or 'none'}")
        count = int(f.number("count", default=1, lo=1, hi=1, integer=True))
        f.done()
        return Entry("motion", count, name, None, None, {}, where)
    mode = f.choice("sample", SAMPLE_MODES, required=True)
    count = int(f.number("count", required=True, lo=1, hi=MAX_SEQUENCES, integer=True))
    keys = f.number("keys", default=None, lo=1, hi=MAX_FRAMES, integer=True)
    spread: dict = {}
    if mode == "uniform":
        frames = int(f.number("frames", default=1, lo=1, hi=MAX_FRAMES, integer=True))
        base = None
        if keys is not None and keys > frames:
            raise InputError(f.vmark("keys"), f"keys is {keys} for {frames} frames", "keys <= frames")
        # every sampled coordinate needs a range (the skeleton's, or one given here)
        for c in skel.coordinates:
            rule = coords.get(c.name)
            if rule is None and c.range is None and c.follows is None:
                raise InputError(f.vmark("sample"), f"coordinate {c.name!r} has no range to sample",
                                 f"give coordinates: {{{c.name}: {{range: [lo, hi]}}}} or {{fixed: value}} "
                                 "in the dataset file, or a range in the skeleton")
    else:
        base = f.name("around", required=True)
        if base not in motions:
            raise InputError(f.vmark("around"), f"unknown motion {base!r}",
                             f"motions defined under motions: {', '.join(motions) or 'none'}")
        if f.has("frames"):
            raise InputError(f.kmark("frames"), "a perturbed sequence has its motion's frames",
                             "select frames under motions: NAME: {frames: ...}")
        frames = None
        sm = f.mapping("spread", required=True)
        for cname, v in sm.items():
            if cname != "default" and cname not in skel.coord_index:
                raise InputError(sm.key_mark(cname), f"unknown coordinate {cname!r}",
                                 f"'default' or coordinates of skeleton {skel.name}")
            if cname != "default" and skel.coordinates[skel.coord_index[cname]].follows is not None:
                raise InputError(sm.key_mark(cname), f"coordinate {cname!r} is coupled: it follows "
                                 f"{skel.coordinates[skel.coord_index[cname]].follows!r}",
                                 "spread free coordinates; coupled ones follow theirs")
            spread[cname] = float(check_number(v, sm.value_mark(cname), f"spread of {cname}", lo=0.0))
    f.done()
    return Entry(mode, count, base, frames, None if keys is None else int(keys), spread, where)


def _parse_activation(value, where: Mark, muscle_names: list[str]) -> Activation:
    if value is None:
        return Activation("motion")
    if isinstance(value, str):
        if value not in ("motion", "none"):
            raise InputError(where, f"activation is {value!r}",
                             "activation is motion, none, or {sample: uniform, range: [lo, hi], muscles: {...}}")
        return Activation(value)
    f = Fields(value, where, "activation")
    f.choice("sample", ("uniform",), required=True)
    rng = f.vector("range", 2, default=(0.0, 1.0), lo=0.0, hi=1.0)
    if rng[1] < rng[0]:
        raise InputError(f.vmark("range"), f"range is {list(rng)}", "[lo, hi] with 0 <= lo <= hi <= 1")
    per = {}
    mm = f.mapping("muscles", default=None)
    if mm is not None:
        for name, v in mm.items():
            if name not in muscle_names:
                raise InputError(mm.key_mark(name), f"unknown muscle {name!r}", "muscles of this data set")
            r = check_vector(v, mm.value_mark(name), f"activation range of {name}", 2, 0.0, 1.0)
            if r[1] < r[0]:
                raise InputError(mm.value_mark(name), f"range is {list(r)}", "[lo, hi] with lo <= hi")
            per[name] = r
    f.done()
    return Activation("uniform", rng, per)


def _parse_cameras(value, where: Mark, skel):
    f = Fields(value, where, "cameras")
    if f.has("rig") == f.has("sphere"):
        raise InputError(where, "cameras needs one of rig or sphere",
                         "rig: [{name, position, target, up, fov}, ...] or sphere: {views, distance, ...}")
    if f.has("rig"):
        seq = f.seq("rig", min_len=1)
        if len(seq) > MAX_VIEWS:
            raise InputError(f.vmark("rig"), f"{len(seq)} cameras", f"at most {MAX_VIEWS}")
        rig, seen = [], set()
        for cv, cm in zip(seq, item_marks(seq, f.vmark("rig"))):
            if not isinstance(cv, dict) or "name" not in cv:
                raise InputError(mark_of(cv, cm), "a rig camera needs a name", "{name, position, target, up, fov}")
            cname = check_name(cv["name"], cv.value_mark("name"), "camera name")
            if cname in seen:
                raise InputError(cv.value_mark("name"), f"camera {cname!r} twice", "camera names are unique")
            seen.add(cname)
            rest = type(cv)({k: v for k, v in cv.items() if k != "name"})
            rest.mark, rest.key_marks, rest.value_marks = cv.mark, cv.key_marks, cv.value_marks
            cam = parse_camera(rest, cm)
            rig.append(RigCamera(cname, cam.position, cam.target, cam.up, cam.fov))
        f.done()
        return tuple(rig), None
    s = Fields(f.mapping("sphere"), f.vmark("sphere"), "sphere")
    views = int(s.number("views", default=1, lo=1, hi=MAX_VIEWS, integer=True))
    dist = s.vector("distance", 2, required=True, lo=MIN_CAMERA_DISTANCE, hi=MAX_ABS_NUMBER)
    elev = s.vector("elevation", 2, default=(0.0, 30.0), lo=-80.0, hi=80.0)
    azim = s.vector("azimuth", 2, default=(0.0, 360.0), lo=-720.0, hi=720.0)
    for key, v in (("distance", dist), ("elevation", elev), ("azimuth", azim)):
        if v[1] < v[0]:
            raise InputError(s.vmark(key), f"{key} is {list(v)}", "[lo, hi] with lo <= hi")
    fov = float(s.number("fov", default=30.0, lo=1.0, hi=170.0))
    target: object = "auto"
    if s.has("target"):
        t = s.raw("target")
        if t == "auto":
            target = "auto"
        elif isinstance(t, dict):
            tf = Fields(t, s.vmark("target"), "target")
            bone = tf.name("bone", required=True)
            tf.done()
            if bone not in skel.bone_index:
                raise InputError(tf.vmark("bone"), f"unknown bone {bone!r}", f"bones of skeleton {skel.name}")
            target = ("bone", bone)
        else:
            target = check_vector(t, s.vmark("target"), "target", 3)
    per = s.choice("per", CAMERA_PER, default="sequence")
    whole = s.boolean("whole", default=True)
    s.done()
    f.done()
    return None, Sphere(views, dist, elev, azim, fov, target, per, whole)


#: Passes of a data set beyond the image files: ``amodal``, each muscle's full extent per view
#: and frame (``<seq>/amodal.json``, COCO RLE; :mod:`axdf_cli.dataset.amodal`); ``mask`` and
#: ``depth``, the EXR's id and Z as PNG (``<frame>.mask.png``, ``.depth.png``:
#: :data:`axdf_cli.render.views.VIEW_PNG_PASSES`).
DATASET_PASSES = ("amodal", "mask", "depth")


def _parse_render(value, where: Mark):
    if value is None:
        return RenderSettings(enabled=True, size=(256, 256)), tuple(FRAME_WRITERS)
    for k in RENDER_KEYS_ELSEWHERE:
        if k in value:
            raise InputError(value.key_mark(k), f"render key {k!r} does not apply to a data set",
                             "cameras are set under cameras:; render: takes size, passes, supersample, bones, "
                             "background, wireframe")
    passes = tuple(FRAME_WRITERS)
    if "passes" in value:
        pv = value["passes"]
        pm = value.value_mark("passes")
        allowed = tuple(FRAME_WRITERS) + DATASET_PASSES
        if not isinstance(pv, list) or not pv or any(p not in allowed for p in pv) or len(set(pv)) != len(pv):
            raise InputError(pm, f"passes is {pv!r}", f"a non-empty list of {', '.join(allowed)}")
        passes = tuple(p for p in allowed if p in pv)
    rest = type(value)({k: v for k, v in value.items() if k != "passes"})
    rest.mark, rest.key_marks, rest.value_marks = value.mark, value.key_marks, value.value_marks
    if "size" not in rest:
        rest["size"] = [256, 256]
    settings = parse_render_settings(rest, where)
    return settings, passes


# ----------------------------------------------------------------------------- sequences


def entry_frames(spec: DatasetSpec, k: int, fit: bool = True) -> int:
    """Frames of each sequence of entry ``k`` (``fit`` False: a take's counted, not fitted)."""
    e = spec.entries[k]
    return e.frames if e.kind == "uniform" else len(motion_frames(spec, e.motion, fit))


def count(spec: DatasetSpec, shard=(0, 1), fit: bool = True) -> tuple[int, int, int]:
    """(sequences of the data set, sequences of shard K/N, their frames), counted without
    listing them: ``--dry-run`` stays small and fast for any number of sequences (and with
    ``fit`` False, without fitting a motion-capture take: its frames are the file's)."""
    k, n = shard
    start = total = mine = frames = 0
    for i, e in enumerate(spec.entries):
        # indices start .. start + count - 1 that are k modulo n
        first = start + (k - start) % n
        m = 0 if first >= start + e.count else (start + e.count - 1 - first) // n + 1
        mine += m
        frames += m * entry_frames(spec, i, fit) if m else 0
        start += e.count
        total += e.count
    return total, mine, frames


def expand_sequences(spec: DatasetSpec) -> list[Sequence]:
    """Every sequence of the data set in order: ``seq_00000``, ``seq_00001``, ..."""
    width = max(5, len(str(sum(e.count for e in spec.entries) - 1)))
    out = []
    for k, e in enumerate(spec.entries):
        if e.kind == "uniform":
            n = e.frames
        else:
            n = len(motion_frames(spec, e.motion))
        for _ in range(e.count):
            s = len(out)
            out.append(Sequence(s, f"seq_{s:0{width}d}", k, n))
    return out


_MOTION_CACHE: dict = {}  # motions by file, content and skeleton (a worker loads each once)
_FIT_WARNINGS: dict = {}  # a retargeted motion's fit warnings, by the same key
_TAKE_FRAMES: dict = {}  # a take's frame count (read, not fitted), by the same key


def _motion_key(spec: DatasetSpec, name: str) -> tuple:
    from axdf_cli.fileio.atomic import sha256_file

    m = spec.motions[name]
    return (m.path, sha256_file(m.path), m.kind, m.fps, spec.skeleton_path, sha256_file(spec.skeleton_path),
            m.map, None if m.map is None else sha256_file(m.map), m.step, m.scale)


def fit_warnings(spec: DatasetSpec, name: str) -> list[str]:
    """The warnings ``axdf retarget`` would print for the named motion (none unless it is
    retargeted motion capture)."""
    load_motion(spec, name)
    return list(_FIT_WARNINGS.get(_motion_key(spec, name), []))


def load_motion(spec: DatasetSpec, name: str) -> Pose:
    """The named motion as a Pose of the data set's skeleton (pose files are loaded with
    :func:`loaders.load_pose`; OpenSim motions go through the importer's reader and unit rules,
    MuJoCo qpos motions through ``axdf import mjcf``'s; motion capture is retargeted onto the
    skeleton through its map, as ``axdf retarget`` does)."""
    m = spec.motions[name]
    key = _motion_key(spec, name)
    if key in _MOTION_CACHE:
        return _MOTION_CACHE[key]
    skel = load_skeleton(spec.skeleton_path, spec.policy)
    if m.kind == "pose":
        pose = load_pose(m.path, spec.policy)
        if Path(pose.skeleton_path).resolve() != Path(spec.skeleton_path).resolve():
            raise InputError(m.mark, f"pose {Path(m.path).name} uses skeleton {pose.skeleton_path}",
                             f"the data set's skeleton {spec.skeleton_path}")
    elif m.kind == "retarget":
        pose, _FIT_WARNINGS[key] = retarget_pose(Path(m.path), Path(m.map), skel, name, m.step, m.scale, spec.policy)
    elif Path(m.path).suffix.lower() == ".npz":
        pose = qpos_pose(Path(m.path), skel, name, m.fps, m.mark)
    else:
        pose = motion_pose(Path(m.path), skel, name, m.fps)
    _MOTION_CACHE[key] = pose
    return pose


def check_motion_frames(spec: DatasetSpec) -> None:
    """Every motion's ``frames:`` selection checked against its length before any motion
    capture is fitted (minutes for a long take): pose files and OpenSim and qpos motions
    first (they load at once), then each take's frame count from its file alone."""
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.model.pose import parse_frames

    for name, m in spec.motions.items():
        if m.kind != "retarget":
            motion_frames(spec, name)
    for m in spec.motions.values():
        if m.kind == "retarget" and m.frames is not None:
            n = len(read_motion(Path(m.path), scale=m.scale, step=m.step).positions)
            parse_frames(m.frames, m.mark, 0, max(0, n - 1))


def take_frames(spec: DatasetSpec, name: str) -> int:
    """How many frames the named motion-capture take gives (its file read at its ``step``,
    not fitted): a fitted take has one pose frame per frame read."""
    key = _motion_key(spec, name)
    if key not in _TAKE_FRAMES:
        from axdf_cli.importers.mocap import read_motion

        m = spec.motions[name]
        _TAKE_FRAMES[key] = len(read_motion(Path(m.path), scale=m.scale, step=m.step).positions)
    return _TAKE_FRAMES[key]


def check_take(spec: DatasetSpec, name: str) -> None:
    """A motion-capture take checked without fitting it: its file reads, its map reads and
    names the data set's skeleton's bones and coordinates."""
    from axdf_cli.tools.retarget import load_map

    m = spec.motions[name]
    load_map(Path(m.map), load_skeleton(spec.skeleton_path, spec.policy), spec.policy)
    take_frames(spec, name)


def motion_frames(spec: DatasetSpec, name: str, fit: bool = True):
    """The output frames of a named motion: its ``frames:`` selection, else all of them
    (``fit`` False: a motion-capture take's from its file, not fitted)."""
    from axdf_cli.model.pose import parse_frames

    m = spec.motions[name]
    if not fit and m.kind == "retarget":
        n = take_frames(spec, name)
        return np.arange(n) if m.frames is None else parse_frames(m.frames, m.mark, 0, max(0, n - 1))
    pose = load_motion(spec, name)
    if m.frames is None:
        return pose.frames
    return parse_frames(m.frames, m.mark, pose.first, pose.last)
