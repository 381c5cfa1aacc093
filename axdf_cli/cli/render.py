"""Render preview frames (PNG) and data passes (OpenEXR) from a finished run's meshes.

Writes ``OUT/frames/<frame:04d>.png|.exr`` and ``OUT/camera.json`` (``OUT`` defaults to
RUN_DIR) and records them, with the render settings and the GL renderer, in OUT's manifest:
marked incomplete while frames are written, complete at the end. Settings come from the
run's manifest, overridden by the flags below. Frames that exist are rendered again only
with ``--overwrite``; ``--resume`` finishes an interrupted render with the same settings.
``--jobs N`` renders over N worker processes (the same bytes).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from axdf_cli.cli import progress
from axdf_cli.cli.run import positive
from axdf_cli.errors import InputError, Mark, UsageError
from axdf_cli.specs.render import add_render_args, check_pinned, settings_from_args, settings_to_dict
from axdf_cli.fileio.runfolder import (RUN_COMMAND, command_of, CAMERA, FRAME_EXTENSIONS, MANIFEST_INTERVAL_S, Root, Session, Target,
                                check_dirs, describe_differences, frame_relpath, gl_record, is_file_with, prepare,
                                read_run_manifest, try_write_manifest, write_manifest)


def add_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="folder written by `axdf run`")
    parser.add_argument("--out", metavar="DIR", help="write frames here instead of RUN_DIR")
    parser.add_argument("--frames", metavar="SPEC", help="frames to render (default: every frame of the run)")
    g = parser.add_mutually_exclusive_group()
    g.add_argument("--overwrite", action="store_true", help="render frames that exist again")
    g.add_argument("--resume", action="store_true", help="finish an interrupted render (same settings)")
    parser.add_argument("--jobs", type=positive, default=1, metavar="N",
                        help="worker processes for the rendering (default 1; same output bytes)")
    add_render_args(parser)


def _select(spec: str, frames: list[int]) -> list[int]:
    from axdf_cli.model.pose import parse_frames

    chosen = [int(f) for f in parse_frames(spec, Mark("--frames"), min(frames), max(frames))]
    missing = sorted(set(chosen) - set(frames))
    if missing:
        raise InputError(Mark("--frames"), f"frame {missing[0]} is not a frame of this run",
                         f"frames of the run: {frames[0]}..{frames[-1]} ({len(frames)} frames)")
    return chosen


def _frame_files(frames) -> list[str]:
    return [frame_relpath(f, ext) for f in frames for ext in FRAME_EXTENSIONS]


#: What makes a render folder's frames those of a run: the run's inputs, settings (but the
#: render settings) and frames.
IDENTITY = ("inputs", "frames", "muscles")


def _identity(manifest: dict) -> dict:
    settings = manifest.get("settings")
    settings = {k: v for k, v in settings.items() if k != "render"} if isinstance(settings, dict) else settings
    return {"settings": settings, **{k: manifest.get(k) for k in IDENTITY}}


def run(args: argparse.Namespace) -> int:
    from axdf_cli.render.runio import load_run_source, recorded_render_settings
    from axdf_cli.render.framefiles import check_render, render_frames_of

    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        raise UsageError(f"{run_dir} is not a folder", "give the output folder of `axdf run`")
    run_manifest = read_run_manifest(run_dir)
    if command_of(run_manifest) != RUN_COMMAND:
        raise InputError(run_manifest.mark(("command",)), f"{run_dir} holds the output of axdf "
                         f"{command_of(run_manifest)}, not a run", "give the output folder of `axdf run`")
    all_frames = run_manifest.frames()
    chosen = all_frames if args.frames is None else _select(args.frames, all_frames)
    settings = settings_from_args(recorded_render_settings(run_manifest), args)
    check_pinned(settings, chosen)

    # every check before the first byte: the folder, the frames there, the settings, EGL
    out = Path(args.out) if args.out else run_dir
    if out.resolve() == run_dir.resolve():
        target = Target(run_dir, run_manifest, False)
    else:  # another folder: new, or one `axdf render --out` wrote before from this run
        target = prepare(out, resume=True, command="render")
        if target.previous is not None and _identity(target.previous.data) != _identity(run_manifest.data):
            changed = describe_differences(target.previous, run_manifest.data, keys=("settings",) + IDENTITY)
            if not args.overwrite:
                raise InputError(target.previous.mark(("inputs",)),
                                 f"{out} holds frames rendered from another run ({'; '.join(changed)[:300]})",
                                 "pass --overwrite to replace them (only once the new frames are complete), "
                                 "or another --out")
            target = dataclasses.replace(target, replace=True)  # staged, then swapped in
    check_dirs(out, [os.path.dirname(frame_relpath(0, "png"))])
    old = target.previous if not target.replace else None
    old_files = old.files() if old is not None else {}
    new_render = settings_to_dict(settings)
    old_settings = old.get(("settings",), dict, "an object", required=False, default={}) if old is not None else {}
    old_render = old_settings.get("render")
    existing = [f for f in chosen if any(os.path.lexists(out / r) for r in _frame_files([f]))]
    if existing and not (args.overwrite or args.resume):
        raise UsageError(f"{len(existing)} of the frames are rendered already in {out} "
                         f"(frames/{existing[0]:04d}.png ...)",
                         "pass --overwrite to render them again, --resume to finish an interrupted render, "
                         "or --frames for others")
    if old_render != new_render:
        changed = describe_differences(old, {"settings": {**old_settings, "render": new_render}},
                                       keys=("settings",)) if old is not None else []
        if args.resume and changed and old_render is not None:
            raise InputError(old.mark(("settings", "render")), f"--resume with other render settings: {'; '.join(changed)}",
                             "resume with the settings of the interrupted render, or pass --overwrite")
        others = sorted({r for r in old_files if r.startswith("frames/")} - set(_frame_files(chosen)))
        if others:
            raise InputError(old.mark(("settings", "render")),
                             f"{others[0]} and others were rendered with other settings ({'; '.join(changed)})",
                             "render every frame (no --frames) with the new settings, or keep the recorded ones")
    todo = chosen
    if args.resume:
        done = {f for f in chosen
                if all(r in old_files and is_file_with(out / r, old_files[r]) for r in _frame_files([f]))}
        todo = [f for f in chosen if f not in done]
    settings = check_render(settings, on_note=lambda text: print(f"note: {text}", file=sys.stderr))
    new_render = settings_to_dict(settings)
    cam = settings.camera
    aim = (cam.target_bone, cam.target_mark) if cam is not None and cam.target_bone is not None else None
    scene, source, _ = load_run_source(run_dir, run_manifest, frames=todo, target_bone=aim)

    stale = set(_frame_files(todo)) | {CAMERA}
    if old is not None:
        base = dict(old.data)
    else:  # a new folder for the frames: the run's description, none of its files
        base = {k: v for k, v in run_manifest.data.items() if k not in ("files", "gl", "bounds")}
        base["command"] = "render"
    kept = {r: s for r, s in old_files.items() if r not in stale}
    base.update(complete=False, settings={**(base.get("settings") or {}), "render": new_render}, files=kept)

    bar = progress.bar(args.quiet, "frame", total=len(todo), leave=False)
    with Session(target) as session:
        root = session.root  # OUT, or the staging folder when the frames of another run are replaced
        write_manifest(root, base)  # incomplete while frames are written
        clock = {"t": time.monotonic(), "files": {}}

        def checkpoint(files: dict) -> None:
            clock["files"] = files
            if time.monotonic() - clock["t"] >= MANIFEST_INTERVAL_S:
                write_manifest(root, dict(base, files={**kept, **files}))
                clock["t"] = time.monotonic()

        try:
            result = render_frames_of(scene, source, todo, settings, Root(root), args.jobs,
                                      progress=(lambda f: bar.update()) if bar else None, on_frame=checkpoint)
        except BaseException:  # stopped: list the whole frames, for --resume (a staging folder goes)
            if not target.replace:
                try_write_manifest(out, dict(base, files={**kept, **clock["files"]}))
            raise
        finally:
            if bar is not None:
                bar.close()
        session.commit(dict(base, complete=True, files={**kept, **result["files"]},
                            gl=gl_record(result["gl_renderer"], result["gl_version"])))
    if not args.quiet:
        print(f"{len(todo)} frames rendered with {result['gl_renderer']} "
              f"({result['gl_version']}): {out / 'frames'}, {out / CAMERA}"
              + (f"; {len(chosen) - len(todo)} were complete" if len(todo) < len(chosen) else ""))
    return 0
