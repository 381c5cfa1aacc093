"""Row 8, packed formats (npz, pc2, mdd, usd): writing all muscles x all frames as the run
streams them against ``ndarray.tofile`` of the same bytes in one file, and ``axdf run`` of the
job (pose stretched to the bench's frames) per format against the same run writing no meshes,
with peak memory."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from axdf_cli.formats import FORMATS, read_preference
from axdf_cli.model.muscle import MuscleModel
from benchmarks.case import Case
from benchmarks.common import RESOLUTIONS, ROOT, Table, mark
from benchmarks.sections import writers
from benchmarks.settings import Run

UNIT = False


PACKED_FORMATS = tuple(read_preference(FORMATS))  # every per-sequence format, fastest to read first
TARGET_PACKED = 1.5  # pc2 and npz writing within 1.5x of ndarray.tofile of the same bytes in one file


def time_sequence_writers(models: list[MuscleModel], world: np.ndarray, tension: np.ndarray, folder: Path,
                          n_muscles: int, repeats: int, fps: float = 60.0) -> dict:
    """Seconds to write ``n_muscles`` muscles x F frames in each per-sequence format as the run
    streams them (chunks of ``pipeline.CHUNK_FRAMES`` frames, muscle by muscle in each chunk, then
    every file completed: headers, CRC, rename), without and with the sha256 the manifest
    records, against ``ndarray.tofile`` of the same bytes into one file (written in the same
    chunks). Medians of ``repeats`` rounds; in each round the three variants of a format run
    back to back, each after ``os.sync()`` (a variant that meets the previous one's dirty
    pages being written back is slowed by the disk, not by its own work). The frames are evaluated once beforehand (``models`` cycled over the
    muscles, each file its own)."""
    from axdf_cli.formats.packed import SequenceInfo
    from axdf_cli.pipeline import CHUNK_FRAMES

    F = world.shape[0]
    data = []
    for j, m in enumerate(models):
        r = m.evaluate(world, tension[:, j % tension.shape[1]])
        data.append((m, r.vertices.astype(np.float32), r.normals.astype(np.float32)))
    frames = np.arange(F)

    def write(fmt: str, sha256: bool) -> int:
        cls = FORMATS[fmt].writer
        d = folder / fmt
        d.mkdir(parents=True)
        writers = [cls(d / f"m{j}.{cls.extension}", SequenceInfo(frames, fps, f"m{j}"), data[j % len(data)][0].faces,
                       data[j % len(data)][0].n_vertices, sha256=sha256) for j in range(n_muscles)]
        for s in range(0, F, CHUNK_FRAMES):
            for j, w in enumerate(writers):
                _, pos, nrm = data[j % len(data)]
                w.append(pos[s:s + CHUNK_FRAMES], nrm[s:s + CHUNK_FRAMES])
        for w in writers:
            w.finish()
        return sum(p.stat().st_size for p in d.iterdir())

    def tofile(fmt: str) -> int:
        ref = folder / f"{fmt}.raw"
        with open(ref, "wb") as fh:
            for s in range(0, F, CHUNK_FRAMES):
                for j in range(n_muscles):
                    _, pos, nrm = data[j % len(data)]
                    pos[s:s + CHUNK_FRAMES].tofile(fh)
                    if FORMATS[fmt].normals:
                        nrm[s:s + CHUNK_FRAMES].tofile(fh)
        return ref.stat().st_size

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for fmt in PACKED_FORMATS:
        t = {"write": [], "sha256": [], "tofile": []}
        sizes = {}
        for _ in range(max(1, repeats)):
            for key, fn in (("tofile", lambda: tofile(fmt)), ("write", lambda: write(fmt, False)),
                            ("sha256", lambda: write(fmt, True))):
                os.sync()  # (untimed) every variant starts with no dirty pages waiting for the disk
                t0 = time.perf_counter()
                sizes[key] = fn()
                t[key].append(time.perf_counter() - t0)
                shutil.rmtree(folder / fmt, ignore_errors=True)
                (folder / f"{fmt}.raw").unlink(missing_ok=True)
        out[fmt] = {k: float(np.median(v)) for k, v in t.items()} | {"bytes": sizes["write"],
                                                                     "tofile_bytes": sizes["tofile"]}
    return out


PACKED_SCRIPT = r"""
import json, resource, sys, time, dataclasses
from pathlib import Path
from benchmarks.case import stretched_pose
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, execute
job, n, fmt, out = sys.argv[1], int(sys.argv[2]), sys.argv[3], Path(sys.argv[4])
plan = plan_run(load_job(job), out_arg=str(out), fmt_arg=None if fmt == "none" else fmt, stages={"contact": False})
plan.pose = stretched_pose(plan.pose, n)
plan.frames = plan.pose.frames
plan.render = dataclasses.replace(plan.render, enabled=False)
if fmt == "none":
    plan.formats = ()  # evaluation, stats.csv, bones.csv and the manifest only: the baseline
def cpu():  # user + system seconds of this process, all its threads
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
t0, c0 = time.perf_counter(), cpu()
summary = execute(plan, overwrite=True)
dt, dc = time.perf_counter() - t0, cpu() - c0
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) * 1024
nbytes = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
print(json.dumps({"seconds": dt, "cpu": dc, "maxrss": hwm, "bytes": nbytes, "files": summary["files"],
                  "muscle_frames": len(plan.frames) * len(plan.models)}))
"""


def packed_run(job: Path, n_frames: int, fmt: str, out: Path) -> dict:
    """``execute`` of ``job`` (its pose stretched to ``n_frames``) to ``fmt`` ('none': no
    meshes) in a subprocess: wall and CPU seconds (all threads), peak RSS (VmHWM), bytes and
    files written."""
    import json

    p = subprocess.run([sys.executable, "-c", PACKED_SCRIPT, str(job), str(n_frames), fmt, str(out)], cwd=ROOT,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"packed run ({fmt}) failed: {p.stderr[-600:]}")
    shutil.rmtree(out, ignore_errors=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def packed_rows(table: "Table", case: "Case", job: Path, tmp: Path, n_frames: int, quick: bool,
                ply_us: float | None = None) -> None:
    """The packed formats' rows: writing them against ndarray.tofile of the same bytes in one
    file (and, given PLY write()'s µs per file, what one PLY per frame would cost), then
    ``axdf run`` end to end (evaluation only, then each format) with peak memory."""
    nm = min(len(case.specs), 92)
    models = case.models(min(8, nm), RESOLUTIONS[0])
    w = time_sequence_writers(models, case.world, case.tension, tmp / "packed", nm, 1 if quick else 3)
    table.section(f"packed formats: {nm} muscles x {n_frames} frames ({RESOLUTIONS[0][0]}x{RESOLUTIONS[0][1]}) "
                  "streamed in chunks as axdf run does (headers, CRC, rename; + the manifest's sha256) vs "
                  "ndarray.tofile of the same bytes into one file")
    for fmt, d in w.items():
        ratio = d["write"] / d["tofile"]
        target = f"<= {TARGET_PACKED:g}x {mark(ratio <= TARGET_PACKED)}" if fmt in ("pc2", "npz") else "reported"
        table.add(f"{fmt} write ({d['bytes'] / 2**20:.0f} MiB in {nm} files)", f"{d['write']:.2f} s",
                  f"tofile {d['tofile']:.2f} s ({d['tofile_bytes'] / 2**20:.0f} MiB)", f"{ratio:.2f}x", target)
        table.add(f"{fmt} write + sha256 (what axdf run does)", f"{d['sha256']:.2f} s", f"tofile {d['tofile']:.2f} s",
                  f"{d['sha256'] / d['tofile']:.2f}x")
    if ply_us:
        t = ply_us * 1e-6 * nm * n_frames
        table.add(f"PLY, one file per frame ({nm * n_frames} files; PLY write() row x files)", f"{t:.2f} s",
                  f"tofile {w['npz']['tofile']:.2f} s", f"{t / w['npz']['tofile']:.2f}x")
    runs = {"none": [packed_run(job, n_frames, "none", tmp / "packed-none")]}
    for fmt in ("npz", "pc2", "usd"):
        runs[fmt] = [packed_run(job, n_frames, fmt, tmp / f"packed-{fmt}")]
    runs["none"].append(packed_run(job, n_frames, "none", tmp / "packed-none"))  # before and after: load drifts
    base = min(runs["none"], key=lambda r: r["cpu"])
    table.section(f"end to end: axdf run {job.relative_to(ROOT)} (pose stretched to {n_frames} frames, no "
                  "render; subprocess) per format; the CPU time its writing adds (all threads; wall time "
                  "moves with the machine's other load) vs tofile of the same bytes")
    table.add(f"axdf run, no meshes ({base['muscle_frames']} muscle-frames: evaluation, stats, manifest)",
              f"{base['seconds']:.1f} s", f"CPU {base['cpu']:.1f} s; peak {base['maxrss'] / 2**20:.0f} MiB")
    for fmt in ("npz", "pc2", "usd"):
        r = runs[fmt][0]
        added = r["cpu"] - base["cpu"]
        ref = w[fmt]["tofile"] * r["bytes"] / max(w[fmt]["tofile_bytes"], 1)
        table.add(f"axdf run --format {fmt} ({r['files']} files, {r['bytes'] / 2**20:.0f} MiB)",
                  f"{r['seconds']:.1f} s", f"CPU {r['cpu']:.1f} s (+{added:.1f} s); peak {r['maxrss'] / 2**20:.0f} MiB",
                  f"{added / ref:.2f}x tofile")


def rows(table: Table, run: Run) -> list[str]:
    """:func:`packed_rows` on the run's case and job, with the writers' PLY write() figure (measured
    here when the writers' section is not in the run)."""
    _, wr = writers.measure(run)
    packed_rows(table, run.case(), run.job, run.tmp, run.n_frames, run.quick, ply_us=wr["ply"]["write"])
    return []
