"""MyoSuite's full body (imported by ``axdf import mjcf``) moved by motion capture: CMU subject
131's walk fitted onto myobody through ``poses/maps/cmu_to_myobody.yaml`` (what ``make import``
ships in ``poses/retargeted/cmu_131_01_walk_myobody``), as tests/test_retarget.py holds the
gait2392 map: hips, knees and ankles within 3% of the leg length (RMS, after the one similarity
of the map's scale and alignment), every coordinate inside its range, and all 416 muscles
running over it without a warning."""
from __future__ import annotations

import numpy as np
import pytest

from test_retarget import CMU_BVH, REPO, assert_shipped_as_made, leg_joint_errors, needs_bvh, run_job_stats

MYO_MAP = REPO / "poses" / "maps" / "cmu_to_myobody.yaml"
SHIPPED = REPO / "poses" / "retargeted" / "cmu_131_01_walk_myobody"
JOB = REPO / "poses" / "jobs" / "myobody_cmu_walk.yaml"


@pytest.fixture(scope="module")
def myo_walk():
    from axdf_cli.tools.retarget import build_retarget

    return build_retarget(CMU_BVH, MYO_MAP, SHIPPED, step=4, name="cmu_131_01_walk_myobody")


@needs_bvh
def test_cmu_walk_on_myobody_joint_centres_within_3_percent_of_the_leg(myo_walk):
    res = myo_walk.retargeted
    errors = leg_joint_errors(res)
    assert max(errors.values()) < 0.03, errors  # measured: 1.4-2.2%
    # one scale for the whole model: myobody's legs (0.805 m hip to ankle) are the subject's (0.800 m)
    assert 0.95 < res.world.scale < 1.02


@needs_bvh
def test_cmu_walk_on_myobody_keeps_every_coordinate_in_range(myo_walk):
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    pose = load_pose(SHIPPED / "cmu_131_01_walk_myobody.yaml")
    q = sample_coordinates(pose, pose.frames)
    assert len(q) == 249
    moved = 0
    for c, coord in enumerate(pose.skeleton.coordinates):
        if coord.range is not None:
            assert coord.range[0] - 1e-9 <= q[:, c].min() and q[:, c].max() <= coord.range[1] + 1e-9, coord.name
        moved += np.ptp(q[:, c]) > 1.0
    assert moved >= 20  # the root, the lumbar joints and both legs move; the arms keep their rest pose
    rotations = [c for c, coord in enumerate(pose.skeleton.coordinates) if coord.type == "rotation"]
    assert np.abs(np.diff(q[:, rotations], axis=0)).max() <= 15.0 + 1e-6  # the map's max_speed at 30 fps


@needs_bvh
def test_shipped_myobody_walk_is_what_make_import_makes(myo_walk):
    assert_shipped_as_made(myo_walk, "../../skeletons/myobody.yaml")


@needs_bvh
def test_all_416_myobody_muscles_follow_the_retargeted_walk(tmp_path, monkeypatch):
    rows = run_job_stats(JOB, "0:248:24", tmp_path / "walk", monkeypatch)
    assert len({r["muscle"] for r in rows}) == 416 and len(rows) == 416 * 11
    vas = np.array([float(r["length"]) for r in rows if r["muscle"] == "vasint_r"])
    assert vas.max() > 1.1 * vas.min()  # the knee bends: the vasti lengthen
