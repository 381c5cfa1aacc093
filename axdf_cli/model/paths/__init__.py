"""Muscle paths: points (fixed, moving, conditional) and wrap surfaces (cylinder, sphere,
ellipsoid, torus), evaluated per frame into axis control points (see :mod:`.path`)."""
from axdf_cli.model.paths.points import Moving, PathPoint, PathSpec, WrapSurface, default_control_points

__all__ = ["Moving", "PathPoint", "PathSpec", "WrapSurface", "default_control_points"]
