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
from axdf_cli.render.png import DEPTH_PNG_PER_METRE, encode_depth_png, encode_label_png, label_png_bits
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
        self.labels = scene_labels(scene)

    def render(self, frame: int, positions, normals, bone_world: np.ndarray | None,
               cameras: list[Camera], layers=()) -> list[FrameImages]:
        """``positions`` / ``normals``: per muscle (V_m, 3) float32 world arrays;
        ``bone_world`` (n_scene_bones, 4, 4); ``layers``: per scene layer its (V, 3) positions
        and normals; one :class:`FrameImages` per camera."""
        return [self.renderer.render(frame, positions, normals, bone_world, [cam], layers) for cam in cameras]

    def release(self) -> None:
        if os.getpid() == self.pid:
            self.renderer.release()
            self.ctx.release()


def scene_labels(scene: Scene) -> int:
    """How many ids a scene's id pass holds: 0 (background), 1..M muscles, M+1.. bones, then
    the scene's layers (the skin among them)."""
    return 1 + len(scene.muscles) + len(scene.bones) + len(scene.layers)


#: Image passes of a data set's views beyond the frame files (png, exr): pass -> the file's
#: ending after ``<frame:04d>``. ``mask``: the EXR's ``id`` channel as a greyscale PNG (8-bit
#: up to 256 ids, else 16-bit: :func:`~axdf_cli.render.png.label_png_bits` of the scene's id
#: count, the same for every image of a data set); ``depth``: the EXR's ``Z`` as a 16-bit
#: greyscale PNG in millimetres, 0 = background (:data:`~axdf_cli.render.png.DEPTH_PNG_PER_METRE`).
VIEW_PNG_PASSES = {"mask": ".mask.png", "depth": ".depth.png"}
VIEW_PNG_NOTES = {
    "mask": "views/<view>/<frame>.mask.png: the id pass (0 background, 1..M muscles, M+1.. bones: ids) as a "
            "greyscale PNG, 8-bit up to 256 ids, else 16-bit",
    "depth": f"views/<view>/<frame>.depth.png: camera z as a 16-bit greyscale PNG, value = round(z * "
             f"{DEPTH_PNG_PER_METRE:g}) (millimetres, within 0.5 mm), 0 = background, at most 65535 (65.535 m)",
}


def view_png(pass_name: str, img: FrameImages, labels: int | None) -> bytes:
    """A :data:`VIEW_PNG_PASSES` image's bytes (``labels``: the scene's id count; None: 16-bit)."""
    if pass_name == "mask":
        return encode_label_png(img.ids, 16 if labels is None else label_png_bits(labels))
    return encode_depth_png(img.depth)


def write_view_images(folder: Path, rel_folder: str, img: FrameImages, passes, labels: int | None = None) -> dict:
    """Write ``<folder>/<frame:04d>.<pass>`` for each image pass (png, exr) and
    ``<frame:04d>.mask.png``, ``.depth.png`` for the :data:`VIEW_PNG_PASSES` (others are not
    files of a view); return {relative path: sha256}. ``labels``: the scene's id count
    (:func:`scene_labels`), which sets the mask's bit depth."""
    from axdf_cli.fileio import atomic

    out = {}
    for ext in (p for p in passes if p in FRAME_WRITERS):
        name = f"{img.frame:04d}.{ext}"
        out[f"{rel_folder}/{name}"] = FRAME_WRITERS[ext](Path(folder) / name, img)
    for p in (p for p in passes if p in VIEW_PNG_PASSES):
        name = f"{img.frame:04d}{VIEW_PNG_PASSES[p]}"
        out[f"{rel_folder}/{name}"] = atomic.write_bytes(Path(folder) / name, view_png(p, img, labels))
    return out
