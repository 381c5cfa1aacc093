"""What the renderer consumes: pure arrays, produced by ``axdf run`` or read back from a run.

A :class:`Scene` fixes everything that does not change over time (topology, colours, bone
geometry, the sequence's bounds); :class:`FrameChunk` carries a block of consecutive
output frames (batch dimension first).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SceneMuscle:
    name: str
    color: tuple[float, float, float]  # linear RGB in [0, 1]
    faces: np.ndarray  # (T, 3) int32, counter-clockwise seen from outside


@dataclass(frozen=True)
class SceneBone:
    name: str
    vertices: np.ndarray  # (V, 3) float32 in the bone's local frame (metres)
    faces: np.ndarray  # (T, 3) int32


#: The skin's colour: linear RGB of sRGB #e0ac96, a light skin tone.
SKIN_COLOR = (0.745, 0.413, 0.305)


@dataclass(frozen=True)
class SceneSkin:
    """The body's skin over the muscles (``axdf run --skin``): one closed triangle mesh."""

    faces: np.ndarray  # (T, 3) int32, counter-clockwise seen from outside
    color: tuple[float, float, float]  # linear RGB in [0, 1]


@dataclass(frozen=True)
class Scene:
    muscles: tuple[SceneMuscle, ...]
    bones: tuple[SceneBone, ...]  # bones drawn: their meshes, or sticks (render.renderer.BoneLayout)
    bounds: np.ndarray  # (2, 3) float64 world AABB of every muscle over the written frames
    frames: tuple[int, ...]  # every output frame number, in order
    framing: np.ndarray | None = None  # (N, 3) points the automatic camera frames (render/framing.py)
    first_frame: int | None = None  # the pose's first frame: where an orbit's angle is 0
    targets: np.ndarray | None = None  # (F, 3) the camera's target bone's origin at each of `frames`
    follow: np.ndarray | None = None  # (F, 3) a following camera's offset at each of `frames`; `framing` is relative to it
    ground: tuple[str, ...] = ()  # names of `bones` drawn as a ground plate under the subject (render/framing.py)
    footprint: np.ndarray | None = None  # (2, 2) the subject's horizontal box [lo, hi] a ground plate covers
    skin: SceneSkin | None = None  # drawn as RenderSettings.skin says


@dataclass(frozen=True)
class FrameChunk:
    frames: np.ndarray  # (C,) int frame numbers
    positions: tuple[np.ndarray, ...]  # per muscle: (C, V_m, 3) float32 world positions
    normals: tuple[np.ndarray, ...]  # per muscle: (C, V_m, 3) float32 unit outward normals
    bone_world: np.ndarray  # (C, n_scene_bones, 4, 4) float64 world transform of each Scene bone
    skin: tuple[np.ndarray, np.ndarray] | None = None  # (C, V, 3) float32 positions and normals of Scene.skin
