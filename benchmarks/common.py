"""What every section of the bench shares: the repository's paths, timing, the table and the
machine line."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GAIT_MUSCLES = ROOT / "muscles" / "gait2392"
ATLAS_MUSCLES = ROOT / "muscles" / "gait2392_atlas"
GAIT_POSE = ROOT / "poses" / "gait2392_walk.yaml"
GAIT_JOB = ROOT / "poses" / "jobs" / "gait2392_walk.yaml"
CMU_GAIT_JOB = ROOT / "poses" / "jobs" / "gait2392_cmu_walk.yaml"
#: The evaluation rows time the paper's model alone: contact (on by default in axdf run) has
#: its own section (sections/contact.py) and one end-to-end row.
NO_CONTACT = {"contact": False}
ARM_MUSCLES = ROOT / "muscles" / "arm26"
ARM_POSE = ROOT / "poses" / "arm26_flex.yaml"
ARM_JOB = ROOT / "poses" / "jobs" / "arm26_flex.yaml"
DEMO_MUSCLES = ROOT / "muscles" / "demo"
DEMO_POSE = ROOT / "poses" / "demo.yaml"
DEMO_JOB = ROOT / "poses" / "jobs" / "demo.yaml"
RESOLUTIONS = ((48, 24), (96, 48))
MUSCLE_COUNTS = (1, 10, 92)
DATASET_FILE = ROOT / "poses" / "datasets" / "gait2392_random.yaml"
DATASET_SAMPLES = 1000


def gait_shipped() -> bool:
    """Whether the gait2392 library and walk are shipped (the case is gait2392, not synthetic)."""
    return GAIT_MUSCLES.is_dir() and GAIT_POSE.is_file()


def median_time(fn, repeats: int) -> float:
    """Median wall time (s) of ``fn()`` over ``repeats`` runs."""
    ts = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def mark(ok: bool) -> str:
    return "✓" if ok else "✗"


def mbs(nbytes: float, us: float) -> str:
    return f"{nbytes / us:.0f} MB/s"


def run_subprocess(args: list[str], cwd: Path = ROOT) -> dict:
    """Run ``python -m axdf_cli ARGS``: wall time (s), exit code, peak RSS (bytes) of the child.

    The peak comes from GNU time (``/usr/bin/time -f %M``) when present: Linux carries a
    process's peak RSS across exec, so the child of a large forked benchmark would otherwise
    report the benchmark's own peak. Without GNU time, wait4's figure is an upper bound."""
    cmd = [sys.executable, "-m", "axdf_cli", *args]
    gnu_time = shutil.which("time") or ("/usr/bin/time" if Path("/usr/bin/time").is_file() else None)
    with tempfile.TemporaryDirectory() as d:
        report = Path(d) / "time.txt"
        if gnu_time:
            cmd = [gnu_time, "-f", "%M", "-o", str(report), *cmd]
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        err = p.stderr.read()
        _, status, usage = os.wait4(p.pid, 0)
        p.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        maxrss = usage.ru_maxrss * 1024
        if gnu_time and report.is_file():
            maxrss = int(report.read_text().split()[-1]) * 1024
    return {"wall": wall, "rc": p.returncode, "maxrss": maxrss, "stderr": err.decode(errors="replace")}


# ----------------------------------------------------------------------------- the table


class Table:
    def __init__(self):
        self.rows: list[tuple[str, ...]] = []

    def add(self, what: str, value: str, ref: str = "", ratio: str = "", target: str = ""):
        self.rows.append((what, value, ref, ratio, target))

    def section(self, title: str):
        self.rows.append((title,))

    def text(self) -> str:
        head = ("measure", "figure", "reference (same run)", "ratio", "target")
        body = [r for r in self.rows if len(r) == 5]
        widths = [max([len(head[i])] + [len(r[i]) for r in body]) for i in range(5)]  # sections alone: the heads
        line = "  ".join("-" * w for w in widths)
        fmt = lambda r: "  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip()  # noqa: E731
        out = [fmt(head), line]
        for r in self.rows:
            out.append(f"[{r[0]}]" if len(r) == 1 else fmt(r))
        return "\n".join(out)

    def markdown(self) -> str:
        """The rows as Markdown: one table per section (a section's title as a heading)."""
        head = "| measure | figure | reference (same run) | ratio | target |\n|---|---|---|---|---|"
        out: list[str] = []
        open_table = False
        for r in self.rows:
            if len(r) == 1:
                out += ["", f"### {r[0]}", ""]
                open_table = False
            else:
                if not open_table:
                    out.append(head)
                    open_table = True
                out.append("| " + " | ".join(c.replace("|", "\\|") for c in r) + " |")
        return "\n".join(out).strip() + "\n"


def machine_line(page: Path | None = None) -> str:
    """The machine and commit a table was measured on, for the generated file's header; changes
    to ``page`` itself (the page being written, from an earlier --only run) do not count as
    uncommitted."""
    import platform

    cpu_name = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu_name = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        commit = subprocess.run(["git", "rev-parse", "--short=12", "HEAD"], cwd=ROOT, capture_output=True,
                                text=True, check=True).stdout.strip()
        inside = page is not None and Path(page).resolve().is_relative_to(ROOT)
        spec = ["--", ".", f":(exclude){Path(page).resolve().relative_to(ROOT)}"] if inside else []
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", *spec], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
        commit += " (with uncommitted changes)" if dirty else ""
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown (not a git checkout)"
    return (f"commit {commit}; {cpu_name}, {os.cpu_count()} logical CPUs; {platform.system()} "
            f"{platform.release()}; Python {platform.python_version()}, numpy {np.__version__}")
