"""Fit muscle meshes as AxDf muscles: ``axdf fit MESH [MESH ...] --skeleton SKEL --out DIR``.

Each closed muscle surface (STL, PLY, OBJ), given in the skeleton's rest frame in ``--units``,
becomes one ordinary muscle file ``DIR/muscles/STEM.yaml``: an axis of 5 control points through
its medial curve bound to the nearest bones, ``--sections`` outlines of 8 points fitted so that
the model's rest surface passes through the mesh, tendons where its ends are thin
(axdf_cli/tools/fit.py; docs/FIT.md); ``--inside`` keeps each fitted surface inside its mesh.
DIR also receives ``fit_report.json`` and ``FIT.md`` (each fit's IoU, surface distance and
volume ratio, measured on the written file) and ``manifest.json``: DIR is the command's own
folder (``--overwrite`` replaces an earlier fit there; docs/OUTPUTS.md). ``--transform FILE``
carries meshes from another frame (an atlas' scan frame) into the skeleton's rest frame first.
A mesh that is missing, open, inconsistently wound, without volume, of several pieces or far
from every bone writes nothing (exit 2), and every such mesh of the batch is named at once;
slivers of a mesh are dropped and said so on stderr.
"""
from __future__ import annotations

import sys
from pathlib import Path

from axdf_cli.cli.importer import add_overwrite_arg
from axdf_cli.fileio.outputs import OutputSet, check_outputs, write_outputs


def add_args(p) -> None:
    p.add_argument("meshes", nargs="+", metavar="MESH", help="closed muscle surfaces (STL, PLY, OBJ) at the rest pose")
    p.add_argument("--skeleton", required=True, metavar="SKELETON",
                   help="skeleton YAML whose rest frame the meshes are in (its bone meshes, or segments, bind the axis)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (muscles/, fit_report.json, FIT.md)")
    p.add_argument("--units", default="m", metavar="UNIT", help="the meshes' unit: mm, cm or m (default m)")
    p.add_argument("--sections", type=int, default=None, metavar="N",
                   help="sections per muscle (default 16, chosen by measurement: docs/FIT.md)")
    p.add_argument("--transform", default=None, metavar="FILE",
                   help="a YAML `matrix:` (4x4) from the meshes' frame, in metres after --units, into the skeleton's "
                        "rest frame (docs/FIT.md, \"Meshes in another frame\")")
    p.add_argument("--paths", default=None, metavar="DIR",
                   help="the model's muscle files: a mesh binds only to the bones the file of its name there "
                        "spans (its path's and those between), so a muscle across two joints hangs on each")
    p.add_argument("--inside", action="store_true",
                   help="keep each fitted surface inside its mesh (bounded sections; for meshes that share no space, "
                        "such as axdf atlas --partition's territories, the fits then share none)")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    add_overwrite_arg(p)


def run(args) -> int:
    from axdf_cli.tools import constants as tol
    from axdf_cli.model.muscle import OCT
    from axdf_cli.specs import RefPolicy
    from axdf_cli.tools.fit import SUMMARY, build_fit, unit_scale

    unit_scale(args.units)  # an unknown unit is refused before anything is read
    policy = RefPolicy.for_command([args.skeleton, args.paths, args.transform] + list(args.meshes), args.allow_outside)
    out = OutputSet(args.out, "fit")
    dirs = [args.paths] if args.paths else []
    named = [args.skeleton, *args.meshes] + ([args.transform] if args.transform else [])
    check_outputs(out, inputs=named, overwrite=args.overwrite, input_dirs=dirs)

    def told(name, e):
        if args.verbose:
            print(f"  {name}: IoU {e['iou']:.3f}, mean distance {e['distance_mean_mm']:.2f} mm, "
                  f"volume ratio {e['volume_ratio']:.3f}", file=sys.stderr)

    res = build_fit([Path(m) for m in args.meshes], Path(args.skeleton), args.units, args.sections, policy, told,
                    paths=None if args.paths is None else Path(args.paths),
                    transform=None if args.transform is None else Path(args.transform), inside=args.inside)
    for rel, data in res.files.items():
        out.add(Path(args.out) / rel, data, "output")
    write_outputs(out, inputs=res.inputs, overwrite=args.overwrite, input_dirs=dirs)
    for m in res.report["muscles"]:
        if m.get("dropped_pieces"):
            print(f"axdf: note: {m['mesh']}: {m['dropped_pieces']} closed pieces under "
                  f"{100 * tol.FIT_MIN_PIECE_SHARE:g}% of its volume dropped as slivers "
                  f"({100 * m['dropped_volume_share']:.2f}% of the volume in all; fit_report.json)", file=sys.stderr)
        if m["iou"] < tol.FIT_WARN_IOU:
            print(f"axdf: warning: {m['mesh']}: the fitted muscle overlaps its mesh by IoU {m['iou']:.2f} only "
                  f"(volume ratio {m['volume_ratio']:.2f}): an axis and {OCT}-point sections do not follow "
                  "its shape (docs/FIT.md)", file=sys.stderr)
    if not args.quiet:
        ms = res.report["muscles"]
        worst = min(ms, key=lambda m: m["iou"])
        print(f"fitted {len(ms)} muscles into {Path(args.out) / 'muscles'} ({res.report['sections']} sections): "
              f"IoU {worst['iou']:.3f} (least, {worst['muscle']}), volume ratio "
              f"{min(m['volume_ratio'] for m in ms):.3f}..{max(m['volume_ratio'] for m in ms):.3f}")
        if args.inside:
            far = max(ms, key=lambda m: m["outside_over_1mm"])
            print(f"inside: {100 * far['outside_over_1mm']:.2f}% of {far['muscle']}'s vertices more than 1 mm outside "
                  f"its mesh (most), farthest {max(m['outside_farthest_mm'] for m in ms):.1f} mm")
        print(f"report: {Path(args.out) / SUMMARY}")
    return 0
