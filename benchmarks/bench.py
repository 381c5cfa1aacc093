"""``make bench``: one table of speed figures, every figure and every limit measured in the same run.

    python -m benchmarks.bench [--quick] [--long] [--profile] [--only ROWS] [--markdown PATH]

Rows (medians of repeated runs timed with ``time.perf_counter``; the machine may be shared,
so figures are noisy and only ratios taken in the same run are compared with targets):

1. evaluation: µs per muscle-frame of ``MuscleModel.evaluate`` at 48x24 and 96x48, over
   1000 frames in chunks of ``pipeline.CHUNK_FRAMES``, for 1, 10 and 92 muscles (the gait2392
   library and walk when shipped, else demo muscles replicated and perturbed on the demo
   skeleton with a synthetic pose);
2. the limit: numpy filling the same outputs (``np.copyto`` into preallocated (F, V, 3)
   float64 vertices and normals), and evaluation / limit;
3. a peer: the same surface tessellated by geomdl (NURBS-Python), per muscle-frame;
4. writers: PLY and OBJ (encode; encode + atomic write) in MB/s and µs per muscle-frame,
   against ``ndarray.tofile`` of the same bytes;
5. rendering: frames per second at 512x512 for a demo-sized scene (``benchmark_fps``);
6. end to end: ``axdf run`` of the largest shipped job as a subprocess (frames per second,
   peak memory), and the split of its time between evaluation and writing (cProfile);
7. data sets: ``axdf dataset build`` of poses/datasets/gait2392_random.yaml (1000 samples, 100
   with ``--quick``) at 1 and 2 workers, the scaling ratio, and a sample's split between
   evaluation, writing and rendering.
8. packed formats (npz, pc2, mdd, usd): writing all muscles x all frames as the run streams
   them against ``ndarray.tofile`` of the same bytes in one file, and ``axdf run`` of the job
   (pose stretched to the bench's frames) per format against the same run writing no meshes,
   with peak memory.
9. contact: the gait2392 walk and Rajagopal2016's running stride (muscles only) evaluated with
   and without the contact stage (µs per muscle-frame, the ratio), and the shares of vertices
   inside another muscle or a bone and the deepest penetration before and after (the
   product's own measures, stats.csv's), the volume, and the muscle-frames that pop (a
   vertex step over 1.5x the no-contact one); where the skeleton has bone meshes, the share
   inside a bone and the deepest point in one after contact by libigl's distance to the
   meshes themselves, against the fields the product reads them through;
10. rendering split over processes: ``make demo``'s first job (poses/jobs/demo.yaml, meshes and
   512x512 frames; every 2nd frame with ``--quick``) as a subprocess at ``--jobs 1`` and
   ``--jobs 2``, and their ratio.
11. retargeting: ``axdf retarget``'s fit of the CMU walk onto gait2392 (frames per second at 30
   and 120 fps; every 4th frame of the take with ``--quick``), and one Jacobian of the mapped
   points by the analytic formula against central differences batched as frames of one
   forward-kinematics call (the alternative the fit could use).
12. jiggle: ``evaluate_plan`` of the gait2392 walk (92 muscles, the whole trial; 54 jiggle)
   with and without the jiggle stage (timed in turn, medians of 5), µs per muscle-frame, and
   the stage alone; and a ``--frames`` subset's extra cost (frames not selected are advanced too).
13. skin: the skin stage (``axdf run --skin``) over the gait2392 walk and the CMU walk onto
   gait2392 (packed muscles, contact on): its ms per frame against the muscles plus contact,
   measured side by side, the skin's volume against rest, muscle vertices outside it.

``--only retarget`` prints just the retargeting rows, ``--only jiggle`` the jiggle rows,
``--only contact`` the contact rows, ``--only skin`` the skin stage's,
``--only compiled`` the compiled pass's (a whole run of the walk stretched to 1051 frames
at 48x24 into npz against tofile of the same bytes; 92 muscles x 1 frame; a chunk's outputs
into fresh memory against steady state; numba's first-run compile cost).

``--long`` adds the memory check of 10,000 frames x 92 muscles streamed through
``pipeline.evaluate_chunks`` in a subprocess (several minutes). Helpers are importable for the
smoke test (``tests/test_bench_smoke.py``), which runs them on a tiny case.

``--markdown PATH`` also writes the table as a generated Markdown page (``make bench`` writes
docs/BENCH.md, which the docs link to instead of pasting figures): a header with the command,
the commit and the machine, then one table per section.
"""
from __future__ import annotations

import argparse
import cProfile
import dataclasses
import io
import json
import os
import pstats
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from axdf_cli import runtime

runtime.configure()  # threads and numba's kernel cache as the command line sets them (before numpy)

import numpy as np  # noqa: E402

from axdf_cli.fileio import atomic  # noqa: E402
from axdf_cli.formats import FORMATS, ObjWriter, PlyWriter, read_preference
from axdf_cli.specs import Pose, expand_muscle_paths, load_muscle_file, load_pose
from axdf_cli.model.muscle import OCT, MuscleModel, MuscleSpec
from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics

ROOT = Path(__file__).resolve().parent.parent
GAIT_MUSCLES = ROOT / "muscles" / "gait2392"
ATLAS_MUSCLES = ROOT / "muscles" / "gait2392_atlas"
GAIT_POSE = ROOT / "poses" / "gait2392_walk.yaml"
GAIT_JOB = ROOT / "poses" / "jobs" / "gait2392_walk.yaml"
CMU_GAIT_JOB = ROOT / "poses" / "jobs" / "gait2392_cmu_walk.yaml"
#: The evaluation rows time the paper's model alone: contact (on by default in axdf run) has
#: its own section (contact_rows) and one end-to-end row.
NO_CONTACT = {"contact": False}
ARM_MUSCLES = ROOT / "muscles" / "arm26"
ARM_POSE = ROOT / "poses" / "arm26_flex.yaml"
ARM_JOB = ROOT / "poses" / "jobs" / "arm26_flex.yaml"
#: Wrapping may add at most this to evaluation.
TARGET_WRAP = 1.5
DEMO_MUSCLES = ROOT / "muscles" / "demo"
DEMO_POSE = ROOT / "poses" / "demo.yaml"
DEMO_JOB = ROOT / "poses" / "jobs" / "demo.yaml"
RESOLUTIONS = ((48, 24), (96, 48))
MUSCLE_COUNTS = (1, 10, 92)

# targets: ratios measured in the same run
TARGET_LIMIT = 3.0  # evaluation within 3x of numpy filling the same outputs
TARGET_PEER = 100.0  # at least 100x faster than geomdl
TARGET_PLY = 1.5  # PLY writing within 1.5x of ndarray.tofile of the same bytes
TARGET_OBJ = 5.0  # OBJ within 5x of PLY
LONG_FRAMES = 10_000
LONG_MEMORY = 1 << 30  # 1 GiB


def median_time(fn, repeats: int) -> float:
    """Median wall time (s) of ``fn()`` over ``repeats`` runs."""
    ts = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


# ----------------------------------------------------------------------------- the case


@dataclasses.dataclass
class Case:
    """Muscles, skeleton and a pose sampled over ``n_frames`` frames, in memory."""

    name: str  # 'gait2392' or 'synthetic'
    specs: list  # [MuscleSpec]
    skeleton: object
    rest: np.ndarray  # (B, 4, 4) rest world transforms
    world: np.ndarray  # (F, B, 4, 4)
    tension: np.ndarray  # (F, M) effective tension of each spec
    coords: np.ndarray | None = None  # (F, C) skeleton coordinates (moving / conditional path points)

    def models(self, n_muscles: int, resolution: tuple[int, int]) -> list[MuscleModel]:
        specs = [self.specs[i % len(self.specs)] for i in range(n_muscles)]
        return [MuscleModel(dataclasses.replace(s, resolution=tuple(resolution)), self.skeleton.bone_index, self.rest,
                            self.skeleton) for s in specs]


def stretched_pose(pose: Pose, n_frames: int) -> Pose:
    """The pose's keys spread over frames 0 .. n_frames - 1 (same motion, finer in time)."""
    span = max(pose.last - pose.first, 1)
    scale = (n_frames - 1) / span

    def stretch(curves):
        return {k: (tuple((f - pose.first) * scale for f in fr), vals) for k, (fr, vals) in curves.items()}

    return dataclasses.replace(pose, first=0, last=n_frames - 1, keys=stretch(pose.keys),
                               activation=stretch(pose.activation))


def synthetic_pose(skeleton, n_frames: int) -> Pose:
    """A smooth in-memory pose: every rotational coordinate swings within its range."""
    keys = {}
    kf = np.linspace(0, n_frames - 1, max(2, n_frames // 10))
    for i, c in enumerate(skeleton.coordinates):
        if c.type != "rotation":
            continue
        lo, hi = c.range if c.range is not None else (-30.0, 30.0)
        mid, amp = 0.5 * (lo + hi), 0.4 * (hi - lo)
        vals = mid + amp * np.sin(2 * np.pi * kf / max(n_frames, 1) * (1 + i % 3) + i)
        keys[c.name] = (tuple(float(f) for f in kf), tuple(float(v) for v in vals))
    return Pose("synthetic", skeleton, 60.0, 0, n_frames - 1, "linear", keys, {}, {})


def perturbed(spec: MuscleSpec, k: int, rng: np.random.Generator) -> MuscleSpec:
    """A copy of ``spec`` (named ``<name>_<k>``) with axis points moved by up to 5 mm and
    sections scaled by 0.8 .. 1.2."""
    if k == 0:
        return spec
    axis = tuple(dataclasses.replace(p, at=tuple(float(x) for x in np.asarray(p.at) + rng.uniform(-0.005, 0.005, 3)))
                 for p in spec.axis)
    f = float(rng.uniform(0.8, 1.2))
    secs = tuple(dataclasses.replace(s, radii=None if s.radii is None else (s.radii[0] * f, s.radii[1] * f),
                                     outline=None if s.outline is None else tuple((a * f, b * f) for a, b in s.outline))
                 for s in spec.sections)
    return dataclasses.replace(spec, name=f"{spec.name}_{k}", axis=axis, sections=secs)


def load_case(n_frames: int = 1000, n_muscles: int = 92, prefer_gait: bool = True) -> Case:
    """gait2392 muscles and walk (stretched to ``n_frames``) when shipped, else synthetic."""
    if prefer_gait and GAIT_MUSCLES.is_dir() and GAIT_POSE.is_file():
        pose = load_pose(GAIT_POSE)
        specs = [s for f in expand_muscle_paths([(GAIT_MUSCLES, None)]) for s in load_muscle_file(f)]
        name = "gait2392"
        pose = stretched_pose(pose, n_frames)
    else:
        demo = load_pose(DEMO_POSE)
        base = [s for f in expand_muscle_paths([(DEMO_MUSCLES, None)]) for s in load_muscle_file(f)]
        rng = np.random.default_rng(7)
        specs = [perturbed(base[i % len(base)], i // len(base), rng) for i in range(n_muscles)]
        name = "synthetic"
        pose = synthetic_pose(demo.skeleton, n_frames)
    specs = specs[:n_muscles]
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    frames = np.arange(pose.first, pose.last + 1)
    q = sample_coordinates(pose, frames)
    world = forward_kinematics(skel, q)
    act = sample_activation(pose, [s.name for s in specs], frames)
    tension = np.stack([effective_tension(s.tension, act[:, j]) for j, s in enumerate(specs)], axis=1)
    return Case(name, specs, skel, rest, world, tension, q)


def load_wrap_case(n_frames: int, wraps: bool = True) -> Case | None:
    """arm26's muscles (4 of 6 wrap over cylinders and ellipsoids) over its elbow flexion,
    stretched to ``n_frames``; with ``wraps=False`` the same paths without wrap surfaces."""
    if not (ARM_MUSCLES.is_dir() and ARM_POSE.is_file()):
        return None
    pose = stretched_pose(load_pose(ARM_POSE), n_frames)
    specs = [s for f in expand_muscle_paths([(ARM_MUSCLES, None)]) for s in load_muscle_file(f)]
    if not wraps:
        specs = [dataclasses.replace(s, path=dataclasses.replace(s.path, wraps=())) for s in specs]
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    q = sample_coordinates(pose, np.arange(pose.first, pose.last + 1))
    return Case("arm26", specs, skel, rest, forward_kinematics(skel, q), np.zeros((len(q), len(specs))), q)


# ----------------------------------------------------------------------------- evaluation


def evaluate_all(models: list[MuscleModel], world: np.ndarray, tension: np.ndarray, chunk: int,
                 coords: np.ndarray | None = None) -> None:
    """Evaluate every model over every frame, ``chunk`` frames at a time (as ``axdf run``)."""
    nf = world.shape[0]
    for s in range(0, nf, chunk):
        w = world[s:s + chunk]
        q = coords[s:s + chunk] if coords is not None else None
        for j, m in enumerate(models):
            m.evaluate(w, tension[s:s + chunk, j % tension.shape[1]], coords=q)


def time_evaluation(models, world, tension, repeats: int, chunk: int | None = None, coords=None) -> float:
    """µs per muscle-frame (median of ``repeats`` passes)."""
    from axdf_cli.pipeline import CHUNK_FRAMES

    chunk = chunk or CHUNK_FRAMES
    evaluate_all(models, world[:chunk], tension[:chunk], chunk,
                 coords[:chunk] if coords is not None else None)  # warm-up (caches, allocator)
    dt = median_time(lambda: evaluate_all(models, world, tension, chunk, coords), repeats)
    return dt / (len(models) * world.shape[0]) * 1e6


def time_limit(n_frames: int, n_vertices: int, repeats: int) -> float:
    """µs per muscle-frame for numpy to fill what evaluate returns: vertices and normals,
    each a preallocated (F, V, 3) float64 array, by ``np.copyto`` from a warm source."""
    src = np.random.default_rng(0).random((n_frames, n_vertices, 3))
    verts = np.empty_like(src)
    norms = np.empty_like(src)
    np.copyto(verts, src)  # touch the pages once
    np.copyto(norms, src)

    def fill():
        np.copyto(verts, src)
        np.copyto(norms, src)

    return median_time(fill, repeats) / n_frames * 1e6


# ----------------------------------------------------------------------------- the peer


def control_net(model: MuscleModel, rest_world: np.ndarray) -> np.ndarray:
    """The rest surface's control net (m, 8, 3): origin pole, sections, insertion pole."""
    axis = model._axis_points(rest_world[None], model.rest_q)[0]  # (n, 3)
    secs = np.asarray(model.rest_control_points).reshape(-1, OCT, 3)
    return np.concatenate([np.repeat(axis[:1, None], OCT, 1), secs, np.repeat(axis[-1:, None], OCT, 1)])


def geomdl_surface(net: np.ndarray, weights=None):
    """A degree (2, 2) geomdl surface through the net (m, 8, 3): clamped along (u), closed
    around (v) by wrapping the first 2 control points with a uniform (unclamped) knot vector."""
    try:
        from geomdl import BSpline, NURBS
    except ImportError as e:
        raise RuntimeError("geomdl is needed for the peer benchmark: pip install geomdl (or make bench)") from e
    m = net.shape[0]
    wrapped = np.concatenate([net, net[:, :2]], axis=1)  # (m, 10, 3)
    nv = wrapped.shape[1]
    surf = NURBS.Surface() if weights is not None else BSpline.Surface()
    surf.degree_u, surf.degree_v = 2, 2
    if weights is not None:
        w = np.repeat(np.concatenate([[1.0], weights, [1.0]])[:, None], nv, 1)
        pts = np.concatenate([wrapped * w[..., None], w[..., None]], axis=-1)  # weighted (x w, y w, z w, w)
        surf.ctrlpts_size_u, surf.ctrlpts_size_v = m, nv
        surf.ctrlptsw = pts.reshape(-1, 4).tolist()
    else:
        surf.ctrlpts_size_u, surf.ctrlpts_size_v = m, nv
        surf.ctrlpts = wrapped.reshape(-1, 3).tolist()
    inner = np.arange(1, m - 2) / (m - 2)
    surf.knotvector_u = [0.0, 0.0, 0.0] + inner.tolist() + [1.0, 1.0, 1.0]
    surf.knotvector_v = (np.arange(nv + 3) / (nv + 2)).tolist()
    return surf


def geomdl_tessellate(surf, resolution: tuple[int, int]) -> np.ndarray:
    """Evaluate at the axdf grid: ``along`` rows u in [0, 1] x ``around`` columns over the
    closed v range → (U, A, 3)."""
    along, around = resolution
    kv = surf.knotvector_v
    v0, v1 = kv[2], kv[len(kv) - 3]
    us = np.linspace(0.0, 1.0, along)
    vs = v0 + (v1 - v0) * np.arange(around) / around
    params = [(float(u), float(v)) for u in us for v in vs]
    return np.array(surf.evaluate_list(params)).reshape(along, around, 3)


def time_geomdl(model: MuscleModel, rest_world: np.ndarray, n_frames: int) -> tuple[float, float]:
    """(µs per muscle-frame, max |geomdl - axdf| at rest in metres). Each frame moves the net
    rigidly (so that nothing is cached) and tessellates it again."""
    net = control_net(model, rest_world)
    w = None if model.spec.weights is None else np.asarray(model.spec.weights)
    grid = geomdl_tessellate(geomdl_surface(net, w), model.spec.resolution)
    ref = np.asarray(model.rest_vertices, dtype=np.float64)
    verts = np.concatenate([grid[:1, 0], grid[1:-1].reshape(-1, 3), grid[-1:, 0]])
    err = float(np.abs(verts - ref).max())
    ts = []
    for f in range(n_frames):
        shift = np.array([0.001 * (f + 1), 0.0, 0.0])
        t0 = time.perf_counter()
        geomdl_tessellate(geomdl_surface(net + shift, w), model.spec.resolution)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)) * 1e6, err


# ----------------------------------------------------------------------------- writers


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


# ----------------------------------------------------------------------------- rendering


def render_fps(size=(512, 512), frames: int = 24, n_muscles: int = 6, verts: int = 1106) -> dict:
    """Frames per second of a demo-sized scene (6 muscles of 48x24, a bone); {'error': ...}
    when no GL context can be made."""
    from axdf_cli.errors import AxdfError
    from axdf_cli.render import benchmark_fps

    try:
        return benchmark_fps(size=size, n_muscles=n_muscles, verts=verts, frames=frames)
    except (AxdfError, ImportError, OSError) as e:
        return {"error": str(e).splitlines()[0]}


# ----------------------------------------------------------------------------- end to end


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


def end_to_end(job: Path, out: Path, fmt: str = "ply", contact: bool = False) -> dict:
    """``axdf run JOB --no-render`` in a subprocess: wall time, frames, peak memory; without
    contact unless ``contact`` (the default of axdf run)."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import plan_run

    r = run_subprocess(["run", str(job), "--out", str(out), "--format", fmt, "--no-render", "--quiet"]
                       + ([] if contact else ["--no-contact"]))
    if r["rc"] != 0:
        raise RuntimeError(f"axdf run {job} failed ({r['rc']}): {r['stderr'][-400:]}")
    plan = plan_run(load_job(job), out_arg=str(out))
    r.update(frames=len(plan.frames), muscles=len(plan.models))
    return r


def _cum(stats: pstats.Stats, file_end: str, func: str) -> float:
    return sum(v[3] for (f, _, fn), v in stats.stats.items() if fn == func and f.endswith(file_end))


def profile_run(job: Path, out: Path, fmt: str = "ply", top: int = 0) -> dict:
    """Run ``execute`` in-process under cProfile (no rendering): seconds in evaluation (the
    pipeline's pre-pass, chunks and surfaces: ``pipeline.evaluate``), in writing (encode, sha256, atomic
    writes) and in total; ``top`` functions by own time as text."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import execute, plan_run

    t0 = time.perf_counter()
    plan = plan_run(load_job(job), out_arg=str(out), fmt_arg=fmt, stages=NO_CONTACT)
    t_plan = time.perf_counter() - t0
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.runcall(execute, plan)
    total = time.perf_counter() - t0
    st = pstats.Stats(prof)
    # evaluation: the pre-pass (twist references, time stages' states), the chunks (kinematics,
    # axis points, time stages) and their surfaces (RMF, surface, frame stages), as the mesh pass reads them
    ev = (_cum(st, "evaluate.py", "prepare") + _cum(st, "evaluate.py", "evaluate_plan")
          + _cum(st, "evaluate.py", "_surfaces"))
    enc = _cum(st, f"{fmt}.py", "encode")
    wr = _cum(st, "runfolder.py", "write")  # OutputWriter.write: sha256 + atomic write
    text = ""
    if top:
        buf = io.StringIO()
        pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(top)
        text = buf.getvalue()
    return {"plan": t_plan, "total": total, "evaluation": ev, "writing": enc + wr, "encode": enc,
            "muscle_frames": len(plan.frames) * len(plan.models), "top": text}


# ----------------------------------------------------------------------------- packed formats

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
from benchmarks.bench import stretched_pose
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
        target = f"<= {TARGET_PACKED:g}x {_mark(ratio <= TARGET_PACKED)}" if fmt in ("pc2", "npz") else "reported"
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


# ----------------------------------------------------------------------------- data sets

DATASET_FILE = ROOT / "poses" / "datasets" / "gait2392_random.yaml"
DATASET_SAMPLES = 1000
TARGET_DATASET_SCALING = 1.7  # samples/s with 2 workers over 1 worker, on 2 cores


def time_dataset(n_samples: int, jobs: int, out: Path) -> dict:
    """``axdf dataset build`` of the first ``n_samples`` sequences of DATASET_FILE (one frame,
    one view each; a shard 0/K of its 1000), in process: wall seconds and per-stage seconds."""
    from axdf_cli.dataset import engine
    from axdf_cli.dataset.worker import build_context
    from axdf_cli.specs import RefPolicy

    ctx = build_context(DATASET_FILE, policy=RefPolicy.for_command([DATASET_FILE]))
    shard = (0, max(1, len(ctx.sequences) // n_samples))
    t0 = time.perf_counter()
    res = engine.build(DATASET_FILE, out, jobs=jobs, shard=shard, ctx=ctx, overwrite=True)
    return {"samples": res.built_samples, "wall": time.perf_counter() - t0, "timing": res.timing,
            "renderer": res.gl_renderer}


def dataset_evaluation(n_sequences: int) -> float:
    """Seconds per sample of the evaluation inside a sequence's run (twist references,
    kinematics, ``evaluate``), timed alone on the data set's first sequences."""
    from axdf_cli.dataset import door
    from axdf_cli.dataset.worker import build_context, sequence_pose
    from axdf_cli.pipeline import evaluate_chunks
    from axdf_cli.specs import RefPolicy

    ctx = build_context(DATASET_FILE, policy=RefPolicy.for_command([DATASET_FILE]))
    t = 0.0
    n = 0
    for seq in ctx.sequences[:n_sequences]:
        pose, frames = sequence_pose(ctx, seq)
        plan = door.sequence_plan(pose, frames, ctx.muscles, ctx.models, "ply", Path("unused"), {}, ctx.stages)
        t0 = time.perf_counter()
        for _, _, results in evaluate_chunks(plan):
            for _ in results:
                pass
        t += time.perf_counter() - t0
        n += len(frames)
    return t / max(n, 1)


def dataset_rows(table: "Table", n_samples: int, tmp: Path) -> None:
    """Samples per second at 1 and 2 workers, their ratio, and where a sample's time goes."""
    rel = DATASET_FILE.relative_to(ROOT)
    table.section(f"data sets: axdf dataset build {rel}, {n_samples} samples (92 muscles, 1 frame, one 256x256 "
                  "view, PNG + EXR, PLY meshes), in process")
    one = time_dataset(n_samples, 1, tmp / "dataset-1")
    shutil.rmtree(tmp / "dataset-1", ignore_errors=True)
    two = time_dataset(n_samples, 2, tmp / "dataset-2")
    shutil.rmtree(tmp / "dataset-2", ignore_errors=True)
    r1, r2 = one["samples"] / one["wall"], two["samples"] / two["wall"]
    table.add("dataset, 1 worker", f"{r1:.2f} samples/s", f"{one['wall']:.0f} s for {one['samples']}")
    table.add("dataset, 2 workers (process pool)", f"{r2:.2f} samples/s", f"1 worker {r1:.2f} samples/s",
              f"{r2 / r1:.2f}x", f">= {TARGET_DATASET_SCALING:g}x {_mark(r2 / r1 >= TARGET_DATASET_SCALING)}")
    t = {k: v * 1000 / max(one["samples"], 1) for k, v in one["timing"].items()}
    ev = dataset_evaluation(min(20, n_samples)) * 1000
    writing = t["run"] - ev + t["write"]
    table.add("per sample, 1 worker: evaluation / writing / rendering", f"{ev:.0f} / {writing:.0f} / {t['render']:.0f} ms",
              f"of {1000 / r1:.0f} ms; meshes read back {t['read']:.0f} ms")
    table.add("  (writing = the run's meshes, tables, manifest", f"{t['run'] - ev:.0f} ms",
              f"+ labels, PNG, EXR {t['write']:.0f} ms)")
    # CPU seconds (all threads) per sample, summed over workers: on a machine shared with other
    # jobs the wall-clock ratio above depends on their load; this does much less
    c1 = one["timing"]["cpu"] / max(one["samples"], 1) * 1000
    c2 = two["timing"]["cpu"] / max(two["samples"], 1) * 1000
    table.add("CPU per sample: 1 worker / 2 workers", f"{c1:.0f} / {c2:.0f} ms",
              f"2 idle cores: <= {2 * c1 / c2:.2f}x", f"{c2 / c1:.2f}x CPU")


# ----------------------------------------------------------------------------- rendering over processes


def run_jobs(job: Path, out: Path, jobs: int, frames: str | None = None) -> dict:
    """``axdf run JOB --jobs N`` (meshes and frames, as the job says) in a subprocess: wall
    seconds, with the load average of the minute before it started (the machine may be shared)."""
    load = os.getloadavg()[0]
    args = ["run", str(job), "--out", str(out), "--overwrite", "--jobs", str(jobs), "--quiet", "--no-contact"]
    r = run_subprocess(args + (["--frames", frames] if frames else []))
    if r["rc"] != 0:
        raise RuntimeError(f"axdf run {job} --jobs {jobs} failed ({r['rc']}): {r['stderr'][-400:]}")
    r["load"] = load
    return r


def render_jobs_rows(table: "Table", tmp: Path, quick: bool) -> None:
    """``make demo``'s first job at --jobs 1 and --jobs 2 (the frames split over render workers)."""
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import plan_run

    frames = "0:191:2" if quick else None
    plan = plan_run(load_job(DEMO_JOB), out_arg=str(tmp / "unused"), frames_arg=frames)
    w, h = plan.render.size
    table.section(f"rendering over processes: axdf run {DEMO_JOB.relative_to(ROOT)} ({len(plan.models)} muscles x "
                  f"{len(plan.frames)} frames, meshes + {w}x{h} PNG + EXR; subprocess) at --jobs 1 and --jobs 2")
    one = run_jobs(DEMO_JOB, tmp / "jobs-1", 1, frames)
    two = run_jobs(DEMO_JOB, tmp / "jobs-2", 2, frames)
    shutil.rmtree(tmp / "jobs-1", ignore_errors=True)
    shutil.rmtree(tmp / "jobs-2", ignore_errors=True)
    n = len(plan.frames)
    table.add("axdf run --jobs 1", f"{one['wall']:.1f} s", f"{n / one['wall']:.1f} frames/s; load before {one['load']:.2f}")
    table.add("axdf run --jobs 2 (frames over 2 render workers)", f"{two['wall']:.1f} s",
              f"--jobs 1 {one['wall']:.1f} s; load before {two['load']:.2f}", f"{one['wall'] / two['wall']:.2f}x",
              f"faster than --jobs 1 {_mark(two['wall'] < one['wall'])}")


# ----------------------------------------------------------------------------- retargeting

CMU_BVH = ROOT.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"
CMU_MAP = ROOT / "poses" / "maps" / "cmu_to_gait2392.yaml"


def jacobian_times(rmap, repeats: int) -> tuple[float, float, float]:
    """µs per Jacobian of the map's points at one pose: analytic (``point_jacobian``) and central
    differences batched as 2C + 1 frames of one ``forward_kinematics`` call; and their largest
    difference (metres per unit)."""
    from axdf_cli.tools.retarget import model_points
    from axdf_cli.model.ik import pose_points, subskeleton
    from axdf_cli.model.skeleton import dof_frames, point_jacobian

    mp = model_points(rmap)
    skel, old = subskeleton(rmap.skeleton, mp.bones)
    bones = np.searchsorted(old, mp.bones)
    q = mp.samples[1]
    n = len(q)

    def analytic():
        world, frames = dof_frames(skel, q[None])
        return point_jacobian(skel, frames, world, bones, mp.local)[1][0]

    h = 1e-6
    steps = np.concatenate([np.zeros((1, n)), h * np.eye(n), -h * np.eye(n)])

    def batched():
        pts = pose_points(skel, q + steps, bones, mp.local)  # (2C + 1, P, 3)
        return np.moveaxis((pts[1:n + 1] - pts[n + 1:]) / (2 * h), 0, -1)

    diff = float(np.abs(analytic() - batched()).max())
    return median_time(analytic, repeats) * 1e6, median_time(batched, repeats) * 1e6, diff


def retarget_rows(table: "Table", quick: bool) -> None:
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.tools.retarget import load_map, retarget

    if not CMU_BVH.is_file():
        table.section("retargeting: the CMU walk is not here (../shared/data/bvh); skipped")
        return
    rmap = load_map(CMU_MAP)
    table.section(f"retargeting: {CMU_BVH.name} onto gait2392 ({len(rmap.points)} points; map "
                  f"{CMU_MAP.relative_to(ROOT)}), per-frame least squares warm-started from the previous frame")
    for step in ((4,) if quick else (4, 1)):
        mocap = read_motion(CMU_BVH, step=step)
        t0 = time.perf_counter()
        res = retarget(rmap, mocap)
        dt = time.perf_counter() - t0
        n = len(res.fit.q)
        table.add(f"fit {n} frames at {mocap.fps:g} fps ({len(res.points.free)} coordinates)", f"{n / dt:.0f} frames/s",
                  f"{dt:.1f} s; {res.fit.evaluations.mean():.1f} evaluations per frame")
    a, b, diff = jacobian_times(rmap, 20 if quick else 100)
    table.add("Jacobian: analytic (point_jacobian)", f"{a:.0f} µs", f"batched central differences {b:.0f} µs",
              f"{b / a:.1f}x", f"max |Δ| {diff:.1e}")


# ----------------------------------------------------------------------------- --long

LONG_SCRIPT = r"""
import json, sys, time
import numpy as np
from benchmarks.bench import stretched_pose
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, evaluate_chunks, chunk_frames
job, n = sys.argv[1], int(sys.argv[2])
plan = plan_run(load_job(job), stages={"contact": False})
plan.pose = stretched_pose(plan.pose, n)
plan.frames = plan.pose.frames
nm = len(plan.models)
stats = np.zeros((n, nm, 6))
files = {}
t0 = time.perf_counter()
for sl, world, results in evaluate_chunks(plan):
    for j, res in results:  # what execute keeps per muscle-frame: float32 meshes, stats, file list
        pos = res.vertices.astype(np.float32); nrm = res.normals.astype(np.float32)
        stats[sl, j, 0] = res.length; stats[sl, j, 1] = res.volume
        for f in plan.frames[sl]:
            files[f"meshes/{plan.names[j]}/{plan.names[j]}_{int(f):04d}.ply"] = "%064x" % (f * nm + j)
dt = time.perf_counter() - t0
manifest = json.dumps({"files": files}, indent=1)
# VmHWM: this process's own peak (ru_maxrss would include the forking parent's, kept across exec)
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) * 1024
print(json.dumps({"seconds": dt, "muscle_frames": n * nm, "chunk": chunk_frames(plan),
                  "manifest_bytes": len(manifest), "maxrss": hwm}))
"""


def time_chunks(plan, repeats: int) -> float:
    """Median seconds of evaluating every selected frame of ``plan`` (all muscles, no writing)
    through ``evaluate_plan``, its pre-pass (twist references, TIME stages' block states)
    included."""
    return time_pair(plan, plan, repeats)[0]


def time_pair(a, b, repeats: int) -> tuple[float, float]:
    """Median seconds of evaluating plans ``a`` and ``b`` (as :func:`time_chunks`), timed in
    turn (a, b, a, b, ...): on a shared machine both see the same load."""
    from axdf_cli.pipeline.evaluate import evaluate_plan

    def once(plan):
        t0 = time.perf_counter()
        for _, results in evaluate_plan(plan):
            for _ in results:
                pass
        return time.perf_counter() - t0

    ts = [(once(a), once(b)) for _ in range(max(1, repeats))]
    return float(np.median([t[0] for t in ts])), float(np.median([t[1] for t in ts]))


def time_jiggle_stage(plan, repeats: int) -> tuple[float, int]:
    """Median seconds of the jiggle stage alone over the pose's frames from its first to the
    last selected (the axis placed once, outside the timing), and the number of jiggling
    muscles."""
    from axdf_cli.pipeline.evaluate import TIME_BLOCK, _chunk
    from axdf_cli.pipeline.jiggle_stage import JiggleStage

    stage = JiggleStage()
    which = list(range(len(plan.models)))
    frames = plan.pose.frames[plan.pose.frames <= plan.frames.max()]
    chunks = [_chunk(plan, slice(s, s + TIME_BLOCK), frames[s:s + TIME_BLOCK], which)
              for s in range(0, len(frames), TIME_BLOCK)]

    def once():
        state = stage.start(plan)
        for ck in chunks:
            state, _ = stage(state, ck)

    return median_time(once, repeats), len(stage.start(plan).muscles)


def jiggle_rows(table: "Table", reps: int) -> None:
    """Rows 10: the jiggle stage's cost on the gait2392 walk (or the demo when not shipped)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job

    job = load_job(GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB)
    base = plan_run(job, stages=NO_CONTACT)
    plan = dataclasses.replace(base, frames=base.pose.frames)  # the whole trial
    off = dataclasses.replace(plan, stages=())
    nm, nf = len(plan.models), len(plan.frames)
    mf = nm * nf
    t_on, t_off = time_pair(plan, off, reps)
    t_stage, n_jig = time_jiggle_stage(plan, reps)
    table.section(f"jiggle ({plan.pose.name}: {nm} muscles, {n_jig} with jiggle, {nf} frames): evaluate_plan "
                  "(all muscles, no writing) with the stage vs without")
    table.add("evaluate with jiggle", f"{t_on / mf * 1e6:.1f} µs/mf", f"without {t_off / mf * 1e6:.1f} µs/mf",
              f"{t_on / t_off:.3f}x")
    table.add("the jiggle stage alone (axis placed outside)", f"{t_stage / mf * 1e6:.2f} µs/mf",
              f"{t_stage / (n_jig * nf) * 1e6:.2f} µs per jiggling muscle-frame")
    every4 = dataclasses.replace(plan, frames=plan.frames[::4])
    t_sub, t_sub_off = time_pair(every4, dataclasses.replace(every4, stages=()), reps)
    per = nm * len(every4.frames)
    table.add("--frames every 4th (frames between advanced too)", f"{t_sub / per * 1e6:.1f} µs/mf",
              f"without {t_sub_off / per * 1e6:.1f} µs/mf", f"{t_sub / t_sub_off:.3f}x")


def long_memory(job: Path, n_frames: int = LONG_FRAMES) -> dict:
    """Stream ``n_frames`` (the job's pose stretched) x all muscles through evaluate_chunks in
    a subprocess, keeping what ``execute`` keeps (stats, the manifest's file list); peak RSS."""
    import json

    t0 = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", LONG_SCRIPT, str(job), str(n_frames)], cwd=ROOT,
                       capture_output=True, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"long run failed: {p.stderr[-600:]}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r["wall"] = time.perf_counter() - t0
    return r


# ----------------------------------------------------------------------------- the compiled pass

TARGET_RUN_US = 20.0  # a whole run (npz, 92 muscles, 48x24) per muscle-frame, after start-up
TARGET_SAMPLE_MS = 10.0  # 92 muscles x 1 frame (a data-set sample's evaluation)
RUN_FRAMES = 1051  # the walk stretched to this many frames for the whole-run row

RUN_SCRIPT = r"""
import dataclasses, json, os, resource, sys, time
t_start = time.perf_counter()
from pathlib import Path
from benchmarks.bench import stretched_pose
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, execute
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.skeleton import forward_kinematics
job, n, fmt, out, res, profile = sys.argv[1], int(sys.argv[2]), sys.argv[3], Path(sys.argv[4]), sys.argv[5], sys.argv[6]
plan = plan_run(load_job(job), out_arg=str(out), fmt_arg=None if fmt == "none" else fmt, stages={"contact": False})
if res != "library":
    skel = plan.pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    plan.muscles = [dataclasses.replace(s, resolution=tuple(map(int, res.split("x")))) for s in plan.muscles]
    plan.models = [MuscleModel(s, skel.bone_index, rest, skel) for s in plan.muscles]
plan.pose = stretched_pose(plan.pose, n)
plan.frames = plan.pose.frames
plan.render = dataclasses.replace(plan.render, enabled=False)
if fmt == "none":
    plan.formats = ()
def cpu():
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime
t_ready, c0 = time.perf_counter(), cpu()
if profile != "-":
    import cProfile, io, pstats
    prof = cProfile.Profile()
    prof.runcall(execute, plan, overwrite=True)
    buf = io.StringIO()
    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(int(profile))
    top = buf.getvalue()
else:
    execute(plan, overwrite=True)
    top = ""
dt, dc = time.perf_counter() - t_ready, cpu() - c0
nbytes = sum(p.stat().st_size for p in out.rglob("*") if p.is_file())
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:")) * 1024
print(json.dumps({"startup": t_ready - t_start, "seconds": dt, "cpu": dc, "bytes": nbytes, "top": top,
                  "maxrss": hwm, "muscle_frames": len(plan.frames) * len(plan.models)}))
"""


def whole_run(job: Path, n_frames: int, fmt: str, out: Path, resolution: str = "48x24", top: int = 0) -> dict:
    """``execute`` of ``job`` (pose stretched to ``n_frames``, muscles at ``resolution`` or
    "library") in a subprocess: start-up (imports, plan, models) and run seconds (wall and CPU
    of all threads), bytes written, muscle-frames; cProfile's ``top`` functions when asked."""
    import json

    shutil.rmtree(out, ignore_errors=True)
    p = subprocess.run([sys.executable, "-c", RUN_SCRIPT, str(job), str(n_frames), fmt, str(out), resolution,
                        str(top) if top else "-"], cwd=ROOT, capture_output=True, text=True)
    shutil.rmtree(out, ignore_errors=True)
    if p.returncode != 0:
        raise RuntimeError(f"whole run ({fmt}) failed: {p.stderr[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def tofile_seconds(nbytes: int, folder: Path, block: int = 64 << 20) -> float:
    """Seconds for ``ndarray.tofile`` to write ``nbytes`` into one new file, 64 MiB at a time
    (after os.sync(), as the run starts with no dirty pages of its own)."""
    data = np.random.default_rng(0).random(block // 8)
    path = folder / "tofile.raw"
    os.sync()
    t0 = time.perf_counter()
    with open(path, "wb") as fh:
        left = nbytes
        while left > 0:
            data[:max(1, min(left, block) // 8)].tofile(fh)
            left -= block
    dt = time.perf_counter() - t0
    path.unlink(missing_ok=True)
    return dt


COMPILE_SCRIPT = r"""
import json, sys, time
t0 = time.perf_counter()
from pathlib import Path
from axdf_cli.specs import load_job
from axdf_cli.pipeline import plan_run, evaluate_plan
t1 = time.perf_counter()
plan = plan_run(load_job(sys.argv[1]), out_arg="unused", frames_arg="0:1", stages={"contact": False})
t2 = time.perf_counter()
for chunk, results in evaluate_plan(plan):
    for _ in results:
        pass
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "plan": t2 - t1, "evaluate": t3 - t2}))
"""


def compile_cost(job: Path, cache: Path) -> dict:
    """Start-up of a two-frame evaluation in a subprocess whose numba cache is ``cache``:
    seconds to import, plan (the models: the first compiled calls) and evaluate."""
    import json

    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    p = subprocess.run([sys.executable, "-c", COMPILE_SCRIPT, str(job)], cwd=ROOT, capture_output=True, text=True,
                       env=env)
    if p.returncode != 0:
        raise RuntimeError(f"compile-cost run failed: {p.stderr[-600:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def first_touch(job: Path, repeats: int) -> tuple[float, float, int]:
    """µs per muscle-frame of the compiled step 1b (every muscle of a chunk of
    ``chunk_frames`` frames, :meth:`MuscleBatch.surfaces`) into fresh memory (every output
    page faulted in and zeroed by the kernel on first touch) and in steady state (the batch's
    buffers reused, warm); and the chunk's frames."""
    from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates
    from axdf_cli.pipeline import chunk_frames, plan_run
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(job), out_arg="unused", stages=NO_CONTACT)
    batch = __import__("axdf_cli.pipeline.evaluate", fromlist=["batch_of"]).batch_of(plan)
    nf = chunk_frames(plan)
    frames = plan.pose.frames[:nf]
    q = sample_coordinates(plan.pose, frames)
    world = forward_kinematics(plan.pose.skeleton, q)
    act = sample_activation(plan.pose, plan.names, frames)
    every = list(range(len(plan.models)))
    tension = np.stack([effective_tension(s.tension, act[:, j]) for j, s in enumerate(plan.muscles)], axis=1)
    p, _ = batch.axis_points(world, q, every)
    mf = len(every) * len(frames)

    def once():
        batch.surfaces(world, p, tension, None, every)

    once()
    batch.pool.free = False  # np.empty each call: fresh pages
    cold = median_time(once, repeats)
    batch.pool.free = True
    once()
    warm = median_time(once, repeats)
    return cold / mf * 1e6, warm / mf * 1e6, len(frames)


def compiled_rows(table: "Table", tmp: Path, quick: bool, top: int = 0) -> list[str]:
    """The compiled pass: a whole run per muscle-frame against tofile of the
    same bytes, the data-set sample's evaluation (92 muscles x 1 frame), the first-touch cost
    of a chunk's outputs, and numba's first-run compile cost. Returns cProfile texts (``top``)."""
    job = GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB
    n = 200 if quick else RUN_FRAMES
    runs = {fmt: whole_run(job, n, fmt, tmp / f"run-{fmt}", top=top) for fmt in ("none", "npz")}
    r, base = runs["npz"], runs["none"]
    mf = r["muscle_frames"]
    ref = tofile_seconds(r["bytes"], tmp)
    table.section(f"the compiled pass: axdf run {job.relative_to(ROOT)}, walk stretched to {n} frames, "
                  f"{mf // n} muscles at 48x24, no render (subprocess; after start-up; wall and CPU of all threads)")
    table.add(f"whole run --format npz ({r['bytes'] / 2**20:.0f} MiB)", f"{r['seconds'] / mf * 1e6:.1f} µs/mf",
              f"CPU {r['cpu'] / mf * 1e6:.1f} µs/mf; tofile {ref / mf * 1e6:.1f} µs/mf", f"{r['seconds'] / ref:.1f}x tofile",
              f"<= {TARGET_RUN_US:g} µs/mf {_mark(r['seconds'] / mf * 1e6 <= TARGET_RUN_US)}")
    table.add("whole run, no meshes (evaluation, stats, manifest)", f"{base['seconds'] / mf * 1e6:.1f} µs/mf",
              f"CPU {base['cpu'] / mf * 1e6:.1f} µs/mf")
    table.add("peak memory: npz / no meshes", f"{r['maxrss'] / 2**20:.0f} / {base['maxrss'] / 2**20:.0f} MiB")
    table.add("start-up (imports, plan, 92 models)", f"{r['startup']:.2f} s")
    cold, warm, nf = first_touch(job, 3 if quick else 7)
    table.add(f"step 1b, {mf // n} muscles x {nf} frames, outputs in fresh memory", f"{cold:.1f} µs/mf",
              f"steady state (buffers reused) {warm:.1f} µs/mf", f"{cold / warm:.2f}x first touch")
    if DATASET_FILE.is_file():
        ms = dataset_evaluation(5 if quick else 20) * 1000
        table.add("92 muscles x 1 frame (a data-set sample's evaluation)", f"{ms:.1f} ms", "",
                  "", f"<= {TARGET_SAMPLE_MS:g} ms {_mark(ms <= TARGET_SAMPLE_MS)}")
    empty = tmp / "numba-cache"
    cold_c = compile_cost(job, empty)
    warm_c = compile_cost(job, empty)
    first = cold_c["plan"] + cold_c["evaluate"]
    again = warm_c["plan"] + warm_c["evaluate"]
    table.add("numba: first run (empty cache; compiles)", f"{first:.1f} s", f"cached {again:.2f} s",
              f"{first - again:.1f} s compiling")
    return [f"== whole run --format {fmt} ==\n{v['top']}" for fmt, v in runs.items() if v.get("top")]


# ----------------------------------------------------------------------------- the table


#: Contact may at most double evaluation, and its targets on the walk.
TARGET_CONTACT_COST = 2.0
TARGET_INSIDE_MUSCLE = 0.02
TARGET_INSIDE_BONE = 0.005
TARGET_DEPTH = 0.003


#: A muscle-frame pops when a vertex steps more than this times its largest no-contact step.
POP_RATIO = 1.5


def contact_pass(plan) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
    """Evaluate every frame of ``plan`` (with its stages): wall time (s), the contact measures
    (F, M, 3) (zeros where no stage measured), each muscle's largest vertex step from the
    previous frame of the plan (F, M; row 0 zero) and its volume (F, M)."""
    from axdf_cli.pipeline.evaluate import evaluate_plan

    nf, nm = len(plan.frames), len(plan.models)
    out = np.zeros((nf, nm, 3))
    step = np.zeros((nf, nm))
    vol = np.zeros((nf, nm))
    prev: dict = {}
    t0 = time.perf_counter()
    for chunk, results in evaluate_plan(plan):
        for j, r in results:
            rows = np.arange(nf)[chunk.rows]
            if r.contact is not None:
                out[rows, j] = r.contact
            vol[rows, j] = r.volume
            v = np.concatenate([prev[j][None], r.vertices]) if j in prev else r.vertices
            d = np.linalg.norm(np.diff(v, axis=0), axis=-1).max(axis=-1)
            step[rows[1:] if j not in prev else rows, j] = d
            prev[j] = r.vertices[-1].copy()
    return time.perf_counter() - t0, out, step, vol


def bones_by_libigl(plan) -> tuple[float, float, float, int]:
    """What a bone's mesh says, not its field: every frame of ``plan`` (its stages, contact
    included) evaluated again (apart from :func:`contact_pass`, which is timed), and every vertex within 1 cm of a bone's mesh box
    tested by libigl's signed distance to that mesh (the fast-winding-number sign, as the
    fields are made). Returns (share of the vertices inside a bone by libigl, the same by the
    product's measure (stats.csv's inside_bone, weighted by vertices), the deepest point in a
    bone by libigl (m), frames read)."""
    import igl

    from axdf_cli.pipeline.evaluate import evaluate_plan

    meshes = {i: (np.asarray(v, np.float64), np.asarray(f, np.int64)) for i, (v, f, _) in plan.bone_meshes.items()}
    n_all = n_in = 0
    field = deep = 0.0
    for chunk, results in evaluate_plan(plan):
        results = list(results)
        for fi in range(len(chunk.frames)):
            X = np.concatenate([r.vertices[fi] for _, r in results]).astype(np.float64)
            nv = np.array([len(r.vertices[fi]) for _, r in results], dtype=np.float64)
            field += float(sum(n * r.contact[fi, 1] for n, (_, r) in zip(nv, results) if r.contact is not None))
            sd = np.full(len(X), np.inf)
            inv = np.linalg.inv(chunk.world[fi])
            for b, (bv, bf) in meshes.items():
                y = X @ inv[b, :3, :3].T + inv[b, :3, 3]
                near = np.all((y > bv.min(axis=0) - 0.01) & (y < bv.max(axis=0) + 0.01), axis=1)
                if near.any():
                    d = igl.signed_distance(y[near], bv, bf, sign_type=igl.SIGNED_DISTANCE_TYPE_FAST_WINDING_NUMBER)[0]
                    sd[near] = np.minimum(sd[near], d)
            n_all += len(X)
            n_in += int((sd < 0).sum())
            deep = max(deep, float(-sd.min()))
    return n_in / max(n_all, 1), field / max(n_all, 1), deep, len(plan.frames)


def rajagopal_plan(tmp: Path, stages=None, packed: bool = False):
    """Rajagopal2016 over its running stride (tests/data/rajagopal2016, imported without bone
    meshes into ``tmp``: the contact is muscle against muscle only); ``packed``: its muscles
    packed by ``axdf pack --pose`` over the stride (timed: the row "axdf pack")."""
    from axdf_cli.cli.main import main as axdf_main
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import RefPolicy

    data = ROOT / "tests" / "data" / "rajagopal2016"
    imp = tmp / "rajagopal2016"
    if not imp.is_dir():
        rc = axdf_main(["import", "osim", str(data / "Rajagopal2016.osim"), "--motion", str(data / "run_stride_ik.mot"),
                        "--name", "rajagopal2016", "--no-meshes", "--out", str(imp), "-q"])
        if rc != 0:
            raise RuntimeError(f"axdf import osim Rajagopal2016 failed ({rc})")
    muscles = imp / "muscles"
    if packed:
        muscles = tmp / "rajagopal2016_packed"
        if not muscles.is_dir():
            skel = imp / "skeletons" / "rajagopal2016.yaml"
            t0 = time.perf_counter()
            rc = axdf_main(["pack", str(imp / "muscles"), "--skeleton", str(skel), "--pose",
                            str(imp / "run_stride_ik.yaml"), "--out", str(muscles), "--allow-outside", "-q"])
            PACK_TIMES["Rajagopal2016"] = time.perf_counter() - t0
            if rc != 0:
                raise RuntimeError(f"axdf pack Rajagopal2016 failed ({rc})")
    return plan_run(None, muscle_args=[str(muscles)], pose_arg=str(imp / "run_stride_ik.yaml"),
                    policy=RefPolicy(allow_outside=True), stages=stages)


#: How long ``axdf pack`` took, by model (seconds; filled by :func:`rajagopal_plan`).
PACK_TIMES: dict = {}


def pack_rows(table: "Table") -> None:
    """The shipped packed gait2392 library's report (muscles/gait2392_packed/pack_report.json,
    made by ``make pack``): the rest pose's overlap and volumes before and after packing, and
    the packing times measured here."""
    rep = ROOT / "muscles" / "gait2392_packed" / "pack_report.json"
    if not rep.is_file():
        return
    r = json.loads(rep.read_text())
    b, a = r["before"], r["after"]
    table.section("axdf pack (rest pose; gait2392: muscles/gait2392_packed/pack_report.json)")
    table.add("gait2392 rest: vertices inside another muscle", f"{a['inside_muscle'] * 100:.2f}%",
              f"as imported {b['inside_muscle'] * 100:.2f}%")
    table.add("gait2392 rest: vertices inside a bone", f"{a['inside_bone'] * 100:.2f}%",
              f"as imported {b['inside_bone'] * 100:.2f}%")
    table.add("gait2392 rest: volume kept", f"median {a['volume_ratio_median']:.3f}",
              f"least {a['volume_ratio_min']:.3f}", f"total {a['volume_total'] * 1000:.2f} / {b['volume_total'] * 1000:.2f} L")
    for k, t in PACK_TIMES.items():
        table.add(f"axdf pack {k}", f"{t:.0f} s")


def contact_rows(table: "Table", quick: bool, tmp: Path | None = None) -> None:
    """The shipped gait2392 walk (every frame; every 6th with --quick; with the muscles as
    imported, packed, and the atlas library, whose cost per muscle-frame is set beside the
    others'), its CMU walk, arm26's
    elbow flexion (as imported and packed) and Rajagopal2016's running stride (muscles only:
    imported without bone meshes): evaluation without any stage, with the penetration stage
    alone (--penetration: measures only), and with contact;
    the shares of vertices inside another muscle and inside a bone (mean over muscle-frames),
    the deepest penetration, the volume, and the muscle-frames whose largest vertex step from
    the previous frame exceeds POP_RATIO times the no-contact one (pops)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.stages import ContactStage
    from axdf_cli.specs import load_job

    frames = "18:84:6" if quick else None
    cases = [("gait2392 walk, muscles as imported", lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames,
                                                                         muscle_args=[str(GAIT_MUSCLES)], stages=sw)),
             ("gait2392 walk, packed (axdf pack --pose: the job's muscles)",
              lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames, stages=sw)),
             ("gait2392 walk, the atlas library (muscles/gait2392_atlas: fitted to the Visible Human)",
              lambda sw: plan_run(load_job(GAIT_JOB), frames_arg=frames, muscle_args=[str(ATLAS_MUSCLES)], stages=sw)),
             ("CMU walk retargeted onto gait2392, packed (not the motion packed over)",
              lambda sw: plan_run(load_job(CMU_GAIT_JOB), frames_arg="0:248:24" if quick else None, stages=sw)),
             ("arm26 elbow flexion, muscles as imported", lambda sw: plan_run(
                 load_job(ARM_JOB), muscle_args=[str(ARM_MUSCLES)], stages=sw)),
             ("arm26 elbow flexion, packed (axdf pack --pose: the job's muscles)",
              lambda sw: plan_run(load_job(ARM_JOB), stages=sw))]
    if tmp is not None:
        cases.append(("Rajagopal2016 run, no bones", lambda sw: rajagopal_plan(tmp, sw)))
        cases.append(("Rajagopal2016 run, no bones, packed", lambda sw: rajagopal_plan(tmp, sw, packed=True)))
    for label, make in cases:
        plans = {k: make(sw) for k, sw in
                 (("none", {"contact": False, "penetration": False}),
                  ("measure", {"contact": False, "penetration": True}),
                  ("contact", {"contact": True, "penetration": True}))}
        t0 = time.perf_counter()
        ContactStage().start(plans["contact"])  # the bone fields (from the disk cache after the first run)
        t_fields = time.perf_counter() - t0
        plan = plans["contact"]
        mf = len(plan.frames) * len(plan.models)
        contact_pass(plans["none"])  # compiled code loaded, caches warm
        contact_pass(dataclasses.replace(plan, frames=plan.frames[:2]))  # contact's too (compiled after an edit)
        t_none, _, step0, vol0 = contact_pass(plans["none"])
        t_meas, before, _, _ = contact_pass(plans["measure"])
        t_con, after, step1, vol1 = contact_pass(plan)
        table.section(f"contact ({label}, {len(plan.frames)} frames x {len(plan.models)} muscles; bone fields "
                      f"{t_fields:.1f} s)")
        us = lambda t: t / mf * 1e6  # noqa: E731
        table.add("evaluate with contact", f"{us(t_con):.0f} µs/mf", f"without {us(t_none):.0f} µs/mf",
                  f"{t_con / t_none:.2f}x", f"<= {TARGET_CONTACT_COST:g}x {_mark(t_con / t_none <= TARGET_CONTACT_COST)}")
        table.add("evaluate, measures only (--penetration)", f"{us(t_meas):.0f} µs/mf",
                  f"without {us(t_none):.0f} µs/mf", f"{t_meas / t_none:.2f}x")
        for k, (what, target) in enumerate((("vertices inside another muscle", TARGET_INSIDE_MUSCLE),
                                            ("vertices inside a bone", TARGET_INSIDE_BONE))):
            a, b = after[..., k].mean(), before[..., k].mean()
            table.add(what, f"{a * 100:.2f}%", f"before {b * 100:.2f}%", f"{a / max(b, 1e-12):.3f}x",
                      f"<= {target * 100:g}% {_mark(a <= target)}")
        a, b = after[..., 2].max(), before[..., 2].max()
        table.add("deepest penetration", f"{a * 1000:.1f} mm", f"before {b * 1000:.1f} mm",
                  f"{a / max(b, 1e-12):.2f}x", f"<= {TARGET_DEPTH * 1000:g} mm {_mark(a <= TARGET_DEPTH)}")
        deep_a, deep_b = after[..., 2], before[..., 2]
        table.add(f"muscle-frames deeper than {TARGET_DEPTH * 1000:g} mm", f"{(deep_a > TARGET_DEPTH).sum()}",
                  f"before {(deep_b > TARGET_DEPTH).sum()} of {deep_a.size}",
                  f"> 5 mm: {(deep_a > 0.005).sum()} (before {(deep_b > 0.005).sum()})",
                  f"p99 {np.percentile(deep_a, 99) * 1000:.1f} mm (before {np.percentile(deep_b, 99) * 1000:.1f})")
        if plan.bone_meshes:
            exact, field, deep, nb = bones_by_libigl(plan)
            table.add("vertices inside a bone by the meshes (libigl)",
                      f"{exact * 100:.3f}%", f"the fields {field * 100:.3f}% ({nb} frames)",
                      f"{exact / max(field, 1e-12):.2f}x", f"<= {TARGET_INSIDE_BONE * 100:g}% "
                      f"{_mark(exact <= TARGET_INSIDE_BONE)}")
            table.add("deepest in a bone by the meshes (libigl)", f"{deep * 1000:.1f} mm",
                      f"as measured {a * 1000:.1f} mm (all frames)", "",
                      f"<= {TARGET_DEPTH * 1000:g} mm {_mark(deep <= TARGET_DEPTH)}")
        dv = np.abs(vol1 / vol0 - 1.0).max()
        table.add("volume against no contact", f"{dv * 100:.2g}% off", "", "", f"<= 0.5% {_mark(dv <= 0.005)}")
        ratio = step1[1:] / np.maximum(step0[1:], 1e-12)
        pops = (ratio > POP_RATIO).mean()
        table.add(f"muscle-frames stepping > {POP_RATIO:g}x their no-contact step", f"{pops * 100:.2f}%",
                  f"worst {ratio.max():.2f}x", f"> {POP_RATIO:g}x + 0.5 mm: "
                  f"{(step1[1:] > POP_RATIO * step0[1:] + 5e-4).mean() * 100:.2f}%", f"none {_mark(pops == 0)}")


def skin_pass(plan) -> tuple[float, np.ndarray]:
    """Evaluate every frame of ``plan`` with its stages: wall time (s) and, where the plan has
    a skin, its measures per frame (F, len(SKIN_COLUMNS)); zeros without one."""
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS

    out = np.zeros((len(plan.frames), len(SKIN_COLUMNS)))
    t0 = time.perf_counter()
    for chunk, results in evaluate_plan(plan):
        for _ in results:
            pass
        if chunk.skin is not None:
            out[np.arange(len(plan.frames))[chunk.rows]] = chunk.skin.stats
    return time.perf_counter() - t0, out


def skin_checks(plan) -> dict:
    """Over every frame of ``plan`` (a run with a skin), by libigl's winding numbers on the
    meshes the stage leaves: the share of muscle vertices outside the skin and of skin vertices
    inside a bone (each bone mesh with its holes capped), at the worst frame; and the largest
    change, between consecutive frames of the plan, of a skin vertex's offset from where
    skinning alone puts it (m): a pop is the stage's own jump, not the motion's."""
    import igl

    from axdf_cli.model import skin as kernels
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SkinStage
    from axdf_cli.tools.skin_muscles import capped

    model = next(s for s in plan.stages if isinstance(s, SkinStage)).start(plan)
    worn = set(model.bones.tolist())
    bones = {b: capped(v, f) for b, (v, f, _) in plan.bone_meshes.items() if b in worn}
    outside = inside = step = 0.0
    prev = None
    for chunk, results in evaluate_plan(plan):
        res = {j: r for j, r in results}
        for i in range(len(chunk.frames)):
            y = chunk.skin.positions[i].astype(np.float64)
            mus = np.concatenate([res[j].vertices[i] for j in sorted(res)]).astype(np.float64)
            outside = max(outside, float((igl.fast_winding_number(y, model.faces, mus) < 0.5).mean()))
            ins = np.zeros(len(y), bool)
            for b, (bv, bf) in bones.items():
                w = chunk.world[i, b]
                wv = bv @ w[:3, :3].T + w[:3, 3]
                near = np.flatnonzero(np.all((y > wv.min(axis=0)) & (y < wv.max(axis=0)), axis=1))
                if len(near):
                    ins[near[np.abs(igl.winding_number(wv, bf, y[near])) > 0.5]] = True
            inside = max(inside, float(ins.mean()))
            x = np.empty_like(y)
            kernels.blend(model.weights, np.ascontiguousarray((chunk.world[i][model.bones] @ model.inv_rest)[:, :3, :]),
                          model.rest, x)
            if prev is not None:
                step = max(step, float(np.linalg.norm((y - x) - prev, axis=1).max()))
            prev = y - x
    return {"outside": outside, "inside_bone": inside, "offset_step": step}


#: Pops are looked for at 1/POP_SUBSTEPS of a frame, and the largest steps found again at
#: 1/POP_SUBSTEPS of that.
POP_SUBSTEPS = 8
#: Where pops are looked for: the walk's swing, and the CMU walk's crouch into its turn (its
#: deepest hip flexion, where the skin's pushes are largest).
POP_WINDOWS = {"gait2392 walk": (54, 66), "CMU walk retargeted onto gait2392": (66, 78)}


def skin_offsets(plan, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The skin's offset from where skinning alone puts it (F, V, 3) at ``frames`` (fractional
    frames: the pose interpolated between its keys), and those frames, sorted. TIME stages
    (jiggle) are left out: they integrate at the pose's own frame rate."""
    from axdf_cli.model import skin as kernels
    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.skin_stage import SkinStage
    from axdf_cli.pipeline.stages import Scope

    plan = dataclasses.replace(plan, frames=np.asarray(frames, np.float64),
                               stages=tuple(s for s in plan.stages if s.scope != Scope.TIME))
    model = next(s for s in plan.stages if isinstance(s, SkinStage)).start(plan)
    at, out = [], []
    for chunk, results in evaluate_plan(plan):
        for _ in results:
            pass
        for i in range(len(chunk.frames)):
            y = chunk.skin.positions[i].astype(np.float64)
            x = np.empty_like(y)
            kernels.blend(model.weights, np.ascontiguousarray((chunk.world[i][model.bones] @ model.inv_rest)[:, :3, :]),
                          model.rest, x)
            at.append(float(chunk.frames[i]))
            out.append(y - x)
    order = np.argsort(at, kind="stable")
    return np.asarray(at)[order], np.stack(out)[order]


def skin_pops(plan, first: int, last: int, look: int = 3) -> dict:
    """Pops, as jumps: a continuous skin's step shrinks with the time step, a pop's does not.
    The skin's offsets from skinning over frames ``first..last`` at 1/POP_SUBSTEPS of a frame;
    the ``look`` largest sub-steps (each a vertex and an interval) are sampled again at
    1/POP_SUBSTEPS of that. ``share``: the largest part of a sub-step that one of its finer
    steps takes (about 1/POP_SUBSTEPS where the skin moves smoothly, all of it at a jump)."""
    at, off = skin_offsets(plan, np.linspace(first, last, (last - first) * POP_SUBSTEPS + 1))
    steps = np.linalg.norm(np.diff(off, axis=0), axis=2)  # (S, V)
    share, coarse = 0.0, float(steps.max(initial=0.0))
    for flat in np.argsort(steps, axis=None)[::-1][:look]:
        k, v = np.unravel_index(flat, steps.shape)
        _, fine = skin_offsets(plan, np.linspace(at[k], at[k + 1], POP_SUBSTEPS + 1))
        fine_steps = np.linalg.norm(np.diff(fine[:, v], axis=0), axis=1)
        share = max(share, float(fine_steps.max() / max(steps[k, v], 1e-12)))
    return {"substep": coarse, "share": share}


def skin_rows(table: "Table", quick: bool, tmp: Path) -> None:
    """The skin stage (``axdf run --skin``) over the shipped gait2392 walk and the CMU walk
    retargeted onto gait2392 (packed muscles, contact on), the skin made by ``axdf skin --push``
    against those muscles: its cost per frame against the muscles' evaluation plus contact,
    measured side by side, and per frame the skin's volume against its rest volume, the share
    of muscle vertices outside it, and the largest push."""
    from axdf_cli.cli.main import main as axdf_main
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS, SkinStage
    from axdf_cli.specs import load_job

    skin_dir = tmp / "skin_gait2392"
    if axdf_main(["skin", "--skeleton", str(ROOT / "poses" / "skeletons" / "gait2392.yaml"), "--muscles",
                  str(ROOT / "muscles" / "gait2392_packed"), "--push", "--out", str(skin_dir), "-q"]) != 0:
        table.section("skin stage: axdf skin failed (no rows)")
        return
    skin = str(skin_dir / "skin.yaml")
    for label, job, frames in (("gait2392 walk", GAIT_JOB, "18:84:6" if quick else None),
                               ("CMU walk retargeted onto gait2392", CMU_GAIT_JOB, "0:248:24" if quick else None)):
        if not job.is_file():
            continue
        without = plan_run(load_job(job), frames_arg=frames)
        with_skin = plan_run(load_job(job), frames_arg=frames, skin_arg=skin)
        skin_pass(dataclasses.replace(with_skin, frames=with_skin.frames[:2]))  # compiled code and the start warm
        t_base, _ = skin_pass(without)
        t_skin, m = skin_pass(with_skin)
        stage = next(s for s in with_skin.stages if isinstance(s, SkinStage))
        t0 = time.perf_counter()
        stage.start(with_skin)  # once per run (its candidates and their rest skin vertices)
        t_start = time.perf_counter() - t0
        nf = len(without.frames)
        ms = lambda t: t / nf * 1e3  # noqa: E731
        cost = (t_skin - t_start - t_base) / t_base
        table.section(f"skin stage ({label}, {nf} frames x {len(without.models)} packed muscles, contact on; "
                      f"skin: MakeHuman's body fitted by axdf skin --push)")
        table.add("skin stage per frame", f"{ms(t_skin - t_start - t_base):.1f} ms",
                  f"muscles + contact {ms(t_base):.1f} ms", f"{cost:.2f}x", f"<= 1x {_mark(cost <= 1.0)}")
        table.add("skin stage start, once per run (and per worker)", f"{t_start * 1e3:.0f} ms")
        ratio = m[:, SKIN_COLUMNS.index("volume_ratio")]
        table.add("skin volume against rest (worst frame)", f"{np.abs(ratio - 1).max() * 100:.2f}% off",
                  f"range {ratio.min():.4f}..{ratio.max():.4f}", "", f"<= 3% {_mark(np.abs(ratio - 1).max() <= 0.03)}")
        out = m[:, SKIN_COLUMNS.index("outside")]
        table.add("muscle vertices above the skin by the normal test (skin.csv outside, worst frame; the bound is "
                  "the winding number's below)", f"{out.max() * 100:.2f}%", f"mean {out.mean() * 100:.2f}%")
        table.add("largest push", f"{m[:, SKIN_COLUMNS.index('push')].max() * 1000:.0f} mm")
        window = {"gait2392 walk": "54:66", "CMU walk retargeted onto gait2392": "66:78"}[label] if quick else frames
        c = skin_checks(plan_run(load_job(job), frames_arg=window, skin_arg=skin))
        where = f"frames {window}" if window else "every frame"
        table.add(f"muscle vertices outside the skin, winding number ({where}, worst)", f"{c['outside'] * 100:.3f}%",
                  "", "", f"<= 0.5% {_mark(c['outside'] <= 0.005)}")
        table.add(f"skin vertices inside a bone, winding number, holes capped ({where}, worst)",
                  f"{c['inside_bone'] * 100:.3f}%", "", "", f"<= 0.5% {_mark(c['inside_bone'] <= 0.005)}")
        table.add(f"largest change of a skin vertex's offset from skinning, frame to frame ({where})",
                  f"{c['offset_step'] * 1000:.1f} mm")
        first, last = POP_WINDOWS[label]
        pops = skin_pops(plan_run(load_job(job), frames_arg=f"{first}:{last + 1}", skin_arg=skin), first, last)
        table.add(f"pops: the largest offset steps at 1/{POP_SUBSTEPS} frame (frames {first}:{last}), sampled "
                  f"{POP_SUBSTEPS}x finer: the most one finer step takes (a jump: all)",
                  f"{pops['share'] * 100:.0f}%", f"of {pops['substep'] * 1000:.1f} mm", "",
                  f"< 50% {_mark(pops['share'] < 0.5)}")


def _mark(ok: bool) -> str:
    return "✓" if ok else "✗"


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


def machine_line() -> str:
    """The machine and commit a table was measured on, for the generated file's header."""
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
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
        commit += " (with uncommitted changes)" if dirty else ""
    except (OSError, subprocess.CalledProcessError):
        commit = "unknown (not a git checkout)"
    return (f"commit {commit}; {cpu_name}, {os.cpu_count()} logical CPUs; {platform.system()} "
            f"{platform.release()}; Python {platform.python_version()}, numpy {np.__version__}")


def write_markdown(path: Path, table: "Table", argv: list[str], seconds: float) -> None:
    """Write ``table`` as a generated Markdown page (docs/BENCH.md from ``make bench``)."""
    args = " ".join(argv)
    text = "\n".join([
        "# Benchmark tables",
        "",
        "<!-- Generated by `make bench` (python -m benchmarks.bench); do not edit by hand. -->",
        "",
        f"Generated by `make bench` (`python -m benchmarks.bench{' ' + args if args else ''}`) on: "
        f"{machine_line()}. Total bench time {seconds:.0f} s.",
        "",
        "Medians of repeated runs; the machine may be shared, so absolute figures are noisy and only "
        "ratios taken in the same run are compared with targets. µs/mf: microseconds per muscle-frame.",
        "",
        *([f"This page holds only the `{argv[argv.index('--only') + 1]}` rows (`--only`); `make bench` "
           "without it measures every section.", ""] if "--only" in argv[:-1] else []),
        table.markdown(),
    ])
    atomic.write_bytes(Path(path), text.encode("utf-8"))


def _mbs(nbytes: float, us: float) -> str:
    return f"{nbytes / us:.0f} MB/s"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats (about a minute)")
    ap.add_argument("--long", action="store_true", help=f"also {LONG_FRAMES} frames x all muscles: peak memory")
    ap.add_argument("--profile", action="store_true", help="print the top functions of the slow rows")
    ap.add_argument("--tmp", default=None, help="folder for the written files (default: a new temporary folder)")
    ap.add_argument("--only", choices=("retarget", "jiggle", "compiled", "contact", "skin"), default=None,
                    help="print only these rows (retarget: the retargeting fit; jiggle: the jiggle stage; "
                         "compiled: the compiled pass, a whole run; contact: the walk and Rajagopal2016 with "
                         "and without contact; skin: the skin stage over the walks)")
    ap.add_argument("--dataset-samples", type=int, default=None, metavar="N",
                    help=f"samples of the data-set rows (default {DATASET_SAMPLES}, 100 with --quick; 0: skip them)")
    ap.add_argument("--markdown", default=None, metavar="PATH",
                    help="also write the table as Markdown to PATH (make bench: docs/BENCH.md)")
    args = ap.parse_args(argv)
    argv_used = list(sys.argv[1:] if argv is None else argv)
    argv_shown = [a for i, a in enumerate(argv_used)
                  if a != "--markdown" and not a.startswith("--markdown=")
                  and not (i > 0 and argv_used[i - 1] == "--markdown")]

    t_start = time.perf_counter()

    def emit(table: Table, texts=(), unit: bool = True) -> int:
        seconds = time.perf_counter() - t_start
        print(table.text())
        print(f"({'µs/mf: microseconds per muscle-frame; ' if unit else ''}total bench time {seconds:.0f} s)")
        for t in texts:
            print()
            print(t)
        if args.markdown:
            write_markdown(Path(args.markdown), table, argv_shown, seconds)
            print(f"(tables written to {args.markdown})", file=sys.stderr)
        return 0

    if args.only == "retarget":
        table = Table()
        retarget_rows(table, args.quick)
        return emit(table, unit=False)
    if args.only == "compiled":
        table = Table()
        tmp = Path(tempfile.mkdtemp(prefix="axdf-bench-", dir=args.tmp))
        try:
            texts = compiled_rows(table, tmp, args.quick, top=25 if args.profile else 0)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return emit(table, texts)
    if args.only == "contact":
        table = Table()
        tmp = Path(tempfile.mkdtemp(prefix="axdf-bench-", dir=args.tmp))
        try:
            contact_rows(table, args.quick, tmp)
            pack_rows(table)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return emit(table)
    if args.only == "skin":
        table = Table()
        tmp = Path(tempfile.mkdtemp(prefix="axdf-bench-", dir=args.tmp))
        try:
            skin_rows(table, args.quick, tmp)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        return emit(table, unit=False)
    if args.only == "jiggle":
        table = Table()
        jiggle_rows(table, 3 if args.quick else 5)
        return emit(table)
    n_frames = 200 if args.quick else 1000
    reps = 2 if args.quick else 3
    counts = (1, 10) if args.quick else MUSCLE_COUNTS
    tmp = Path(tempfile.mkdtemp(prefix="axdf-bench-", dir=args.tmp))
    table = Table()
    profiles: list[str] = []
    try:
        case = load_case(n_frames, max(counts))
        job = GAIT_JOB if case.name == "gait2392" and GAIT_JOB.is_file() else DEMO_JOB
        print(f"axdf bench: {case.name} muscles ({len(case.specs)}), {n_frames} frames, median of {reps} runs "
              f"(one run for 92 muscles); shared machine: figures are noisy, ratios are taken in the same run",
              file=sys.stderr)

        # 1-2. evaluation against the limit
        table.section(f"evaluation ({case.name}, {n_frames} frames in chunks of pipeline.CHUNK_FRAMES) vs numpy "
                      "filling the same outputs (vertices + normals, 2 x (F, V, 3) float64)")
        eval_us: dict = {}
        worst_limit = 0.0
        for res in RESOLUTIONS:
            for nm in counts:
                if nm > len(case.specs):
                    continue
                models = case.models(nm, res)
                r = reps if nm < 92 else 1
                us = time_evaluation(models, case.world, case.tension, r, coords=case.coords)
                eval_us[res, nm] = us
                nv = models[0].n_vertices
                lim = time_limit(n_frames, nv, 5)
                worst_limit = max(worst_limit, us / lim)
                table.add(f"evaluate {res[0]}x{res[1]} ({nv} v), {nm} muscle{'s' if nm > 1 else ''}",
                          f"{us:.1f} µs/mf", f"fill {lim:.2f} µs/mf", f"{us / lim:.1f}x",
                          f"<= {TARGET_LIMIT:g}x {_mark(us / lim <= TARGET_LIMIT)}")
                if args.profile and nm == 1:
                    prof = cProfile.Profile()
                    prof.runcall(evaluate_all, models, case.world, case.tension, 128, case.coords)
                    buf = io.StringIO()
                    pstats.Stats(prof, stream=buf).sort_stats("tottime").print_stats(12)
                    profiles.append(f"== evaluate {res} 1 muscle ==\n{buf.getvalue()}")

        # 2b. wrapping
        wc, nc = load_wrap_case(n_frames, True), load_wrap_case(n_frames, False)
        if wc is not None:
            table.section(f"wrapping (arm26's 6 muscles, {n_frames} frames of elbow flexion, {RESOLUTIONS[0][0]}x"
                          f"{RESOLUTIONS[0][1]}): paths with their wrap surfaces vs the same paths without")
            w_us = time_evaluation(wc.models(6, RESOLUTIONS[0]), wc.world, wc.tension, reps, coords=wc.coords)
            n_us = time_evaluation(nc.models(6, RESOLUTIONS[0]), nc.world, nc.tension, reps, coords=nc.coords)
            table.add("evaluate with wrapping", f"{w_us:.1f} µs/mf", f"without {n_us:.1f} µs/mf", f"{w_us / n_us:.2f}x",
                      f"<= {TARGET_WRAP:g}x {_mark(w_us / n_us <= TARGET_WRAP)}")

        # 2c. contact
        if GAIT_JOB.is_file():
            contact_rows(table, args.quick, tmp)
            pack_rows(table)

        # 3. geomdl
        table.section("peer: geomdl (NURBS-Python) tessellating the same surface, per muscle-frame")
        for res in RESOLUTIONS:
            model = case.models(1, res)[0]
            g_us, err = time_geomdl(model, case.rest, 2 if args.quick else 3)
            ours = eval_us[res, 1]
            table.add(f"geomdl {res[0]}x{res[1]} (points only; max |Δ| {err:.1e} m)", f"{g_us / 1000:.1f} ms/mf",
                      f"axdf {ours:.1f} µs/mf", f"{g_us / ours:.0f}x faster",
                      f">= {TARGET_PEER:g}x {_mark(g_us / ours >= TARGET_PEER)}")

        # 4. writers
        model = case.models(1, RESOLUTIONS[0])[0]
        n_files = 50 if args.quick else 200
        wr = time_writers(model, case.world, case.tension, tmp / "writers", n_files, reps + 2)
        ply, obj = wr["ply"], wr["obj"]
        table.section(f"writers ({RESOLUTIONS[0][0]}x{RESOLUTIONS[0][1]}, {n_files} new files per pass) "
                      "vs ndarray.tofile of the same bytes")
        for ext, d in wr.items():
            table.add(f"{ext.upper()} encode ({d['bytes'] / 1e3:.0f} kB)", f"{d['encode']:.0f} µs/mf",
                      _mbs(d["bytes"], d["encode"]))
            table.add(f"{ext.upper()} write(): encode + atomic write", f"{d['write']:.0f} µs/mf",
                      f"tofile {d['tofile']:.0f} µs/mf", f"{d['write'] / d['tofile']:.2f}x",
                      f"<= {TARGET_PLY:g}x {_mark(d['write'] / d['tofile'] <= TARGET_PLY)}" if ext == "ply" else "")
            table.add(f"{ext.upper()} encode + atomic.write_bytes (+sha256)", f"{d['write_bytes']:.0f} µs/mf",
                      f"tofile {d['tofile']:.0f} µs/mf", f"{d['write_bytes'] / d['tofile']:.2f}x")
            table.add(f"{ext.upper()} write() throughput", _mbs(d["bytes"], d["write"]),
                      f"tofile {_mbs(d['bytes'], d['tofile'])}")
        table.add("OBJ write() vs PLY write()", f"{obj['write']:.0f} µs/mf", f"PLY {ply['write']:.0f} µs/mf",
                  f"{obj['write'] / ply['write']:.2f}x", f"<= {TARGET_OBJ:g}x {_mark(obj['write'] / ply['write'] <= TARGET_OBJ)}")

        # 5. rendering
        table.section("rendering (benchmark_fps: 6 muscles x 1106 vertices + a bone, as the demo)")
        rf = render_fps(frames=12 if args.quick else 24)
        if "error" in rf:
            table.add("render 512x512", "n/a", rf["error"][:60])
        else:
            table.add("render 512x512 (+ read-back)", f"{rf['render_fps']:.1f} fps",
                      f"{rf['gl_renderer'][:40]}, supersample {rf['supersample']}")

        # 6. end to end
        table.section(f"end to end: axdf run {job.relative_to(ROOT)} --no-render --no-contact (subprocess; PLY)")
        e2e = end_to_end(job, tmp / "e2e")
        mf = e2e["frames"] * e2e["muscles"]
        table.add(f"axdf run ({e2e['muscles']} muscles x {e2e['frames']} frames)", f"{e2e['frames'] / e2e['wall']:.1f} fps",
                  f"{mf / e2e['wall']:.0f} muscle-frames/s, {e2e['wall']:.1f} s")
        e2c = end_to_end(job, tmp / "e2e-contact", contact=True)
        table.add("axdf run with contact (the default)", f"{e2c['frames'] / e2c['wall']:.1f} fps",
                  f"{mf / e2c['wall']:.0f} muscle-frames/s, {e2c['wall']:.1f} s", f"{e2c['wall'] / e2e['wall']:.2f}x")
        table.add("axdf run peak memory", f"{e2e['maxrss'] / 2**20:.0f} MiB")
        pr = profile_run(job, tmp / "e2e-profile", top=15 if args.profile else 0)
        ev, wt = pr["evaluation"], pr["writing"]
        table.add("execute: evaluation / writing (cProfile)", f"{ev:.1f} s / {wt:.1f} s",
                  f"of {pr['total']:.1f} s (plan {pr['plan']:.1f} s)", f"{wt / max(ev, 1e-9):.2f}x",
                  f"writing >= evaluation {_mark(wt >= ev)}")
        if pr["top"]:
            profiles.append(f"== execute {job.name} ==\n{pr['top']}")

        # 6b. the compiled pass: a whole run, a data-set sample, first touch, compile cost
        profiles += compiled_rows(table, tmp, args.quick, top=15 if args.profile else 0)

        # 7. data sets
        n_ds = args.dataset_samples if args.dataset_samples is not None else (100 if args.quick else DATASET_SAMPLES)
        if n_ds > 0:
            dataset_rows(table, n_ds, tmp)

        # 8. packed formats
        packed_rows(table, case, job, tmp, n_frames, args.quick, ply_us=ply["write"])

        # 9. rendering over processes
        if "error" not in rf:
            render_jobs_rows(table, tmp, args.quick)

        # 10. retargeting
        retarget_rows(table, args.quick)

        # 11. jiggle
        jiggle_rows(table, 2 * reps - 1)

        # 12. the skin stage
        skin_rows(table, args.quick, tmp)

        # --long
        if args.long:
            lj = GAIT_JOB if GAIT_JOB.is_file() else DEMO_JOB
            lr = long_memory(lj)
            table.section(f"--long: {LONG_FRAMES} frames x all muscles through pipeline.evaluate_chunks "
                          "(+ stats and the manifest's file list)")
            table.add(f"peak memory ({lr['muscle_frames']} muscle-frames, chunk {lr['chunk']})",
                      f"{lr['maxrss'] / 2**20:.0f} MiB", f"{lr['seconds']:.0f} s evaluating",
                      f"{lr['maxrss'] / LONG_MEMORY:.2f} of 1 GiB", f"< 1 GiB {_mark(lr['maxrss'] < LONG_MEMORY)}")
            table.add("manifest JSON (files list only)", f"{lr['manifest_bytes'] / 2**20:.0f} MiB")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return emit(table, profiles)


if __name__ == "__main__":
    sys.exit(main())
