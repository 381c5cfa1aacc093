"""The per-model tables the tools read, as data (axdf_cli/data/): each file read once per
process through the YAML reader with positions (axdf_cli/fileio/yamlio.py) and checked, so
that a bad entry is refused as ``FILE:LINE:COL: what is wrong; what is allowed`` (exit 2) and
a new model is a new entry, not a change of code.

- :func:`rig`: MakeHuman's rig as ``axdf skin`` uses it (data/makehuman/bone_map.yaml);
- :func:`families`: the skeleton families the body is fitted to (data/skeleton_families.yaml);
- :func:`load_atlas_map`: an atlas onto a model, for ``axdf atlas --map`` (atlases/gait2392.yaml:
  the Visible Human Female's legs onto gait2392).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from axdf_cli.errors import InputError, Mark
from axdf_cli.tools import constants as tol
from axdf_cli.fileio.yamlio import NAME_ALLOWED, Fields, check_name, did_you_mean, is_name, item_marks, load_yaml

DATA = Path(__file__).resolve().parent.parent / "data"
RIG_FILE = DATA / "makehuman" / "bone_map.yaml"
FAMILIES_FILE = DATA / "skeleton_families.yaml"

#: The sides a ``{s}`` entry is made for, in order: (s, S, side).
SIDES = (("l", "L", "Left"), ("r", "R", "Right"))
PLACEHOLDERS = "{s} (l, r), {S} (L, R), {side} (Left, Right)"
#: The landmarks every family has: the stature is estimated from them (axdf_cli/model/stature.py).
NEEDED_LANDMARKS = ("hip_l", "hip_r", "knee_l", "knee_r", "ankle_l", "ankle_r")


def _names(value, where: Mark, what: str, most: int | None = None, empty: bool = False) -> tuple:
    """A non-empty (``empty``: possibly empty) list of at most ``most`` names."""
    if not isinstance(value, list) or not (value or empty):
        raise InputError(where, f"{what} is not a list of names", f"{what}: a list of one name or more, [A, B]")
    if most is not None and len(value) > most:
        raise InputError(where, f"{what} lists {len(value)} names", f"{what}: at most {most}")
    return tuple(check_name(v, m, what) for v, m in zip(value, item_marks(value, where)))


def _entries(f: Fields, key: str, optional: bool = False, most: int | None = None) -> list:
    """(key, value, key mark, value mark) of the mapping ``key`` of ``f`` (required, not empty;
    ``optional``: absent or empty gives none), of at most ``most`` entries."""
    m = f.mapping(key, required=not optional)
    if not m:
        if optional:
            return []
        raise InputError(f.vmark(key), f"{key} is empty", f"{key}: one entry or more")
    if most is not None and len(m) > most:
        raise InputError(f.vmark(key), f"{key} has {len(m)} entries", f"{key}: at most {most}")
    return [(k, v, m.key_mark(k), m.value_mark(k)) for k, v in m.items()]


def _known(key, kmark: Mark, known, what: str) -> str:
    if key not in known:
        raise InputError(kmark, f"unknown {what} {key!r}", f"{did_you_mean(key, known)}{what}s: {', '.join(known)}")
    return key


# ----------------------------------------------------------------------------- the rig


@dataclass(frozen=True)
class Rig:
    """MakeHuman's rig as the fit reads it (the file's own doc)."""

    parts: dict  # part -> (segment whose map moves it, rig bones that start it)
    segments: dict  # segment -> (parent or None, proximal landmark, distal landmark or None), parents first
    keep_length: frozenset  # segments turned but kept at MakeHuman's length
    landmarks: dict  # landmark -> rig bones whose heads' mean it is
    centres: dict  # centre -> (landmark, landmark): their midpoint
    lower_belly: str  # the rig bone moving with the pelvis whose skin has the belly's fat
    bone_marks: dict = field(default_factory=dict, compare=False)  # rig bone -> where it is first named
    fallback: dict = field(default_factory=dict)  # part -> the part it is bound as where a family binds it no bone
    across: dict = field(default_factory=dict)  # segment -> (landmark, landmark): the direction fixing its turn
    turn: dict = field(default_factory=dict)  # segment -> the share (0..1) of its across: turn it takes


def load_rig(path: Path | str = RIG_FILE) -> Rig:
    path = str(path)
    f = Fields(load_yaml(path), Mark(path), "the rig", keys=("parts", "segments", "landmarks", "centres",
                                                              "lower_belly"))
    marks: dict = {}

    def bones(value, where, what):
        out = _names(value, where, what)
        for b, m in zip(out, item_marks(value, where)):
            marks.setdefault(b, m)
        return out

    landmarks = {check_name(k, km, "landmark"): bones(v, vm, f"landmark {k}'s bones")
                 for k, v, km, vm in _entries(f, "landmarks")}
    centres = {}
    for k, v, km, vm in _entries(f, "centres"):
        pair = _names(v, vm, f"centre {k}")
        if len(pair) != 2:
            raise InputError(vm, f"centre {k} names {len(pair)} landmarks", "a centre: [LEFT, RIGHT], two landmarks")
        for p, m in zip(pair, item_marks(v, vm)):
            _known(p, m, landmarks, "landmark")
        centres[check_name(k, km, "centre")] = pair
    points = list(landmarks) + list(centres)
    segments, keep, across, turn = {}, set(), {}, {}
    for k, v, km, vm in _entries(f, "segments"):
        s = Fields(v, vm, f"segment {k}", keys=("parent", "from", "to", "keep_length", "across", "turn"))
        parent = s.raw("parent", required=True)
        if parent is not None and parent not in segments:
            raise InputError(s.vmark("parent"), f"segment {k}'s parent {parent!r} is not a segment before it",
                             f"{did_you_mean(parent, segments)}parents first: {', '.join(segments) or 'none yet'}")
        prox = _known(s.name("from", required=True), s.vmark("from"), points, "landmark")
        dist = s.raw("to", required=True)
        if dist is not None:
            _known(dist, s.vmark("to"), points, "landmark")
        if s.boolean("keep_length", default=False):
            keep.add(k)
        if s.has("across"):
            pair = _names(s.raw("across"), s.vmark("across"), f"segment {k}'s across")
            if len(pair) != 2 or pair[0] == pair[1]:
                raise InputError(s.vmark("across"), f"segment {k}'s across names {len(pair)} landmarks"
                                 if len(pair) != 2 else f"segment {k}'s across names {pair[0]} twice",
                                 "across: [FROM, TO], two landmarks: the direction from one to the other")
            for p, m in zip(pair, item_marks(s.raw("across"), s.vmark("across"))):
                _known(p, m, points, "landmark")
            across[k] = pair
            turn[k] = float(s.number("turn", default=1.0, lo=0.0, hi=1.0))
        elif s.has("turn"):
            raise InputError(s.vmark("turn"), f"segment {k} has turn: but no across:",
                             "turn: the share of the turn its across: landmarks give; give both or neither")
        segments[check_name(k, km, "segment")] = (parent, prox, dist)
    if next(iter(segments.values()))[0] is not None:
        raise InputError(f.vmark("segments"), "the first segment has a parent", "the root segment first (parent: null)")
    parts, fallback = {}, {}
    for k, v, km, vm in _entries(f, "parts"):
        p = Fields(v, vm, f"part {k}", keys=("segment", "bones", "as"))
        seg = _known(p.name("segment", required=True), p.vmark("segment"), list(segments), "segment")
        if p.has("as"):
            fallback[k] = _known(p.name("as"), p.vmark("as"), [q for q in parts if q not in fallback], "part")
        parts[check_name(k, km, "part")] = (seg, bones(p.raw("bones", required=True), p.vmark("bones"),
                                                       f"part {k}'s bones"))
    belly = f.name("lower_belly", required=True)
    marks.setdefault(belly, f.vmark("lower_belly"))
    return Rig(parts, segments, frozenset(keep), landmarks, centres, belly, marks, fallback, across, turn)


@lru_cache(maxsize=None)
def rig() -> Rig:
    """The packaged rig (read once)."""
    return load_rig(RIG_FILE)


# ----------------------------------------------------------------------------- skeleton families


@dataclass(frozen=True)
class Family:
    """How one family of skeletons takes the body: which bone's origin is each landmark, which
    bone each part is bound to, and (without shoulders) the trunk's up axis in a bone's frame."""

    name: str
    landmarks: dict  # landmark -> skeleton bone (its origin at rest is the landmark)
    bind: dict  # part -> skeleton bone
    up: tuple | None = None  # (bone, axis in its frame): the trunk's direction without shoulders
    points: dict = field(default_factory=dict)  # landmark -> (bone, point in its frame): joints it lacks
    back: float = 0.0  # metres the trunk sits behind where its hip centre puts it (the spine's depth)


def _sided(f: Fields, key: str, known, what: str) -> dict:
    """The mapping ``key`` of ``f`` with every ``{s}`` entry made per side (:data:`SIDES`), its
    keys checked against ``known``: key -> skeleton bone."""
    out = {}
    for k, v, km, vm in _entries(f, key):
        if not isinstance(v, str):
            check_name(v, vm, f"{what} {k}'s bone")
        made = [(k, v)]
        if isinstance(k, str) and "{s}" in k:
            try:
                made = [(k.replace("{s}", s), v.format(s=s, S=S, side=side)) for s, S, side in SIDES]
            except (KeyError, IndexError, ValueError):
                raise InputError(vm, f"{what} {k}'s bone {v!r} has an unknown placeholder",
                                 f"placeholders {PLACEHOLDERS}") from None
        for name, bone in made:
            _known(name, km, known, what)
            if name in out:
                raise InputError(km, f"{what} {name} is given twice", f"each {what} once")
            out[name] = check_name(bone, vm, f"{what} {name}'s bone")
    return out


def _family(item, where: Mark, the_rig: Rig) -> Family:
    f = Fields(item, where, "a family", keys=("name", "landmarks", "bind", "points", "up", "back"))
    name = f.name("name", required=True)
    landmarks = _sided(f, "landmarks", list(the_rig.landmarks), "landmark")
    bind = _sided(f, "bind", list(the_rig.parts), "part")
    bind.update({p: bind[q] for p, q in the_rig.fallback.items() if p not in bind and q in bind})
    unbound = [p for p in the_rig.parts if p not in bind]
    if unbound:
        raise InputError(f.vmark("bind"), f"family {name} binds no bone for part{'s' if len(unbound) > 1 else ''} "
                         f"{', '.join(unbound)}", "a bone for every part: " + ", ".join(the_rig.parts))
    points = {}
    for k, v, km, vm in (_entries(f, "points") if f.has("points") else []):
        _known(k, km, list(the_rig.landmarks), "landmark")
        if k in landmarks:
            raise InputError(km, f"landmark {k} is both a bone's origin and a point", "each landmark once")
        p = Fields(v, vm, f"point {k}", keys=("bone", "at"))
        points[k] = (p.name("bone", required=True), p.vector("at", 3, required=True))
    up = None
    if f.has("up"):
        u = Fields(f.mapping("up"), f.vmark("up"), "up", keys=("bone", "axis"))
        up = (u.name("bone", required=True), u.vector("axis", 3, required=True))
    lacking = [k for k in NEEDED_LANDMARKS if k not in landmarks and k not in points]
    if lacking:
        raise InputError(f.vmark("landmarks"), f"family {name} has no landmark {', '.join(lacking)}",
                         f"every family has {', '.join(NEEDED_LANDMARKS)} (the stature is estimated from them)")
    return Family(name, landmarks, bind, up, points, float(f.number("back", default=0.0, lo=0.0, hi=1.0)))


def load_families(path: Path | str = FAMILIES_FILE, the_rig: Rig | None = None) -> tuple:
    path = str(path)
    f = Fields(load_yaml(path), Mark(path), "the skeleton families", keys=("families",))
    seq = f.seq("families", required=True, min_len=1)
    out, seen = [], {}
    for item, m in zip(seq, item_marks(seq, f.vmark("families"))):
        fam = _family(item, m, rig() if the_rig is None else the_rig)
        if fam.name in seen:
            raise InputError(m, f"family {fam.name} is given twice (first at line {seen[fam.name].line})",
                             "each family once")
        seen[fam.name] = m
        out.append(fam)
    return tuple(out)


@lru_cache(maxsize=None)
def families() -> tuple:
    """The packaged skeleton families, in the order they are tried (read once)."""
    return load_families(FAMILIES_FILE)


# ----------------------------------------------------------------------------- the atlas map

#: The placeholders of an atlas map's ``files:`` pattern.
FILE_FIELDS = ("folder", "kind", "name")
#: The placeholders an atlas name may hold: the side's folder word lowercased and capitalised
#: (BodyParts3D spells a side inside its names: ``Clavicular_part_of_{side}_deltoid``).
NAME_FIELDS = ("side", "Side")


@dataclass(frozen=True)
class Landmark:
    """One landmark of an atlas map: an atlas point against a model point.

    ``cartilage``: the centre of the sphere fitted to that atlas cartilage, against the model
    bone's rest origin (a joint centre). ``centroid``: the surface centroid of those atlas
    bones, against the surface centroid of the model bone's mesh at rest (an atlas without
    joint cartilages, BodyParts3D). Exactly one of the two is given."""

    bone: str  # the model bone, without its side suffix (unless ``midline``)
    cartilage: str | None = None
    centroid: tuple = ()
    other: bool = False  # of the other side (the pelvis' width fixes the turn about the leg)
    midline: bool = False  # the model bone has no side suffix (a torso, a spine)


@dataclass(frozen=True)
class AtlasMap:
    """An atlas onto a model (the map file's own doc; atlases/gait2392.yaml). Model names lack
    the side suffix (added per side: ``sides:``, by default ``_r``, ``_l``)."""

    muscles: dict  # model muscle -> atlas muscles, the first that exists on the side
    split: dict  # model group -> (atlas muscles, the group's model muscles in order)
    kept: tuple  # model muscles the atlas lacks
    unused: tuple  # atlas muscles the model has none for
    sides: dict  # side -> the atlas' folder (or word) of that side
    landmarks: dict  # landmark -> Landmark
    bones: tuple  # (atlas bones, model bone, correspondences both ways?, midline?)
    files: str = "{folder}/{name}.ply"  # an atlas file's path in its folder ({folder}, {kind}, {name}; * globs)
    credit: str = ""  # the atlas' credit and licence, written with what is derived from it
    path: str = ""  # the map file
    marks: dict = field(default_factory=dict, compare=False)  # ("landmark", k) | ("bone", i) | key -> Mark
    suffixes: dict = field(default_factory=dict)  # side -> (the model muscles' suffix, the model bones')
    close: tuple = ()  # atlas muscles that are open surfaces, closed by their winding numbers
    articulated: bool = False  # each atlas bone first placed rigidly on its model bone, then the warp
    added: dict = field(default_factory=dict)  # shape muscle the model lacks -> (atlas muscles, its bones)

    def muscle_name(self, name: str, side: str) -> str:
        """A model muscle's name on a side (its suffix added)."""
        return name + self.suffixes.get(side, (f"_{side}", f"_{side}"))[0]

    def on_side(self, name: str, side: str) -> bool:
        """Whether a model muscle's name is of ``side``: it ends with that side's suffix, or, where
        that suffix is empty, with no other side's."""
        sfx = {s: self.suffixes.get(s, (f"_{s}", f"_{s}"))[0] for s in ("r", "l")}
        if sfx[side]:
            return name.endswith(sfx[side])
        return not any(v and name.endswith(v) for s, v in sfx.items() if s != side)

    def added_bones(self, name: str, side: str, bones) -> list[str] | None:
        """An added muscle's bones on a side as the skeleton (``bones``: its bone names) names
        them: each with the side's suffix, or as written (a midline bone); None if one is neither."""
        out = []
        for b in self.added[name][1]:
            got = next((c for c in (self.bone_name(b, side), b) if c in bones), None)
            if got is None:
                return None
            out.append(got)
        return out

    def bone_name(self, name: str, side: str, midline: bool = False) -> str:
        """A model bone's name on a side (its suffix added, unless a midline bone)."""
        return name if midline else name + self.suffixes.get(side, (f"_{side}", f"_{side}"))[1]


def _atlas_names(value, where: Mark, what: str, most: int | None = None, empty: bool = False) -> tuple:
    """Names of atlas files: names, each of which may hold ``{side}`` and ``{Side}``."""
    if not isinstance(value, list) or not (value or empty):
        raise InputError(where, f"{what} is not a list of names", f"{what}: a list of one name or more, [A, B]")
    if most is not None and len(value) > most:
        raise InputError(where, f"{what} lists {len(value)} names", f"{what}: at most {most}")
    out = []
    for v, m in zip(value, item_marks(value, where)):
        bare = v.replace("{side}", "x").replace("{Side}", "X") if isinstance(v, str) else v
        if not is_name(bare):
            raise InputError(m, f"{what}: {v!r} is not an atlas name",
                             f"{NAME_ALLOWED}; {{side}} and {{Side}} stand for the side's word (lower case, "
                             "capitalised)")
        out.append(v)
    return tuple(out)


def load_atlas_map(path: Path | str) -> AtlasMap:
    """An atlas map read and checked (FILE:LINE:COL errors)."""
    path = str(path)
    if not Path(path).is_file():
        raise InputError(Mark(path), "atlas map not found", "a YAML atlas map (atlases/gait2392.yaml shows one)")
    f = Fields(load_yaml(path), Mark(path), "the atlas map",
               keys=("files", "credit", "muscles", "split", "kept", "unused", "sides", "landmarks", "bones", "close",
                     "articulated", "added"))
    marks: dict = {"files": f.vmark("files"), "sides": f.vmark("sides"), "landmarks": f.vmark("landmarks")}
    files = f.string("files", required=True)
    import string

    try:
        parsed = list(string.Formatter().parse(files))
    except ValueError as e:
        raise InputError(f.vmark("files"), f"files: {e}", "a pattern with {folder}, {kind} and {name}") from None
    used = {fld for _, fld, _, _ in parsed if fld is not None}
    spec = next((f"{{{fld}{'!' + conv if conv else ''}{':' + sp if sp else ''}}}" for _, fld, sp, conv in parsed
                 if fld is not None and (sp or conv)), None)
    if not used <= set(FILE_FIELDS) or "name" not in used or Path(files).is_absolute() or ".." in Path(files).parts \
            or spec is not None:
        raise InputError(f.vmark("files"), f"files: {files!r} is not an atlas file pattern"
                         + (f" ({spec}: a placeholder takes no format or conversion)" if spec else ""),
                         "a relative path with {name} and, as needed, {folder} (the side's folder) and {kind} "
                         "(Muscle, Bone, Cartilage), e.g. \"{folder}/VHF_{folder}_{kind}_{name}_smooth.ply\"")
    credit = f.string("credit", default="")
    model: dict = {}  # model muscle -> where the map first names it

    def once(name, where: Mark, what: str):
        if name in model:
            raise InputError(where, f"{what} {name} is named twice (first at line {model[name].line})",
                             "each muscle once, in one of muscles:, split: parts, added: and kept:")
        model[name] = where

    most = tol.ATLAS_MAX_NAMES
    muscles = {}
    for k, v, km, vm in _entries(f, "muscles", most=tol.ATLAS_MAX_MUSCLES):
        once(k, km, "muscle")
        muscles[check_name(k, km, "muscle")] = _atlas_names(v, vm, f"muscle {k}'s atlas names", most)
        marks[("muscle", k)] = vm
    split = {}
    for k, v, km, vm in _entries(f, "split", optional=True, most=tol.ATLAS_MAX_MUSCLES):
        marks[("muscle", k)] = vm
        s = Fields(v, vm, f"split {k}", keys=("atlas", "parts"))
        parts = _names(s.raw("parts", required=True), s.vmark("parts"), "parts", most)
        for q, qm in zip(parts, item_marks(s.raw("parts"), s.vmark("parts"))):
            once(q, qm, f"split {k}'s part")
        split[check_name(k, km, "group")] = (_atlas_names(s.raw("atlas", required=True), s.vmark("atlas"), "atlas", most),
                                             parts)
    added = {}
    for k, v, km, vm in _entries(f, "added", optional=True, most=tol.ATLAS_MAX_MUSCLES):
        once(k, km, "added muscle")
        marks[("muscle", k)] = vm
        a = Fields(v, vm, f"added muscle {k}", keys=("atlas", "bones"))
        added[check_name(k, km, "muscle")] = (
            _atlas_names(a.raw("atlas", required=True), a.vmark("atlas"), "atlas", most),
            _names(a.raw("bones", required=True), a.vmark("bones"), f"added muscle {k}'s bones", most))
    sides, suffixes = {}, {}
    for k, v, km, vm in _entries(f, "sides"):
        side = _known(k, km, ("r", "l"), "side")
        if isinstance(v, dict):
            sf = Fields(v, vm, f"side {k}", keys=("folder", "muscles", "bones"))
            sides[side] = sf.name("folder", required=True)
            suffixes[side] = tuple(_suffix(sf, key, f"_{side}") for key in ("muscles", "bones"))
        else:
            sides[side] = check_name(v, vm, f"side {k}'s folder")
            suffixes[side] = (f"_{side}", f"_{side}")
        marks[("side", k)] = vm
    landmarks = {}
    for k, v, km, vm in _entries(f, "landmarks", most=tol.ATLAS_MAX_LANDMARKS):
        lm = Fields(v, vm, f"landmark {k}", keys=("cartilage", "centroid", "leg", "bone", "midline"))
        if lm.has("cartilage") == lm.has("centroid"):
            raise InputError(vm, f"landmark {k} has {'both' if lm.has('cartilage') else 'neither'} cartilage: and "
                             "centroid:", "one of cartilage: ATLAS (a sphere's centre against the bone's origin) or "
                             "centroid: [ATLAS, ...] (the bones' surface centroid against the bone mesh's)")
        cart = _atlas_names([lm.raw("cartilage")], lm.vmark("cartilage"), "cartilage")[0] if lm.has("cartilage") \
            else None
        cent = _atlas_names(lm.raw("centroid"), lm.vmark("centroid"), "centroid", most) if lm.has("centroid") else ()
        landmarks[check_name(k, km, "landmark")] = Landmark(
            lm.name("bone", required=True), cart, cent, lm.choice("leg", ("same", "other"), default="same") == "other",
            lm.boolean("midline", default=False))
        marks[("landmark", k)] = vm
    if len(landmarks) < 3:
        raise InputError(f.vmark("landmarks"), f"landmarks has {len(landmarks)} entries",
                         "three landmarks or more (a similarity in 3D)")
    seq = f.seq("bones", required=True, min_len=1)
    if len(seq) > tol.ATLAS_MAX_BONES:
        raise InputError(f.vmark("bones"), f"bones has {len(seq)} entries", f"bones: at most {tol.ATLAS_MAX_BONES}")
    bones = []
    for i, (item, m) in enumerate(zip(seq, item_marks(seq, f.vmark("bones")))):
        b = Fields(item, m, "a bone pair", keys=("atlas", "bone", "both", "midline"))
        bones.append((_atlas_names(b.raw("atlas", required=True), b.vmark("atlas"), "atlas", most),
                      b.name("bone", required=True), b.boolean("both", required=True),
                      b.boolean("midline", default=False)))
        marks[("bone", i)] = m
    kept = _names(f.raw("kept", default=[]), f.vmark("kept") if f.has("kept") else Mark(path), "kept", empty=True)
    for q, qm in zip(kept, item_marks(f.raw("kept", default=[]), f.vmark("kept") if f.has("kept") else Mark(path))):
        once(q, qm, "kept muscle")
    unused = _names(f.raw("unused", default=[]), f.vmark("unused") if f.has("unused") else Mark(path), "unused",
                    empty=True)
    close = _atlas_names(f.raw("close", default=[]), f.vmark("close") if f.has("close") else Mark(path), "close",
                         most=tol.ATLAS_MAX_MUSCLES, empty=True)
    return AtlasMap(muscles, split, kept, unused, sides, landmarks, tuple(bones), files, credit, path, marks,
                    suffixes, close, f.boolean("articulated", default=False), added)


def _suffix(f: Fields, key: str, default: str) -> str:
    """A side's name suffix (``muscles:`` or ``bones:``): empty, or '_' and a name."""
    v = f.raw(key, default=default)
    if v is None:
        v = ""
    if not isinstance(v, str) or (v and not is_name(v)):
        raise InputError(f.vmark(key), f"{key}: {v!r} is not a name suffix",
                         f"{key}: the suffix the model adds to its names on that side, e.g. '_r', or '' for none")
    return v
