"""Compare a run (or one file) with a golden one: exit 0 same, 1 different, 2 bad usage.

Meshes by vertex distance with exact topology, images (PNG, EXR) by a per-pixel tolerance,
an allowed fraction of failing pixels and a hard maximum, CSV/JSON numerically, the
manifest's inputs and settings as likely causes, anything else byte for byte. Tolerances
and their reasons: docs/COMPARE.md.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from axdf_cli.cli import progress
from axdf_cli.fileio.atomic import write_bytes, write_text
from axdf_cli.errors import UsageError


def add_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("actual", metavar="ACTUAL", help="the run folder (or file) to check")
    p.add_argument("golden", metavar="GOLDEN", help="the golden run folder (or file)")
    p.add_argument("--report", metavar="FILE.json", help="write every file's metrics and verdict as JSON")
    p.add_argument("--junit", metavar="FILE.xml", help="write JUnit XML, one test case per file")
    p.add_argument("--diff-dir", metavar="DIR",
                   help="where to write actual|golden|heat-map PNGs of failing images "
                        "(default: REPORT-diffs/ beside --report, else beside --junit, else none)")
    p.add_argument("--update", action="store_true",
                   help="bless: copy ACTUAL over GOLDEN (add, replace, remove files) and list each change")
    p.add_argument("--tolerances", metavar="FILE.yaml", help="tolerance YAML with per-glob overrides")
    p.add_argument("--ignore", metavar="GLOB", action="append", default=[],
                   help="leave files matching GLOB out (relative path; repeatable)")
    g = p.add_argument_group("tolerances (override the YAML's top level; defaults in docs/COMPARE.md)")
    g.add_argument("--mesh-max", type=_nonneg, metavar="M", help="max vertex distance in metres")
    g.add_argument("--mesh-rms", type=_nonneg, metavar="M", help="RMS vertex distance in metres")
    g.add_argument("--pixel-threshold", type=_unit, metavar="T", help="PNG per-pixel threshold in [0, 1]")
    g.add_argument("--fail-fraction", type=_unit, metavar="F",
                   help="allowed fraction of failing pixels (PNG and EXR) in [0, 1]")
    g.add_argument("--hard-max", type=_unit, metavar="T", help="PNG hard maximum per-pixel difference")
    g.add_argument("--table-atol", type=_nonneg, metavar="A", help="CSV absolute tolerance")
    g.add_argument("--table-rtol", type=_nonneg, metavar="R", help="CSV relative tolerance")


def _nonneg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not v >= 0 or v == float("inf"):
        raise argparse.ArgumentTypeError(f"{text!r}: a finite number >= 0")
    return v


def _unit(text: str) -> float:
    v = _nonneg(text)
    if v > 1:
        raise argparse.ArgumentTypeError(f"{text!r}: a number in [0, 1]")
    return v


def _flag_changes(args) -> dict:
    ch: dict = {}

    def put(section, key, value):
        if value is not None:
            ch.setdefault(section, {})[key] = value

    put("mesh", "max_distance", args.mesh_max)
    put("mesh", "rms_distance", args.mesh_rms)
    put("png", "threshold", args.pixel_threshold)
    put("png", "fail_fraction", args.fail_fraction)
    put("exr", "fail_fraction", args.fail_fraction)
    put("png", "hard_max", args.hard_max)
    put("table", "atol", args.table_atol)
    put("table", "rtol", args.table_rtol)
    return ch


JSON_HEAD = b'{\n "tool": "axdf compare"'  # how to_json's output starts
JUNIT_HEAD = b'<testsuites name="axdf compare"'  # to_junit's root element, after the XML declaration


def _output_path(text: str | None, flag: str, head: bytes) -> Path | None:
    """--report / --junit: a new file or an earlier one of ours (never a golden file, a run's
    manifest or anything else; the output rule, axdf_cli/fileio/outputs.py)."""
    from axdf_cli.fileio.outputs import check_file_output

    if text is None:
        return None
    p = Path(text)
    check_file_output(p, flag, lambda data: head in data)
    return p


def run(args) -> int:
    from dataclasses import replace

    from axdf_cli.compare import check_path, check_paths, compare_paths
    from axdf_cli.compare.report import shown, summary, to_json, to_junit
    from axdf_cli.compare.thresholds import Tolerances, load_tolerances

    # everything that can be bad usage is checked before anything is written
    tol = load_tolerances(args.tolerances) if args.tolerances else Tolerances()
    tol = replace(tol.with_flags(_flag_changes(args)), ignore=tol.ignore + tuple(args.ignore))
    actual, golden = Path(args.actual), Path(args.golden)
    if args.report and args.junit and os.path.realpath(args.report) == os.path.realpath(args.junit):
        raise UsageError(f"--report and --junit are the same file {args.junit}", "give them different paths")
    report_path = _output_path(args.report, "--report", JSON_HEAD)
    junit_path = _output_path(args.junit, "--junit", JUNIT_HEAD)
    first_bless = args.update and actual.exists() and not os.path.lexists(golden)  # a new golden
    if first_bless:
        check_path("ACTUAL", actual)
    else:
        check_paths(actual, golden)
    diff_dir = Path(args.diff_dir) if args.diff_dir else None
    if diff_dir is None and (report_path or junit_path):
        beside = report_path or junit_path
        diff_dir = beside.with_name(beside.stem + "-diffs")
    if diff_dir is not None and diff_dir.exists() and not diff_dir.is_dir():
        raise UsageError(f"--diff-dir {diff_dir} is a file", "--diff-dir takes a folder")
    if diff_dir is not None and diff_dir.is_symlink():
        raise UsageError(f"--diff-dir {diff_dir} is a symbolic link",
                         "axdf never writes through a link; give the folder's own path")
    exclude = [p for p in (report_path, junit_path, diff_dir) if p is not None]
    steps = None
    if args.update:
        from axdf_cli.compare.bless import apply_bless, plan_bless

        steps = plan_bless(actual, golden, tol, exclude)  # refusals (exit 2) before any write
    if first_bless:
        _print_changes(apply_bless(steps, actual, golden), golden, args)
        return 0

    if diff_dir is not None and diff_dir.is_dir():
        _clear_old_pictures(diff_dir)
    bar = progress.bar(args.quiet or bool(os.environ.get("CI")), "file", total=0, desc="compare", leave=False)
    try:
        report = compare_paths(actual, golden, tol, diff_dir, exclude, bar.show if bar else None)
    finally:
        if bar is not None:
            bar.close()
    if report_path:
        write_text(report_path, to_json(report, tol.source))
    if junit_path:
        write_bytes(junit_path, to_junit(report))
    print(summary(report, verbose=args.verbose, quiet=args.quiet))
    if report_path and not args.quiet:
        print(f"report: {shown(str(report_path))}")
    if junit_path and not args.quiet:
        print(f"junit: {shown(str(junit_path))}")
    if steps is not None:
        _print_changes(apply_bless(steps, actual, golden, report), golden, args)
        return 0
    return 0 if report.passed else 1


def _print_changes(changes, golden: Path, args) -> None:
    from axdf_cli.compare.report import shown

    if not args.quiet:
        for c in changes:
            where = golden / c.path if golden.is_dir() else golden
            print(shown(f"{c.action:<8} {where}" + (f" ({c.note})" if c.note else "")))
    n = {a: sum(1 for c in changes if c.action == a) for a in ("added", "replaced", "removed")}
    print(shown(f"updated golden {golden}: {n['added']} added, {n['replaced']} replaced, {n['removed']} removed"))


def _clear_old_pictures(diff_dir: Path) -> None:
    """Pictures of an earlier comparison would mislead: remove our own *.diff.png files (those
    axdf compare made, by the mark in them; a file of yours of that name stays)."""
    from axdf_cli.compare import is_own_picture

    for p in diff_dir.rglob("*.diff.png"):
        if is_own_picture(p):
            try:
                p.unlink()
            except OSError:
                pass
