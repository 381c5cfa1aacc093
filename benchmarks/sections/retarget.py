"""Row 11, retargeting: ``axdf retarget``'s fit of the CMU walk onto gait2392 (frames per second
at 30 and 120 fps; every 4th frame of the take with ``--quick``), and one Jacobian of the
mapped points by the analytic formula against central differences batched as frames of one
forward-kinematics call (the alternative the fit could use)."""
from __future__ import annotations

import time

import numpy as np

from benchmarks.common import ROOT, Table, median_time
from benchmarks.settings import Run

UNIT = False


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


def rows(table: Table, run: Run) -> list[str]:
    retarget_rows(table, run.quick)
    return []
