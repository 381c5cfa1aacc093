"""MyoSuite's full body (imported by ``axdf import mjcf``) moved by motion capture: CMU subject
131's walk fitted onto myobody through ``poses/maps/cmu_to_myobody.yaml`` (what ``make import``
ships in ``poses/retargeted/cmu_131_01_walk_myobody``), as tests/test_retarget.py holds the
gait2392 map: hips, knees and ankles within 3% of the leg length (RMS, after the one similarity
of the map's scale and alignment), every coordinate inside its range, and all 416 muscles
running over it without a warning."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from test_retarget import CMU_BVH, REPO, needs_bvh

MYO_MAP = REPO / "poses" / "maps" / "cmu_to_myobody.yaml"
SHIPPED = REPO / "poses" / "retargeted" / "cmu_131_01_walk_myobody"
JOB = REPO / "poses" / "jobs" / "myobody_cmu_walk.yaml"


@pytest.fixture(scope="module")
def myo_walk():
    from axdf_cli.importers.retarget import build_retarget

    return build_retarget(CMU_BVH, MYO_MAP, SHIPPED, step=4, name="cmu_131_01_walk_myobody")


@needs_bvh
def test_cmu_walk_on_myobody_joint_centres_within_3_percent_of_the_leg(myo_walk):
    res = myo_walk.retargeted
    pos, idx = res.mocap.positions, res.mocap.index
    leg = np.median(np.linalg.norm(pos[:, idx["RightHip"]] - pos[:, idx["RightKnee"]], axis=1)
                    + np.linalg.norm(pos[:, idx["RightKnee"]] - pos[:, idx["RightAnkle"]], axis=1))
    names = [p.name for p in res.rmap.points]
    for point in ("femur_r", "femur_l", "tibia_r", "tibia_l", "talus_r", "talus_l"):  # hips, knees, ankles
        rms = np.sqrt(np.mean(res.error[:, names.index(point)] ** 2))
        assert rms < 0.03 * leg, (point, rms / leg)
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


@needs_bvh
def test_shipped_myobody_walk_is_what_make_import_makes(myo_walk):
    for path, data in myo_walk.files.items():
        shipped = Path(path).read_bytes()
        if path.endswith(".yaml"):
            a, b = yaml.safe_load(shipped), yaml.safe_load(data)
            assert a["skeleton"] == b["skeleton"] == "../../skeletons/myobody.yaml"
            assert sorted(a["keys"]) == sorted(b["keys"])
            for f in b["keys"]:  # the optimizer's last bits may differ across CPUs
                assert a["keys"][f].keys() == b["keys"][f].keys()
                assert max(abs(a["keys"][f][c] - b["keys"][f][c]) for c in b["keys"][f]) < 1e-3
        elif path.endswith(".json"):
            a, b = json.loads(shipped), json.loads(data)
            assert a["files"] == b["files"] and a["motion"] == b["motion"] and a["map"] == b["map"]
            assert abs(a["error"]["rms_m"] - b["error"]["rms_m"]) < 1e-5


@needs_bvh
def test_all_416_myobody_muscles_follow_the_retargeted_walk(tmp_path, monkeypatch):
    from axdf_cli.cli.main import main

    monkeypatch.chdir(REPO)
    out = tmp_path / "walk"
    assert main(["run", str(JOB.relative_to(REPO)), "--no-render", "--frames", "0:248:24", "--out", str(out),
                 "-q"]) == 0
    rows = list(csv.DictReader((out / "stats.csv").open()))
    assert len({r["muscle"] for r in rows}) == 416 and len(rows) == 416 * 11
    assert not [r for r in rows if r["warning"]]  # no coordinate out of range, no degenerate frame
    vas = np.array([float(r["length"]) for r in rows if r["muscle"] == "vasint_r"])
    assert vas.max() > 1.1 * vas.min()  # the knee bends: the vasti lengthen
