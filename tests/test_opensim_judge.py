"""OpenSim itself as the judge: every imported muscle's axis length against
``Muscle.getLength`` at every frame of the shipped motions, and the wrapped path's points
(tangent points included) against ``GeometryPath.getCurrentPath``."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from osim_common import ARM, GAIT, REPO, needs_data

pytestmark = needs_data
opensim = pytest.importorskip("opensim", reason="the OpenSim judge needs `pip install opensim` (test extra)")

from opensim_judge import OpenSimModel, compare, pose_coordinates  # noqa: E402

LENGTH_TOL = 0.01  # relative: the bound for every muscle at every frame
POINT_TOL = 2e-4  # m: path and tangent points against getCurrentPath

CASES = {"arm26": (ARM, REPO / "muscles" / "arm26", REPO / "poses" / "arm26_flex.yaml"),
         "gait2392": (GAIT, REPO / "muscles" / "gait2392", REPO / "poses" / "gait2392_walk.yaml")}


@pytest.mark.parametrize("case", sorted(CASES))
def test_every_muscle_length_within_1pct_of_opensim(case):
    names, ours, ref = compare(*CASES[case])
    assert len(names) == {"arm26": 6, "gait2392": 92}[case]
    assert ours.shape == ref.shape and ours.shape[0] > 50
    rel = np.abs(ours - ref) / ref
    worst = rel.max(axis=0)
    bad = {n: f"{w:.2%}" for n, w in zip(names, worst) if w > LENGTH_TOL}
    assert not bad, bad


@pytest.mark.parametrize("case", sorted(CASES))
def test_wrapped_path_points_match_getCurrentPath(case):
    from axdf_cli.specs import expand_muscle_paths, load_muscle_file
    from axdf_cli.model.paths.path import PathModel
    from axdf_cli.model.skeleton import forward_kinematics

    osim, mdir, posef = CASES[case]
    pose, frames, q = pose_coordinates(posef)
    pick = np.linspace(0, len(frames) - 1, 5).astype(int)
    q = q[pick]
    skel = pose.skeleton
    world = forward_kinematics(skel, q)
    om = OpenSimModel(osim)
    specs = {s.name: s for f in expand_muscle_paths([(Path(mdir), None)]) for s in load_muscle_file(f)}
    wrapped = 0
    for f in range(len(q)):
        g = world[f, skel.bone_index["ground"]]  # OpenSim's ground in axdf's world
        om.set_pose(skel, q[f])
        for name in om.names:
            ref = om.current_path(name) @ g[:3, :3].T + g[:3, 3]
            pm = PathModel(specs[name].path, skel.bone_index, skel.coord_index)
            path = pm.wrap(world[f:f + 1], q[f:f + 1])
            ours = path.points[0, :path.count[0]]
            assert len(ours) == len(ref), (name, f, len(ours), len(ref))
            np.testing.assert_allclose(ours, ref, rtol=0, atol=POINT_TOL, err_msg=f"{name} frame {f}")
            wrapped += len(ref) > sum(1 for p in specs[name].path.points if p.active is None) and bool(
                specs[name].path.wraps)
    if case == "arm26":
        assert wrapped > 0  # some frames do wrap (tangent points present)
