"""Several explicit cameras per frame, each its own image (data sets: ``axdf dataset``).

:class:`ViewRenderer` keeps one GL context and one :class:`~axdf_cli.render.renderer.Renderer`
for a scene topology (muscles' faces, bone meshes) and renders any number of frames and
cameras with it, so a worker process that makes many sequences of the same muscles (or a
render worker of ``--jobs``, many blocks of frames) uploads the topology once. The context
is created in the process that renders (after any fork).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from axdf_cli.render.camera import Camera
from axdf_cli.render.context import create_gl_context, gl_info
from axdf_cli.render.renderer import FrameImages, Renderer
from axdf_cli.render.passes import FRAME_WRITERS
from axdf_cli.specs.render import RenderSettings
from axdf_cli.render.scene import Scene


def view_camera(name: str, K: np.ndarray, world_to_camera: np.ndarray, near: float, far: float,
                size: tuple[int, int]) -> Camera:
    """A whole-image camera from intrinsics ``K`` (3, 3) and ``world_to_camera`` (4, 4)."""
    W, H = size
    return Camera(name, np.asarray(K, float), np.asarray(world_to_camera, float), (0, 0, W, H),
                  float(near), float(far))


class ViewRenderer:
    """One GL context and renderer for a fixed scene topology; :meth:`render` draws one
    image per camera (``panels`` 1), ``renderer.frames`` whole frames of ``panels`` panels
    side by side (a sequence's render worker). Use from the process that created it only."""

    def __init__(self, scene: Scene, settings: RenderSettings, panels: int = 1):
        self.pid = os.getpid()
        self.settings = settings
        self.ctx = create_gl_context(device=settings.device, libegl=settings.egl_library)
        self.info = gl_info(self.ctx)
        self.renderer = Renderer(self.ctx, scene, settings, panels)

    def render(self, frame: int, positions, normals, bone_world: np.ndarray | None,
               cameras: list[Camera]) -> list[FrameImages]:
        """``positions`` / ``normals``: per muscle (V_m, 3) float32 world arrays;
        ``bone_world`` (n_scene_bones, 4, 4); one :class:`FrameImages` per camera."""
        return [self.renderer.render(frame, positions, normals, bone_world, [cam]) for cam in cameras]

    def release(self) -> None:
        if os.getpid() == self.pid:
            self.renderer.release()
            self.ctx.release()


def write_view_images(folder: Path, rel_folder: str, img: FrameImages, passes) -> dict:
    """Write ``<folder>/<frame:04d>.<pass>`` for each image pass (png, exr; others are not
    files of a view); return {relative path: sha256}."""
    out = {}
    for ext in (p for p in passes if p in FRAME_WRITERS):
        name = f"{img.frame:04d}.{ext}"
        out[f"{rel_folder}/{name}"] = FRAME_WRITERS[ext](Path(folder) / name, img)
    return out
