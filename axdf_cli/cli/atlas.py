"""Register an atlas onto a skeleton and fit it: ``axdf atlas ATLAS_DIR --onto SKELETON --map
MAP --muscles DIR --out DIR``.

The atlas (meshes in millimetres, in its own scan frame) is brought onto the skeleton at rest
side by side (axdf_cli/tools/atlas.py; docs/ATLAS.md): a similarity of landmarks (joint centres
from sphere fits to cartilages) onto the skeleton's joints, then a thin-plate warp pulling the
atlas' bones onto the model's bone meshes. The map (``--map``, atlases/gait2392.yaml) names the
atlas' files, the landmarks, the bones the warp pulls and which atlas muscle is which model
muscle. DIR receives ``registered/NAME.ply`` (each atlas muscle carried onto the skeleton, under
the model's name, metres), ``landmarks_SIDE.yaml`` (each side's landmark similarity as an
``axdf fit --transform`` file), ``atlas_report.json`` (the residuals per landmark and per bone,
before and after the warp, and each fit's error) and, unless ``--register-only``, the fitted
library ``muscles/`` (every model muscle: the atlas' fitted, the rest copied from
``--muscles``; README.md with the atlas' credit). Bad input writes nothing (exit 2).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

from axdf_cli.cli.importer import add_overwrite_arg


def add_args(p) -> None:
    p.add_argument("atlas", metavar="ATLAS_DIR", help="the atlas' folder (its meshes in millimetres)")
    p.add_argument("--onto", required=True, metavar="SKELETON", help="skeleton YAML to register the atlas onto")
    p.add_argument("--map", required=True, metavar="MAP",
                   help="the atlas map (YAML: its files, landmarks, bones and muscle names; atlases/gait2392.yaml)")
    p.add_argument("--muscles", required=True, metavar="DIR",
                   help="the model's muscle files: their paths bind the fits and cut shared atlas muscles; "
                        "what the atlas lacks is copied from them")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (registered/, landmarks_SIDE.yaml, atlas_report.json, muscles/)")
    p.add_argument("--sides", default="r,l", metavar="S[,S]", help="the sides to register: r, l or r,l (default)")
    p.add_argument("--sections", type=int, default=None, metavar="N",
                   help="sections per fitted muscle (default: axdf fit's, 16)")
    p.add_argument("--register-only", action="store_true",
                   help="register and write the meshes and residuals; fit nothing (seconds, not minutes)")
    p.add_argument("--partition", action="store_true",
                   help="also the registered atlas as a partition of space: territories/NAME.ply, one closed, "
                        "non-overlapping mesh per muscle (bones win; a 0.5 mm gap; minutes)")
    add_overwrite_arg(p)


def run(args) -> int:
    from axdf_cli.errors import UsageError
    from axdf_cli.fileio.outputs import OutputSet, check_outputs, write_outputs
    from axdf_cli.tools.atlas import Atlas
    from axdf_cli.tools.atlas_library import LIBRARY, REGISTERED, build_library
    from axdf_cli.tools.tables import load_atlas_map

    sides = tuple(dict.fromkeys(s.strip() for s in args.sides.split(",")))
    if not sides or any(s not in ("r", "l") for s in sides):
        raise UsageError(f"--sides {args.sides!r}: the sides to register", "r, l or r,l")
    if args.sections is not None and not 4 <= args.sections <= 64:
        raise UsageError(f"--sections {args.sections}: sections per fitted muscle", "4 to 64 (axdf fit's)")
    out = OutputSet(args.out, "atlas")
    out.settings = {"sides": list(sides), "sections": args.sections, "register_only": bool(args.register_only),
                    "partition": bool(args.partition)}
    named = [args.onto, args.map]
    dirs = [args.atlas, args.muscles]
    check_outputs(out, inputs=named, overwrite=args.overwrite, input_dirs=dirs)
    atlas = Atlas(Path(args.atlas), load_atlas_map(args.map))
    t0 = time.time()

    def phase(text):
        if not args.quiet:
            print(f"[{time.time() - t0:6.1f} s] {text}", file=sys.stderr, flush=True)

    def muscle(name, e):
        if args.verbose:
            print(f"[{time.time() - t0:6.1f} s]   {name}: IoU {e['iou']:.3f}, volume {e['volume_ratio']:.3f}",
                  file=sys.stderr, flush=True)

    files, report = build_library(atlas, Path(args.onto), Path(args.muscles), sides, args.sections, muscle, phase,
                                  fit=not args.register_only, partition=args.partition)
    for rel, data in sorted(files.items()):
        out.add(Path(args.out) / rel, data, "output")
    write_outputs(out, inputs=[args.onto, args.map], overwrite=args.overwrite, input_dirs=dirs)
    if not args.quiet:
        for side, rep in report["sides"].items():
            lm = ", ".join(f"{k} {v:.1f}" for k, v in rep["landmark_residual_mm"].items())
            after = rep.get("bones_after", rep["bones_before"])
            bones = ", ".join(f"{b} {e['mean_mm']:.2f}" for b, e in after.items())
            print(f"side {side}: scale {rep['scale']:.4f}; landmarks off by (mm) {lm}; bones after the warp, mean "
                  f"distance (mm) {bones}")
        n = sum(1 for rel in files if rel.startswith(f"{REGISTERED}/"))
        line = f"registered {n} atlas muscles into {Path(args.out) / REGISTERED}"
        if not args.register_only:
            fitted = report["fitted"]
            worst = min(fitted, key=lambda m: m["iou"]) if fitted else None
            line += (f"; library {Path(args.out) / LIBRARY}: {len(fitted)} fitted"
                     + (f" (IoU {worst['iou']:.3f} least, {worst['muscle']})" if worst else "")
                     + f", {len(report['failed'])} fits refused, {len(report['kept'])} copied"
                     + (f", {len(report['weak'])} kept below the bar inside their territories" if report.get("weak")
                        else ""))
        print(line)
        if "partition" in report:
            pr = report["partition"]
            print(f"partition: {len(pr['volume_ratio'])} territories into {Path(args.out) / 'territories'}; more than "
                  f"1 mm inside another muscle {100 * pr['registered']['inside_muscle_over_1mm']:.2f}% of the "
                  f"registered meshes' vertices, {100 * pr['territories']['inside_muscle_over_1mm']:.2f}% of the "
                  f"territories'; volume kept {pr['volume_ratio_median']:.3f} (median), "
                  f"{pr['volume_ratio_least']:.3f} least")
            measured = [m for m in report["fitted"] if "atlas" in m]
            if measured:
                far = max(report["fitted"], key=lambda m: m["outside_over_1mm"])
                low = min(measured, key=lambda m: m["atlas"]["iou"])
                ious = sorted(m["atlas"]["iou"] for m in measured)
                print(f"fitted into the territories: against the registered atlas meshes IoU "
                      f"{ious[len(ious) // 2]:.3f} (median), {low['atlas']['iou']:.3f} least ({low['muscle']}); "
                      f"{100 * far['outside_over_1mm']:.2f}% of {far['muscle']}'s vertices more than 1 mm outside "
                      "its territory (most)")
        print(f"report: {Path(args.out) / 'atlas_report.json'}")
    return 0
