"""Build data sets: many sequences, seeded sampling, several views, labels and one index."""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from axdf_cli.cli import progress
from axdf_cli.cli.run import positive
from axdf_cli.errors import UsageError
from axdf_cli.tolerances import MAX_SEED

_SHARD_RE = re.compile(r"(\d+)/(\d+)")  # (fullmatch)


def add_args(p) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", parser_class=type(p))
    sub.required = True
    b = sub.add_parser("build", help="make the data set's sequences (this shard's), then the index",
                       description="Make a data set from a dataset file (docs/FORMATS.md, Data sets).")
    b.add_argument("dataset", metavar="DATASET.yaml", help="dataset file")
    b.add_argument("--out", metavar="DIR", help="output folder (default out/<dataset name>)")
    b.add_argument("--seed", type=int, metavar="N", help="override the file's seed")
    b.add_argument("--jobs", type=positive, default=1, metavar="N",
                   help="worker processes (meshes and rendering); Ray CPUs for a local Ray (default 1)")
    b.add_argument("--shard", metavar="K/N", default="0/1",
                   help="make only sequences with index %% N == K (a SLURM array: $SLURM_ARRAY_TASK_ID/N)")
    b.add_argument("--engine", choices=("local", "ray"), default="local",
                   help="local process pool (default) or a Ray cluster")
    b.add_argument("--address", metavar="ADDR",
                   help="Ray cluster address for ray.init (default: start a local Ray with --jobs CPUs)")
    g = b.add_mutually_exclusive_group()
    g.add_argument("--resume", action="store_true", help="keep complete sequences, finish the others")
    g.add_argument("--overwrite", action="store_true", help="make this run's sequences again")
    b.add_argument("--dry-run", action="store_true", help="check the inputs, print what would be made; write nothing")
    b.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    m = sub.add_parser("merge", help="join the shards' sequences into OUT/index.parquet",
                       description="Write OUT/index.parquet once every shard is done.")
    m.add_argument("out", metavar="OUT", help="the data set's folder")
    for sp in (b, m):  # -q/-v after the action too (SUPPRESS: never override the parent's value)
        gq = sp.add_mutually_exclusive_group()
        gq.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS, help="print only errors")
        gq.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS, help="print more detail")


def parse_shard(text: str) -> tuple[int, int]:
    from axdf_cli.dataset.spec import MAX_SHARDS

    m = _SHARD_RE.fullmatch(text or "")
    if not m or not (1 <= int(m.group(2)) <= MAX_SHARDS and 0 <= int(m.group(1)) < int(m.group(2))):
        raise UsageError(f"--shard {text!r}", f"K/N with 0 <= K < N <= {MAX_SHARDS}, e.g. --shard 3/16")
    return int(m.group(1)), int(m.group(2))


def run(args) -> int:
    if args.action == "merge":
        from axdf_cli.dataset.engine import merge

        idx, rows = merge(Path(args.out))
        if not args.quiet:
            print(f"wrote {idx} ({rows} samples)")
        return 0
    return _build(args)


def _build(args) -> int:
    from axdf_cli.dataset import engine
    from axdf_cli.dataset.worker import build_context
    from axdf_cli.specs import RefPolicy

    shard = parse_shard(args.shard)
    if args.seed is not None and not 0 <= args.seed <= MAX_SEED:
        raise UsageError(f"--seed {args.seed}", f"a whole number in 0..{MAX_SEED} (as a dataset file's seed:)")
    policy = RefPolicy.for_command([args.dataset], args.allow_outside)
    if args.dry_run:
        return _dry_run(args, shard, policy)
    ctx = build_context(args.dataset, args.seed, policy)
    warn_ranges(ctx, args.quiet)
    out = Path(args.out or f"out/{ctx.spec.name}")
    mine = [s for s in ctx.sequences if s.index % shard[1] == shard[0]]
    views = len(ctx.spec.views)
    total = sum(s.n_frames for s in mine) * views
    bar = progress.bar(args.quiet, "sample", total=total, desc=ctx.spec.name, smoothing=0.05)
    try:
        res = engine.build(args.dataset, out, seed=args.seed, jobs=args.jobs, shard=shard, engine=args.engine,
                           address=args.address, resume=args.resume, overwrite=args.overwrite,
                           progress=bar.update if bar else None, ctx=ctx)
    finally:
        if bar:
            bar.close()
    bulk = bulk_warning(res, ctx)
    if bulk:  # (even with -q, as axdf run's)
        print(f"warning: {bulk}", file=sys.stderr)
    if not args.quiet:
        print(summary_text(res, shard))
    return 0


def warn_ranges(ctx, quiet: bool, fit: bool = True) -> None:
    """A warning per named motion that poses the data set's muscles outside a coordinate's
    range (as ``axdf run`` warns a run: every muscle the coordinate moves, path muscles too),
    and a retargeted take's fit warnings (as ``axdf retarget`` prints them); with ``fit`` False
    (a dry run, which does not fit takes) a take is left to the build."""
    from axdf_cli.dataset.spec import fit_warnings, load_motion, motion_frames
    from axdf_cli.model.pose import muscle_range_warnings

    if quiet:
        return
    for name, m in ctx.spec.motions.items():
        if not fit and m.kind == "retarget":
            continue
        for w in fit_warnings(ctx.spec, name):  # a retargeted take's, as axdf retarget prints them
            print(f"warning: motion {name} ({m.path}): {w}", file=sys.stderr)
        warns = muscle_range_warnings(load_motion(ctx.spec, name), motion_frames(ctx.spec, name), ctx.muscles)
        if warns:
            fi, j, msg = warns[0]
            frame = int(motion_frames(ctx.spec, name)[fi])
            print(f"warning: motion {name} ({m.path}): {len(warns)} muscle-frame(s) posed outside a coordinate "
                  f"range, first frame {frame} ({ctx.muscles[j].name}): "
                  f"{msg.replace(' (--clamp-ranges holds it inside)', '')}", file=sys.stderr)


def bulk_warning(res, ctx) -> str | None:
    """The build's one warning when the data set's muscles overlap in bulk after contact over
    the frames made now (as ``axdf run`` tells a run, each sequence's manifest its own), with
    the ``axdf pack`` command for its muscle folders and skeleton (at the rest pose: a data
    set's poses are sampled); None otherwise."""
    from axdf_cli.pipeline.overlap import bulk_overlap_text, pack_command_line

    text = bulk_overlap_text(res.overlap, f"the {res.overlap_frames} frame(s) made")
    if text is None:
        return None
    folders = [Path(m.source).parent for m in ctx.muscles if m.source]
    return (f"{text}; {res.overlap_bulk} of {res.built} sequence(s) made say so in their manifests: "
            f"{pack_command_line(folders, ctx.spec.skeleton_path, None)}")


def _dry_run(args, shard, policy) -> int:
    """Check every input and what OUT holds; print what would be made (counted, not listed:
    bounded memory and time for any number of sequences) and its size: samples, frames, bytes
    and time, both estimated from small sequences made and timed in a temporary folder
    (removed after; :func:`~axdf_cli.dataset.engine.probe`). Motion-capture takes are read, not fitted (the build fits them: a minute
    or more a take), so their fit's warnings come with the build. Writes nothing in OUT."""
    from axdf_cli.dataset.engine import probe
    from axdf_cli.dataset.folder import check_dry
    from axdf_cli.dataset.spec import count
    from axdf_cli.dataset.worker import build_context

    ctx = build_context(args.dataset, args.seed, policy, listed=False, fit=False)
    warn_ranges(ctx, args.quiet, fit=False)
    out = Path(args.out or f"out/{ctx.spec.name}")
    check_dry(out, resume=args.resume, overwrite=args.overwrite)
    if args.engine == "ray":
        from axdf_cli.dataset.raycluster import check_address, import_ray

        import_ray()
        check_address(args.address)
    n_all, n_mine, frames = count(ctx.spec, shard, fit=False)
    views = len(ctx.spec.views)
    samples = frames * views
    takes = [n for n, m in ctx.spec.motions.items() if m.kind == "retarget"]
    print(f"would make {n_mine} of {n_all} sequences ({frames} frames x {views} view(s) = {samples} samples) "
          f"in {out}, {len(ctx.muscles)} muscles, {ctx.spec.format} meshes, "
          f"{'+'.join(ctx.spec.passes)} images {ctx.spec.render.size[0]}x{ctx.spec.render.size[1]}")
    if takes and not args.quiet:
        print(f"motion capture fitted by the build, not now: {', '.join(takes)} (its fit's warnings come then; "
              "axdf retarget shows them alone)")
    p = probe(ctx, args.dataset)
    jobs = max(1, args.jobs)
    seconds = (n_mine * p.per_sequence + samples * p.per_sample) / min(jobs, max(1, n_mine))
    print(f"size: about {_bytes(samples * p.bytes_per_sample)} and {_duration(seconds)} with --jobs {jobs}"
          + (f" (plus fitting {len(takes)} take(s))" if takes else "")
          + f"; estimated from sequences made now: {p.per_sequence:.2f} s a sequence and {p.per_sample:.2f} s and "
          f"{_bytes(p.bytes_per_sample)} a sample (run {p.timing['run'] / max(1, p.samples):.2f} s, "
          f"render {p.timing['render'] / max(1, p.samples):.2f} s a sample at {p.samples} samples)")
    return 0


def _bytes(n: float) -> str:
    for unit, k in (("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if n >= k:
            return f"{n / k:.1f} {unit}"
    return f"{n:.0f} B"


def _duration(s: float) -> str:
    if s >= 3600:
        return f"{s / 3600:.1f} h"
    if s >= 60:
        return f"{s / 60:.0f} min"
    return f"{s:.0f} s"


def summary_text(res, shard) -> str:
    """The closing summary: what was made, how fast, where the time went, the index."""
    made = res.built
    lines = [f"{res.sequences} sequence(s), {res.samples} samples in {res.out}: {made} made, "
             f"{res.skipped} already complete, {res.seconds:.1f} s"
             + (f" ({res.built_samples / res.seconds:.2f} samples/s)" if res.seconds > 0 and made else "")]
    if made:
        t = res.timing
        per = 1000.0 / max(1, res.built_samples)
        lines.append(f"per sample (summed over workers): run (evaluate + write meshes) {t['run'] * per:.0f} ms, "
                     f"read meshes back {t['read'] * per:.0f} ms, render {t['render'] * per:.0f} ms, "
                     f"labels + write images {t['write'] * per:.0f} ms"
                     + (f"; {res.gl_renderer}" if res.gl_renderer else ""))
    if res.index is not None:
        lines.append(f"index: {res.index} ({res.rows} samples)")
    else:
        lines.append(f"shard {shard[0]}/{shard[1]} done; {len(res.missing)} sequence(s) of the data set still to make; "
                     f"when every shard is done: axdf dataset merge {res.out}")
    return "\n".join(lines)
