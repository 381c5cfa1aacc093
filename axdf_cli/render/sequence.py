"""Render a whole sequence to ``OUT/frames/<frame:04d>.png|.exr`` and ``OUT/camera.json``.

:func:`render_sequence` is what ``axdf run --render`` and ``axdf render`` call. It creates
the GL context itself (in the calling process; call it after any fork), renders every
frame, writes each file atomically and returns the GL renderer/version and the sha256 of
every written file for the run's manifest.
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Iterable

from axdf_cli import atomic
from axdf_cli.render.camera import camera_json, sequence_cameras
from axdf_cli.render.context import create_gl_context, gl_info
from axdf_cli.render.exr import exr_channels, write_exr
from axdf_cli.render.png import write_png
from axdf_cli.render.renderer import FrameImages, id_map, render_frames
from axdf_cli.render.settings import RenderSettings
from axdf_cli.scene import FrameChunk, Scene


def _write_png(path: Path, img: FrameImages) -> str:
    return write_png(path, img.rgba)


def _write_exr(path: Path, img: FrameImages) -> str:
    return write_exr(path, exr_channels(img.rgba, img.depth, img.normals, img.ids))


# file extension -> writer(path, FrameImages) -> sha256; every frame gets one file of each
FRAME_WRITERS: dict[str, Callable[[Path, FrameImages], str]] = {"png": _write_png, "exr": _write_exr}


def render_sequence(scene: Scene, chunks: Iterable[FrameChunk], settings: RenderSettings,
                    out_dir: Path, progress: Callable[[int], None] | None = None) -> dict:
    """Render every frame; write ``frames/<frame:04d>.{png,exr}`` and ``camera.json``.

    ``progress`` is called with each finished frame number. Returns
    ``{"gl_renderer": str, "gl_version": str, "files": {relative path: sha256}}``.
    Raises :class:`EnvironmentProblem` (exit 3) when no EGL context can be made.
    """
    out_dir = Path(out_dir)
    cameras = sequence_cameras(scene, settings)
    ctx = create_gl_context(device=settings.device, libegl=settings.egl_library)
    try:
        info = gl_info(ctx)
        files: dict[str, str] = {}
        for img in render_frames(ctx, scene, chunks, settings, cameras):
            for ext, writer in FRAME_WRITERS.items():
                rel = f"frames/{img.frame:04d}.{ext}"
                files[rel] = writer(out_dir / rel, img)
            if progress is not None:
                progress(img.frame)
        cam = camera_json(cameras, scene.frames, settings, id_map(scene, settings.bones))
        files["camera.json"] = atomic.write_text(out_dir / "camera.json",
                                                 json.dumps(cam, indent=1, sort_keys=True) + "\n")
    finally:
        ctx.release()
    return {"gl_renderer": info.renderer, "gl_version": info.version, "files": files}


def benchmark_fps(size: tuple[int, int] = (512, 512), n_muscles: int = 10, verts: int = 2000,
                  frames: int = 24, settings: RenderSettings | None = None,
                  out_dir: Path | None = None) -> dict:
    """Frames per second of a synthetic scene (``n_muscles`` x ~``verts`` vertices + a bone).

    Measures rendering plus read-back and downsampling (``render_fps``); with ``out_dir``
    also PNG + EXR encoding and writing (``write_fps``). Context creation and the first
    (warm-up) frame are excluded.
    """
    from dataclasses import replace

    from axdf_cli.render.synthetic import synthetic_scene

    settings = replace(settings or RenderSettings(enabled=True), size=tuple(size))
    scene, chunks = synthetic_scene(n_muscles=n_muscles, verts=verts, n_frames=frames + 1)
    cameras = sequence_cameras(scene, settings)
    ctx = create_gl_context(device=settings.device, libegl=settings.egl_library)
    try:
        info = gl_info(ctx)
        it = render_frames(ctx, scene, chunks, settings, cameras)
        first = next(it)
        t0 = time.perf_counter()
        n = 0
        t_write = 0.0
        for img in it:
            n += 1
            if out_dir is not None:
                tw = time.perf_counter()
                for ext, writer in FRAME_WRITERS.items():
                    writer(Path(out_dir) / f"{img.frame:04d}.{ext}", img)
                t_write += time.perf_counter() - tw
        dt = time.perf_counter() - t0
        del first
    finally:
        ctx.release()
    out = {"gl_renderer": info.renderer, "gl_version": info.version, "size": list(size),
           "supersample": settings.supersample, "muscles": n_muscles,
           "vertices": sum(int(f.max()) + 1 for f in (m.faces for m in scene.muscles)),
           "frames": n, "render_fps": n / max(dt - t_write, 1e-9)}
    if out_dir is not None:
        out["write_fps"] = n / max(dt, 1e-9)
    return out
