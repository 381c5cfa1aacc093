"""Evaluate muscles over a pose; write meshes, stats.csv, bones.csv and manifest.json (and frames)."""
from __future__ import annotations

import sys
from pathlib import Path

from axdf_cli.formats import WRITERS
from axdf_cli.loaders import load_job, set_ref_policy


def add_args(p) -> None:
    p.add_argument("job", nargs="?", help="job YAML (muscles, pose, out, format, frames, render)")
    p.add_argument("--muscles", nargs="+", metavar="PATH", help="muscle files, folders or globs (override the job)")
    p.add_argument("--pose", metavar="FILE", help="pose YAML (overrides the job)")
    p.add_argument("--out", metavar="DIR", help="output folder (default: the job's out, else out/run)")
    p.add_argument("--format", choices=sorted(WRITERS), help="mesh format (default ply)")
    p.add_argument("--frames", metavar="SPEC", help="frames to write: 0:48, 0:48:2, 3,7,10:12 (ends inclusive)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--render", dest="render", action="store_true", default=None, help="render preview frames")
    g.add_argument("--no-render", dest="render", action="store_false", help="do not render")
    p.add_argument("--jobs", type=_positive, default=1, metavar="N",
                   help="worker processes for the mesh pass (default 1; same output bytes)")
    g2 = p.add_mutually_exclusive_group()
    g2.add_argument("--resume", action="store_true", help="finish an interrupted run in OUT, skipping finished files")
    g2.add_argument("--overwrite", action="store_true", help="replace the outputs of an earlier run in OUT")
    p.add_argument("--dry-run", action="store_true", help="check inputs and print what would be written; write nothing")
    p.add_argument("--strict", action="store_true", help="fail (exit 2) on any per-muscle, per-frame warning")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    from axdf_cli.render.settings import add_render_args

    add_render_args(p)


def _positive(text: str) -> int:
    import argparse

    try:
        n = int(text)
    except ValueError:
        n = 0
    if not 1 <= n <= 256:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number of processes in 1..256")
    return n


def run(args) -> int:
    from axdf_cli import run as runner
    from axdf_cli.yamlio import real_path

    roots = [Path.cwd()] + ([real_path(args.job).parent] if args.job else [])
    set_ref_policy(roots, args.allow_outside)
    job = load_job(args.job) if args.job else None
    from dataclasses import replace

    from axdf_cli.render.settings import settings_from_args

    settings = runner.job_render_settings(job)
    if args.render is not None:
        settings = replace(settings, enabled=args.render)
    plan = runner.plan_run(job, muscle_args=args.muscles, pose_arg=args.pose, out_arg=args.out,
                           fmt_arg=args.format, frames_arg=args.frames, render=settings_from_args(settings, args))
    if args.verbose:
        for n in plan.notes:
            print(f"note: {n}", file=sys.stderr)
    for w in plan.warnings:
        print(f"warning: {w}", file=sys.stderr)
    total = len(plan.frames) * len(plan.models)
    if args.dry_run:
        runner.check_output(plan, resume=args.resume, overwrite=args.overwrite)
        print(f"would write {total} meshes ({len(plan.models)} muscles x {len(plan.frames)} frames, "
              f"{plan.fmt}) to {plan.out}/meshes, plus stats.csv, bones.csv, manifest.json")
        for s, m in zip(plan.muscles, plan.models):
            print(f"  {s.name}: {m.n_vertices} vertices, {len(m.faces)} faces, rest length {m.l0:.4f} m, "
                  f"rest volume {m.v0 * 1e6:.2f} cm^3")
        return 0
    bar = rbar = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm

        bar = tqdm(total=total, unit="mesh", file=sys.stderr, desc="meshes")
        if plan.rendering:
            rbar = tqdm(total=len(plan.frames), unit="frame", file=sys.stderr, desc="frames")
    try:
        summary = runner.execute(plan, resume=args.resume, overwrite=args.overwrite,
                                 progress=bar.update if bar else None, strict=args.strict, jobs=args.jobs,
                                 render_progress=(lambda _f: rbar.update(1)) if rbar else None,
                                 on_note=lambda text: print(f"note: {text}", file=sys.stderr))
    finally:
        for b in (bar, rbar):
            if b:
                b.close()
    if not args.quiet:
        print(f"wrote {summary['files']} files ({summary['muscles']} muscles x {summary['frames']} frames) "
              f"to {summary['out']}" + (f", {summary['skipped']} already complete" if summary["skipped"] else ""))
        print(f"worst volume error {summary['worst_volume_error'] * 100:.3f}%")
        if summary["warnings"]:
            print(f"{len(summary['warnings'])} warning(s): see {summary['out']}/stats.csv", file=sys.stderr)
    return 0
