"""Render preview frames (PNG) and data passes (OpenEXR) from a finished run's meshes.

Writes ``OUT/frames/<frame:04d>.png|.exr`` and ``OUT/camera.json`` (``OUT`` defaults to
RUN_DIR). Settings come from the run's manifest, overridden by the flags below.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from axdf_cli.errors import UsageError
from axdf_cli.render.settings import add_render_args, settings_from_args
from axdf_cli.runfolder import gl_record, write_manifest


def add_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("run_dir", metavar="RUN_DIR", help="folder written by `axdf run`")
    parser.add_argument("--out", metavar="DIR", help="write frames here instead of RUN_DIR")
    add_render_args(parser)


def progress_bar(total: int, quiet: bool):
    """A tqdm bar on stderr when it is a terminal, else None."""
    if quiet or not sys.stderr.isatty():
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="frame", file=sys.stderr, leave=False)


def run(args: argparse.Namespace) -> int:
    from axdf_cli.render.runio import load_run_scene
    from axdf_cli.render.sequence import render_sequence

    run_dir = Path(args.run_dir)
    if not run_dir.is_dir():
        raise UsageError(f"{run_dir} is not a folder", "give the output folder of `axdf run`")
    scene, chunks, settings = load_run_scene(run_dir)
    settings = settings_from_args(settings, args)
    out = Path(args.out) if args.out else run_dir
    bar = progress_bar(len(scene.frames), args.quiet)
    try:
        result = render_sequence(scene, chunks, settings, out,
                                 progress=(lambda f: bar.update(1)) if bar else None)
    finally:
        if bar is not None:
            bar.close()
    if out.resolve() == run_dir.resolve():
        update_manifest(run_dir, result)
    if not args.quiet:
        print(f"{len(scene.frames)} frames rendered with {result['gl_renderer']} "
              f"({result['gl_version']}): {out / 'frames'}, {out / 'camera.json'}")
    return 0


def update_manifest(run_dir: Path, result: dict) -> None:
    """Record the GL renderer and the new files' sha256 in the run's manifest."""
    path = run_dir / "manifest.json"
    manifest = json.loads(path.read_text())
    manifest["gl"] = gl_record(result["gl_renderer"], result["gl_version"])
    files = manifest.get("files")
    if isinstance(files, dict):
        files.update(result["files"])
    else:
        manifest["files"] = dict(result["files"])
    write_manifest(run_dir, manifest)
