"""Pose files (``pose:``, ``keys:``) → a frozen :class:`Pose` on its skeleton (docs/FORMATS.md)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.model.skeleton import Skeleton
from axdf_cli.specs.refs import RefPolicy
from axdf_cli.specs.skeleton import load_skeleton
from axdf_cli.fileio.yamlio import (Fields, YMap, check_name, check_number, check_vector, did_you_mean, load_yaml)



INTERPOLATIONS = ("linear", "step", "cubic")
POSE_KEYS = ("pose", "skeleton", "fps", "frames", "interpolation", "clamp_ranges", "keys", "activation")


@dataclass(frozen=True)
class Pose:
    name: str
    skeleton: Skeleton
    fps: float
    first: int
    last: int
    interpolation: str
    keys: dict  # coord -> ((frames...), (values...))
    activation: dict  # muscle -> ((frames...), (values...))
    activation_marks: dict  # muscle -> Mark (to report unknown muscles)
    source: str = ""
    skeleton_path: str = ""
    clamp_ranges: bool = False  # hold coordinates inside their skeleton ranges (else: warn)
    key_marks: dict = field(default_factory=dict)  # coord -> Mark of its first key (for range warnings)

    @property
    def frames(self) -> np.ndarray:
        return np.arange(self.first, self.last + 1)


def _frame_key(frame, where: Mark, what: str, first: int, last: int) -> int:
    f = check_number(frame, where, what, 0, 10_000_000, integer=True)
    if not first <= f <= last:
        raise InputError(where, f"{what} {f} is outside the pose's frames [{first}, {last}]",
                         f"keys at frames {first}..{last} (widen `frames` to key more)")
    return int(f)


#: Motion files that are not poses → the command that turns them into one.
MOTION_IMPORTS = {".bvh": "axdf retarget FILE.bvh --map MAP.yaml --out DIR",
                  ".mot": "axdf import osim MODEL.osim --motion FILE --out DIR",
                  ".sto": "axdf import osim MODEL.osim --motion FILE --out DIR"}
#: The retarget maps shipped with axdf (a clone's poses/maps/), for the hint of a BVH given as a pose.
SHIPPED_MAPS = Path(__file__).resolve().parents[2] / "poses" / "maps"


def motion_hint(path: Path) -> str:
    """What to do with a motion file given where a pose belongs. A BVH is fitted onto the
    muscles' skeleton by ``axdf retarget`` through a map (the shipped ones name the exact
    command); ``axdf import bvh`` would make a pose of the BVH's own skeleton, whose bones no
    muscle library uses."""
    suffix = path.suffix.lower()
    if suffix != ".bvh":
        return f"import it first ({MOTION_IMPORTS[suffix]}) and pass the pose YAML it writes"
    maps = sorted(SHIPPED_MAPS.glob("cmu_to_*.yaml")) if SHIPPED_MAPS.is_dir() else []
    if not maps:
        return ("fit it onto the muscles' skeleton first: axdf retarget FILE.bvh --onto SKELETON.yaml --map MAP.yaml "
                "--out DIR (docs/FORMATS.md, 'Retarget map'), then pass DIR/NAME.yaml as the pose")
    first = next((m for m in maps if m.stem == "cmu_to_gait2392"), maps[0])
    onto = first.stem[len("cmu_to_"):]
    name = f"{path.stem}_{onto}"
    others = ", ".join(f"{_shown(m)} onto {m.stem[len('cmu_to_'):]}" for m in maps)
    return (f"fit it onto the muscles' skeleton first, e.g. for {onto}'s muscles: axdf retarget {_shown(path)} "
            f"--map {_shown(first)} --name {name} --out out/{name}, then --pose out/{name}/{name}.yaml "
            f"(shipped maps for CMU-style takes: {others}; another take's joints need a map of their own, "
            "docs/FORMATS.md 'Retarget map')")


def _shown(p: Path) -> str:
    """``p`` relative to the current folder where it lies under it, else absolute."""
    rel = os.path.relpath(p.resolve())
    return rel if not rel.startswith("..") else str(p.resolve())


def load_pose(path: Path | str, policy: RefPolicy | None = None) -> Pose:
    policy = policy or RefPolicy()
    path = Path(path)
    if path.suffix.lower() in MOTION_IMPORTS:
        raise InputError(Mark(str(path)), f"a {path.suffix} motion is not an axdf pose", motion_hint(path))
    return pose_from_document(load_yaml(path), path, policy)


def parse_pose_text(text: str, path: Path | str, skeletons: dict | None = None,
                    policy: RefPolicy | None = None) -> Pose:
    """A pose from YAML text that will live at ``path``; ``skeletons``: skeletons not on disk
    yet, by path (an importer checks what it is about to write)."""
    from axdf_cli.fileio.yamlio import parse_yaml

    return pose_from_document(parse_yaml(text, str(path)), Path(path), policy or RefPolicy(), skeletons)


def pose_from_document(doc, path: Path, policy: RefPolicy, skeletons: dict | None = None) -> Pose:
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "pose file", keys=POSE_KEYS)
    name = f.name("pose", required=True)
    skel_ref = f.string("skeleton", required=True)
    skel_path = policy.resolve(path, skel_ref, f.vmark("skeleton"))
    known = {os.path.realpath(k): v for k, v in (skeletons or {}).items()}
    skel = known.get(os.path.realpath(skel_path))
    if skel is None and skeletons is not None and not skel_path.is_file():
        # a pose about to be written: its folder may not exist yet, so '..' is taken lexically
        skel_path = Path(os.path.normpath(skel_path))
    if skel is None:
        if not skel_path.is_file():
            raise InputError(f.vmark("skeleton"), f"skeleton file {skel_ref!r} not found",
                             "a path relative to the pose file")
        skel = load_skeleton(skel_path, policy)
    fps = f.number("fps", default=30.0, lo=0.0, hi=tol.MAX_FPS, lo_open=True)
    fr = f.raw("frames", required=True)
    first, last = check_vector(fr, f.vmark("frames"), "frames", 2, 0, 10_000_000)
    if not (float(first).is_integer() and float(last).is_integer()) or last < first:
        raise InputError(f.vmark("frames"), f"frames is {list(fr)}", "[first, last] integers with first <= last")
    first, last = int(first), int(last)
    interp = f.choice("interpolation", INTERPOLATIONS, default="linear")
    clamp = f.boolean("clamp_ranges", default=False)
    keys_map = f.mapping("keys", required=True)
    cidx = skel.coord_index
    series: dict[str, list] = {}
    key_marks: dict[str, Mark] = {}
    for frame, values in keys_map.items():
        fnum = _frame_key(frame, keys_map.key_mark(frame), "key frame", first, last)
        vm = keys_map.value_mark(frame)
        if not isinstance(values, dict):
            raise InputError(vm, f"key {frame} is not a mapping", "keys: {FRAME: {COORD: value}}")
        for coord, val in values.items():
            cm = values.key_mark(coord) if isinstance(values, YMap) else vm
            if coord not in cidx:
                raise InputError(cm, f"unknown coordinate {coord!r}",
                                 f"{did_you_mean(coord, cidx)}coordinates of skeleton {skel.name}: {', '.join(cidx)}")
            leader = skel.coordinates[cidx[coord]].follows
            if leader is not None:
                raise InputError(cm, f"coordinate {coord!r} is coupled: it follows {leader!r} through the "
                                 f"skeleton's function", f"key {leader!r} instead; a pose sets free coordinates only")
            x = check_number(val, values.value_mark(coord) if isinstance(values, YMap) else vm, coord)
            series.setdefault(coord, []).append((fnum, float(x)))
            key_marks.setdefault(coord, cm)
    act_map = f.mapping("activation", default=None)
    activation, act_marks = {}, {}
    if act_map is not None:
        for muscle, curve in act_map.items():
            mm = act_map.key_mark(muscle)
            check_name(muscle, mm, "muscle name")
            if not isinstance(curve, dict):
                raise InputError(act_map.value_mark(muscle), f"activation of {muscle} is not a mapping",
                                 "activation: {MUSCLE: {FRAME: 0..1}}")
            pts = []
            for frame, val in curve.items():
                fnum = _frame_key(frame, curve.key_mark(frame), "activation frame", first, last)
                pts.append((fnum, float(check_number(val, curve.value_mark(frame), "activation", 0.0, 1.0))))
            pts.sort()
            activation[muscle] = (tuple(p[0] for p in pts), tuple(p[1] for p in pts))
            act_marks[muscle] = mm
    f.done()
    keys = {}
    for coord, pts in series.items():
        pts.sort()
        keys[coord] = (tuple(p[0] for p in pts), tuple(p[1] for p in pts))
    return Pose(name, skel, float(fps), first, last, interp, keys, activation, act_marks, str(path), str(skel_path),
                clamp, key_marks)
