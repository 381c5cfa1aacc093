"""Row 4, writers: PLY and OBJ (encode; encode + atomic write) in MB/s and µs per
muscle-frame, against ``ndarray.tofile`` of the same bytes."""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.formats import ObjWriter, PlyWriter
from axdf_cli.model.muscle import MuscleModel
from benchmarks.common import RESOLUTIONS, Table, mark, mbs
from benchmarks.settings import Run

UNIT = True
TARGET_PLY = 1.5  # PLY writing within 1.5x of ndarray.tofile of the same bytes
TARGET_OBJ = 5.0  # OBJ within 5x of PLY


def time_writers(model: MuscleModel, world: np.ndarray, tension: np.ndarray, folder: Path,
                 n_files: int, repeats: int) -> dict:
    """Per-file µs and bytes for PLY/OBJ encode, encode + atomic write, and tofile of the same
    bytes, over ``n_files`` evaluated frames written to new files (as a run does)."""
    res = model.evaluate(world[:n_files], tension[:n_files, 0])
    pos = res.vertices.astype(np.float32)
    nrm = res.normals.astype(np.float32)
    n = len(pos)
    out = {}
    counter = [0]

    def fresh(ext: str) -> Path:  # a new folder per pass: every file is new, like a run's
        counter[0] += 1
        d = folder / f"{ext}{counter[0]}"
        d.mkdir(parents=True)
        return d

    writers = {cls.extension: cls(model.faces, model.spec.name) for cls in (PlyWriter, ObjWriter)}
    arrays = {ext: [np.frombuffer(w.encode(pos[i], nrm[i]), dtype=np.uint8) for i in range(n)]
              for ext, w in writers.items()}

    # one file of every format and variant in turn, so that all meet the same state of the
    # disk cache and of the machine's other work (writeback stalls hit all alike)
    def variants(ext: str, i: int, dirs: dict):
        w, name = writers[ext], f"m_{i:04d}.{ext}"
        yield "encode", lambda: w.encode(pos[i], nrm[i])
        yield "write", lambda: w.write(dirs["write"] / name, pos[i], nrm[i])
        yield "write_bytes", lambda: atomic.write_bytes(dirs["write_bytes"] / name, w.encode(pos[i], nrm[i]))
        yield "tofile", lambda: arrays[ext][i].tofile(dirs["tofile"] / name)

    keys = ("encode", "write", "write_bytes", "tofile")
    totals = {(ext, k): [] for ext in writers for k in keys}
    for _ in range(max(1, repeats)):
        dirs = {ext: {k: fresh(ext) for k in keys[1:]} for ext in writers}  # new files, like a run's
        acc = dict.fromkeys(totals, 0.0)
        for i in range(n):
            for ext in writers:
                for key, fn in variants(ext, i, dirs[ext]):
                    t0 = time.perf_counter()
                    fn()
                    acc[ext, key] += time.perf_counter() - t0
        for k, v in acc.items():
            totals[k].append(v)
    for ext in writers:
        out[ext] = {"bytes": float(np.mean([len(a) for a in arrays[ext]])),
                    **{k: float(np.median(totals[ext, k])) / n * 1e6 for k in keys}}
    return out


def measure(run: Run) -> tuple[int, dict]:
    """(files per pass, :func:`time_writers` of one 48x24 muscle of the run's case), measured once
    per run: the packed rows read its PLY write() figure."""
    if "writers" not in run.results:
        case = run.case()
        model = case.models(1, RESOLUTIONS[0])[0]
        n_files = 50 if run.quick else 200
        run.results["writers"] = n_files, time_writers(model, case.world, case.tension, run.tmp / "writers", n_files,
                                                       run.reps + 2)
    return run.results["writers"]


def rows(table: Table, run: Run) -> list[str]:
    n_files, wr = measure(run)
    ply, obj = wr["ply"], wr["obj"]
    table.section(f"writers ({RESOLUTIONS[0][0]}x{RESOLUTIONS[0][1]}, {n_files} new files per pass) "
                  "vs ndarray.tofile of the same bytes")
    for ext, d in wr.items():
        table.add(f"{ext.upper()} encode ({d['bytes'] / 1e3:.0f} kB)", f"{d['encode']:.0f} µs/mf",
                  mbs(d["bytes"], d["encode"]))
        table.add(f"{ext.upper()} write(): encode + atomic write", f"{d['write']:.0f} µs/mf",
                  f"tofile {d['tofile']:.0f} µs/mf", f"{d['write'] / d['tofile']:.2f}x",
                  f"<= {TARGET_PLY:g}x {mark(d['write'] / d['tofile'] <= TARGET_PLY)}" if ext == "ply" else "")
        table.add(f"{ext.upper()} encode + atomic.write_bytes (+sha256)", f"{d['write_bytes']:.0f} µs/mf",
                  f"tofile {d['tofile']:.0f} µs/mf", f"{d['write_bytes'] / d['tofile']:.2f}x")
        table.add(f"{ext.upper()} write() throughput", mbs(d["bytes"], d["write"]),
                  f"tofile {mbs(d['bytes'], d['tofile'])}")
    table.add("OBJ write() vs PLY write()", f"{obj['write']:.0f} µs/mf", f"PLY {ply['write']:.0f} µs/mf",
              f"{obj['write'] / ply['write']:.2f}x", f"<= {TARGET_OBJ:g}x {mark(obj['write'] / ply['write'] <= TARGET_OBJ)}")
    return []
