"""Import models from other tools: ``axdf import osim MODEL.osim [--motion F] [--controls F] --out DIR``
and ``axdf import bvh FILE.bvh --out DIR [--scale S]``.

``osim`` reads an OpenSim 4 model and writes an axdf skeleton (bodies, joints, coupled
DOFs, bone meshes as PLY), one muscle file per muscle, and, given a motion, a pose (with
muscle activation from a controls file); plus ``import_report.json`` and ``IMPORT.md``
listing what was not imported (wrap objects, markers, ...). Nothing is written when an
input is bad (exit 2, ``FILE:LINE:COL``).

``mjcf`` reads a MuJoCo model (MJCF XML: bodies, hinge/slide/ball/free joints, joint
couplings, spatial tendons with wrap geoms and sidesites, muscle actuators, mesh assets) and,
given an npz with ``qpos``, writes a pose; the same layout and reports as ``osim``.

``bvh`` reads a Biovision motion-capture file and writes an axdf skeleton (Z-up, metres;
end sites become ``<joint>_end`` tip bones) and a pose keyed at every frame; the length unit is
guessed from the skeleton's height unless ``--scale`` gives it.

All three follow the output rule (axdf_cli/fileio/outputs.py): ``--out`` is the import's own folder
(its ``manifest.json``); ``--overwrite`` replaces an earlier import there and files outside it
that the import wrote and nobody changed since; every YAML file is read back as ``axdf
validate`` reads it before anything is written (:func:`write_imported`, which ``retarget`` and
any new importer call too).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from axdf_cli.cli import progress
from axdf_cli.errors import Mark
from axdf_cli.fileio.outputs import OutputSet, check_outputs, write_checked
from axdf_cli.importers.check import check_documents


def output_role(path, args) -> str:
    """What names an output of ``axdf import osim`` in messages: its flag, or its role."""
    p = Path(path)
    for flag in ("skeleton_out", "pose_out"):
        if getattr(args, flag, None) is not None and Path(getattr(args, flag)) == p:
            return "--" + flag.replace("_", "-")
    for flag in ("meshes_out", "muscles_out"):
        if getattr(args, flag, None) is not None and Path(getattr(args, flag)) == p.parent:
            return f"--{flag.replace('_', '-')} file"
    return "output"


def add_args(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="source", metavar="SOURCE", parser_class=type(parser))
    sub.required = True
    p = sub.add_parser("osim", help="OpenSim 4 model (.osim) with optional motion (.mot/.sto) and controls (.sto)",
                       description="Import an OpenSim model: skeleton, muscles, bone meshes, and a pose from a motion.")
    _add_source(p, "MODEL.osim")
    p.add_argument("--motion", type=Path, metavar="FILE", help="coordinates over time (.mot/.sto) → a pose")
    p.add_argument("--controls", type=Path, metavar="FILE", help="muscle excitations (.sto) → the pose's activation")
    _add_model_outputs(p)
    p.add_argument("--fps", type=float, help="resample the motion at this frame rate (default: its own)")
    _add_model_options(p)
    add_overwrite_arg(p)

    j = sub.add_parser("mjcf", help="MuJoCo model (MJCF .xml) with an optional qpos motion (.npz)",
                       description="Import a MuJoCo model: skeleton (bodies, joints, couplings), muscles on spatial "
                                   "tendons, bone meshes, and a pose from a qpos motion.")
    _add_source(j, "MODEL.xml")
    j.add_argument("--motion", type=Path, metavar="QPOS.npz",
                   help="npz with qpos (frames x nq, the model's order) and optional fps → a pose")
    _add_model_outputs(j)
    j.add_argument("--fps", type=float, help="frame rate of the motion (default: its fps, else 30)")
    _add_model_options(j, decimate=True)
    add_overwrite_arg(j)

    b = sub.add_parser("bvh", help="Biovision motion capture (.bvh) → skeleton and pose",
                       description="Import a BVH file: a skeleton (Z-up, metres) and a pose of its motion.")
    _add_source(b, "FILE.bvh")
    b.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder (default place of both files)")
    add_units_args(b, "metres per file unit: a number, or a unit name (default: from the body's height, "
                      "as --units)")
    b.add_argument("--step", type=int, default=1, metavar="N", help="keep every N-th motion row (fps / N)")
    b.add_argument("--name", help="skeleton name (default: the file's name)")
    b.add_argument("--skeleton-out", type=Path, metavar="FILE", help="skeleton YAML (default DIR/skeletons/NAME.yaml)")
    b.add_argument("--pose-out", type=Path, metavar="FILE", help="pose YAML (default DIR/POSE.yaml)")
    b.add_argument("--pose-name", help="pose name (default: the skeleton's name)")
    add_overwrite_arg(b)


def _add_source(p, metavar: str) -> None:
    """``-q``/``-v`` (also accepted after the source: ``axdf import osim -q ...``) and the source file."""
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="print only errors")
    g.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="print more detail")
    p.add_argument("model", metavar=metavar, type=Path)


def _add_model_outputs(p) -> None:
    """Where a muscle model's import writes (``osim``, ``mjcf``)."""
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="output folder (report; default place of every other file)")
    p.add_argument("--name", help="skeleton name (default: the model's name)")
    p.add_argument("--skeleton-out", type=Path, metavar="FILE", help="skeleton YAML (default DIR/skeletons/NAME.yaml)")
    p.add_argument("--meshes-out", type=Path, metavar="DIR",
                   help="bone meshes folder (default: meshes/NAME beside the skeleton)")
    p.add_argument("--muscles-out", type=Path, metavar="DIR", help="muscle YAML folder (default DIR/muscles)")
    p.add_argument("--pose-out", type=Path, metavar="FILE", help="pose YAML (default DIR/MOTION.yaml)")
    p.add_argument("--pose-name", help="pose name (default: the motion file's name)")


def _add_model_options(p, decimate: bool = False) -> None:
    """Bone meshes and colours of a muscle model's import (``osim``, ``mjcf``)."""
    p.add_argument("--no-meshes", action="store_true", help="do not convert bone geometry")
    if decimate:
        p.add_argument("--max-faces", type=int, default=0, metavar="N",
                       help="decimate each bone mesh to at most N triangles (default 0: keep all)")
        p.add_argument("--mesh-edge", type=float, default=0.0, metavar="M",
                       help="decimate each bone mesh to triangles of about this edge length in metres (default 0: off)")
    p.add_argument("--palette", choices=("anatomical", "hashed"), default="anatomical",
                   help="muscle colours: muscle reds varied per muscle (default), or any hue from the name's hash")
    p.add_argument("--volumes", choices=("pcsa", "handsfield"), default="pcsa",
                   help="belly volumes: PCSA x optimal fibre length from the model's numbers (default), or the lower "
                        "limb muscles by the regression of Handsfield et al. 2014 on the subject's --height and "
                        "--mass (docs/IMPORTERS.md, 'Belly volumes')")
    p.add_argument("--height", type=float, metavar="M", help="the subject's height in metres (--volumes handsfield)")
    p.add_argument("--mass", type=float, metavar="KG", help="the subject's body mass in kg (--volumes handsfield)")


def _volume_settings(args) -> dict:
    """The manifest's record of a regression import (nothing with the default law, so the
    manifests of PCSA imports stay as they were)."""
    return {} if args.volumes == "pcsa" else {"volumes": args.volumes, "height": args.height, "mass": args.mass}


def subject_of(args):
    """The subject ``--volumes handsfield`` sizes muscles for (None with ``--volumes pcsa``);
    --height and --mass are needed by it and refused without it."""
    from axdf_cli.errors import UsageError
    from axdf_cli.importers.volumes import HEIGHT_RANGE, MASS_RANGE, Subject

    if args.volumes != "handsfield":
        for flag in ("height", "mass"):
            if getattr(args, flag) is not None:
                raise UsageError(f"--{flag} without --volumes handsfield",
                                 "--volumes handsfield --height M --mass KG (the subject the regression sizes)")
        return None
    for flag, unit, (lo, hi) in (("height", "m", HEIGHT_RANGE), ("mass", "kg", MASS_RANGE)):
        v = getattr(args, flag)
        if v is None:
            raise UsageError(f"--volumes handsfield without --{flag}",
                             f"the subject's {flag} in {unit} ({lo:g}..{hi:g}): e.g. --height 1.80 --mass 75")
        if not lo <= v <= hi:
            raise UsageError(f"--{flag} {v:g}", f"a {flag} in {unit} in [{lo:g}, {hi:g}]")
    return Subject(args.height, args.mass)


def add_units_args(p, scale_help: str) -> None:
    """``--units`` and ``--scale`` of ``import bvh`` and ``retarget`` (one or the other)."""
    from axdf_cli.importers.bvh import UNITS

    g = p.add_mutually_exclusive_group()
    g.add_argument("--units", choices=tuple(UNITS),
                   help="the motion's length unit (cmu: the CMU database's BVH conversions, 1/0.45 inch; "
                        "default for a BVH: the unit that makes a 1.4-2.1 m person, printed)")
    g.add_argument("--scale", metavar="S", help=scale_help)


def parse_scale_step(args):
    """``--units`` or ``--scale`` (metres per unit, a number or a unit name; None: from the
    body's height) and ``--step`` of ``import bvh`` and ``retarget``, checked: the scale, or a
    usage error (exit 2)."""
    from axdf_cli.errors import UsageError
    from axdf_cli.importers.bvh import UNITS

    scale = None
    if getattr(args, "units", None) is not None:
        scale = UNITS[args.units]
    elif args.scale is not None:
        try:
            scale = UNITS[args.scale] if args.scale in UNITS else float(args.scale)
        except ValueError:
            scale = float("nan")
        if not (0 < scale < 1e6):
            raise UsageError(f"--scale {args.scale}", f"a positive number of metres per unit, or one of {', '.join(UNITS)}")
    if not 1 <= args.step <= 10000:
        raise UsageError(f"--step {args.step}", "a whole number in 1..10000")
    return scale


def write_imported(files: OutputSet, inputs, overwrite: bool, source, tick=lambda step: None, assets=()) -> dict:
    """What every importer does with its files (``import osim|bvh|mjcf``, ``retarget``): the
    output rule's checks (axdf_cli/fileio/outputs.py), then every YAML file read back by the
    file specs (what ``axdf validate`` accepts; errors name ``source``), then the write.
    Nothing is written unless all of it passes. ``inputs`` (listed in the manifest) and
    ``assets`` (not listed) are never outputs. ``tick(step)``: the progress bar."""
    checked = check_outputs(files, inputs=inputs, overwrite=overwrite, assets=assets)
    check_documents(files, Mark(str(source)))
    tick("check")
    manifest = write_checked(checked)
    tick("write")
    return manifest


def add_overwrite_arg(p) -> None:
    """``--overwrite``, as every command that writes a set of files has it (fileio/outputs.py)."""
    p.add_argument("--overwrite", action="store_true",
                   help="replace this command's earlier output in DIR (and files outside DIR that it wrote, "
                        "unchanged since); nothing else is ever replaced")


def progress_bar(steps, quiet: bool, desc: str):
    """(tick(step), close()) for a tqdm bar over ``steps`` on stderr; silent when stderr is
    not a terminal or with -q."""
    bar = progress.bar(quiet, "step", total=len(steps), desc=desc, leave=False)
    return (bar.tick, bar.close) if bar is not None else ((lambda step: None), (lambda: None))


def run(args) -> int:
    if args.source == "bvh":
        return run_bvh(args)
    if args.source == "mjcf":
        return run_mjcf(args)
    from axdf_cli.errors import UsageError
    from axdf_cli.importers.emit import build_import
    from axdf_cli.importers.osim_import import read_import

    if args.fps is not None and not (0 < args.fps <= 10000):
        raise UsageError(f"--fps {args.fps}", "a frame rate in (0, 10000]")
    subject = subject_of(args)
    tick, close = progress_bar(("read", "check", "write"), args.quiet, f"import {args.model.name}")
    try:
        model = read_import(args.model, name=args.name, motion=args.motion, controls=args.controls,
                            pose_name=args.pose_name, fps=args.fps, meshes=not args.no_meshes)
        res = build_import(model, _outputs(args), args.palette, subject=subject)
        tick("read")
        files = OutputSet(args.out, "import osim")
        for path, data in res.files.items():
            files.add(path, data, output_role(path, args))
        files.settings = {"name": args.name, "fps": args.fps, "pose_name": args.pose_name,
                          "meshes": not args.no_meshes, "palette": args.palette, **_volume_settings(args)}
        write_imported(files, res.inputs, args.overwrite, args.model, tick)
    finally:
        close()
    c = res.report["counts"]
    _print_summary(args, res, f"{c['bodies']} bodies, {c['coordinates']} coordinates, {c['muscles']} muscles, "
                              f"{c['meshes']} bone meshes")
    return 0


def _print_summary(args, res, counts: str) -> None:
    """What a muscle model's import (``osim``, ``mjcf``) says when done: its warnings (stderr),
    then unless ``-q`` what it imported, what it left out by kind (``not imported: 2 markers,
    ...``), the meshes it could not find, with ``-v`` every file, and where its report is."""
    for w in res.warnings:
        print(f"axdf: warning: {w}", file=sys.stderr)
    if args.quiet:
        return
    print(f"imported {args.model.name}: {counts}")
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
    if res.report.get("counts", {}).get("muscles", 0) > 1 and res.layout:
        from axdf_cli.pipeline.overlap import pack_command_line

        lay = res.layout
        print(f"next: {pack_command_line([lay['muscles']], lay['skeleton'], lay['pose'])}  (imported muscles "
              "overlap in bulk, more than contact clears: packing makes their rest shapes share space; docs/CONTACT.md)")


def run_mjcf(args) -> int:
    from axdf_cli.errors import UsageError
    from axdf_cli.importers.emit import build_import
    from axdf_cli.importers.mjcf_import import read_import

    if args.fps is not None and not (0 < args.fps <= 10000):
        raise UsageError(f"--fps {args.fps}", "a frame rate in (0, 10000]")
    if not 0 <= args.max_faces <= 10_000_000:
        raise UsageError(f"--max-faces {args.max_faces}", "a whole number in 0..10000000 (0: keep every triangle)")
    if not 0 <= args.mesh_edge <= 1:
        raise UsageError(f"--mesh-edge {args.mesh_edge}", "metres in [0, 1] (0: off)")
    subject = subject_of(args)
    tick, close = progress_bar(("read", "check", "write"), args.quiet, f"import {args.model.name}")
    try:
        model = read_import(args.model, name=args.name, motion=args.motion, pose_name=args.pose_name, fps=args.fps,
                            meshes=not args.no_meshes, max_faces=args.max_faces, mesh_edge=args.mesh_edge)
        res = build_import(model, _outputs(args), args.palette, subject=subject)
        tick("read")
        files = OutputSet(args.out, "import mjcf")
        for path, data in res.files.items():
            files.add(path, data, output_role(path, args))
        files.settings = {"name": args.name, "fps": args.fps, "pose_name": args.pose_name,
                          "meshes": not args.no_meshes, "max_faces": args.max_faces, "mesh_edge": args.mesh_edge,
                          "palette": args.palette, **_volume_settings(args)}
        write_imported(files, res.inputs, args.overwrite, args.model, tick, assets=res.assets)
    finally:
        close()
    c = res.report["counts"]
    _print_summary(args, res, f"{c['bodies']} bodies, {c['coordinates']} coordinates ({c['couplings']} coupled "
                              f"joints), {c['muscles']} muscles, {c['meshes']} bone meshes")
    return 0


def _outputs(args):
    """Where an import writes: ``--out`` and the flags that move its parts."""
    from axdf_cli.importers.model import Outputs

    return Outputs(args.out, args.skeleton_out, getattr(args, "muscles_out", None), args.pose_out,
                   getattr(args, "meshes_out", None))


class _Adding(dict):
    """A file mapping that adds each file to an :class:`OutputSet` as it comes, under the next
    of ``roles`` (the set refuses a path twice, naming both roles)."""

    def __init__(self, files: OutputSet, roles):
        super().__init__()
        self.files, self.roles = files, roles

    def __setitem__(self, path, data) -> None:
        self.files.add(path, data, next(self.roles))
        super().__setitem__(path, data)


def run_bvh(args) -> int:
    from axdf_cli.importers.bvh import STEPS, read_import
    from axdf_cli.importers.emit import build_import

    scale = parse_scale_step(args)

    tick, close = progress_bar(STEPS + ("check", "write"), args.quiet, f"import {args.model.name}")
    try:
        model = read_import(args.model, name=args.name, scale=scale, step=args.step, pose_name=args.pose_name)
        tick("read")
        files = OutputSet(args.out, "import bvh")
        roles = iter(("--skeleton-out" if args.skeleton_out else "the skeleton",
                      "--pose-out" if args.pose_out else "the pose"))
        res = build_import(model, _outputs(args), files=_Adding(files, roles))
        tick("skeleton")
        tick("pose")
        files.settings = {"scale": model.report["scale"], "units": args.units, "step": args.step, "name": model.name,
                          "pose_name": model.motion.name}
        write_imported(files, [args.model], args.overwrite, args.model, tick)
    finally:
        close()
    for w in model.report.get("unit_warnings", ()):
        print(f"axdf: warning: {w}", file=sys.stderr)
    if not args.quiet:
        r = res.report
        for line in res.warnings:
            print(line)
        print(f"imported {args.model.name}: {r['joints']} joints, {r['end_sites']} end sites, {r['channels']} channels, "
              f"{r['frames']} frames at {r['fps']:g} fps")
        for o in files:
            print(o.path if not o.path.is_relative_to(Path.cwd()) else o.path.relative_to(Path.cwd()))
    return 0
