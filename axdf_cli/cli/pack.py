"""Make a body's muscles share space: ``axdf pack MUSCLES --skeleton SKEL --out DIR``.

Imported muscles overlap in bulk at the rest pose (OpenSim's lines of action with volumes from
the muscles' forces). ``pack`` resolves that once (axdf_cli/model/pack.py; docs/METHOD.md,
Packing): every muscle gets a territory no other muscle or bone holds, and its sections become
``outline:`` control points fitted inside it, grown outwards until it has its volume again.
DIR receives one file per muscle file (same name), ``pack_report.json`` and ``PACK.md`` (the
rest pose's overlaps and volumes before and after) and ``manifest.json``: DIR is the
command's own folder (``--overwrite`` replaces an earlier pack there; docs/OUTPUTS.md). Bad
input writes nothing (exit 2).
"""
from __future__ import annotations

import sys
from pathlib import Path

from axdf_cli.cli.importer import add_overwrite_arg
from axdf_cli.cli.progress import Phases
from axdf_cli.fileio.outputs import OutputSet, write_outputs


def add_args(p) -> None:
    p.add_argument("muscles", nargs="+", metavar="MUSCLES", help="muscle files, folders or globs of one body")
    p.add_argument("--skeleton", required=True, metavar="SKELETON",
                   help="skeleton YAML the muscles are defined on (its bone meshes are the bones)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--rounds", type=int, default=None, metavar="N",
                   help="rounds of territory, fit and growth (default 20; then 3 rounds of polish "
                        "by contact at the rest pose)")
    p.add_argument("--pose", metavar="POSE", default=None,
                   help="a pose of the same skeleton (a motion): the packed shapes are also polished so "
                        "that they share space at its frames, not only at rest")
    p.add_argument("--frames", metavar="SPEC", default=None,
                   help="the pose's frames to polish over (as axdf run --frames; default: 16 of them, "
                        "evenly spaced)")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    add_overwrite_arg(p)


def run(args) -> int:
    from axdf_cli import tolerances as tol
    from axdf_cli.errors import Mark, UsageError
    from axdf_cli.tools.pack import SUMMARY, build_pack
    from axdf_cli.specs import RefPolicy, expand_muscle_paths

    if args.rounds is not None and not 1 <= args.rounds <= 200:
        raise UsageError(f"--rounds {args.rounds}: give 1..200")
    if args.frames is not None and args.pose is None:
        raise UsageError("--frames needs --pose (the frames are the pose's)")
    policy = RefPolicy.for_command([args.skeleton] + ([args.pose] if args.pose else []) + list(args.muscles),
                                   args.allow_outside)
    files = expand_muscle_paths([(Path(m), Mark(m)) for m in args.muscles], policy)
    out = OutputSet(args.out, "pack")
    # every check of the output folder before the work (it takes a while)
    from axdf_cli.fileio.outputs import check_outputs

    check_outputs(out, inputs=[args.skeleton, *([args.pose] if args.pose else []), *map(str, files)],
                  overwrite=args.overwrite,
                  input_dirs=[m for m in args.muscles if Path(m).is_dir()])

    rounds = args.rounds if args.rounds is not None else tol.PACK_ITERATIONS

    # a bar of rounds on a terminal, a line per phase and round in a log (a pack takes minutes)
    phases = Phases(args.quiet, "axdf pack", "round", rounds + tol.PACK_POLISH_ROUNDS, at_most=True)

    def progress(it, h):
        what = "round" if it < rounds else "polish"
        phases.step(f"inside another muscle {100 * h[0]:.2f}%, inside a bone {100 * h[1]:.2f}%")
        if args.verbose:
            print(f"  {what} {it + 1}: inside another muscle {100 * h[0]:.2f}%, inside a bone {100 * h[1]:.2f}%, "
                  f"deepest {1000 * h[2]:.1f} mm, volume kept {h[3]:.3f}..{h[4]:.3f}", file=sys.stderr)

    try:
        res = build_pack(files, Path(args.skeleton), policy, args.rounds, progress, args.pose, args.frames,
                         on_phase=phases.phase)
    finally:
        phases.close()
    for name, data in res.files.items():
        out.add(Path(args.out) / name, data, "output")
    write_outputs(out, inputs=res.inputs, overwrite=args.overwrite,
                  input_dirs=[m for m in args.muscles if Path(m).is_dir()])
    if not args.quiet:
        b, a = res.report["before"], res.report["after"]
        print(f"packed {len(res.report['muscles'])} muscles into {args.out}: inside another muscle "
              f"{100 * b['inside_muscle']:.1f}% -> {100 * a['inside_muscle']:.2f}%, inside a bone "
              f"{100 * b['inside_bone']:.1f}% -> {100 * a['inside_bone']:.2f}% at the rest pose; volume kept "
              f"{a['volume_ratio_min']:.3f} (least), {a['volume_ratio_median']:.3f} (median)")
        print(f"report: {Path(args.out) / SUMMARY}")
    return 0
