"""The frames of a sequence rendered into files: ``OUT/frames/<frame:04d>.png|.exr`` and
``OUT/camera.json``.

:func:`render_frames_of` is what ``axdf run --render`` (through :func:`render_plan`) and
``axdf render`` call: the frames of a :class:`FrameSource`, in this process
(:func:`render_sequence`, which creates the GL context itself: call it after any fork) or
split in blocks over ``--jobs`` render workers, each with its own GL context. Each file is
written atomically; the result is the GL renderer/version and the sha256 of every written
file for the run's manifest. :func:`check_render` is the check made before
anything is written: EGL works with these settings and the render targets fit the GL's size
limit (the supersampling is lowered when only it does not fit).
"""
from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Callable, Iterable, Iterator, Protocol

from axdf_cli.fileio import atomic
from axdf_cli.errors import InputError
from axdf_cli.render.camera import camera_json, panel_count, sequence_cameras
from axdf_cli.render.context import create_gl_context, gl_info
from axdf_cli.render.passes import FRAME_WRITERS
from axdf_cli.render.renderer import frame_cameras, id_map, render_frames
from axdf_cli.specs.render import RenderSettings
from axdf_cli.fileio.runfolder import CAMERA, Root, frame_relpath
from axdf_cli.render.scene import FrameChunk, Scene




def render_sequence(scene: Scene, chunks: Iterable[FrameChunk], settings: RenderSettings,
                    out_dir: Path | Root, progress: Callable[[int], None] | None = None,
                    on_frame: Callable[[dict], None] | None = None) -> dict:
    """Render the frames of ``chunks`` (all of ``scene.frames`` or some of them: the cameras
    are those of the whole sequence) in this process; write ``frames/<frame:04d>.{png,exr}``,
    then ``camera.json`` (every frame's camera).

    ``progress`` is called with each finished frame number, ``on_frame`` with the files
    written so far. Returns ``{"gl_renderer": str, "gl_version": str, "files": {relative
    path: sha256}}``. Raises :class:`EnvironmentProblem` (exit 3) when no EGL context can be made.
    """
    from axdf_cli.render.views import ViewRenderer

    root = out_dir if isinstance(out_dir, Root) else Root(Path(out_dir))
    cameras = sequence_cameras(scene, settings)
    vr = ViewRenderer(scene, settings, _panels(cameras))
    try:
        files = _write_frames(vr, chunks, frame_cameras(scene, cameras), root, progress, on_frame)
    finally:
        vr.release()
    files[CAMERA] = _write_camera(root, scene, settings, cameras)
    return {"gl_renderer": vr.info.renderer, "gl_version": vr.info.version, "files": files}


def _panels(cameras) -> int:
    return len(cameras[0]) if cameras else 1


def _write_frames(vr, chunks, cameras: dict, root: Root, progress=None, on_frame=None) -> dict:
    """Render ``chunks`` with the :class:`~axdf_cli.render.views.ViewRenderer` ``vr`` and
    write every frame's files; return {relative path: sha256}."""
    files: dict[str, str] = {}
    for img in vr.renderer.frames(chunks, cameras):
        for ext, writer in FRAME_WRITERS.items():
            rel = frame_relpath(img.frame, ext)
            files[rel] = writer(root.path(rel), img)
        if progress is not None:
            progress(img.frame)
        if on_frame is not None:
            on_frame(files)
    return files


def _write_camera(root: Root, scene: Scene, settings: RenderSettings, cameras) -> str:
    cam = camera_json(cameras, scene.frames, settings, id_map(scene, settings.bones, settings.skin))
    return atomic.write_text(root.path(CAMERA), json.dumps(cam, indent=1, sort_keys=True) + "\n")


class FrameSource(Protocol):
    """Where a render worker gets its frames: :meth:`chunks` yields the :class:`FrameChunk`
    blocks of the given frame numbers (in order). Pickled once per worker process."""

    def chunks(self, frames: list[int]) -> Iterator[FrameChunk]: ...

    #: modules a render worker imports before its first block (optional): what ``chunks`` needs
    preload: tuple[str, ...]


RENDER_CHUNK = 16  # frames per block handed to the renderer (all muscles of a frame at once)


def frame_blocks(frames: list[int], jobs: int) -> list[list[int]]:
    """``frames`` cut into consecutive blocks of at most RENDER_CHUNK, small enough that
    every one of ``jobs`` workers gets one: the tasks the workers take in turn."""
    size = max(1, min(RENDER_CHUNK, -(-len(frames) // max(jobs, 1))))
    return [list(frames[k:k + size]) for k in range(0, len(frames), size)]


def render_frames_of(scene: Scene, source: FrameSource, frames: list[int], settings: RenderSettings,
                     out_dir: Path | Root, jobs: int = 1, progress: Callable[[int], None] | None = None,
                     on_frame: Callable[[dict], None] | None = None) -> dict:
    """:func:`render_sequence` of ``frames`` read from ``source``, split over ``jobs`` worker
    processes (blocks of consecutive frames, :func:`frame_blocks`), each with its own GL
    context; the same bytes as one process. Workers come from a fork server (never forked
    from this process, whatever GL it used before; :func:`axdf_cli.workers.process_map`) and
    stop, each after the file it is writing, when this process is interrupted or dies.
    ``progress`` and ``on_frame`` are called in this process as blocks finish; camera.json is
    written here at the end. With one job (or one frame) everything runs in this process."""
    from axdf_cli.workers import process_map

    frames = [int(f) for f in frames]
    blocks = frame_blocks(frames, jobs)
    if jobs <= 1 or len(blocks) <= 1:
        return render_sequence(scene, source.chunks(frames), settings, out_dir, progress, on_frame)
    root = out_dir if isinstance(out_dir, Root) else Root(Path(out_dir))
    cameras = sequence_cameras(scene, settings)
    files: dict[str, str] = {}
    gl: list = []

    def done(result) -> None:
        block, block_files, info = result
        files.update(block_files)
        gl.append(info)
        for f in block:
            if progress is not None:
                progress(f)
        if on_frame is not None:
            on_frame(files)

    shared = (scene, source, settings, cameras, root.root)
    process_map(_render_block, blocks, shared, jobs=jobs, on_result=done, fresh=True,
                preload=("axdf_cli.render.framefiles",) + tuple(getattr(source, "preload", ())))
    files[CAMERA] = _write_camera(root, scene, settings, cameras)
    renderer, version = gl[0]
    return {"gl_renderer": renderer, "gl_version": version, "files": files}


_WORKER: dict = {}  # in a render worker: pid -> its ViewRenderer (a GL context never crosses a fork)


def _render_block(shared, block: list[int]) -> tuple:
    """In a render worker: render and write one block of frames (the GL context and the
    scene's topology are made on the worker's first block and kept)."""
    import os

    from axdf_cli.render.views import ViewRenderer
    from axdf_cli.workers import check_parent

    scene, source, settings, cameras, root = shared
    vr = _WORKER.get(os.getpid())
    if vr is None:
        vr = _WORKER[os.getpid()] = ViewRenderer(scene, settings, _panels(cameras))
    files = _write_frames(vr, source.chunks(block), frame_cameras(scene, cameras), Root(root),
                          progress=lambda _f: check_parent())
    return block, files, (vr.info.renderer, vr.info.version)


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
    from axdf_cli.workers import in_child

    info, limit = in_child(probe, settings)
    return fit_size(settings, limit, info.renderer, on_note)



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
