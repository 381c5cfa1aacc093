"""A :class:`Report` as a human summary (text), a JSON document and JUnit XML.

The functions return text or bytes; the CLI prints the summary and writes the files.
"""
from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET

from axdf_cli import __version__
from axdf_cli.compare.result import ERROR, EXTRA, FAIL, MISSING, PASS, Report

# how many failing files the summary lists (all with --verbose)
SUMMARY_MAX_FILES = 25
_LABEL = {PASS: "ok", FAIL: "FAIL", MISSING: "MISSING", EXTRA: "EXTRA", ERROR: "ERROR"}


def _json_safe(v):
    """Non-finite floats become null (PSNR of identical images is infinite)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_safe(x) for x in v]
    return v


def to_json(report: Report, tolerance_file: str | None = None) -> str:
    """Every file with its kind, verdict, reasons, notes, metrics and tolerances."""
    doc = {
        "tool": "axdf compare",
        "version": __version__,
        "actual": report.actual,
        "golden": report.golden,
        "tolerance_file": tolerance_file,
        "verdict": "same" if report.passed else "different",
        "counts": report.counts(),
        "likely_causes": list(report.likely_causes),
        "seconds": round(report.seconds, 3),
        "files": [
            {"path": f.path, "kind": f.kind, "verdict": f.verdict, "reasons": list(f.reasons),
             "notes": list(f.notes), "metrics": f.metrics, "tolerance": f.tolerance,
             "diff_picture": f.diff_picture}
            for f in report.files
        ],
    }
    return json.dumps(_json_safe(doc), indent=1, allow_nan=False) + "\n"


def to_junit(report: Report) -> bytes:
    """One JUnit test case per file: failure for fail/missing/extra, error for unreadable."""
    c = report.counts()
    failures = c[FAIL] + c[MISSING] + c[EXTRA]
    attrs = {"tests": str(c["total"]), "failures": str(failures), "errors": str(c[ERROR]),
             "skipped": "0", "time": f"{report.seconds:.3f}"}
    root = ET.Element("testsuites", {"name": "axdf compare", **attrs})
    suite = ET.SubElement(root, "testsuite", {"name": f"axdf compare {report.actual} vs {report.golden}", **attrs})
    props = ET.SubElement(suite, "properties")
    for k, v in (("actual", report.actual), ("golden", report.golden), ("axdf_version", __version__)):
        ET.SubElement(props, "property", {"name": k, "value": v})
    for f in report.files:
        folder = f.path.rsplit("/", 1)[0].replace("/", ".") if "/" in f.path else "run"
        case = ET.SubElement(suite, "testcase", {"classname": f"axdf.compare.{folder}", "name": f.path,
                                                 "time": f"{f.seconds:.3f}"})
        if f.verdict != PASS:
            tag = "error" if f.verdict == ERROR else "failure"
            body = "\n".join(f.reasons)
            if f.metrics:
                body += "\nmetrics: " + json.dumps(_json_safe(f.metrics), sort_keys=True)
            if f.diff_picture:
                body += f"\ndiff picture: {f.diff_picture}"
            el = ET.SubElement(case, tag, {"type": f.verdict, "message": f.reasons[0] if f.reasons else f.verdict})
            el.text = body
        if f.notes:
            ET.SubElement(case, "system-out").text = "\n".join(f.notes)
    if report.likely_causes:
        ET.SubElement(suite, "system-out").text = "likely causes:\n" + "\n".join(report.likely_causes)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def summary(report: Report, verbose: bool = False, quiet: bool = False) -> str:
    """The human summary: failing files with their reasons, a line per kind, likely causes
    from the manifests, where the diff pictures are, and the verdict."""
    lines: list[str] = []
    failing = [f for f in report.files if f.failed]
    if not quiet:
        lines.append(f"axdf compare: {report.actual} vs golden {report.golden}")
    shown = failing if verbose or quiet else failing[:SUMMARY_MAX_FILES]
    for f in shown:
        lines.append(f"  {_LABEL[f.verdict]:<7} {f.path}")
        lines += [f"          {r}" for r in f.reasons]
        lines += [f"          note: {n}" for n in f.notes]
        if f.diff_picture:
            lines.append(f"          picture: {f.diff_picture}")
    if len(shown) < len(failing):
        lines.append(f"  ... and {len(failing) - len(shown)} more failing files (--verbose or --report lists all)")
    if quiet:
        return "\n".join(lines)
    if verbose:
        for f in report.files:
            if not f.failed:
                lines.append(f"  ok      {f.path}  {_brief(f.metrics)}")
    lines += _per_kind(report)
    if report.likely_causes:
        lines.append("likely causes (the manifests' inputs or settings differ):")
        lines += [f"  {n}" for n in report.likely_causes[: SUMMARY_MAX_FILES if not verbose else None]]
    c = report.counts()
    identical = sum(1 for f in report.files if f.metrics.get("identical"))
    if report.passed:
        lines.append(f"SAME: {c['total']} files within tolerance ({identical} identical) in {report.seconds:.2f} s")
    else:
        parts = ", ".join(f"{c[v]} {v}" for v in (FAIL, MISSING, EXTRA, ERROR) if c[v])
        lines.append(f"DIFFERENT: {len(failing)} of {c['total']} files ({parts}); {c[PASS]} pass "
                     f"({identical} identical) in {report.seconds:.2f} s")
    return "\n".join(lines)


def _brief(m: dict) -> str:
    if m.get("identical"):
        return "identical"
    keys = ("max_distance", "rms_distance", "max_difference", "failing_fraction", "psnr_db", "flip_mean",
            "max_abs_difference")
    return ", ".join(f"{k}={_fmt(m[k])}" for k in keys if k in m and not isinstance(m[k], dict))


def _fmt(v) -> str:
    return "inf" if v is None else f"{v:.3g}" if isinstance(v, float) else str(v)


def _per_kind(report: Report) -> list[str]:
    """One line per kind of file: how many, how many pass, the worst metric and where."""
    worst_key = {"mesh": ("max_distance", max, "max vertex distance", " m"),
                 "png": ("psnr_db", min, "lowest PSNR", " dB"),
                 "exr": ("failing_fraction", max, "largest failing fraction", "")}
    lines = []
    kinds = sorted({f.kind for f in report.files})
    for k in kinds:
        fs = [f for f in report.files if f.kind == k]
        npass = sum(1 for f in fs if not f.failed)
        text = f"  {k:<8} {len(fs):>5} files, {npass} pass"
        if k in worst_key:
            key, pick, label, unit = worst_key[k]
            vals = [(f.metrics[key], f.path) for f in fs if f.metrics.get(key) is not None]
            if vals:
                v, p = pick(vals)
                text += f"; {label} {v:.3g}{unit} ({p})"
        lines.append(text)
    return lines
