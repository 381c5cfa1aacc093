"""What the renderer consumes: pure arrays, produced by ``axdf run`` or read back from a run.

A :class:`Scene` fixes everything that does not change over time (topology, colours, bone
geometry, the sequence's bounds); :class:`FrameChunk` carries a block of consecutive
output frames (batch dimension first).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli.parts import Kind, of_kind


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


@dataclass(frozen=True)
class SceneLayer:
    """A part a run's stages add (:class:`axdf_cli.parts.Part`): one closed triangle mesh,
    drawn by its kind (a skin as ``RenderSettings.skin`` says, any other opaque)."""

    name: str
    kind: Kind
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
    layers: tuple[SceneLayer, ...] = ()  # the parts the stages add, after the muscles and bones

    @property
    def skin(self) -> SceneLayer | None:
        """The scene's skin: its first layer of kind skin, or None."""
        return next(iter(of_kind(self.layers, Kind.SKIN)), None)

    @property
    def skin_index(self) -> int | None:
        """Where the skin is among ``layers`` (None: no skin)."""
        return next((k for k, p in enumerate(self.layers) if Kind(p.kind) is Kind.SKIN), None)


@dataclass(frozen=True)
class FrameChunk:
    frames: np.ndarray  # (C,) int frame numbers
    positions: tuple[np.ndarray, ...]  # per muscle: (C, V_m, 3) float32 world positions
    normals: tuple[np.ndarray, ...]  # per muscle: (C, V_m, 3) float32 unit outward normals
    bone_world: np.ndarray  # (C, n_scene_bones, 4, 4) float64 world transform of each Scene bone
    layers: tuple = ()  # per Scene layer: ((C, V, 3) float32 positions, normals)
