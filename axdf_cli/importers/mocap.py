"""Motion as joint positions: a BVH take or an ``.npz`` of 3D keypoints → :class:`Mocap`.

Whatever drives a muscle model through ``axdf retarget`` is first turned into named joint
centres over frames, in axdf's world (Z-up, metres):

- **BVH** (:func:`read_bvh_joints`): the file is read by the BVH importer
  (:func:`axdf_cli.importers.bvh.read_bvh`, its checks and ``FILE:LINE:COL`` errors) and posed
  by forward kinematics on the skeleton ``axdf import bvh`` would write (the same conventions:
  root ``ground`` turning Y-up into Z-up, channels as DOFs). Joint j is bone j's origin, named
  as the imported bone (``RightKnee``; an end site ``<joint>_end``). Lengths times ``scale``
  (metres per file unit; None: guessed from the rest height, as the importer guesses).
- **npz** (:func:`read_npz_joints`): ``joints`` (F, J, 3) positions, ``names`` (J,) strings
  and an optional scalar ``fps`` (default 30); any keypoint source (SMPL/AMASS joints, a
  video pose estimator) written with ``np.savez``. ``up`` says the file's up axis: ``z``
  (axdf's own) or ``y`` (SMPL, BVH, most estimators: turned as BVH is, X kept, Y → Z,
  Z → −Y). Errors name the array and the index: ``FILE: joints[12, 3, 1]: ...``.

``step`` keeps every step-th frame (fps / step).
"""
from __future__ import annotations

import io
import math
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name, read_input
from axdf_cli.model.skeleton import Bone, Coordinate, Dof, Skeleton, forward_kinematics

#: Suffixes of the motions ``axdf retarget`` reads.
MOTION_SUFFIXES = (".bvh", ".npz")
#: Arrays an ``.npz`` of joints may hold.
NPZ_KEYS = ("joints", "names", "fps")
NPZ_DEFAULT_FPS = 30.0
#: Up axes an ``.npz`` may have, and the rotation taking it to axdf's Z-up world.
UP_AXES = {"z": np.eye(3), "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])}
#: Frames posed at once when a BVH take is turned into joint positions (bounds memory).
FK_CHUNK = 4096
MAX_FRAMES = 1_000_000
MAX_JOINTS = 10_000
#: Values one npz array may hold (3e7: 100,000 frames of 100 joints; 240 MB as float64).
NPZ_MAX_VALUES = 30_000_000


@dataclass(frozen=True)
class Mocap:
    """Named joint positions over frames, in axdf's world."""

    source: str  # the file, as given
    kind: str  # "bvh" | "npz"
    names: tuple[str, ...]  # (J,)
    positions: np.ndarray  # (F, J, 3) float64, metres, Z-up
    fps: float
    notes: tuple[str, ...] = ()  # lines for the user (the unit guess)
    warnings: tuple[str, ...] = ()  # what the user should check (a BVH scaled to a typical height)
    skeleton: object = None  # the motion's own rest skeleton (a BVH's, metres), None for points alone

    @property
    def index(self) -> dict[str, int]:
        return {n: j for j, n in enumerate(self.names)}


def read_motion(path: Path | str, *, scale: float | None = None, step: int = 1, up: str = "z") -> Mocap:
    """A ``.bvh`` or ``.npz`` motion as joint positions (by its suffix)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return read_bvh_joints(path, scale=scale, step=step)
    if suffix == ".npz":
        return read_npz_joints(path, scale=1.0 if scale is None else scale, step=step, up=up)
    raise InputError(Mark(str(path)), f"a {path.suffix or 'suffix-less'} file is not a motion axdf retargets",
                     "a BVH take (.bvh) or joint positions (.npz with joints, names, fps)")


# ----------------------------------------------------------------------------- BVH


def bvh_skeleton(bvh, scale: float) -> Skeleton:
    """The skeleton ``axdf import bvh`` writes for ``bvh`` (``bvh.bvh_bones``), as a
    :class:`Skeleton` in memory."""
    from axdf_cli.importers.bvh import bvh_bones

    bones_in = bvh_bones(bvh, scale)
    index = {b.name: i for i, b in enumerate(bones_in)}
    bones, coords = [], []
    for b in bones_in:
        dofs = tuple(Dof(d.type, tuple(float(x) for x in d.axis), d.coord) for d in b.dofs)
        coords.extend(Coordinate(d.coord, d.type) for d in dofs)
        bones.append(Bone(b.name, index[b.parent] if b.parent is not None else -1,
                          tuple(float(x) for x in (b.offset or (0.0, 0.0, 0.0))),
                          tuple(float(x) for x in (b.orient or (0.0, 0.0, 0.0))), dofs))
    return Skeleton("mocap", tuple(bones), tuple(coords), bvh.source)


def read_bvh_joints(path: Path | str, *, scale: float | None = None, step: int = 1) -> Mocap:
    """Every joint and end site of a BVH take, posed: (F, J, 3) with F = ceil(rows / step)."""
    from axdf_cli.importers.bvh import CHANNELS, coordinate_name, bone_names, choose_unit, frame_rate, read_bvh

    bvh = read_bvh(path)
    units = choose_unit(bvh, scale)
    scale, notes = units.scale, units.notes(person=False)  # (the subject's height: axdf retarget's, one definition)
    skel = bvh_skeleton(bvh, scale)
    names = bone_names(bvh)
    rows = bvh.data[::step]
    cidx = skel.coord_index
    q = np.zeros((len(rows), len(skel.coordinates)))
    for (j, c), values in zip(bvh.columns, rows.T):
        q[:, cidx[coordinate_name(names[j], c)]] = values * scale if CHANNELS[c.lower()][0] == "translation" \
            else values
    positions = np.empty((len(rows), len(names), 3))
    for s in range(0, len(rows), FK_CHUNK):
        world = forward_kinematics(skel, q[s:s + FK_CHUNK])  # (chunk, 1 + J, 4, 4): ground first
        positions[s:s + FK_CHUNK] = world[:, 1:, :3, 3]
    fps = frame_rate(bvh.frame_time, bvh.frame_time_text) / step
    return Mocap(str(path), "bvh", tuple(names), positions, float(fps), tuple(notes), tuple(units.warnings()), skel)


# ----------------------------------------------------------------------------- npz


def _where(path: Path, array: str, index=None) -> str:
    """``FILE: ARRAY[i, j, k]``: where a bad value of an npz sits (InputError's where)."""
    if index is None:
        return f"{path}: {array}"
    return f"{path}: {array}[{', '.join(str(int(i)) for i in index)}]"


#: The longest joint name an npz's ``names`` may hold (axdf names are at most 200 characters).
NAME_MAX_CHARS = 200


def _npz_array(archive: zipfile.ZipFile, info: zipfile.ZipInfo, path: Path, key: str) -> np.ndarray:
    """One array of an npz: its header is read first (shape and dtype), so an object array, one
    past NPZ_MAX_VALUES or NPZ_MAX_ARRAY_BYTES, or names wider than NAME_MAX_CHARS, is refused
    before anything is decompressed into memory (:mod:`~axdf_cli.importers.npzfile`)."""
    from axdf_cli.importers import npzfile

    where = _where(path, key)
    h = npzfile.header(archive, info, where, key)
    if h.dtype.hasobject:
        raise InputError(where, "holds Python objects (pickled)",
                         "numbers (joints, fps) or fixed-width strings (names)")
    if int(np.prod(h.shape, dtype=object)) > NPZ_MAX_VALUES:
        raise InputError(where, f"has shape {h.shape}", f"at most {NPZ_MAX_VALUES} values")
    chars = h.dtype.itemsize // (4 if h.dtype.kind == "U" else 1)
    if h.dtype.kind in "US" and chars > NAME_MAX_CHARS:
        raise InputError(where, f"is {h.dtype}: strings of {chars} characters",
                         f"names of at most {NAME_MAX_CHARS} characters")
    return npzfile.read(archive, h, where)


def read_npz_joints(path: Path | str, *, scale: float = 1.0, step: int = 1, up: str = "z") -> Mocap:
    """``joints`` (F, J, 3), ``names`` (J,) and optional ``fps`` from an ``.npz``; every
    problem names the array (and the index of the first bad value)."""
    path = Path(path)
    data = read_input(path, str(path), "an existing .npz file (numpy's np.savez)")
    allowed = "an archive written by np.savez with joints, names and fps"
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except (zipfile.BadZipFile, ValueError, OSError) as e:
        raise InputError(Mark(str(path)), f"not a readable .npz ({e})", allowed) from None
    arrays = {}
    with archive:
        members = {}
        for info in archive.infolist():
            key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
            if key not in NPZ_KEYS:
                raise InputError(Mark(str(path)), f"unknown array {key!r}", f"arrays: {', '.join(NPZ_KEYS)}")
            members[key] = info
        for k in ("joints", "names"):
            if k not in members:
                raise InputError(Mark(str(path)), f"no array {k!r}",
                                 "joints (F, J, 3) positions and names (J,) strings; fps optional")
        for key, info in members.items():
            arrays[key] = _npz_array(archive, info, path, key)
    joints, names = arrays["joints"], arrays["names"]
    if joints.dtype.kind not in "fiu" or joints.ndim != 3 or joints.shape[2] != 3:
        raise InputError(_where(path, "joints"), f"is {joints.dtype} of shape {joints.shape}",
                         "numbers of shape (F, J, 3): F frames of J joint positions")
    n_frames, n_joints = joints.shape[:2]
    if not (1 <= n_frames <= MAX_FRAMES and 1 <= n_joints <= MAX_JOINTS):
        raise InputError(_where(path, "joints"), f"has shape {joints.shape}",
                         f"1..{MAX_FRAMES} frames of 1..{MAX_JOINTS} joints")
    values = joints.astype(np.float64)
    bad = ~np.isfinite(values) | (np.abs(values) > tol.MAX_ABS_NUMBER)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise InputError(_where(path, "joints", idx), f"is {values[tuple(idx)]!r}",
                         f"finite numbers within ±{tol.MAX_ABS_NUMBER:g}")
    if names.dtype.kind not in "US" or names.shape != (n_joints,):
        raise InputError(_where(path, "names"), f"is {names.dtype} of shape {names.shape}",
                         f"strings of shape ({n_joints},): one name per joint of joints")
    seen: dict[str, int] = {}
    out_names = []
    for j, raw in enumerate(names):
        try:
            name = raw.decode("ascii") if isinstance(raw, bytes) else str(raw)
        except UnicodeDecodeError:
            name = None
        if name is None or not is_name(name):
            raise InputError(_where(path, "names", (j,)), f"is {raw!r}", NAME_ALLOWED)
        if name in seen:
            raise InputError(_where(path, "names", (j,)), f"{name!r} repeats names[{seen[name]}]", "unique names")
        seen[name] = j
        out_names.append(name)
    fps = NPZ_DEFAULT_FPS
    if "fps" in arrays:
        f = arrays["fps"]
        ok = f.dtype.kind in "fiu" and f.size == 1
        fps = float(f.reshape(-1)[0]) if ok else float("nan")
        if not (math.isfinite(fps) and 0 < fps <= 100000):
            raise InputError(_where(path, "fps"), f"is {f.dtype} {f.reshape(-1)[:3].tolist()} of shape {f.shape}",
                             "one number: frames per second in (0, 100000]")
    turn = UP_AXES[up]
    # p[f, j, i] = turn[i, k] joints[f, j, k] * scale
    positions = np.einsum("ik,fjk->fji", turn, values[::step]) * scale
    return Mocap(str(path), "npz", tuple(out_names), positions, fps / step)
