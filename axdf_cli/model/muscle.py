"""The AxDf muscle: axis, bound cross-sections, volume, tension and the B-spline surface.

Method (PAPER.md): the axis ``C(t) = sum_i N_i^2(t) p_i`` is a clamped quadratic B-spline
whose control points ``p_i`` are fixed in bones. Each section is a closed quadratic
B-spline of 8 control points. Every section control point P is bound once, at the rest
pose, as (t, u, v, w): t its closest-point parameter on the rest axis, (u, v, w) its offset
in the axis frame (T, R, S) at t, where T = C'/|C'| and (R, S) is rotation-minimizing
(double reflection, Wang et al. 2008). Deformed, ``P' = C(t) + k (u T + v R + w S)`` in the
new frame, rotated about T by the twist at t.

A section's points are bound on its own part of the axis. A section lies in the plane normal
to the axis at its t, so that t is a stationary point of each of its points' distance to the
axis; their closest point is elsewhere in a bend (the inner side past the centre of curvature:
a little along) or where another part of the axis comes nearer (a folded or flat axis). A
closest point farther along the rest axis from the section's t than the point is from the
section's centre lies on another part: the point is bound at its section's t instead (the
atlas quadratus femoris: 42 of its 128 points, whose closest points lie up to 0.74 away in
t). Bound at such a point, it would be carried by another part's frame and turned about
another part's tangent by another part's share of the twist: its section would come apart
(a roll near a full turn wrung that muscle inside out, its exact volume without a solution;
docs/FIT.md, "Volume under twist"). A closest point within that reach (a bend's: gait2392's
iliacus, arm26's triceps) is kept.

Frames. The start vector R(0) is fixed in the origin bone (the bone of the first axis
point), so a rigid motion of the skeleton moves the muscle rigidly. The insertion bone's
roll is the signed angle at t = 1 between the propagated R(1) and the insertion bone's
rest R(1) carried by that bone; it is spread along the axis in proportion to rest arc
length, and kept continuous over time (past 180 degrees) by unwrapping it against a coarse
pass over the pose's whole frame range, so that any frame subset gives the same meshes.

Radial factor of a control point c: ``k_c = (1 - beta_c) + beta_c * K_c`` with
``K_c = tau_c (e b_c s0 + (1 - e b_c) s)`` (= s without tension), where
- beta_c = 1 in the belly, 0 in the tendons (``tendons: [a, b]`` fractions of rest arc length);
- s the volume factor of the frame: ``paper`` sqrt(l0/l1) as published; ``none`` 1; ``exact``
  the root of the mesh volume's cubic V(s) = V0 (the mesh is affine in s, so its volume is
  exactly a cubic in s; solved by Newton to 1e-10);
- tau_c the isometric tension law: section area multiplied by
  ``1 + g e (2 b - 1)``, b = sin^2(pi x) over the belly (x in [0, 1]), e the effective tension,
  g = TENSION_GAIN. The share e*b of a belly point (its middle at full tension) keeps the
  length-only scale s0 = sqrt(l0/l1) instead of s, so with ``exact`` only the rest (the ends)
  gives way to keep the volume: ``k_c = tau_c (e b s0 + (1 - e b) s)`` (still affine in s).
  Length and volume do not change; tension 1 thickens the mid-belly (the tests require at
  least 15% more area there on the demo muscles).

Surface: a tensor-product quadratic NURBS over the control net [origin pole (8 copies of
C(0)), sections..., insertion pole], clamped along and closed around, tessellated at
``resolution = (along, around)`` into a grid whose pole rows collapse to single vertices.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from axdf_cli.model import bspline, kernels, rmf
from axdf_cli.model.batch import MuscleBatch
from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.model.jiggle import JiggleSpec
from axdf_cli.model.paths.points import PathSpec
from axdf_cli.model.skeleton import bone_of

OCT = 8  # control points per section (the paper's choice)


class VolumeMode(str, Enum):
    """How sections scale with the axis length (module doc): ``exact`` keeps the mesh volume,
    ``paper`` scales by sqrt(l0/l1) as published, ``none`` keeps the rest sections."""

    EXACT = "exact"
    PAPER = "paper"
    NONE = "none"


VOLUME_MODES = tuple(m.value for m in VolumeMode)

# ----------------------------------------------------------------------------- specs


@dataclass(frozen=True)
class AxisPoint:
    bone: str
    at: tuple[float, float, float]
    mark: Mark = field(default=Mark(""), compare=False)


@dataclass(frozen=True)
class Section:
    t: float
    radii: tuple[float, float] | None  # semi-axes (m); None: default from the rest length
    angle: float = 0.0  # degrees, direction of radii[0] from R towards S
    outline: tuple[tuple[float, float], ...] | None = None  # 8 (v, w) control points


@dataclass(frozen=True)
class ContactSpec:
    """A muscle file's ``contact:`` mapping. ``group``: muscles of one group do not collide
    with each other ('' = no group); ``ignore``: names this muscle does not collide with;
    ``yield_``: how deep the muscle lies, in layers (None: from its depth at the rest pose,
    :func:`auto_yield`); of two touching muscles the one with the larger yield gives way more."""

    group: str = ""
    ignore: tuple[str, ...] = ()
    yield_: float | None = None


@dataclass(frozen=True)
class MuscleSpec:
    name: str
    color: tuple[float, float, float]
    axis: tuple[AxisPoint, ...]
    sections: tuple[Section, ...]
    strength: float = 1.0
    tension: float = 0.0
    volume: str = "exact"
    tendons: tuple[float, float] = (0.0, 0.0)
    twist: float = 0.0
    resolution: tuple[int, int] = (40, 24)
    weights: tuple[float, ...] | None = None
    source: str = ""
    group: str = ""  # the multi-head muscle this head belongs to ('' for single muscles)
    path: PathSpec | None = None  # a path (points, wrap surfaces): the axis, or with an axis the line of action
    jiggle: JiggleSpec | None = None  # secondary motion of the axis (model/jiggle.py); None: none
    contact: ContactSpec = ContactSpec()  # the muscle file's ``contact:`` (axdf_cli/model/contact.py)


def ellipse_outline(a: float, b: float, angle_deg: float) -> np.ndarray:
    """8 control points (8, 2) whose closed quadratic B-spline touches the ellipse of
    semi-axes (a, b), rotated by ``angle_deg``, at the 8 edge midpoints of the polygon."""
    th = np.arange(OCT) * (2.0 * np.pi / OCT)
    c = 1.0 / np.cos(np.pi / OCT)
    p = np.stack([c * a * np.cos(th), c * b * np.sin(th)], axis=1)
    ca, sa = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    return p @ np.array([[ca, sa], [-sa, ca]])


def outline_area(p: np.ndarray) -> float:
    """Signed area of a closed polygon (8, 2): positive when counter-clockwise."""
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


# ----------------------------------------------------------------------------- topology


def grid_faces(along: int, around: int) -> np.ndarray:
    """Triangles of the tessellated muscle, counter-clockwise seen from outside: (T, 3) int32.

    Vertex order: origin pole (0), rings 1 .. along-2 (``around`` each), insertion pole.
    """
    rings = along - 2
    last = 1 + rings * around
    j = np.arange(around)
    jn = (j + 1) % around
    faces = [np.stack([np.zeros(around, np.int64), 1 + jn, 1 + j], axis=1)]
    for i in range(rings - 1):
        a = 1 + i * around + j
        b = 1 + i * around + jn
        c = 1 + (i + 1) * around + j
        d = 1 + (i + 1) * around + jn
        faces.append(np.stack([a, b, c], axis=1))
        faces.append(np.stack([c, b, d], axis=1))
    top = 1 + (rings - 1) * around
    faces.append(np.stack([top + j, top + jn, np.full(around, last)], axis=1))
    return np.concatenate(faces).astype(np.int32)


# ----------------------------------------------------------------------------- the model


@dataclass
class FrameResult:
    """One muscle over a block of frames (batch dimension first)."""

    vertices: np.ndarray  # (F, V, 3) float64
    normals: np.ndarray  # (F, V, 3) float64
    length: np.ndarray  # (F,) axis arc length (m); a muscle with a line of action, that line's
    volume: np.ndarray  # (F,) mesh volume (m^3)
    scale: np.ndarray  # (F,) volume factor s
    twist: np.ndarray  # (F,) insertion roll spread along the axis (degrees, unwrapped)
    tension: np.ndarray  # (F,) effective tension
    warnings: list  # [(frame index in block, message)]
    contact: np.ndarray | None = None  # (F, 3) inside another muscle, inside a bone (shares), deepest (m)
    # what the sinks write of it, made after every stage (axdf_cli.pipeline.evaluate.finite_or_rest):
    # positions, normals (F, V, 3) float32, the frames replaced by the rest shape, bounds (F, 2, 3)
    written: tuple | None = None


class MuscleModel:
    """A muscle prepared for evaluation: basis matrices, binding and rest values.

    Built once from a :class:`MuscleSpec`, the skeleton's bone index and the rest pose's
    world transforms ``rest_world`` (n_bones, 4, 4); evaluated for any block of frames.
    """

    def __init__(self, spec: MuscleSpec, bone_index: dict[str, int], rest_world: np.ndarray, skeleton=None):
        """The preparation pipeline, each stage a method of its own: (1) bones and axis bases,
        (2) the rest axis and its frames, (3) the sections' rest control points, (4) their
        binding (t, u, v, w), (5) belly and tension weights, (6) the surface basis, (7) the
        rest surface and its volume V0. ``skeleton`` (its coordinates) is needed by paths with
        moving or conditional points."""
        self.spec = spec
        self.volume_mode = VolumeMode(spec.volume)
        self._stage_bones(bone_index, skeleton)  # 1
        self._stage_axis_bases(self.n_axis)  # 1
        rest_p, x, t, r = self._stage_rest_axis(rest_world)  # 2
        p_rest, cp_t = self._stage_rest_control_points(rest_p, x, t, r)  # 3
        self._stage_binding(rest_p, x, t, r, p_rest, cp_t)  # 4
        self._stage_belly_weights()  # 5
        self._stage_surface_basis()  # 6
        # 7: the rest surface, evaluated without a volume target, gives V0
        rest = self.surface(rest_world[None], rest_p, np.zeros(1), rest_volume=None)
        self.v0 = float(rest.volume[0])
        self._one = None  # (packed again with V0 when next needed)
        self.rest_vertices = rest.vertices[0].astype(np.float32)
        self.rest_normals = rest.normals[0].astype(np.float32)
        self.rest_control_points = p_rest  # (8N, 3) world, rest pose (for tests)
        if not self.v0 > 0:
            raise InputError(_spec_mark(spec), f"muscle {spec.name!r}: rest volume is {self.v0:.3g}",
                             "sections must enclose the axis with positive radii")

    # -- preparation stages -------------------------------------------------------------
    def _stage_bones(self, bone_index: dict[str, int], skeleton) -> None:
        """Bone of every axis control point and the points in their bones; or the path model
        that places the axis control points every frame; or, a muscle with both, the axis's
        bones and the path as its line of action (``self.line``: the path model and the bases
        of its length)."""
        spec = self.spec
        self.rest_q = skeleton.rest_coordinates()[None] if skeleton is not None else None
        self.line = None
        if spec.path is not None:
            from axdf_cli.model.paths.path import PathModel

            path = PathModel(spec.path, bone_index, skeleton.coord_index if skeleton is not None else None)
        if spec.path is not None and spec.axis:  # the path is the line of action only (line_length)
            knots = bspline.clamped_knots(path.n, 2)
            gt, gw = bspline.gauss_legendre_params(knots, 2, tol.LENGTH_GAUSS_POINTS)
            self.line = (path, bspline.basis_matrix(knots, 2, gt, 1), gw)
            if skeleton is not None:
                _check_axis_on_path(spec, bone_index, skeleton)
        elif spec.path is not None:
            self.path = path
            self.n_axis = self.path.n
            self.origin_bone = self.path.origin_bone
            self.insertion_bone = self.path.insertion_bone
            return
        self.path = None
        self.n_axis = len(spec.axis)
        self.bones = np.array([bone_of(bone_index, p.bone, p.mark) for p in spec.axis])
        self.at = np.array([p.at for p in spec.axis], dtype=np.float64)  # (n, 3)
        self.origin_bone = int(self.bones[0])
        self.insertion_bone = int(self.bones[-1])

    def _stage_axis_bases(self, n: int) -> None:
        """Basis matrices of the axis (n control points): dense samples for the RMF recurrence,
        a coarse set for the twist branch, Gauss-Legendre points for the length."""
        knots = bspline.clamped_knots(n, 2)
        self.knots = knots
        self.ts = np.linspace(0.0, 1.0, tol.rmf_samples(n) + 1)
        self.Bs = bspline.basis_matrix(knots, 2, self.ts)
        self.dBs = bspline.basis_matrix(knots, 2, self.ts, 1)
        tc = np.linspace(0.0, 1.0, 4 * (n - 2) + 1)
        self.Bc = bspline.basis_matrix(knots, 2, tc)
        self.dBc = bspline.basis_matrix(knots, 2, tc, 1)
        gt, self.gw = bspline.gauss_legendre_params(knots, 2, tol.LENGTH_GAUSS_POINTS)
        self.dBg = bspline.basis_matrix(knots, 2, gt, 1)
        # the same bases as sparse rows (3 non-zeros each): products cost O(3), not O(n)
        # (keyed by the basis' attribute name, so a pickled or copied model keeps them)
        self.sparse = {k: kernels.sparse_rows(getattr(self, k)) for k in ("Bs", "dBs", "Bc", "dBc", "dBg")}

    def _stage_rest_axis(self, rest_world: np.ndarray):
        """The rest axis: control points, rest length l0 (checked), sampled frames, the start
        vector in the origin bone, the insertion's rest reference, the rest arc fractions."""
        spec = self.spec
        rest_p = self._axis_points(rest_world[None], self.rest_q)  # (1, n, 3)
        self.l0 = float(self._length(rest_p)[0])
        if not self.l0 > tol.MIN_AXIS_LENGTH:
            raise InputError(_spec_mark(spec), f"muscle {spec.name!r}: the rest axis has length {self.l0:.3g} m",
                             "axis control points must not all coincide at the rest pose")
        x, t = self._samples(rest_p, "Bs", "dBs")
        # the start vector is chosen in the origin bone's own axes, so the rest shape does not
        # depend on where the skeleton stands in the world
        r_org = rest_world[self.origin_bone, :3, :3]
        self.r0_local = rmf.any_perpendicular(r_org.T @ t[0, 0])
        r0 = rmf.perpendicular_unit(r_org @ self.r0_local, t[:, 0])
        r = rmf.propagate(x, t, r0)
        self.rend_local = rest_world[self.insertion_bone, :3, :3].T @ r[0, -1]
        # rest arc length along the dense samples, as a fraction
        seg = np.linalg.norm(np.diff(x[0], axis=0), axis=1)
        self.arc = np.concatenate([[0.0], np.cumsum(seg)]) / max(seg.sum(), 1e-300)
        return rest_p, x, t, r

    def _stage_rest_control_points(self, rest_p, x, t, r):
        """Sections (outline x strength, own twist) placed in the rest frame: world control
        points (8N, 3) and the curve parameter of each."""
        spec = self.spec
        outlines = []
        for s in spec.sections:
            if s.outline is not None:
                o = np.array(s.outline, dtype=np.float64)
            else:
                a, b = s.radii if s.radii is not None else (0.08 * self.l0, 0.06 * self.l0)
                o = ellipse_outline(a, b, s.angle)
            outlines.append(o)
        outlines = np.array(outlines) * math.sqrt(spec.strength)  # (N, 8, 2): strength scales area
        sec_t = np.array([s.t for s in spec.sections])
        cp_t = np.repeat(sec_t, OCT)
        c_rest, tt, rr, ss = self._frames_at(rest_p, x, t, r, cp_t, self._sample_index(cp_t))
        tw = self._rest_twist(cp_t)
        ov, ow = outlines[..., 0].ravel(), outlines[..., 1].ravel()
        cw, sw = np.cos(tw), np.sin(tw)
        v_rot, w_rot = ov * cw - ow * sw, ov * sw + ow * cw
        p_rest = c_rest[0] + v_rot[:, None] * rr[0] + w_rot[:, None] * ss[0]  # (8N, 3)
        return p_rest, cp_t

    def _rest_twist(self, cp_t: np.ndarray) -> np.ndarray:
        """The muscle's own twist (radians) at axis parameters cp_t (the rest shape's)."""
        return math.radians(self.spec.twist) * np.interp(cp_t, self.ts, self.arc)

    def rest_frames(self, rest_world: np.ndarray, cp_t: np.ndarray):
        """The rest axis' frame at parameters cp_t (Q,), as sections are placed in it: axis
        points, R and S axes (Q, 3) each, and the muscle's own twist there (Q,) (``axdf pack``
        refits the sections in these frames)."""
        rest_p = self._axis_points(rest_world[None], self.rest_q)
        x, t = self._samples(rest_p, "Bs", "dBs")
        r0 = rmf.perpendicular_unit(rest_world[self.origin_bone, :3, :3] @ self.r0_local, t[:, 0])
        c, _, rr, ss = self._frames_at(rest_p, x, t, rmf.propagate(x, t, r0), cp_t, self._sample_index(cp_t))
        return c[0], rr[0], ss[0], self._rest_twist(cp_t)

    def _stage_binding(self, rest_p, x, t, r, p_rest, cp_t) -> None:
        """Bind every control point once: closest rest-axis parameter t and offset (u, v, w)
        in the frame there; the bases at those t and the rest arc fraction of each."""
        # on its section's own part of the axis (module doc): a closest point farther along the
        # rest axis from the section's t than the point is from the section's centre lies on
        # another part of it, and the point is bound at its section's t
        closest = self._closest_t(rest_p[0], p_rest, cp_t)
        along = np.abs(np.interp(closest, self.ts, self.arc) - np.interp(cp_t, self.ts, self.arc)) * self.l0
        offset = np.linalg.norm(p_rest - bspline.basis_matrix(self.knots, 2, cp_t) @ rest_p[0], axis=1)
        self.bind_t = np.where(along > offset, cp_t, closest)
        self.bind_j = self._sample_index(self.bind_t)
        cb, tb, rb, sb = self._frames_at(rest_p, x, t, r, self.bind_t, self.bind_j)
        off = p_rest - cb[0]
        self.uvw = np.stack([np.einsum("nc,nc->n", off, tb[0]), np.einsum("nc,nc->n", off, rb[0]),
                             np.einsum("nc,nc->n", off, sb[0])], axis=1)  # (8N, 3)
        self.Bb = bspline.basis_matrix(self.knots, 2, self.bind_t)
        self.dBb = bspline.basis_matrix(self.knots, 2, self.bind_t, 1)
        self.sparse.update({k: kernels.sparse_rows(getattr(self, k)) for k in ("Bb", "dBb")})
        self.lam = np.interp(self.bind_t, self.ts, self.arc)  # rest arc fraction of each bound point

    def _stage_belly_weights(self) -> None:
        """Belly weight beta (1 in the belly, 0 in the tendons) and tension bump per bound point."""
        a0, a1 = self.spec.tendons
        belly_len = max(1.0 - a0 - a1, 1e-9)
        xb = (self.lam - a0) / belly_len
        self.beta = ((xb >= 0.0) & (xb <= 1.0)).astype(np.float64)
        self.bump = np.where(self.beta > 0, np.sin(np.pi * np.clip(xb, 0.0, 1.0)) ** 2, 0.0)

    def _stage_surface_basis(self) -> None:
        """Surface basis: along (clamped, rational with per-row weights) x around (closed),
        as sparse rows for the compiled stage; the mesh's faces."""
        spec = self.spec
        along, around = spec.resolution
        m = len(spec.sections) + 2
        w = np.ones(m)
        if spec.weights is not None:
            w[1:-1] = spec.weights
        bu = bspline.basis_matrix(bspline.clamped_knots(m, 2), 2, np.linspace(0.0, 1.0, along))
        self.Bu = bspline.rational(bu, w)  # (U, m)
        self.Bv = bspline.periodic_quadratic_basis(OCT, np.arange(around) / around)  # (A, 8)
        self.U, self.A = along, around
        self.u_idx, self.u_w = kernels.sparse_rows(self.Bu)  # 3 non-zeros per row each way
        self.v_idx, self.v_w = kernels.sparse_rows(self.Bv)
        self.faces = grid_faces(along, around)
        self.n_vertices = 2 + (along - 2) * around

    # -- pieces ---------------------------------------------------------------------------
    def axis_points(self, world: np.ndarray, coords: np.ndarray | None = None) -> tuple[np.ndarray, list]:
        """Step 1a of the deformation: the axis control points in world space, world (F, B, 4, 4)
        (and coordinates (F, C) for paths that need them) → ((F, n, 3), warnings [(frame
        index, message)]: frames where a path could not wrap over a surface)."""
        if self.path is not None:
            p, inside = self.path.control_points(world, coords)
            warnings = []
            for i in np.nonzero(inside)[0]:
                w = self.spec.path.wraps[int(inside[i]) - 1]
                warnings.append((int(i), f"path cannot wrap over {w.name!r}: an end point lies inside it; "
                                         "kept the straight segment"))
            return p, warnings
        m = world[:, self.bones]  # (F, n, 4, 4)
        # P[f,i,c] = sum_k M[f,i,c,k] at[i,k] + M[f,i,c,3]
        return np.einsum("fick,ik->fic", m[..., :3, :3], self.at) + m[..., :3, 3], []

    def _axis_points(self, world: np.ndarray, coords: np.ndarray | None = None) -> np.ndarray:
        """:meth:`axis_points` without the warnings: (F, n, 3)."""
        return self.axis_points(world, coords)[0]

    def _apply(self, b: str, p: np.ndarray) -> np.ndarray:
        """X[f,s,c] = sum_i B[s,i] P[f,i,c] for the basis matrix named ``b`` (its sparse rows)."""
        idx, w = self.sparse[b]
        return np.einsum("sk,fskc->fsc", w, p[:, idx])

    def _samples(self, p: np.ndarray, b: str, db: str):
        # X[f,s,c] = sum_i B[s,i] P[f,i,c]; likewise the derivative
        return self._apply(b, p), _unit(self._apply(db, p))

    def axis_length(self, world: np.ndarray, coords: np.ndarray | None = None) -> np.ndarray:
        """The axis arc length (F,) for frames world (F, B, 4, 4) (and coordinates (F, C))."""
        return self._length(self._axis_points(world, coords))

    def line_length(self, world: np.ndarray, coords: np.ndarray | None = None) -> np.ndarray | None:
        """The length (F,) of the muscle's line of action, where it has one besides its axis (a
        ``path:`` with an ``axis:``): the arc length of the quadratic B-spline through the
        path's control points, as a path muscle's axis length is. None without one."""
        if self.line is None:
            return None
        path, dbg, gw = self.line
        p, _ = path.control_points(world, coords)
        return np.linalg.norm(np.einsum("gi,fic->fgc", dbg, p), axis=-1) @ gw

    def _length(self, p: np.ndarray) -> np.ndarray:
        d = self._apply("dBg", p)
        return np.linalg.norm(d, axis=-1) @ self.gw

    def _sample_index(self, t: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.ts, t, side="right") - 1, 0, len(self.ts) - 1)

    def _frames_at(self, p, x, t, r, tq, jq):
        """Untwisted frames at parameters tq (Q,) from the sampled RMF: one double-reflection
        step from sample jq. Returns C (F, Q, 3), T, R, S."""
        b = bspline.basis_matrix(self.knots, 2, tq)
        db = bspline.basis_matrix(self.knots, 2, tq, 1)
        c = np.einsum("qi,fic->fqc", b, p)
        tt = _unit(np.einsum("qi,fic->fqc", db, p))
        rr = rmf.reflect_step(x[:, jq], t[:, jq], r[:, jq], c, tt)
        ss = np.cross(tt, rr)
        return c, tt, rr, ss

    def _closest_t(self, p_axis: np.ndarray, pts: np.ndarray, t_guess: np.ndarray) -> np.ndarray:
        """True closest-point parameters on the rest axis for points (Q, 3): dense search, then
        Newton on g(t) = (P - C(t)) . C'(t) = 0."""
        n = self.n_axis
        td = np.linspace(0.0, 1.0, tol.BIND_DENSE_SAMPLES_PER_SPAN * (n - 2) + 1)
        cd = bspline.basis_matrix(self.knots, 2, td) @ p_axis
        dist = np.linalg.norm(pts[:, None, :] - cd[None], axis=-1)  # (Q, D)
        t = td[np.argmin(dist, axis=1)]
        for _ in range(tol.BIND_NEWTON_ITERS):
            c = bspline.basis_matrix(self.knots, 2, t) @ p_axis
            d1 = bspline.basis_matrix(self.knots, 2, t, 1) @ p_axis
            d2 = bspline.basis_matrix(self.knots, 2, t, 2) @ p_axis
            diff = pts - c
            g = np.einsum("qc,qc->q", diff, d1)
            dg = np.einsum("qc,qc->q", diff, d2) - np.einsum("qc,qc->q", d1, d1)
            step = np.where(dg < 0, -g / np.where(dg < 0, dg, -1.0), 0.0)
            t = np.clip(t + step, 0.0, 1.0)
        return t

    # -- evaluation -----------------------------------------------------------------------
    def evaluate(self, world: np.ndarray, tension: np.ndarray, twist_reference: np.ndarray | None = None,
                 rest_volume: float | None | str = "model", coords: np.ndarray | None = None,
                 control_points: np.ndarray | None = None) -> FrameResult:
        """Deform for a block of frames: :meth:`axis_points` (step 1a), then :meth:`surface`
        (step 1b) from those points. The run (:mod:`axdf_cli.pipeline.evaluate`) calls the
        two steps itself, so that stages may change the axis between them; see :meth:`surface`
        for the arguments, and ``coords`` (F, C) skeleton coordinates for paths with moving
        or conditional points."""
        p, warnings = self.axis_points(world, coords)
        res = self.surface(world, p, tension, twist_reference, rest_volume, warnings=warnings,
                           control_points=control_points)
        line = self.line_length(world, coords)
        if line is not None:
            res.length = line
        return res

    def surface(self, world: np.ndarray, points: np.ndarray, tension: np.ndarray,
                twist_reference: np.ndarray | None = None, rest_volume: float | None | str = "model",
                warnings=(), control_points: np.ndarray | None = None) -> FrameResult:
        """Step 1b of the deformation: RMF, bound sections, twist, tension, volume, surface and
        normals, from the axis control points (compiled: :meth:`MuscleBatch.surfaces
        <axdf_cli.model.batch.MuscleBatch.surfaces>` of this muscle alone; a run makes every
        muscle of a chunk in one call).

        world : (F, n_bones, 4, 4) bone world transforms (the bones of the start vector and of
        the insertion roll); points : (F, n, 3) axis control points in the world (step 1a's,
        or as a stage left them); tension : (F,) effective tension 0..1; twist_reference :
        (F,) unwrapped coarse insertion roll (radians) choosing the branch of the exact roll,
        or None (roll unwrapped within the block); rest_volume : the volume V0 that ``exact``
        keeps ("model": the model's own rest volume; None: no target, the start scale as it
        is); warnings : [(frame index, message)] of step 1a, listed first in the result's;
        control_points : (F, 8N, 3) to receive the bound section control points as the surface
        is made from them (fixed + s scaled), or None.
        """
        p = np.ascontiguousarray(points, dtype=np.float64)
        nf = p.shape[0]
        tension = np.broadcast_to(np.asarray(tension, dtype=np.float64), (nf,))[:, None]
        ref = None if twist_reference is None else np.asarray(twist_reference, dtype=np.float64).reshape(nf, 1)
        return FrameResult(**self._batch().surfaces(world, p, tension, ref, [0], rest_volume, {0: list(warnings)},
                                                    control_points)[0])

    def _batch(self) -> MuscleBatch:
        """This muscle alone, packed for the compiled passes (made once, when first needed)."""
        if getattr(self, "_one", None) is None:
            self._one = MuscleBatch([self])
        return self._one

    def __getstate__(self):
        state = dict(self.__dict__)
        state["_one"] = None  # (made again where needed: pickles stay small)
        return state


def _check_axis_on_path(spec, bone_index: dict[str, int], skeleton) -> None:
    """A muscle with both ``axis:`` and ``path:``: every axis point must hang on a bone its path
    spans (the path's points' and wraps' bones and those between them on the skeleton's tree),
    so that the belly moves with its line of action (an axis on femur_l under a path on femur_r
    would not)."""
    from axdf_cli.model.skeleton import bones_between

    names = {p.bone for p in spec.path.points} | {w.bone for w in spec.path.wraps} | \
        {w.side[0] for w in spec.path.wraps if w.side is not None}
    span = bones_between(skeleton, {bone_of(bone_index, n, _spec_mark(spec)) for n in names})
    for p in spec.axis:
        if bone_of(bone_index, p.bone, p.mark) not in span:
            spans = ", ".join(skeleton.bones[b].name for b in sorted(span))
            raise InputError(p.mark or _spec_mark(spec), f"muscle {spec.name!r}: axis point on bone {p.bone!r}, which "
                             "its path does not span", f"an axis on the bones of its path: {spans}")


def _spec_mark(spec: MuscleSpec) -> Mark:
    return spec.axis[0].mark if spec.axis else spec.path.points[0].mark


def _unit(d: np.ndarray) -> np.ndarray:
    return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-300)
