"""Labels are right: projected joint centres land on their own ball in the `id` and depth
passes, every ball pixel unprojects onto its ball, hidden joints are flagged, and the
coordinate values reproduce the bone frames by forward kinematics."""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from dataset_helpers import BALL_R, build_in, write_tiny
from render_helpers import read_exr

RIG_YAML = """\
dataset: rig
seed: 3
skeleton: chain.yaml
muscles: [chainm.yaml]
coordinates:
  stretch: {range: [0.0, 0.3]}
  bend: {range: [-50, 50]}
  roll: {range: [-80, 80]}
motions:
  straight: {pose: straight.yaml}
sequences:
  - {sample: uniform, count: 3, frames: 2}
  - {motion: straight}
activation: none
cameras:
  rig:
    - {name: front, position: [0, -1.2, -0.25], target: [0, 0, -0.25], fov: 40}
    - {name: side, position: [1.3, 0, -0.2], target: [0, 0, -0.25], fov: 40}
    - {name: below, position: [0, 0, -2.0], target: [0, 0, 0], up: [0, 1, 0], fov: 30}
render: {size: [96, 112], supersample: 1}
labels: {visibility_tolerance: 0.05}
"""

STRAIGHT_YAML = """\
pose: straight
skeleton: chain.yaml
frames: [0, 0]
keys:
  0: {bend: 0, roll: 0, stretch: 0}
"""

DEPTH_TOL = 2e-3  # m: a pixel centre up to ~0.7 px (5 mm) off the joint's ray sees the ball
# ~0.4 mm deeper than its front point; the icosphere's facets add less than 0.1 mm


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The rig's data set without contact: its muscle runs through the joint balls, and contact
    would push it off them and over their pixels (tests/test_contact.py covers contact)."""
    from axdf_cli.pipeline import stages

    d = tmp_path_factory.mktemp("rig")
    write_tiny(d, RIG_YAML)
    (d / "straight.yaml").write_text(STRAIGHT_YAML)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(stages, "STAGES", {k: v for k, v in stages.STAGES.items() if k not in ("contact", "penetration")})
        return build_in(d, "out")


def _ball_ids(out) -> dict:
    ids = json.loads((out / "dataset.json").read_text())["ids"]
    return {v["name"]: int(k) for k, v in ids.items() if v["kind"] == "bone"}


def test_joint_pixels_show_their_ball_at_the_right_depth(rig):
    ball = _ball_ids(rig)
    for seq in ("seq_00000", "seq_00001", "seq_00002", "seq_00003"):
        lab = np.load(rig / seq / "labels.npz")
        names = [str(lab["bone_names"][b]) for b in lab["joint_bones"]]  # each keypoint's ball
        assert list(lab["joint_names"]) == ["b0_b1", "b1_b2", "b2_b3", "b3_b4"]  # b0: no DOFs, no joint
        for fi, f in enumerate(lab["frames"]):
            for vi, view in enumerate(lab["view_names"]):
                if view == "below":
                    continue  # there the joints hide one another (next test)
                exr = read_exr(rig / seq / "views" / view / f"{f:04d}.exr")
                for j, name in enumerate(names):
                    u, v = lab["joints2d"][fi, vi, j]
                    col, row = int(np.floor(u)), int(np.floor(v))
                    assert exr["id"][row, col] == ball[name], (seq, view, name)
                    z = lab["joints_depth"][fi, vi, j]
                    assert abs(exr["Z"][row, col] - (z - BALL_R)) < DEPTH_TOL, (seq, view, name)
                    assert lab["visible"][fi, vi, j]


def test_every_ball_pixel_unprojects_onto_its_ball(rig):
    ball = _ball_ids(rig)
    lab = np.load(rig / "seq_00001" / "labels.npz")
    names = list(lab["bone_names"])
    for vi, view in enumerate(lab["view_names"]):
        exr = read_exr(rig / "seq_00001" / "views" / view / "0001.exr")
        K, M = lab["K"][vi], lab["world_to_camera"][1, vi]
        rows, cols = np.nonzero(np.isin(exr["id"], list(ball.values())))
        assert len(rows) > 100
        z = exr["Z"][rows, cols]
        # p_cam = z K^-1 [u, v, 1] at the pixel centre; p_world = R^T (p_cam - t)
        pc = z[:, None] * (np.stack([cols + 0.5, rows + 0.5, np.ones_like(z)], 1) @ np.linalg.inv(K).T)
        pw = (pc - M[:3, 3]) @ M[:3, :3]
        centre = lab["bone_world"][1][[names.index(n) for n in
                                       [next(k for k, v in ball.items() if v == i) for i in exr["id"][rows, cols]]],
                                      :3, 3]
        dist = np.linalg.norm(pw - centre, axis=1)
        assert np.abs(dist - BALL_R).max() < DEPTH_TOL


def test_hidden_joints_are_not_visible(rig):
    lab = np.load(rig / "seq_00003" / "labels.npz")  # the straight chain
    vi = list(lab["view_names"]).index("below")
    uv = lab["joints2d"][0, vi]
    assert np.abs(uv - uv[-1]).max() < 1.0  # looking up the chain: every joint on one pixel
    # only the lowest ball (b4) shows; the others are 0.1 m or more behind its surface
    assert list(lab["visible"][0, vi]) == [False, False, False, True]
    assert lab["visible"][0, :vi].all()


def test_coordinates_reproduce_bone_frames_and_tables(rig):
    from axdf_cli.specs import load_skeleton
    from axdf_cli.model.skeleton import forward_kinematics

    skel = load_skeleton(rig.parent / "chain.yaml")
    for seq in ("seq_00000", "seq_00002", "seq_00003"):
        lab = np.load(rig / seq / "labels.npz")
        assert list(lab["coord_names"]) == [c.name for c in skel.coordinates]
        world = forward_kinematics(skel, lab["coords"])
        np.testing.assert_allclose(lab["bone_world"], world, rtol=0, atol=1e-12)
        np.testing.assert_allclose(lab["joints3d"], world[:, 1:, :3, 3], rtol=0, atol=1e-12)
        assert list(lab["joint_bones"]) == [1, 2, 3, 4] and list(lab["joint_parents"]) == [-1, 0, 1, 2]
        with open(rig / seq / "bones.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        xyz = np.array([[float(r[k]) for k in "xyz"] for r in rows]).reshape(len(lab["frames"]), -1, 3)
        np.testing.assert_allclose(xyz, lab["bone_world"][..., :3, 3], rtol=0, atol=1e-8)
        with open(rig / seq / "stats.csv", newline="") as fh:
            rows = list(csv.DictReader(fh))
        length = np.array([float(r["length"]) for r in rows]).reshape(len(lab["frames"]), -1)
        np.testing.assert_allclose(lab["muscle_length"], length, rtol=1e-8)
        assert (lab["muscle_activation"] == 0).all()  # activation: none
    # the sampled coordinates differ between frames and sequences, within their ranges
    a, b = (np.load(rig / s / "labels.npz")["coords"] for s in ("seq_00000", "seq_00001"))
    assert not np.allclose(a, b) and not np.allclose(a[0], a[1])
    for q in (a, b):
        assert (q[:, 0] >= 0).all() and (q[:, 0] <= 0.3).all() and (np.abs(q[:, 1]) <= 50).all()


def test_cameras_of_the_rig_are_the_labels(rig):
    from axdf_cli.render.camera import look_at

    lab = np.load(rig / "seq_00000" / "labels.npz")
    M = look_at([0, -1.2, -0.25], [0, 1.2, 0], [0, 0, 1])
    np.testing.assert_allclose(lab["world_to_camera"][:, 0], np.broadcast_to(M, (2, 4, 4)), atol=1e-12)
    # the target projects to the image centre (96 x 112)
    uv = lab["K"][0] @ (M[:3, :3] @ [0, 0, -0.25] + M[:3, 3])
    np.testing.assert_allclose(uv[:2] / uv[2], [48, 56], atol=1e-9)
