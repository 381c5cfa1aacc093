"""Skeletons: bones with ordered degrees of freedom, and batched forward kinematics.

A bone's transform in its parent's frame is (applied left to right)::

    M_local = T(offset) · R(orient) · D_1(q) · D_2(q) · ... · D_k(q) · (T(post_offset) · R(post_orient))^-1

where ``R(orient)`` is a body-fixed X-Y-Z Euler rotation in degrees (``Rx·Ry·Rz``, as OpenSim
writes frame orientations), and each ``D_i`` is a rotation about ``axis`` (degrees) or a
translation along ``axis`` (metres) by the value of its coordinate, or by a function of one
coordinate (coupled DOFs such as the knee's translations). ``post_offset``/``post_orient``
place the joint in the child bone's own frame (OpenSim's child offset frame); both default
to identity. World transforms are ``(F, n_bones, 4, 4)``, batch dimension first; bones are
ordered parents before children (checked at load time).

Coordinate values are in axdf units: degrees for rotational coordinates, metres for
translational ones. A function maps its coordinate's value to the DOF's value in the DOF's
units. A *coupled coordinate* (``Coordinate.follows``, OpenSim's ``CoordinateCouplerConstraint``)
is no input: its value is a function of the coordinate it follows, set by
:meth:`Skeleton.couple` wherever coordinates are made (the rest pose, a pose's samples) and
before forward kinematics, so every consumer of ``q`` (kinematics, moving and conditional
path points, labels) sees the same value.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from axdf_cli.errors import InputError

# ----------------------------------------------------------------------------- functions


@dataclass(frozen=True)
class Constant:
    value: float

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.full_like(x, self.value, dtype=np.float64)


@dataclass(frozen=True)
class Linear:
    slope: float
    intercept: float

    def __call__(self, x):
        return self.slope * x + self.intercept


@dataclass(frozen=True)
class Polynomial:
    coefficients: tuple[float, ...]  # increasing powers: c0 + c1 x + c2 x^2 ...

    def __call__(self, x):
        return np.polynomial.polynomial.polyval(x, np.asarray(self.coefficients))


@dataclass(frozen=True)
class Multiplier:
    scale: float
    function: object

    def __call__(self, x):
        return self.scale * self.function(x)


@dataclass(frozen=True, eq=False)
class Spline:
    """Piecewise cubic through (x, y): ``y_i + b_i dx + c_i dx^2 + d_i dx^3`` on [x_i, x_i+1].

    ``kind='fmm'`` uses the end conditions of Forsythe, Malcolm & Moler (1977), the spline of
    OpenSim's SimmSpline; ``kind='natural'`` zero second derivatives (NaturalCubicSpline).
    Outside [x_0, x_n-1] the spline continues linearly with its end slope.
    """

    x: np.ndarray
    y: np.ndarray
    kind: str = "fmm"
    b: np.ndarray = field(init=False, repr=False)
    c: np.ndarray = field(init=False, repr=False)
    d: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        x = np.asarray(self.x, dtype=np.float64)
        y = np.asarray(self.y, dtype=np.float64)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "y", y)
        b, c, d = (_fmm_coefficients if self.kind == "fmm" else _natural_coefficients)(x, y)
        object.__setattr__(self, "b", b)
        object.__setattr__(self, "c", c)
        object.__setattr__(self, "d", d)

    def __call__(self, xq):
        xq = np.asarray(xq, dtype=np.float64)
        x, y = self.x, self.y
        i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 1)
        dx = xq - x[i]
        val = y[i] + dx * (self.b[i] + dx * (self.c[i] + dx * self.d[i]))
        lo, hi = xq < x[0], xq > x[-1]
        val = np.where(lo, y[0] + (xq - x[0]) * self.b[0], val)
        val = np.where(hi, y[-1] + (xq - x[-1]) * self.b[-1], val)
        return val


def _fmm_coefficients(x: np.ndarray, y: np.ndarray):
    """Forsythe-Malcolm-Moler cubic spline coefficients (netlib ``spline.f``)."""
    n = len(x)
    b = np.zeros(n)
    c = np.zeros(n)
    d = np.zeros(n)
    if n < 3:
        b[:] = (y[1] - y[0]) / (x[1] - x[0]) if n == 2 else 0.0
        return b, c, d
    nm1 = n - 1
    d[0] = x[1] - x[0]
    c[1] = (y[1] - y[0]) / d[0]
    for i in range(1, nm1):
        d[i] = x[i + 1] - x[i]
        b[i] = 2.0 * (d[i - 1] + d[i])
        c[i + 1] = (y[i + 1] - y[i]) / d[i]
        c[i] = c[i + 1] - c[i]
    b[0] = -d[0]
    b[nm1] = -d[n - 2]
    c[0] = 0.0
    c[nm1] = 0.0
    if n > 3:
        c[0] = c[2] / (x[3] - x[1]) - c[1] / (x[2] - x[0])
        c[nm1] = c[n - 2] / (x[nm1] - x[n - 3]) - c[n - 3] / (x[n - 2] - x[n - 4])
        c[0] = c[0] * d[0] ** 2 / (x[3] - x[0])
        c[nm1] = -c[nm1] * d[n - 2] ** 2 / (x[nm1] - x[n - 4])
    for i in range(1, n):
        t = d[i - 1] / b[i - 1]
        b[i] -= t * d[i - 1]
        c[i] -= t * c[i - 1]
    c[nm1] /= b[nm1]
    for i in range(n - 2, -1, -1):
        c[i] = (c[i] - d[i] * c[i + 1]) / b[i]
    b[nm1] = (y[nm1] - y[n - 2]) / d[n - 2] + d[n - 2] * (c[n - 2] + 2.0 * c[nm1])
    for i in range(nm1):
        b[i] = (y[i + 1] - y[i]) / d[i] - d[i] * (c[i + 1] + 2.0 * c[i])
        d[i] = (c[i + 1] - c[i]) / d[i]
        c[i] = 3.0 * c[i]
    c[nm1] = 3.0 * c[nm1]
    d[nm1] = d[n - 2]
    return b, c, d


def _natural_coefficients(x: np.ndarray, y: np.ndarray):
    from scipy.interpolate import CubicSpline

    n = len(x)
    if n < 3:
        b = np.full(n, (y[1] - y[0]) / (x[1] - x[0]) if n == 2 else 0.0)
        return b, np.zeros(n), np.zeros(n)
    cs = CubicSpline(x, y, bc_type="natural")
    d3, c2, b1, _ = cs.c  # highest power first, per interval
    b = np.append(b1, cs(x[-1], 1))
    c = np.append(c2, 0.0)
    d = np.append(d3, 0.0)
    return b, c, d


# ----------------------------------------------------------------------------- specs


@dataclass(frozen=True)
class Dof:
    type: str  # 'rotation' (degrees) | 'translation' (metres)
    axis: tuple[float, float, float]  # unit vector in the joint frame
    coord: str | None  # driving coordinate (None: constant function)
    function: object | None = None  # maps the coordinate's value to this DOF's value


@dataclass(frozen=True)
class Coordinate:
    name: str
    type: str  # 'rotation' | 'translation'
    default: float = 0.0
    range: tuple[float, float] | None = None
    #: a coupled coordinate: the coordinate it follows (None: a free coordinate, set by poses)
    follows: str | None = None
    #: its value ``function(q[follows])``, from the leader's units to its own
    function: object | None = None


@dataclass(frozen=True)
class Bone:
    name: str
    parent: int  # index of the parent bone, -1 for the root
    offset: tuple[float, float, float]
    orient: tuple[float, float, float]  # body-fixed XYZ Euler, degrees
    dofs: tuple[Dof, ...]
    post_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    post_orient: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mesh: str | None = None  # path of a PLY in bone-local coordinates (resolved)


@dataclass(frozen=True)
class Skeleton:
    name: str
    bones: tuple[Bone, ...]
    coordinates: tuple[Coordinate, ...]
    source: str = ""

    @property
    def bone_index(self) -> dict[str, int]:
        return {b.name: i for i, b in enumerate(self.bones)}

    @property
    def coord_index(self) -> dict[str, int]:
        return {c.name: i for i, c in enumerate(self.coordinates)}

    def rest_coordinates(self) -> np.ndarray:
        """(C,) float64 default values: the rest pose (coupled coordinates follow theirs)."""
        q = np.array([c.default for c in self.coordinates], dtype=np.float64)
        return self.couple(q[None])[0]

    @cached_property
    def followers(self) -> tuple[tuple[int, int, object], ...]:
        """Coupled coordinates as ``(index, leader index, function)``, every leader before the
        coordinates that follow it (the loader refuses cycles)."""
        idx = self.coord_index
        pending = [c for c in self.coordinates if c.follows is not None]
        done = {c.name for c in self.coordinates if c.follows is None}
        out = []
        while pending:
            ready = [c for c in pending if c.follows in done]
            if not ready:
                raise ValueError(f"coupled coordinates form a cycle: {', '.join(c.name for c in pending)}")
            for c in ready:
                out.append((idx[c.name], idx[c.follows], c.function))
                done.add(c.name)
            pending = [c for c in pending if c.name not in done]
        return tuple(out)

    def couple(self, q: np.ndarray) -> np.ndarray:
        """``q`` (F, C) with every coupled coordinate set to its function of its leader
        (in place; returned): ``q[:, i] = f_i(q[:, leader(i)])``, leaders first. What a
        ``CoordinateCouplerConstraint`` enforces in OpenSim, applied before kinematics."""
        for i, j, fn in self.followers:
            q[:, i] = fn(q[:, j])
        return q

    def stick_parents(self) -> list[int]:
        """Per bone: its parent when the two form one segment (what a stick between their joints
        draws), else -1: for the root, and for a bone a coordinate translates directly (a
        floating base such as a BVH's hips, whose "segment" to the world origin is no bone)."""
        out = []
        for bone in self.bones:
            free = any(d.type == "translation" and d.coord is not None and d.function is None for d in bone.dofs)
            out.append(-1 if bone.parent < 0 or free else bone.parent)
        return out

    def moved_bones(self) -> dict[str, frozenset[int]]:
        """Coordinate → indices of the bones it moves (those whose DOFs it drives, and their
        descendants)."""
        moved: dict[str, set[int]] = {c.name: set() for c in self.coordinates}
        leads: dict[str, set[str]] = {c.name: {c.name} for c in self.coordinates}  # coordinate -> it and its leaders
        for i, j, _ in self.followers:  # leaders first: a leader's own leaders are complete
            leads[self.coordinates[i].name] |= leads[self.coordinates[j].name]
        drivers: list[set[str]] = []  # per bone: every coordinate moving it
        for b, bone in enumerate(self.bones):
            own = set().union(*(leads[d.coord] for d in bone.dofs if d.coord is not None))
            drivers.append(own | (drivers[bone.parent] if bone.parent >= 0 else set()))
            for c in drivers[b]:
                moved[c].add(b)
        return {c: frozenset(v) for c, v in moved.items()}


# ----------------------------------------------------------------------------- rotations


def bone_of(index: dict[str, int], bone: str, mark) -> int:
    """The index of bone ``bone`` in a skeleton's ``bone_index``; an unknown name is an
    :class:`InputError` at ``mark`` naming the skeleton's bones."""
    if bone not in index:
        known = ", ".join(sorted(index))
        raise InputError(mark, f"unknown bone {bone!r}", f"bones of the skeleton: {known}")
    return index[bone]


def euler_xyz(deg) -> np.ndarray:
    """Body-fixed X-Y-Z rotation ``Rx(a)·Ry(b)·Rz(c)`` from degrees: (3, 3) float64."""
    a, b, c = np.radians(np.asarray(deg, dtype=np.float64))
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rx = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rz = np.array([[cc, -sc, 0], [sc, cc, 0], [0, 0, 1]])
    return rx @ ry @ rz


def axis_angle(axis: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Rotations about one unit ``axis`` (3,) by ``angle_rad`` (F,): (F, 3, 3) (Rodrigues)."""
    x, y, z = axis
    c = np.cos(angle_rad)[:, None, None]
    s = np.sin(angle_rad)[:, None, None]
    k = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    kk = np.outer(axis, axis)
    return c * np.eye(3) + s * k + (1.0 - c) * kk


def rigid(rot: np.ndarray, trans) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = trans
    return m


def matrix_to_quaternion(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations → (..., 4) unit quaternions (w, x, y, z) with w >= 0."""
    from scipy.spatial.transform import Rotation

    shape = r.shape[:-2]
    q = Rotation.from_matrix(r.reshape(-1, 3, 3)).as_quat()  # (x, y, z, w)
    q = np.concatenate([q[:, 3:], q[:, :3]], axis=1)
    q *= np.where(q[:, :1] < 0, -1.0, 1.0)
    return q.reshape(*shape, 4)


# ----------------------------------------------------------------------------- kinematics


def dof_values(skel: Skeleton, q: np.ndarray) -> list[list[np.ndarray]]:
    """Per bone, per DOF: the DOF's value over frames (F,), from coordinates ``q`` (F, C)."""
    cidx = skel.coord_index
    out = []
    for bone in skel.bones:
        vals = []
        for dof in bone.dofs:
            x = q[:, cidx[dof.coord]] if dof.coord is not None else np.zeros(q.shape[0])
            vals.append(dof.function(x) if dof.function is not None else x)
        out.append(vals)
    return out


def forward_kinematics(skel: Skeleton, q: np.ndarray) -> np.ndarray:
    """World transform of every bone: ``q`` (F, C) coordinates → (F, n_bones, 4, 4) float64."""
    q = np.asarray(q, dtype=np.float64)
    n_frames = q.shape[0]
    values = dof_values(skel, q)
    world = np.empty((n_frames, len(skel.bones), 4, 4))
    for b, bone in enumerate(skel.bones):
        pre = rigid(euler_xyz(bone.orient), bone.offset)
        local = np.broadcast_to(pre, (n_frames, 4, 4)).copy()
        for dof, v in zip(bone.dofs, values[b]):
            axis = np.asarray(dof.axis)
            if dof.type == "rotation":
                r = axis_angle(axis, np.radians(v))
                # local[f] = local[f] @ [r 0; 0 1]
                local[:, :3, :3] = np.einsum("fij,fjk->fik", local[:, :3, :3], r)
            else:
                # local[f] = local[f] @ T(v axis): translation expressed in the current frame
                local[:, :3, 3] += np.einsum("fij,j->fi", local[:, :3, :3], axis) * v[:, None]
        if any(bone.post_offset) or any(bone.post_orient):
            post = np.linalg.inv(rigid(euler_xyz(bone.post_orient), bone.post_offset))
            local = local @ post
        world[:, b] = local if bone.parent < 0 else world[:, bone.parent] @ local
    return world
