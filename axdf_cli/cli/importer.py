"""Import models from other tools: ``axdf import osim MODEL.osim [--motion F] [--controls F] --out DIR``.

``osim`` reads an OpenSim 4 model and writes an axdf skeleton (bodies, joints, coupled
DOFs, bone meshes as PLY), one muscle file per muscle, and, given a motion, a pose (with
muscle activation from a controls file); plus ``import_report.json`` and ``IMPORT.md``
listing what was not imported (wrap objects, markers, ...). Nothing is written when an
input is bad (exit 2, ``FILE:LINE:COL``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from axdf_cli.atomic import write_bytes


def add_args(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="source", metavar="SOURCE", parser_class=type(parser))
    sub.required = True
    p = sub.add_parser("osim", help="OpenSim 4 model (.osim) with optional motion (.mot/.sto) and controls (.sto)",
                       description="Import an OpenSim model: skeleton, muscles, bone meshes, and a pose from a motion.")
    g = p.add_mutually_exclusive_group()  # also accepted after the source (`axdf import osim -q ...`)
    g.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="print only errors")
    g.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="print more detail")
    p.add_argument("model", metavar="MODEL.osim", type=Path)
    p.add_argument("--motion", type=Path, metavar="FILE", help="coordinates over time (.mot/.sto) → a pose")
    p.add_argument("--controls", type=Path, metavar="FILE", help="muscle excitations (.sto) → the pose's activation")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="output folder (report; default place of every other file)")
    p.add_argument("--name", help="skeleton name (default: the model's name)")
    p.add_argument("--skeleton-out", type=Path, metavar="FILE", help="skeleton YAML (default DIR/skeletons/NAME.yaml)")
    p.add_argument("--meshes-out", type=Path, metavar="DIR",
                   help="bone meshes folder (default: meshes/NAME beside the skeleton)")
    p.add_argument("--muscles-out", type=Path, metavar="DIR", help="muscle YAML folder (default DIR/muscles)")
    p.add_argument("--pose-out", type=Path, metavar="FILE", help="pose YAML (default DIR/MOTION.yaml)")
    p.add_argument("--pose-name", help="pose name (default: the motion file's name)")
    p.add_argument("--fps", type=float, help="resample the motion at this frame rate (default: its own)")
    p.add_argument("--no-meshes", action="store_true", help="do not convert bone geometry")


def run(args) -> int:
    from axdf_cli.errors import UsageError
    from axdf_cli.importers.osim_import import build_import

    if args.fps is not None and not (0 < args.fps <= 10000):
        raise UsageError(f"--fps {args.fps}", "a frame rate in (0, 10000]")
    res = build_import(args.model, args.out, name=args.name, motion=args.motion, controls=args.controls,
                       skeleton_out=args.skeleton_out, muscles_out=args.muscles_out, pose_out=args.pose_out,
                       meshes_out=args.meshes_out, pose_name=args.pose_name, fps=args.fps,
                       meshes=not args.no_meshes)
    for w in res.warnings:
        print(f"axdf: warning: {w}", file=sys.stderr)
    for path, data in sorted(res.files.items()):
        write_bytes(path, data)
    if not args.quiet:
        c = res.report["counts"]
        print(f"imported {args.model.name}: {c['bodies']} bodies, {c['coordinates']} coordinates, "
              f"{c['muscles']} muscles, {c['meshes']} bone meshes")
        kinds: dict[str, int] = {}
        for i in res.report["ignored"]:
            kinds[i["kind"]] = kinds.get(i["kind"], 0) + 1
        if kinds:
            print("not imported: " + ", ".join(f"{n} {k}{'s' if n != 1 else ''}" for k, n in sorted(kinds.items())))
        skipped = res.report.get("missing_meshes", [])
        if skipped:
            print(f"meshes skipped: {len(skipped)}")
        if args.verbose:
            for path in sorted(res.files):
                print(path)
        print(f"report: {Path(args.out) / 'IMPORT.md'}")
    return 0
