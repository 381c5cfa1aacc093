"""Muscle path points and wrap surfaces: the specs (what the YAML says) and their per-frame
evaluation, batched over frames.

- A fixed point sits at ``at`` in its bone.
- A moving point (OpenSim's MovingPathPoint) has, per axis, ``{coord, function}``: the
  location along that axis of the bone is the function of the coordinate (axdf units:
  degrees for rotational coordinates, metres out); an axis without one keeps ``at``.
- A conditional point (OpenSim's ConditionalPathPoint) is part of the path only while
  its coordinate lies within ``range`` (inclusive).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.model.skeleton import bone_of


@dataclass(frozen=True)
class Moving:
    """One axis of a moving point: the coordinate and the function giving the location."""

    coord: str
    function: object  # an axdf_cli.model.skeleton function (axdf units)


@dataclass(frozen=True)
class PathPoint:
    bone: str
    at: tuple[float, float, float]
    moving: tuple[Moving | None, Moving | None, Moving | None] | None = None
    active: tuple[str, float, float] | None = None  # (coordinate, lo, hi): conditional point
    mark: Mark = field(default=Mark(""), compare=False)


@dataclass(frozen=True)
class WrapSurface:
    name: str
    bone: str
    shape: str  # cylinder | sphere | ellipsoid | torus | mujoco_sphere | mujoco_cylinder
    size: tuple[float, float, float]  # cylinder (radius, length, 0); sphere (radius, 0, 0);
    #                                   ellipsoid semi-axes; torus (inner, outer, 0);
    #                                   mujoco_sphere, mujoco_cylinder (radius, 0, 0)
    at: tuple[float, float, float] = (0.0, 0.0, 0.0)
    orient: tuple[float, float, float] = (0.0, 0.0, 0.0)  # degrees, body-fixed X-Y-Z
    quadrant: str = "all"
    method: str = "hybrid"  # ellipsoid: hybrid | midpoint | axial
    range: tuple[int, int] = (-1, -1)  # 1-based path point indices; -1: the path's ends
    active: bool = True
    mark: Mark = field(default=Mark(""), compare=False)
    side: tuple[str, tuple[float, float, float]] | None = None  # MuJoCo shapes: (bone, at) of the side point


@dataclass(frozen=True)
class PathSpec:
    points: tuple[PathPoint, ...]
    wraps: tuple[WrapSurface, ...] = ()
    control_points: int = 0  # axis control points; 0: the default for the path (DEFAULT_CONTROL_POINTS)

    @property
    def coordinates(self) -> set[str]:
        out = set()
        for p in self.points:
            if p.active is not None:
                out.add(p.active[0])
            for mv in p.moving or ():
                if mv is not None:
                    out.add(mv.coord)
        return out


def default_control_points(spec: PathSpec) -> int:
    """Axis control points for a path: 8, plus 4 per interior path point and per wrap surface
    (sharp corners at via points need denser sampling for the axis length to stay close to the
    path's; importers add more where it falls short by over ``tolerances.AXIS_SHORTFALL_MAX``),
    at most 48."""
    return int(np.clip(8 + 4 * (len(spec.points) - 2) + 4 * len(spec.wraps), 8, 48))


class PointsModel:
    """Vectorized evaluation of a path's points: positions (F, P, 3) and active flags (F, P)."""

    def __init__(self, spec: PathSpec, bone_index: dict[str, int], coord_index: dict[str, int] | None):

        self.spec = spec
        self.bones = np.array([bone_of(bone_index, p.bone, p.mark) for p in spec.points])
        self.at = np.array([p.at for p in spec.points], dtype=np.float64)
        need = spec.coordinates
        if need and coord_index is None:
            raise InputError(spec.points[0].mark, "moving or conditional path points need the skeleton's coordinates",
                             "evaluate the muscle with its skeleton")
        ci = coord_index or {}

        def coord(name, mark):
            if name not in ci:
                raise InputError(mark, f"unknown coordinate {name!r}", "coordinates of the skeleton: " + ", ".join(sorted(ci)))
            return ci[name]

        self.moving = [(k, a, coord(mv.coord, p.mark), mv.function) for k, p in enumerate(spec.points)
                       for a, mv in enumerate(p.moving or ()) if mv is not None]
        self.conditional = [(k, coord(p.active[0], p.mark), p.active[1], p.active[2])
                            for k, p in enumerate(spec.points) if p.active is not None]
        self.uses_coordinates = bool(need)

    def local(self, coords: np.ndarray | None, nf: int) -> np.ndarray:
        """Point locations in their bones (F, P, 3)."""
        loc = np.broadcast_to(self.at, (nf,) + self.at.shape).copy()
        for k, a, c, fn in self.moving:
            loc[:, k, a] = fn(coords[:, c])
        return loc

    def evaluate(self, world: np.ndarray, coords: np.ndarray | None):
        nf = world.shape[0]
        if self.uses_coordinates and coords is None:
            raise ValueError("this path needs coordinates per frame")
        loc = self.local(coords, nf)
        m = world[:, self.bones]  # (F, P, 4, 4)
        pts = np.einsum("fpck,fpk->fpc", m[..., :3, :3], loc) + m[..., :3, 3]
        active = np.ones((nf, len(self.bones)), dtype=np.bool_)
        for k, c, lo, hi in self.conditional:
            q = coords[:, c]
            active[:, k] = (q >= lo) & (q <= hi)
        return pts, active
