"""Rows 1-3 and wrapping: µs per muscle-frame of ``MuscleModel.evaluate`` at 48x24 and 96x48
over the bench's frames in chunks of ``pipeline.CHUNK_FRAMES``, for 1, 10 and 92 muscles, against
numpy filling the same outputs (the limit); arm26's paths with and without their wrap
surfaces; and geomdl (NURBS-Python) tessellating the same surface (a peer)."""
from __future__ import annotations

import cProfile
import io
import pstats
import time

import numpy as np

from axdf_cli.model.muscle import OCT, MuscleModel
from benchmarks.case import load_wrap_case
from benchmarks.common import RESOLUTIONS, Table, mark, median_time
from benchmarks.settings import Run

UNIT = True
#: Wrapping may add at most this to evaluation.
TARGET_WRAP = 1.5
TARGET_LIMIT = 3.0  # evaluation within 3x of numpy filling the same outputs
TARGET_PEER = 100.0  # at least 100x faster than geomdl


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


def control_net(model: MuscleModel, rest_world: np.ndarray) -> np.ndarray:
    """The rest surface's control net (m, 8, 3): origin pole, sections, insertion pole."""
    axis = model.axis_points(rest_world[None], model.rest_q)[0][0]  # (n, 3)
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


def rows(table: Table, run: Run) -> list[str]:
    """The evaluation rows against the limit, the wrapping rows and the peer's."""
    case = run.case()
    n_frames, reps, counts = run.n_frames, run.reps, run.counts
    profiles: list[str] = []
    # 1-2. evaluation against the limit
    table.section(f"evaluation ({case.name}, {n_frames} frames in chunks of pipeline.CHUNK_FRAMES) vs numpy "
                  "filling the same outputs (vertices + normals, 2 x (F, V, 3) float64)")
    eval_us: dict = {}
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
            table.add(f"evaluate {res[0]}x{res[1]} ({nv} v), {nm} muscle{'s' if nm > 1 else ''}",
                      f"{us:.1f} µs/mf", f"fill {lim:.2f} µs/mf", f"{us / lim:.1f}x",
                      f"<= {TARGET_LIMIT:g}x {mark(us / lim <= TARGET_LIMIT)}")
            if run.profile and nm == 1:
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
                  f"<= {TARGET_WRAP:g}x {mark(w_us / n_us <= TARGET_WRAP)}")

    # 3. geomdl
    table.section("peer: geomdl (NURBS-Python) tessellating the same surface, per muscle-frame")
    for res in RESOLUTIONS:
        model = case.models(1, res)[0]
        g_us, err = time_geomdl(model, case.rest, 2 if run.quick else 3)
        ours = eval_us[res, 1]
        table.add(f"geomdl {res[0]}x{res[1]} (points only; max |Δ| {err:.1e} m)", f"{g_us / 1000:.1f} ms/mf",
                  f"axdf {ours:.1f} µs/mf", f"{g_us / ours:.0f}x faster",
                  f">= {TARGET_PEER:g}x {mark(g_us / ours >= TARGET_PEER)}")
    return profiles
