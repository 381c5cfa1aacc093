"""Evaluate muscles over a pose; write meshes, stats.csv, bones.csv and manifest.json (and frames)."""
from __future__ import annotations

import sys

from axdf_cli.cli import progress
from axdf_cli.formats import FORMATS, MESH_FILES
from axdf_cli.specs import RefPolicy, load_job


def add_args(p) -> None:
    p.add_argument("job", nargs="?", help="job YAML (muscles, pose, out, format, mesh_files, frames, render)")
    p.add_argument("--muscles", nargs="+", metavar="PATH", help="muscle files, folders or globs (override the job)")
    p.add_argument("--pose", metavar="FILE", help="pose YAML (overrides the job)")
    p.add_argument("--out", metavar="DIR", help="output folder (default: the job's out, else out/run)")
    p.add_argument("--format", action="append", metavar="FMT",
                   help="mesh format(s): " + ", ".join(FORMATS) + " (ply, obj: a file per frame; the others a file "
                        "per muscle); several as ply,usd or repeated (default ply)")
    p.add_argument("--mesh-files", choices=MESH_FILES, default=None,
                   help="ply and obj files: one per muscle per frame (muscle, the default) or one per frame "
                        "holding every muscle as a named part (frame: meshes/<frame>.obj|ply); overrides the "
                        "job's mesh_files")
    p.add_argument("--frames", metavar="SPEC", help="frames to write: 0:48, 0:48:2, 3,7,10:12 (ends inclusive)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--render", dest="render", action="store_true", default=None, help="render preview frames")
    g.add_argument("--no-render", dest="render", action="store_false", help="do not render")
    p.add_argument("--jobs", type=positive, default=1, metavar="N",
                   help="worker processes for the mesh pass and the rendering (default 1; same output bytes)")
    g2 = p.add_mutually_exclusive_group()
    g2.add_argument("--resume", action="store_true", help="finish an interrupted run in OUT, skipping finished files")
    g2.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in OUT")
    p.add_argument("--dry-run", action="store_true", help="check inputs and print what would be written; write nothing")
    p.add_argument("--strict", action="store_true", help="fail (exit 2) on any per-muscle, per-frame warning")
    p.add_argument("--clamp-ranges", action="store_true",
                   help="hold coordinates inside their skeleton ranges (default: warn per frame)")
    p.add_argument("--skin", metavar="FILE",
                   help="wear this skin (a skin file written by axdf skin, docs/SKIN.md) over the muscles: "
                        "meshes/skin/ and skin.csv (overrides the job's skin)")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    add_stage_args(p)
    from axdf_cli.specs.render import add_render_args

    add_render_args(p)


def add_stage_args(p) -> None:
    """``--<stage>`` / ``--no-<stage>`` for every stage of the table
    (:data:`axdf_cli.pipeline.stages.STAGES`); neither: the job's word, else the stage's default."""
    import argparse

    from axdf_cli.pipeline.stages import stage_default, switched

    for name in switched():
        p.add_argument(f"--{name}", dest=f"stage_{name}", action=argparse.BooleanOptionalAction, default=None,
                       help=f"run the {name} stage, or leave it out (default: the job's {name}: key, else "
                            f"{'on' if stage_default(name) else 'off'})")


def stage_switches(args) -> dict:
    """The stages switched on or off on the command line: name -> bool."""
    from axdf_cli.pipeline.stages import switched

    return {name: v for name in switched() if (v := getattr(args, f"stage_{name}", None)) is not None}


def positive(text: str) -> int:
    import argparse

    try:
        n = int(text)
    except ValueError:
        n = 0
    if not 1 <= n <= 256:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of processes in 1..256")
    return n


def run(args) -> int:
    from axdf_cli import pipeline

    plan = plan_from_args(args)
    if args.verbose:
        for n in plan.notes:
            print(f"note: {n}", file=sys.stderr)
    for w in plan.warnings:
        print(f"warning: {w}", file=sys.stderr)
    if not args.quiet:  # a line per coordinate outside its range (stats.csv: per muscle and frame)
        for o in plan.outside:
            print(f"{'note' if o.clamped else 'warning'}: {o.text(len(plan.frames))}", file=sys.stderr)
    if args.strict:
        refuse_warnings(plan)
    total = len(plan.frames) * len(plan.models)
    if args.dry_run:
        pipeline.check_output(plan, resume=args.resume, overwrite=args.overwrite)
        what = f"{total} meshes" if plan.mesh_files == "muscle" else \
            f"{len(plan.frames)} mesh files per format, each with every muscle"
        print(f"would write {what} ({len(plan.models)} muscles x {len(plan.frames)} frames, "
              f"{plan.fmt}) to {plan.out}, plus stats.csv, bones.csv, manifest.json")
        for s, m in zip(plan.muscles, plan.models):
            print(f"  {s.name}: {m.n_vertices} vertices, {len(m.faces)} faces, rest length {m.l0:.4f} m, "
                  f"rest volume {m.v0 * 1e6:.2f} cm^3")
        return 0
    bar = progress.bar(args.quiet, "mesh", total=total, desc="meshes")
    rbar = progress.bar(args.quiet, "frame", total=len(plan.frames), desc="frames") if plan.rendering else None
    try:
        summary = pipeline.execute(plan, resume=args.resume, overwrite=args.overwrite,
                                 progress=bar.update if bar else None, strict=args.strict, jobs=args.jobs,
                                 render_progress=(lambda _f: rbar.update()) if rbar else None,
                                 on_note=lambda text: print(f"note: {text}", file=sys.stderr))
    finally:
        for b in (bar, rbar):
            if b:
                b.close()
    for w in summary.get("run_warnings", ()):
        print(f"warning: {w}", file=sys.stderr)
    if not args.quiet:
        print(f"wrote {summary['files']} files ({summary['muscles']} muscles x {summary['frames']} frames) "
              f"to {summary['out']}" + (f", {summary['skipped']} already complete" if summary["skipped"] else ""))
        print(f"worst volume error {summary['worst_volume_error'] * 100:.3f}%")
        n = len(summary["warnings"]) - len(plan.warnings) - len(summary.get("run_warnings", ()))
        if n > 0:
            print(f"{n} warning(s): see {summary['out']}/stats.csv", file=sys.stderr)
    return 0


def plan_from_args(args):
    """The run's plan from the command line, exactly as ``axdf run`` makes it (``axdf validate``
    calls it too). Files named on the command line, and their folders, are trusted roots."""
    from dataclasses import replace

    from axdf_cli import pipeline
    from axdf_cli.specs.render import check_pinned, settings_from_args

    policy = RefPolicy.for_command([args.job, args.pose, getattr(args, "skin", None)] + list(args.muscles or []),
                                   args.allow_outside)
    job = load_job(args.job, policy) if args.job else None
    settings = pipeline.job_render_settings(job)
    if args.render is not None:
        settings = replace(settings, enabled=args.render)
    plan = pipeline.plan_run(job, muscle_args=args.muscles, pose_arg=args.pose, out_arg=args.out,
                           fmt_arg=args.format, frames_arg=args.frames, render=settings_from_args(settings, args),
                           policy=policy, clamp_ranges=args.clamp_ranges or (job is not None and job.clamp_ranges),
                           stages={**job_switches(job), **stage_switches(args)},
                           mesh_files_arg=getattr(args, "mesh_files", None), skin_arg=getattr(args, "skin", None))
    if plan.render is not None:
        check_pinned(plan.render, plan.frames)
    return plan


def job_switches(job) -> dict:
    """The stages a job switches on or off (``jiggle: false``): name -> bool."""
    return {} if job is None else dict(job.stages)


def refuse_warnings(plan) -> None:
    """``--strict``: warnings known before evaluation (misspelt activation names, coordinates
    outside their ranges) are refused before anything is written."""
    from axdf_cli.errors import InputError

    found = list(plan.warnings) + [f"{plan.names[j]} frame {int(plan.frames[i])}: {msg}"
                                   for i, j, msg in plan.frame_warnings]
    if found:
        raise InputError(None, f"{len(found)} warning(s) with --strict; first: {found[0]}",
                         "fix the inputs or run without --strict")
