"""Re-express muscles on another skeleton: ``axdf transfer MUSCLES --from A --to B --map MAP --out DIR``.

Every muscle of MUSCLES (files, folders or globs) defined on skeleton A is moved onto
skeleton B (``--from``/``--to``, or the map's ``from:``/``to:``) through the bone correspondence in MAP (docs/FORMATS.md, "Transfer map"): axis
points (or path points and wrap surfaces) keep their place along each bone's segment, scaled
by the bones' length ratio; section radii scale with the muscle's bones. Muscles on bones the
map does not name, or whose paths cannot be carried, are skipped and listed with the reason
(exit 0 with a warning). DIR receives one file per muscle file (same
name), ``transfer_report.json``, ``TRANSFER.md`` and ``manifest.json``: DIR is the command's own folder
(``--overwrite`` replaces an earlier transfer there; axdf_cli/fileio/outputs.py). A bad map or
muscle writes nothing (exit 2).
"""
from __future__ import annotations

import sys
from pathlib import Path

from axdf_cli.cli.importer import add_overwrite_arg
from axdf_cli.fileio.outputs import OutputSet, write_outputs


def add_args(p) -> None:
    p.add_argument("muscles", nargs="+", metavar="MUSCLES", help="muscle files, folders or globs defined on --from")
    p.add_argument("--from", dest="skel_from", metavar="SKELETON",
                   help="skeleton YAML the muscles use (default: the map's from:)")
    p.add_argument("--to", dest="skel_to", metavar="SKELETON",
                   help="skeleton YAML to move them onto (default: the map's to:)")
    p.add_argument("--map", required=True, metavar="MAP.yaml", help="bone correspondence (docs/FORMATS.md)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    add_overwrite_arg(p)


def run(args) -> int:
    from axdf_cli.errors import Mark
    from axdf_cli.specs import RefPolicy, expand_muscle_paths, load_skeleton
    from axdf_cli.tools.transfer import build_transfer

    # files named here, and their folders, are trusted roots (as for axdf run)
    policy = RefPolicy.for_command([args.map, args.skel_from, args.skel_to] + list(args.muscles), args.allow_outside)
    skel_a = load_skeleton(Path(args.skel_from), policy) if args.skel_from else None
    skel_b = load_skeleton(Path(args.skel_to), policy) if args.skel_to else None
    files = expand_muscle_paths([(Path(m), Mark(m)) for m in args.muscles], policy)
    res = build_transfer(files, skel_a, skel_b, Path(args.map), Path(args.out), policy)
    out = OutputSet(args.out, "transfer")
    for path, data in res.files.items():
        out.add(path, data, "output")
    write_outputs(out, inputs=res.inputs, overwrite=args.overwrite,
                  input_dirs=[m for m in args.muscles if Path(m).is_dir()])
    for s in res.skipped:
        print(f"axdf: warning: {s['file']}: muscle {s['muscle']} skipped: {s['why']}", file=sys.stderr)
    if not args.quiet:
        r = res.report
        print(f"transferred {len(r['muscles'])} muscles from {r['from']} to {r['to']} "
              f"({len(r['skipped'])} skipped) into {args.out}")
        if args.verbose:
            for m in r["muscles"]:
                print(f"  {m['muscle']}: rest length {m['rest_length_from']:.4f} -> {m['rest_length_to']:.4f} m, "
                      f"radii x{m['radius_scale']:.3f}")
        print(f"report: {Path(args.out) / 'TRANSFER.md'}")
    return 0
