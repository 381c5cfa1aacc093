"""MuJoCo ``qpos`` motions → axdf coordinates: one reading for ``axdf import mjcf --motion``
and for a data set's ``{motion: FILE.npz}`` (docs/FORMATS.md, "Imported MuJoCo models" and
"Data sets").

A motion is an ``.npz`` holding ``qpos`` (frames × nq, the model's qpos order: joints as the
bodies list them; a free joint takes 7 values, position then quaternion w x y z, a ball 4,
a hinge or slide 1) and optionally ``fps``. Each joint that is a coordinate of the skeleton
(:class:`QposJoint`) reads its values: a hinge in degrees (MuJoCo's radians), a slide in
metres, a quaternion as intrinsic X-Y-Z Euler angles in degrees, unwrapped over the frames. A
joint coupled by ``<equality><joint>`` is no coordinate: its values are not read (it follows
its polynomial of the joint it depends on).

Which qpos values are whose comes from the MJCF model (``axdf import mjcf``) or, for a data
set, from a skeleton that ``axdf import mjcf`` wrote (:func:`skeleton_qpos`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark

DEG = 180.0 / math.pi
#: Frame rate of a motion whose npz has no ``fps``.
DEFAULT_FPS = 30.0
#: At most this many motion frames (as ``axdf import osim``).
MAX_MOTION_FRAMES = 100_000


@dataclass(frozen=True)
class QposJoint:
    """A joint whose qpos values are read: ``kind`` hinge | slide | ball | free, its first qpos
    index ``address``, and the coordinates it gives (hinge, slide: its own; ball: ``J_rx,
    J_ry, J_rz``; free: ``J_tx, J_ty, J_tz, J_rx, J_ry, J_rz``)."""

    joint: str
    kind: str
    address: int
    coords: tuple[str, ...]


#: qpos values per joint kind.
WIDTH = {"free": 7, "ball": 4, "hinge": 1, "slide": 1}


# ----------------------------------------------------------------------------- rotations


def quat_to_euler(q: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) w x y z → intrinsic X-Y-Z Euler angles (..., 3) in degrees
    (R = Rx(a) Ry(b) Rz(c), b in [-90, 90])."""
    from scipy.spatial.transform import Rotation

    import warnings

    q = np.asarray(q, dtype=np.float64)
    flat = q.reshape(-1, 4)
    with warnings.catch_warnings():  # at b = ±90° (gimbal lock) c is set to 0: the rotation is still exact
        warnings.simplefilter("ignore", UserWarning)
        e = Rotation.from_quat(flat[:, [1, 2, 3, 0]]).as_euler("XYZ", degrees=True)
    return e.reshape(q.shape[:-1] + (3,))


def euler_to_quat(e: np.ndarray) -> np.ndarray:
    """Intrinsic X-Y-Z Euler angles (..., 3) in degrees → unit quaternions (..., 4) w x y z."""
    from scipy.spatial.transform import Rotation

    e = np.asarray(e, dtype=np.float64)
    x = Rotation.from_euler("XYZ", e.reshape(-1, 3), degrees=True).as_quat()
    return x[:, [3, 0, 1, 2]].reshape(e.shape[:-1] + (4,))


def unwrap_degrees(a: np.ndarray) -> np.ndarray:
    """Angles (F, ...) in degrees with jumps of ±360° between frames removed."""
    return np.degrees(np.unwrap(np.radians(a), axis=0))


# ----------------------------------------------------------------------------- reading


def read_motion(path: Path, nq: int) -> tuple[np.ndarray, float]:
    """``qpos`` (F, nq) float64 and fps of a motion npz; InputErrors name the array and index.
    Each array's header (shape, dtype) is checked before its data is read
    (:mod:`~axdf_cli.importers.npzfile`): a small file claiming a huge array costs nothing."""
    from axdf_cli.fileio.yamlio import read_input
    from axdf_cli.importers import npzfile

    shown = str(path)
    where = Mark(shown)
    allowed = "np.savez(FILE, qpos=..., fps=...)"
    data = read_input(path, shown, "an existing .npz file")
    if data.startswith(b"\x93NUMPY"):
        raise InputError(where, "a single .npy array, not an .npz archive", allowed)
    with npzfile.open_archive(data, where, allowed) as z:
        arrays = npzfile.members(z)
        if "qpos" not in arrays:
            raise InputError(where, "no array qpos (arrays: " + (", ".join(arrays) or "none") + ")",
                             "qpos (frames × nq) and an optional fps")
        h = npzfile.header(z, arrays["qpos"], where, "qpos")
        if h.dtype.hasobject or h.dtype.kind not in "fiu":
            raise InputError(where, f"qpos has dtype {h.dtype}", "a float or integer array")
        shape = (1,) + h.shape if len(h.shape) == 1 and h.shape[0] == nq else h.shape
        if len(shape) != 2 or shape[1] != nq:
            raise InputError(where, f"qpos has shape {h.shape}", f"(frames, {nq}): the model's nq")
        if shape[0] == 0 or shape[0] > MAX_MOTION_FRAMES:
            raise InputError(where, f"qpos has {shape[0]} frames", f"1..{MAX_MOTION_FRAMES}")
        q = npzfile.read(z, h, where).reshape(shape)
        fv = None
        if "fps" in arrays:
            hf = npzfile.header(z, arrays["fps"], where, "fps")
            if hf.dtype.hasobject or hf.dtype.kind not in "fiu" or int(np.prod(hf.shape)) != 1:
                raise InputError(where, f"fps = array of shape {hf.shape} and dtype {hf.dtype}",
                                 "one number in (0, 10000]")
            fv = npzfile.read(z, hf, where)
    q = q.astype(np.float64)
    bad = np.argwhere(~np.isfinite(q) | (np.abs(q) > tol.MAX_ABS_NUMBER))
    if len(bad):
        f, k = (int(x) for x in bad[0])
        raise InputError(Mark(shown), f"qpos[{f}, {k}] = {float(q[f, k]):g}",
                         f"finite numbers within ±{tol.MAX_ABS_NUMBER:g}")
    fps = DEFAULT_FPS
    if fv is not None:
        if not (0 < float(fv.reshape(-1)[0]) <= 10000):
            raise InputError(Mark(shown), f"fps = {fv!r}", "one number in (0, 10000]")
        fps = float(fv.reshape(-1)[0])
    return q, fps


def qpos_coordinates(joints: list[QposJoint], q: np.ndarray, source: str) -> dict[str, np.ndarray]:
    """Coordinate name → values (F,) in axdf units from qpos (F, nq): hinges in degrees,
    slides in metres, quaternions as unwrapped X-Y-Z Euler angles in degrees. qpos values of
    joints not in ``joints`` (coupled ones) are not read."""
    out: dict[str, np.ndarray] = {}
    for j in joints:
        a = j.address
        if j.kind in ("hinge", "slide"):
            out[j.coords[0]] = q[:, a] * (DEG if j.kind == "hinge" else 1.0)
            continue
        qa = a + (3 if j.kind == "free" else 0)
        quat = q[:, qa:qa + 4]
        n = np.linalg.norm(quat, axis=1)
        if np.any(n < 1e-9):
            f = int(np.argmax(n < 1e-9))
            raise InputError(Mark(source), f"qpos[{f}, {qa}:{qa + 4}] is a zero quaternion (joint {j.joint!r})",
                             "unit quaternions w x y z for ball and free joints")
        euler = unwrap_degrees(quat_to_euler(quat / n[:, None]))
        if j.kind == "free":
            for k in range(3):
                out[j.coords[k]] = q[:, a + k]
        for k in range(3):
            out[j.coords[-3 + k]] = euler[:, k]
    return out


# ----------------------------------------------------------------------------- from a skeleton


def skeleton_qpos(skel, where: Mark | None = None) -> tuple[list[QposJoint], int]:
    """The qpos layout (joints, nq) of a skeleton written by ``axdf import mjcf``: its bones are
    MuJoCo's bodies in MuJoCo's order, each bone's DOFs its joints in order, and its
    coordinates the uncoupled joints in qpos order. Read per bone, DOF by DOF:

    - six plain DOFs T(X) T(Y) T(Z) R(X) R(Y) R(Z) on coordinates ``J_tx .. J_rz``: free joint J
      (7 values);
    - three plain rotations about X, Y, Z on ``J_rx, J_ry, J_rz``: ball joint J (4 values);
    - a translation of no coordinate by a positive constant, followed by a rotation: the
      anchor MuJoCo turns the hinge or ball about (no value; the importer writes it along the
      anchor's direction, so its length is positive);
    - any other DOF: a hinge (rotation) or slide (translation), one value. It is the joint of
      the next coordinate in order when it drives it as an uncoupled joint does (plainly, or
      ``linear: [1, -default]`` for a non-zero ``ref``); otherwise a coupled joint (its value
      is not read).

    Every coordinate must be met so, in order; otherwise the skeleton is not one ``axdf import
    mjcf`` wrote (InputError at ``where``, the skeleton's file by default). One model reads
    otherwise than MuJoCo does: a slide coupled to a positive constant right before a hinge
    at the body's anchor reads as that hinge's anchor; its nq is then one short, and a motion
    of it is refused by its shape, never misread."""
    from axdf_cli.model.skeleton import Constant, Linear

    coords = [c for c in skel.coordinates if c.follows is None]
    names = [c.name for c in coords]
    joints: list[QposJoint] = []
    k = 0  # the next coordinate
    nq = 0
    eye = np.eye(3)

    def plain(d, kind: str, axis: int, coord: str | None) -> bool:
        return (d.type == kind and d.function is None and d.coord == coord
                and np.allclose(d.axis, eye[axis], atol=1e-12))

    def group(dofs, i: int, suffixes: tuple) -> str | None:
        """J when dofs[i:] begin with plain DOFs on the next coordinates J_<suffix>..."""
        if k + len(suffixes) > len(names) or i + len(suffixes) > len(dofs):
            return None
        base = names[k][:-len(suffixes[0]) - 1]
        for m, sfx in enumerate(suffixes):
            kind = "translation" if sfx[0] == "t" else "rotation"
            if names[k + m] != f"{base}_{sfx}" or not plain(dofs[i + m], kind, "xyz".index(sfx[1]), names[k + m]):
                return None
        return base

    for bone in skel.bones:
        dofs = bone.dofs
        i = 0
        while i < len(dofs):
            d = dofs[i]
            for kind, suffixes in (("free", ("tx", "ty", "tz", "rx", "ry", "rz")), ("ball", ("rx", "ry", "rz"))):
                base = group(dofs, i, suffixes)
                if base is not None:
                    joints.append(QposJoint(base, kind, nq, tuple(names[k:k + len(suffixes)])))
                    nq += WIDTH[kind]
                    k += len(suffixes)
                    i += len(suffixes)
                    break
            else:
                if (d.coord is None and d.type == "translation" and isinstance(d.function, Constant)
                        and d.function.value > 0 and i + 1 < len(dofs) and dofs[i + 1].type == "rotation"):
                    i += 1  # a hinge's or ball's anchor
                    continue
                own = k < len(names) and d.coord == names[k] and (
                    d.function is None or (isinstance(d.function, Linear) and d.function.slope == 1.0
                                           and np.isclose(d.function.intercept, -coords[k].default, rtol=1e-9,
                                                          atol=1e-12)))
                if own:
                    joints.append(QposJoint(names[k], "hinge" if d.type == "rotation" else "slide", nq, (names[k],)))
                    k += 1
                nq += 1
                i += 1
    if k != len(names):
        raise InputError(where or Mark(skel.source), f"skeleton {Path(skel.source).name}: coordinate {names[k]!r} "
                         "is not a MuJoCo joint in qpos order", "for a qpos motion, a skeleton written by axdf import "
                         "mjcf (its bones MuJoCo's bodies, its coordinates the joints in qpos order)")
    return joints, nq
