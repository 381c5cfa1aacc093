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


def shown(text: str) -> str:
    """``text`` safe to print, to put in JSON and in XML: every character that is not
    printable (control characters, the lone surrogates ``os.fsdecode`` makes of bytes that
    are not UTF-8, U+FFFE ...) is written as an escape: ``\\x01``, ``\\xff`` (the byte of a
    surrogate), ``\\ufffe``. Printable text (any language) is kept as it is."""
    if text.isprintable():
        return text
    out = []
    for ch in text:
        if ch.isprintable():
            out.append(ch)
        elif 0xDC80 <= ord(ch) <= 0xDCFF:  # surrogateescape: the original byte
            out.append(f"\\x{ord(ch) - 0xDC00:02x}")
        else:
            out.append(ascii(ch)[1:-1])
    return "".join(out)


def _json_safe(v):
    """Non-finite floats become null (PSNR of identical images is infinite); strings are
    :func:`shown` (file names may hold any byte)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, str):
        return shown(v)
    if isinstance(v, dict):
        return {_json_safe(k): _json_safe(x) for k, x in v.items()}
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
        "differing_parts": {name: list(what) for name, what in report.parts},
        "pixels_on_unchanged_parts": dict(report.bordering),
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
    """One JUnit test case per file: failure for fail/missing/extra, error for unreadable.
    Valid XML for any file name (every text goes through :func:`shown`)."""
    c = report.counts()
    failures = c[FAIL] + c[MISSING] + c[EXTRA]
    attrs = {"tests": str(c["total"]), "failures": str(failures), "errors": str(c[ERROR]),
             "skipped": "0", "time": f"{report.seconds:.3f}"}
    root = ET.Element("testsuites", {"name": "axdf compare", **attrs})
    suite = ET.SubElement(root, "testsuite", {"name": shown(f"axdf compare {report.actual} vs {report.golden}"),
                                              **attrs})
    props = ET.SubElement(suite, "properties")
    for k, v in (("actual", report.actual), ("golden", report.golden), ("axdf_version", __version__)):
        ET.SubElement(props, "property", {"name": k, "value": shown(v)})
    for f in report.files:
        folder = f.path.rsplit("/", 1)[0].replace("/", ".") if "/" in f.path else "run"
        case = ET.SubElement(suite, "testcase", {"classname": shown(f"axdf.compare.{folder}"), "name": shown(f.path),
                                                 "time": f"{f.seconds:.3f}"})
        if f.verdict != PASS:
            tag = "error" if f.verdict == ERROR else "failure"
            body = "\n".join(f.reasons)
            if f.metrics:
                body += "\nmetrics: " + json.dumps(_json_safe(f.metrics), sort_keys=True)
            if f.diff_picture:
                body += f"\ndiff picture: {f.diff_picture}"
            el = ET.SubElement(case, tag, {"type": f.verdict,
                                           "message": shown(f.reasons[0] if f.reasons else f.verdict)})
            el.text = "\n".join(shown(line) for line in body.split("\n"))
        if f.notes:
            ET.SubElement(case, "system-out").text = "\n".join(shown(n) for n in f.notes)
    if report.likely_causes:
        ET.SubElement(suite, "system-out").text = "likely causes:\n" + "\n".join(shown(n) for n in report.likely_causes)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def verdict_line(report: Report) -> str:
    """The last line of every summary: SAME or DIFFERENT with the counts."""
    c = report.counts()
    identical = sum(1 for f in report.files if f.metrics.get("identical"))
    if report.passed:
        return f"SAME: {c['total']} files within tolerance ({identical} identical) in {report.seconds:.2f} s"
    parts = ", ".join(f"{c[v]} {v}" for v in (FAIL, MISSING, EXTRA, ERROR) if c[v])
    return (f"DIFFERENT: {c['total'] - c[PASS]} of {c['total']} files ({parts}); {c[PASS]} pass "
            f"({identical} identical) in {report.seconds:.2f} s")


def summary(report: Report, verbose: bool = False, quiet: bool = False) -> str:
    """The human summary, ending with the verdict line. Default: the failing files (at most
    SUMMARY_MAX_FILES) with their reasons, a line per kind, likely causes from the manifests,
    where the diff pictures are. ``quiet``: only the failing files' names (at most
    SUMMARY_MAX_FILES) and the verdict line, a subset of the default. ``verbose``: every
    failing file, and every passing one with its metrics."""
    lines: list[str] = []
    failing = [f for f in report.files if f.failed]
    if not quiet:
        lines.append(f"axdf compare: {report.actual} (actual) against {report.golden} (golden)")
    shown_files = failing if verbose else failing[:SUMMARY_MAX_FILES]
    for f in shown_files:
        lines.append(f"  {_LABEL[f.verdict]:<7} {f.path}")
        if quiet:
            continue
        lines += [f"          {r}" for r in f.reasons]
        lines += [f"          note: {n}" for n in f.notes]
        if f.diff_picture:
            lines.append(f"          picture: {f.diff_picture}")
    if len(shown_files) < len(failing):
        lines.append(f"  ... and {len(failing) - len(shown_files)} more failing files (--verbose or --report lists all)")
    if not quiet:
        if verbose:
            for f in report.files:
                if not f.failed:
                    lines.append(f"  ok      {f.path}  {_brief(f.metrics)}")
        lines += _per_kind(report)
        if report.parts:
            lines.append("parts that differ (muscles, bones, skin by name):")
            lines += [f"  {name}: {'; '.join(what)}" for name, what in report.parts]
        if report.bordering:
            lines.append("  failing pixels also on parts whose meshes are the same (silhouettes they share): "
                         + ", ".join(f"{name} {n}" for name, n in report.bordering))
        if report.likely_causes:
            lines.append("likely causes (the manifests' inputs or settings differ):")
            lines += [f"  {n}" for n in report.likely_causes[: SUMMARY_MAX_FILES if not verbose else None]]
    lines.append(verdict_line(report))
    return "\n".join(shown(line) for line in lines)


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
            vals = [(f.metrics[key] if math.isfinite(f.metrics[key]) else math.inf, f.path)
                    for f in fs if f.metrics.get(key) is not None]
            if vals:
                v, p = pick(vals)
                text += f"; {label} {v:.3g}{unit} ({p})"
        lines.append(text)
    return lines
