"""Render a whole sequence to ``OUT/frames/<frame:04d>.png|.exr`` and ``OUT/camera.json``.

:func:`render_sequence` is what ``axdf run --render`` and ``axdf render`` call. It creates
the GL context itself (in the calling process; call it after any fork), renders the frames
it is given, writes each file atomically and returns the GL renderer/version and the sha256
of every written file for the run's manifest. :func:`check_render` is the check made before
anything is written: EGL works with these settings and the render targets fit the GL's size
limit (the supersampling is lowered when only it does not fit).
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Iterable

from axdf_cli import atomic
from axdf_cli.errors import InputError
from axdf_cli.render.camera import camera_json, panel_count, sequence_cameras
from axdf_cli.render.context import create_gl_context, gl_info
from axdf_cli.render.exr import exr_channels, write_exr
from axdf_cli.render.png import write_png
from axdf_cli.render.renderer import FrameImages, id_map, render_frames
from axdf_cli.render.settings import RenderSettings
from axdf_cli.runfolder import CAMERA, Root, frame_relpath
from axdf_cli.scene import FrameChunk, Scene


def _write_png(path: Path, img: FrameImages) -> str:
    return write_png(path, img.rgba)


def _write_exr(path: Path, img: FrameImages) -> str:
    return write_exr(path, exr_channels(img.rgba, img.depth, img.normals, img.ids))


# file extension -> writer(path, FrameImages) -> sha256; every frame gets one file of each
FRAME_WRITERS: dict[str, Callable[[Path, FrameImages], str]] = {"png": _write_png, "exr": _write_exr}


def render_sequence(scene: Scene, chunks: Iterable[FrameChunk], settings: RenderSettings,
                    out_dir: Path | Root, progress: Callable[[int], None] | None = None,
                    on_frame: Callable[[dict], None] | None = None) -> dict:
    """Render the frames of ``chunks`` (all of ``scene.frames`` or some of them: the cameras
    are those of the whole sequence); write ``frames/<frame:04d>.{png,exr}``, then
    ``camera.json`` (every frame's camera).

    ``progress`` is called with each finished frame number, ``on_frame`` with the files
    written so far. Returns ``{"gl_renderer": str, "gl_version": str, "files": {relative
    path: sha256}}``. Raises :class:`EnvironmentProblem` (exit 3) when no EGL context can be made.
    """
    root = out_dir if isinstance(out_dir, Root) else Root(Path(out_dir))
    cameras = sequence_cameras(scene, settings)
    ctx = create_gl_context(device=settings.device, libegl=settings.egl_library)
    try:
        info = gl_info(ctx)
        files: dict[str, str] = {}
        for img in render_frames(ctx, scene, chunks, settings, cameras):
            for ext, writer in FRAME_WRITERS.items():
                rel = frame_relpath(img.frame, ext)
                files[rel] = writer(root.path(rel), img)
            if progress is not None:
                progress(img.frame)
            if on_frame is not None:
                on_frame(files)
        cam = camera_json(cameras, scene.frames, settings, id_map(scene, settings.bones))
        files[CAMERA] = atomic.write_text(root.path(CAMERA), json.dumps(cam, indent=1, sort_keys=True) + "\n")
    finally:
        ctx.release()
    return {"gl_renderer": info.renderer, "gl_version": info.version, "files": files}


def fit_size(settings: RenderSettings, limit: int, renderer: str, on_note=None) -> RenderSettings:
    """``settings`` whose render targets (output size x panels x supersample) fit ``limit``
    pixels a side: the supersampling lowered (said through ``on_note``) when needed; a size
    that does not fit even without supersampling is refused (exit 2)."""
    from dataclasses import replace

    w, h = settings.size
    panels = panel_count(settings)
    side = max(w * panels, h)
    what = f"render size {w}x{h}" + (f" x {panels} panels" if panels > 1 else "")
    if side > limit:
        raise InputError(None, f"{what} needs {side} pixels a side, more than this GL's limit {limit} ({renderer})",
                         f"a --size of at most {limit // panels}x{limit}")
    s = min(settings.supersample, limit // side)
    if s < settings.supersample:
        if on_note:
            on_note(f"{what} with supersample {settings.supersample} needs {side * settings.supersample} pixels a "
                    f"side, more than this GL's limit {limit} ({renderer}); supersample lowered to {s}")
        return replace(settings, supersample=s)
    return settings


def check_render(settings: RenderSettings, on_note=None) -> RenderSettings:
    """Before anything is written: make a GL context with ``settings`` (in a forked child, so
    that no GL state exists in this process when the mesh pass forks its workers) and fit the
    render size to its limit (:func:`fit_size`). No EGL: EnvironmentProblem (exit 3)."""
    from axdf_cli.render.context import probe
    from axdf_cli.run.pool import in_child

    info, limit = in_child(probe, settings)
    return fit_size(settings, limit, info.renderer, on_note)


RENDER_CHUNK = 16  # frames per block handed to the renderer by render_plan (all muscles of a frame at once)


def render_plan(plan, out_dir: Path, bounds, twist_ref, progress: Callable[[int], None] | None = None,
                framing_points=None) -> dict:
    """Render a run plan's frames into ``out_dir`` (``axdf run --render``): the muscles are
    evaluated again, block by block (evaluation is cheap next to rendering and this keeps
    memory bounded), exactly as the mesh pass wrote them. ``framing_points``: what the
    automatic camera frames (default :func:`axdf_cli.run.plan.framing`)."""
    import numpy as np

    from axdf_cli.render.renderer import bone_layout
    from axdf_cli.run.evaluate import evaluate_chunks, finite_or_rest
    from axdf_cli.run.plan import framing
    from axdf_cli.scene import SceneMuscle

    skel = plan.pose.skeleton
    framing_points = framing(plan) if framing_points is None else framing_points
    shown = skel.bones if plan.render.bones else ()
    layout = bone_layout([b.name for b in shown], skel.stick_parents() if shown else [],
                         {i: (v, f) for i, (v, f, _) in plan.bone_meshes.items() if shown},
                         float(np.ptp(framing_points, axis=0).max()))
    scene = Scene(
        muscles=tuple(SceneMuscle(s.name, s.color, m.faces) for s, m in zip(plan.muscles, plan.models)),
        bones=layout.bones, bounds=bounds, frames=tuple(int(f) for f in plan.frames),
        framing=framing_points, first_frame=int(plan.pose.first))

    def chunks():
        for sl, world, results in evaluate_chunks(plan, RENDER_CHUNK, twist_ref):
            done = [finite_or_rest(r, plan.models[j]) for j, r in results]
            yield FrameChunk(frames=plan.frames[sl], positions=tuple(d[0] for d in done),
                             normals=tuple(d[1] for d in done), bone_world=layout.transforms(world))

    return render_sequence(scene, chunks(), plan.render, out_dir, progress=progress)


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
