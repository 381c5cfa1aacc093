"""Move a motion onto a muscle model's skeleton: ``axdf retarget MOTION --onto SKELETON --map MAP --out DIR``.

MOTION is a BVH take or an ``.npz`` of 3D joint positions (``joints`` (F, J, 3), ``names``,
optional ``fps``). The model's coordinates are fitted to the motion's joint centres frame by
frame (least squares within the coordinates' ranges, warm-started from the previous frame)
after sizing the model to the subject with one scale factor; the map (docs/FORMATS.md,
"Retarget map") says which mocap joint drives which point of the model. DIR receives the
pose (``NAME.yaml``, for SKELETON), ``retarget.csv`` (per frame: RMS and max joint-centre
error in metres, and every point's) and ``retarget_report.json`` (scale, segments, per point
and per coordinate figures), and ``manifest.json``: DIR is the command's own folder, which
``--overwrite`` replaces (the output rule, axdf_cli/fileio/outputs.py; the pose is read back as
``axdf validate`` reads it before anything is written). Bad input writes nothing (exit 2,
``FILE:LINE:COL``).
"""
from __future__ import annotations

import sys
from pathlib import Path

from axdf_cli.cli import progress
from axdf_cli.errors import Mark
from axdf_cli.cli.importer import add_overwrite_arg, add_units_args, parse_scale_step, write_imported
from axdf_cli.fileio.outputs import OutputSet


def add_args(p) -> None:
    p.add_argument("motion", metavar="MOTION", help="a BVH take (.bvh) or joint positions (.npz: joints, names, fps)")
    p.add_argument("--onto", metavar="SKELETON", help="the muscle model's skeleton YAML (default: the map's onto:)")
    p.add_argument("--map", required=True, metavar="MAP.yaml", help="mocap joints → model points (docs/FORMATS.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (the pose and the report)")
    p.add_argument("--name", help="pose name (default: MOTION's name and the skeleton's)")
    add_units_args(p, "metres per unit of MOTION: a number, or a unit name (default: a BVH's unit from the "
                      "body's height as `axdf import bvh` takes it; an npz is in metres)")
    p.add_argument("--step", type=int, default=1, metavar="N", help="keep every N-th frame of MOTION (fps / N)")
    p.add_argument("--up", choices=("z", "y"), default="z",
                   help="an npz's up axis: z (axdf's world) or y (SMPL, most pose estimators); a BVH is Y-up")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    p.add_argument("--strict", action="store_true",
                   help="refuse (exit 2, nothing written) a fit that is warned on: error or coordinates held at a "
                        "range's end beyond the documented bounds, or a scale far from the model's")
    add_overwrite_arg(p)


def run(args) -> int:
    from axdf_cli.tools.retarget import build_retarget
    from axdf_cli.specs import RefPolicy, load_skeleton

    scale = parse_scale_step(args)
    policy = RefPolicy.for_command([args.map, args.onto, args.motion], args.allow_outside)
    skel = load_skeleton(Path(args.onto), policy) if args.onto else None
    bar = progress.bar(args.quiet, "frame", desc="fit", leave=False, lazy=True)  # opened at the first fitted frame
    try:
        res = build_retarget(Path(args.motion), Path(args.map), Path(args.out), skeleton=skel,
                             skeleton_path=Path(args.onto) if args.onto else None, name=args.name, scale=scale,
                             step=args.step, up=args.up, policy=policy, progress=bar)
    finally:
        if bar is not None:
            bar.close()
    for w in res.warnings:
        print(f"axdf: warning: {w}", file=sys.stderr)
    if args.strict and res.warnings:
        from axdf_cli.errors import InputError

        raise InputError(Mark(str(args.motion)), f"{len(res.warnings)} warning(s) with --strict; first: "
                         f"{res.warnings[0][:200]}", "fix the map or the motion, or run without --strict")
    files = OutputSet(args.out, "retarget")
    for path, data in res.files.items():
        files.add(path, data, "output")
    files.settings = {"name": res.report.get("pose"), "scale": args.scale, "units": args.units, "step": args.step,
                      "up": args.up}
    write_imported(files, [args.motion, args.map, args.onto or res.retargeted.rmap.skeleton.source],
                   args.overwrite, args.motion)
    if not args.quiet:
        for line in res.notes:
            print(line)
        print("\n".join(summary(res.report, args.verbose)))
        print(f"report: {Path(args.out) / 'retarget_report.json'}")
    return 0


def summary(rep: dict, verbose: bool = False) -> list[str]:
    """The report in a few lines: the fit's size, error and the worst points."""
    m, sim, err = rep["motion"], rep["similarity"], rep["error"]
    lines = [f"retargeted {m['file']} ({m['frames']} frames at {m['fps']:g} fps) onto {rep['skeleton']}: "
             f"pose {rep['pose']}",
             f"scale {sim['scale']:.4f} ({sim['scale_from']}), turned {sim['yaw_deg']:.1f} deg; "
             f"joint-centre error RMS {err['rms_m'] * 1000:.1f} mm, max {err['max_m'] * 1000:.1f} mm "
             f"(frame {err['worst_frame']})"]
    b = rep["checks"]["bounds"]
    lines.append(f"  subject {b['body_height_m']:.3f} m tall, head top to sole ("
                 + {"motion": "its own skeleton's stature", "model": f"{rep['skeleton']}'s stature x the scale",
                    "points": "the map's points' extent x the scale"}[b["body_height_from"]] + ")")
    points = sorted(rep["points"].items(), key=lambda kv: -kv[1]["rms_m"])
    shown = points if verbose else points[:3]
    lines.append("  " + ", ".join(f"{k} {v['rms_m'] * 1000:.1f} mm RMS" for k, v in shown)
                 + ("" if verbose else " (worst; -v for all)"))
    ends = [f"{c} {v['frames_at_range_end']}" for c, v in rep["coordinates"].items() if v["frames_at_range_end"]]
    if ends:
        lines.append("  frames at a range's end: " + ", ".join(ends))
    return lines
