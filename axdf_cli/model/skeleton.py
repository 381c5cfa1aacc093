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

import functools
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

    def derivative(self, x: np.ndarray) -> np.ndarray:
        return np.zeros_like(x, dtype=np.float64)


@dataclass(frozen=True)
class Linear:
    slope: float
    intercept: float

    def __call__(self, x):
        return self.slope * x + self.intercept

    def derivative(self, x):
        return np.full_like(x, self.slope, dtype=np.float64)


@dataclass(frozen=True)
class Polynomial:
    coefficients: tuple[float, ...]  # increasing powers: c0 + c1 x + c2 x^2 ...

    def __call__(self, x):
        return np.polynomial.polynomial.polyval(x, np.asarray(self.coefficients))

    def derivative(self, x):
        c = np.polynomial.polynomial.polyder(np.asarray(self.coefficients, dtype=np.float64))
        return np.polynomial.polynomial.polyval(np.asarray(x, dtype=np.float64), c) + np.zeros_like(x, dtype=np.float64)


@dataclass(frozen=True)
class Multiplier:
    scale: float
    function: object

    def __call__(self, x):
        return self.scale * self.function(x)

    def derivative(self, x):
        return self.scale * self.function.derivative(x)


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

    def derivative(self, xq):
        """d/dx of the spline: ``b_i + 2 c_i dx + 3 d_i dx^2``; the end slopes outside."""
        xq = np.asarray(xq, dtype=np.float64)
        x = self.x
        i = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 1)
        dx = xq - x[i]
        val = self.b[i] + dx * (2.0 * self.c[i] + 3.0 * dx * self.d[i])
        return np.where(xq < x[0], self.b[0], np.where(xq > x[-1], self.b[-1], val))


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
        draws), else -1: for the root, for a bone a coordinate translates directly (a
        floating base such as a BVH's hips, whose "segment" to the world origin is no bone),
        and for a child of a root named ``world`` without a mesh (MuJoCo's world body, as
        ``axdf import mjcf`` writes it: a body fixed in space is not a segment from the origin);
        and for every bone of a skeleton whose bones carry meshes: there a bone without one is a
        frame, not a segment (MuJoCo's attachment sites and phantom bodies, myoarm's
        ``Arm_attachment`` 37 cm up the spine from the torso's origin), drawn as nothing, as
        MuJoCo and OpenSim draw a body without geometry. Sticks are for mesh-less skeletons."""
        if any(b.mesh for b in self.bones):
            return [-1] * len(self.bones)
        out = []
        for bone in self.bones:
            free = any(d.type == "translation" and d.coord is not None and d.function is None for d in bone.dofs)
            root = self.bones[bone.parent] if bone.parent >= 0 else None
            bare_root = root is not None and root.parent < 0 and root.name == "world" and root.mesh is None
            out.append(-1 if bone.parent < 0 or free or bare_root else bone.parent)
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


def bones_between(skel: "Skeleton", bones: set[int]) -> set[int]:
    """``bones`` and every bone on the skeleton's tree between two of them: a path from the
    femur to the calcaneus crosses the tibia and the talus, where the calf's belly lies."""
    def up(b: int) -> list[int]:
        out = []
        while b >= 0:
            out.append(b)
            b = skel.bones[b].parent
        return out

    chains = [up(b) for b in bones]
    shared = set.intersection(*map(set, chains)) if chains else set()
    full = set()
    for chain in chains:  # each bone's way up to the bones' lowest common ancestor
        for b in chain:
            full.add(b)
            if b in shared:
                break
    return full


def bones_below(skel: "Skeleton", bones: set[int]) -> set[int]:
    """``bones`` and every bone below one of them on the skeleton's tree: what a skin bound to
    ``bones`` holds inside it (myobody's patella hangs from the femur, its talus from the
    tibia), and not a root above them (gait2392's ground)."""
    out, grew = set(bones), True
    while grew:
        new = {i for i, bone in enumerate(skel.bones) if bone.parent in out} - out
        out |= new
        grew = bool(new)
    return out


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
    eye, k, kk = _rodrigues_parts(tuple(float(a) for a in axis))
    c = np.cos(angle_rad)[:, None, None]
    s = np.sin(angle_rad)[:, None, None]
    return c * eye + s * k + (1.0 - c) * kk


@functools.lru_cache(maxsize=4096)
def _rodrigues_parts(axis: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """I, the cross-product matrix K and the outer product a aᵀ of a unit axis: the parts of
    Rodrigues' formula that do not depend on the angle (cached: a skeleton poses the same axes
    over and over; the arrays are never written to)."""
    x, y, z = axis
    a = np.array(axis)
    parts = (np.eye(3), np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]]), np.outer(a, a))
    for m in parts:
        m.flags.writeable = False
    return parts


@functools.lru_cache(maxsize=4096)
def _joint_frames(offset: tuple, orient: tuple, post_offset: tuple, post_orient: tuple):
    """A bone's constant parts: ``T(offset) R(orient)`` and ``(T(post_offset) R(post_orient))^-1``
    (None when both are zero); cached, read-only."""
    pre = rigid(euler_xyz(orient), offset)
    post = np.linalg.inv(rigid(euler_xyz(post_orient), post_offset)) if any(post_offset) or any(post_orient) else None
    for m in (pre, post):
        if m is not None:
            m.flags.writeable = False
    return pre, post


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
    return _kinematics(skel, q, None)


@dataclass(frozen=True)
class DofFrames:
    """Where every DOF of a skeleton acts, posed (from :func:`dof_frames`); D DOFs in bone order.

    ``axis`` (F, D, 3) the DOF's unit axis in the world, ``origin`` (F, D, 3) the origin of the
    frame it acts in (a rotation turns about the line through it), ``rate`` (F, D) the DOF's
    value per unit of its coordinate (1, or the function's derivative), ``rotation`` (D,) bool,
    ``coord`` (D,) the coordinate index (-1: a constant DOF), ``bone`` (D,) the bone index."""

    axis: np.ndarray
    origin: np.ndarray
    rate: np.ndarray
    rotation: np.ndarray
    coord: np.ndarray
    bone: np.ndarray


def dof_frames(skel: Skeleton, q: np.ndarray) -> tuple[np.ndarray, DofFrames]:
    """:func:`forward_kinematics` that also records where every DOF acts: (world (F, B, 4, 4),
    :class:`DofFrames`). What :func:`point_jacobian` needs."""
    record: list = []
    world = _kinematics(skel, q, record)
    cidx = skel.coord_index
    q = np.asarray(q, dtype=np.float64)
    dofs = [(b, dof) for b, bone in enumerate(skel.bones) for dof in bone.dofs]
    n_frames = q.shape[0]
    rate = np.ones((n_frames, len(dofs)))
    for d, (_, dof) in enumerate(dofs):
        if dof.coord is None:
            rate[:, d] = 0.0
        elif dof.function is not None:
            rate[:, d] = dof.function.derivative(q[:, cidx[dof.coord]])
    if record:
        axis = np.stack([a for a, _ in record], axis=1)
        origin = np.stack([o for _, o in record], axis=1)
    else:
        axis = origin = np.zeros((n_frames, 0, 3))
    return world, DofFrames(axis, origin, rate, np.array([dof.type == "rotation" for _, dof in dofs], bool),
                            np.array([cidx[dof.coord] if dof.coord is not None else -1 for _, dof in dofs], int),
                            np.array([b for b, _ in dofs], int))


def point_jacobian(skel: Skeleton, frames: DofFrames, world: np.ndarray, bones: np.ndarray,
                   local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points fixed in bones, posed, and their derivatives by the coordinates (analytic).

    ``bones`` (P,) bone indices, ``local`` (P, 3) the points in their bones' frames, ``world``
    and ``frames`` from :func:`dof_frames`. Returns (points (F, P, 3), jacobian (F, P, 3, C)):
    a rotation DOF about the world axis a through o turns a point x at ``a × (x − o)`` per
    radian (π/180 per degree), a translation DOF moves it along a; times the DOF's rate by its
    coordinate; summed over the DOFs of the point's bone and its ancestors."""
    bones = np.asarray(bones, dtype=int)
    local = np.asarray(local, dtype=np.float64)
    # x[f, p, i] = R[f, b_p, i, j] local[p, j] + t[f, b_p, i]
    posed = world[:, bones]  # (F, P, 4, 4)
    x = np.einsum("fpij,pj->fpi", posed[..., :3, :3], local) + posed[..., :3, 3]
    n_coords = len(skel.coordinates)
    moves = _dof_moves(skel, frames.bone)[bones]  # (P, D): DOF d moves the bone of point p
    arm = x[:, :, None, :] - frames.origin[:, None, :, :]  # (F, P, D, 3)
    axis = np.broadcast_to(frames.axis[:, None, :, :], arm.shape)
    rot = np.cross(axis, arm) * (np.pi / 180.0)
    per_dof = np.where(frames.rotation[None, None, :, None], rot, axis)
    per_dof = per_dof * (frames.rate[:, None, :, None] * moves[None, :, :, None])
    onehot = np.zeros((len(frames.coord), n_coords))
    driven = frames.coord >= 0
    onehot[np.nonzero(driven)[0], frames.coord[driven]] = 1.0
    # J[f, p, i, c] = sum_d per_dof[f, p, d, i] onehot[d, c]
    return x, np.einsum("fpdi,dc->fpic", per_dof, onehot)


def _dof_moves(skel: Skeleton, dof_bone: np.ndarray) -> np.ndarray:
    """(B, D) bool: DOF d (on bone ``dof_bone[d]``) moves bone b (its own bone or an ancestor's)."""
    anc = np.zeros((len(skel.bones), len(skel.bones)), bool)  # anc[b, a]: a is b or an ancestor of b
    for b, bone in enumerate(skel.bones):
        anc[b, b] = True
        if bone.parent >= 0:
            anc[b] |= anc[bone.parent]
    return anc[:, dof_bone]


def _kinematics(skel: Skeleton, q: np.ndarray, record: list | None) -> np.ndarray:
    """Forward kinematics; with ``record`` a list, appends (world axis (F, 3), world origin
    (F, 3)) of every DOF in bone order, taken in the frame the DOF acts in."""
    q = np.asarray(q, dtype=np.float64)
    n_frames = q.shape[0]
    values = dof_values(skel, q)
    world = np.empty((n_frames, len(skel.bones), 4, 4))
    for b, bone in enumerate(skel.bones):
        pre, post = _joint_frames(tuple(bone.offset), tuple(bone.orient), tuple(bone.post_offset),
                                  tuple(bone.post_orient))
        local = np.broadcast_to(pre, (n_frames, 4, 4)).copy()
        for dof, v in zip(bone.dofs, values[b]):
            axis = np.asarray(dof.axis)
            if record is not None:
                at = local if bone.parent < 0 else world[:, bone.parent] @ local
                # a[f] = R_at[f] @ axis: the DOF's axis in the world; its frame's origin t_at[f]
                record.append((np.einsum("fij,j->fi", at[:, :3, :3], axis), at[:, :3, 3].copy()))
            if dof.type == "rotation":
                r = axis_angle(axis, np.radians(v))
                # local[f] = local[f] @ [r 0; 0 1]
                local[:, :3, :3] = np.einsum("fij,fjk->fik", local[:, :3, :3], r)
            else:
                # local[f] = local[f] @ T(v axis): translation expressed in the current frame
                local[:, :3, 3] += np.einsum("fij,j->fi", local[:, :3, :3], axis) * v[:, None]
        if post is not None:
            local = local @ post
        world[:, b] = local if bone.parent < 0 else world[:, bone.parent] @ local
    return world
