"""The OpenSim model as :mod:`axdf_cli.importers.osim` reads it: small frozen dataclasses in
OpenSim's units and frames (radians, metres, Y-up ground), and its functions as axdf's own
function objects (:mod:`axdf_cli.model.skeleton`) in OpenSim units.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from axdf_cli.errors import Mark
from axdf_cli.model.skeleton import Constant, Linear, Multiplier, Polynomial, Spline, euler_xyz


# ----------------------------------------------------------------------------- functions


# The reader builds axdf's own function objects (axdf_cli.model.skeleton), in OpenSim units;
# osim_import.convert_function turns them into axdf units.
FConst, FLinear, FPoly, FMult = Constant, Linear, Polynomial, Multiplier


def FSpline(x, y, kind: str) -> Spline:
    return Spline(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64), kind)


FUNCTION_TAGS = ("Constant", "LinearFunction", "PolynomialFunction", "SimmSpline", "NaturalCubicSpline",
                 "MultiplierFunction")

# ----------------------------------------------------------------------------- model


@dataclass(frozen=True)
class MeshRef:
    file: str
    scale: tuple[float, float, float]
    mark: Mark


@dataclass(frozen=True)
class Body:
    name: str
    mass_center: tuple[float, float, float]
    meshes: tuple[MeshRef, ...]
    mark: Mark


@dataclass(frozen=True)
class Coordinate:
    name: str
    type: str  # 'rotation' | 'translation'
    default: float  # OpenSim units (rad | m)
    range: tuple[float, float] | None
    locked: bool
    joint: str
    mark: Mark
    #: OpenSim's motion type: 'rotational' | 'translational' | 'coupled' (see :func:`motion_type`)
    motion: str = "rotational"
    #: the dependent coordinate of a CoordinateCouplerConstraint: the coordinate it follows ...
    follows: str | None = None
    #: ... and its value as a function of that one (OpenSim units, the scale factor included)
    function: object | None = None
    #: ... and the constraint's name
    coupler: str | None = None


@dataclass(frozen=True)
class Axis:
    """One transform axis: ``type`` rotation|translation, unit-free axis, function of ``coord``."""

    type: str
    axis: tuple[float, float, float]
    coord: str | None
    function: object  # F* dataclass, OpenSim units


@dataclass(frozen=True)
class Offset:
    """A frame fixed in ``body``: ``translation`` (m) and body-fixed XYZ ``orientation`` (rad)."""

    body: str
    translation: tuple[float, float, float]
    orientation: tuple[float, float, float]

    @property
    def is_identity(self) -> bool:
        return not any(self.translation) and not any(self.orientation)

    def matrix(self) -> np.ndarray:
        m = np.eye(4)
        m[:3, :3] = euler_xyz(np.degrees(self.orientation))
        m[:3, 3] = self.translation
        return m


@dataclass(frozen=True)
class Joint:
    name: str
    type: str
    parent: Offset
    child: Offset
    axes: tuple[Axis, ...]  # in axdf's order: translations first, then rotations
    mark: Mark


@dataclass(frozen=True)
class PathPoint:
    name: str
    body: str
    location: tuple[float, float, float]  # at the rest pose (moving points evaluated there)
    kind: str  # 'fixed' | 'conditional' | 'moving'
    active_at_rest: bool = True
    condition: tuple[str, float, float] | None = None  # (coordinate, lo, hi) for conditional
    mark: Mark | None = None
    #: moving points: per axis (coordinate, function of it in OpenSim units) or None (fixed)
    moving: tuple | None = None
    #: the offset frame between the point's frame and its body (None: the body itself)
    frame: "Offset | None" = None


@dataclass(frozen=True)
class WrapObject:
    """A wrap surface fixed in ``body``: OpenSim units (m, rad)."""

    name: str
    body: str
    shape: str  # cylinder | sphere | ellipsoid | torus
    size: tuple[float, float, float]
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float]  # body-fixed X-Y-Z (rad)
    quadrant: str
    active: bool
    mark: Mark


@dataclass(frozen=True)
class PathWrap:
    wrap: str  # WrapObject name
    method: str
    range: tuple[int, int]
    mark: Mark


@dataclass(frozen=True)
class Muscle:
    name: str
    type: str
    max_isometric_force: float
    optimal_fiber_length: float
    tendon_slack_length: float
    pennation_angle: float  # rad, at optimal fibre length
    points: tuple[PathPoint, ...]  # all points, in path order (inactive ones flagged)
    wraps: tuple[PathWrap, ...]
    mark: Mark


@dataclass
class Model:
    name: str
    source: str
    bodies: dict[str, Body]
    joints: list[Joint]  # ordered parents before children
    coordinates: dict[str, Coordinate]
    muscles: list[Muscle]
    credits: str = ""
    publications: str = ""
    ignored: list[dict] = field(default_factory=list)  # {kind, name, where, why}
    wrap_objects: dict[str, WrapObject] = field(default_factory=dict)
