"""The automatic camera keeps the body in view: the shipped retargeted walk
keeps every keypoint of every frame inside the image with the body at least 40% of its height;
a subject that travels farther than it is tall is followed; framing poses a bounded sample of
the pose, never every frame; a ground plate lies under the subject; data sets aim at a bone
per frame and mark samples that show no keypoint in the index. Cameras are computed as a run
computes them (no rendering), from camera.json's K and per-frame extrinsics."""
from __future__ import annotations

import numpy as np
import pytest

from conftest import REPO_ROOT

WALK_JOB = REPO_ROOT / "poses" / "jobs" / "gait2392_cmu_walk.yaml"

WALKER_SKELETON = """\
skeleton: walker
coordinates:
  tx: {type: translation, default: 0}
  bend: {type: rotation, default: 0}
bones:
  - name: ground
  - name: hips
    parent: ground
    offset: [0, 0, 1.0]
    dofs:
      - {coord: tx, type: translation, axis: [1, 0, 0]}
  - name: thigh
    parent: hips
    dofs:
      - {coord: bend, type: rotation, axis: [1, 0, 0]}
  - name: shin
    parent: thigh
    offset: [0, 0, -0.5]
  - name: foot
    parent: shin
    offset: [0, 0, -0.5]
  - name: head
    parent: hips
    offset: [0, 0, 0.7]
"""


def _project(cam: dict, P: np.ndarray) -> np.ndarray:
    """(N, 2) pixels of world points ``P`` (N, 3) by camera.json's K and world_to_camera."""
    K, M = np.array(cam["K"]), np.array(cam["world_to_camera"])
    pc = P @ M[:3, :3].T + M[:3, 3]
    assert (pc[:, 2] > 0).all()
    uvw = pc @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def _camera_json(plan) -> dict:
    """camera.json as ``axdf run --render`` writes it for ``plan`` (its scene, as render_plan builds it)."""
    from axdf_cli.pipeline.plan import camera_targets
    from axdf_cli.render.camera import camera_json, sequence_cameras
    from axdf_cli.render.framing import plan_framing, scene_framing
    from axdf_cli.render.scene import Scene

    scene = Scene((), (), np.zeros((2, 3)), tuple(int(f) for f in plan.frames), first_frame=int(plan.pose.first),
                  targets=camera_targets(plan), **scene_framing(plan_framing(plan), plan.pose, plan.frames))
    cams = sequence_cameras(scene, plan.render)
    return camera_json(cams, scene.frames, plan.render, {})


def _walker(tmp_path, last: int, travel: float):
    from axdf_cli.specs import load_pose

    (tmp_path / "walker.yaml").write_text(WALKER_SKELETON)
    (tmp_path / "p.yaml").write_text(f"pose: p\nskeleton: walker.yaml\nframes: [0, {last}]\n"
                                     f"keys:\n  0: {{tx: 0, bend: -20}}\n  {last}: {{tx: {travel}, bend: 20}}\n")
    return load_pose(tmp_path / "p.yaml")


@pytest.mark.parametrize("job", [WALK_JOB, REPO_ROOT / "poses" / "jobs" / "myobody_cmu_walk.yaml"],
                         ids=["gait2392", "myobody"])
def test_the_shipped_walk_keeps_every_keypoint_in_view_and_the_body_large(job):
    """Every keypoint (joints, head top, toe tips) of every frame of the retargeted CMU walk
    (gait2392's and myobody's) projects inside the image of its default camera, the body spans
    at least 40% of the image height at every frame, and the followed root (the pelvis) stays in
    the middle across: within 2% of the width of the centre (the framing's hull is made
    symmetric about it; before, it sat 6% right on average, the body in the right half)."""
    from axdf_cli.model.keypoints import skeleton_keypoints
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.render import framing
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(job), frames_arg="0:248")
    cam = _camera_json(plan)
    root = framing.moving_root(plan.pose.skeleton)
    W, H = cam["width"], cam["height"]
    skel = plan.pose.skeleton
    keypoints = skeleton_keypoints(skel, {i: v for i, (v, _, _) in plan.bone_meshes.items()})
    world = forward_kinematics(skel, sample_coordinates(plan.pose, plan.frames))
    joints = keypoints.positions(world)  # (F, J, 3)
    assert {"head_top", "toe_tip_r", "toe_tip_l"} <= set(keypoints.names)
    spans = []
    for fi, rec in enumerate(cam["frames"]):
        uv = _project(rec["cameras"][0], joints[fi])
        assert (uv >= 0).all() and (uv[:, 0] <= W).all() and (uv[:, 1] <= H).all(), (rec["frame"], uv)
        spans.append(np.ptp(uv[:, 1]) / H)
        across = _project(rec["cameras"][0], world[fi, root:root + 1, :3, 3])[0, 0] / W - 0.5
        assert abs(across) <= 0.02, (rec["frame"], across)
    assert min(spans) >= 0.4, min(spans)


def test_a_long_pose_is_framed_from_a_bounded_sample(tmp_path, monkeypatch):
    """One frame of a 10,000,000-frame pose poses at most FRAMING_SAMPLE frames (and the rest
    pose) for the framing, plus the one written frame for the camera's follow offset."""
    from axdf_cli.render import framing
    from axdf_cli.tolerances import FRAMING_SAMPLE

    pose = _walker(tmp_path, 9_999_999, 100.0)
    posed = []
    fk = framing.forward_kinematics
    monkeypatch.setattr(framing, "forward_kinematics", lambda skel, q: posed.append(len(q)) or fk(skel, q))
    fr = framing.run_framing(pose, [], {}, True)
    assert 0 < sum(posed) <= FRAMING_SAMPLE + 1  # the sample and the rest pose
    assert fr.follow == "hips"  # 100 m of travel: the camera follows
    posed.clear()
    off = framing.follow_offsets(pose, fr.follow, np.array([5_000_000]))
    assert sum(posed) == 1
    np.testing.assert_allclose(off, [[50.0, 0.0, 0.0]], atol=1e-5)


def test_a_travelling_subject_is_followed_and_a_still_one_is_not(tmp_path):
    """10 m of travel for a 2.2 m subject: the camera keeps its orientation and moves with the
    hips, the subject stays in view and the same size; 1 m of travel: one fixed camera."""
    from axdf_cli.render.camera import sequence_cameras
    from axdf_cli.render.framing import framing_frames, run_framing, scene_framing, skeleton_points
    from axdf_cli.render.scene import Scene
    from axdf_cli.specs.render import RenderSettings
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics

    for travel, follows in ((10.0, True), (1.0, False)):
        pose = _walker(tmp_path, 48, travel)
        fr = run_framing(pose, [], {}, True)
        assert (fr.follow is not None) == follows
        frames = np.arange(0, 49, 4)
        scene = Scene((), (), np.zeros((2, 3)), tuple(int(f) for f in frames), first_frame=0,
                      **scene_framing(fr, pose, frames))
        settings = RenderSettings(size=(64, 48))
        cams = [c[0] for c in sequence_cameras(scene, settings)]
        R = [c.world_to_camera[:3, :3] for c in cams]
        np.testing.assert_allclose(R, np.broadcast_to(R[0], (len(R), 3, 3)), atol=1e-12)
        world = forward_kinematics(pose.skeleton, sample_coordinates(pose, frames))
        pts = skeleton_points(pose.skeleton, world, {})
        heights = []
        for c, p in zip(cams, pts):
            q = p @ c.world_to_camera[:3, :3].T + c.world_to_camera[:3, 3]
            uv = (q @ c.K.T)[:, :2] / q[:, 2:3]
            assert (uv >= 0).all() and (uv[:, 0] <= 64).all() and (uv[:, 1] <= 48).all()
            heights.append(np.ptp(uv[:, 1]))
        moved = [c.world_to_camera[:3, 3] for c in cams]
        centres = np.array([-c.world_to_camera[:3, :3].T @ c.world_to_camera[:3, 3] for c in cams])
        if follows:  # at a fixed offset from the hips' horizontal position: the same distance
            rel = centres - world[:, 1, :3, 3] * [1, 1, 0]
            np.testing.assert_allclose(rel, np.broadcast_to(rel[0], rel.shape), atol=1e-5)
            assert min(heights) > 0.5 * 48
        else:
            np.testing.assert_array_equal(moved, np.broadcast_to(moved[0], (len(moved), 3)))
        assert len(framing_frames(0, 48)) == 49


def test_the_ground_plate_lies_under_the_subject():
    """A ground plate (here 1 m x 0.5 m at the origin) is scaled and moved to cover the
    subject's footprint (3 m by 0.4 m, 10 m away) with a margin, its height kept."""
    from axdf_cli.render.framing import plate_matrix
    from axdf_cli.tolerances import GROUND_MARGIN

    plate = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.25, 0.25) for z in (-0.01, 0.0)])
    M = plate_matrix(plate, np.array([10.0, 2.0]), np.array([3.0, 0.4]))
    moved = plate @ M[:3, :3].T + M[:3, 3]
    lo, hi = moved.min(0), moved.max(0)
    assert lo[0] <= 10 - 1.5 - GROUND_MARGIN + 1e-9 and hi[0] >= 10 + 1.5 + GROUND_MARGIN - 1e-9
    assert lo[1] <= 2 - 0.2 - GROUND_MARGIN + 1e-9 and hi[1] >= 2 + 0.2 + GROUND_MARGIN - 1e-9
    np.testing.assert_allclose([lo[2], hi[2]], [-0.01, 0.0])


def test_a_bone_target_follows_the_bone_per_frame_in_data_sets_too(tmp_path):
    """``target: {bone: NAME}`` aims at the bone's origin at every frame (as in a run); ``auto``
    follows a subject that travels farther than it is tall and holds still for one that does
    not."""
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.render.framing import sequence_targets, skeleton_points

    for travel in (10.0, 0.5):
        pose = _walker(tmp_path, 8, travel)
        skel = pose.skeleton
        world = forward_kinematics(skel, sample_coordinates(pose, pose.frames))
        subject = skeleton_points(skel, world, {})
        np.testing.assert_array_equal(sequence_targets(skel, world, subject, ("bone", "shin")), world[:, 3, :3, 3])
        auto = sequence_targets(skel, world, subject, "auto")
        if travel > 2:
            np.testing.assert_allclose(auto[:, 0] - world[:, 1, 0, 3], auto[0, 0] - world[0, 1, 0, 3], atol=1e-6)
        else:
            np.testing.assert_array_equal(auto, np.broadcast_to(auto[0], auto.shape))


def test_the_index_marks_samples_with_no_visible_keypoint():
    """The index's visible_keypoints column counts each sample's visible keypoints (0: none);
    a record without the counts leaves it empty."""
    from axdf_cli.dataset.index import index_rows

    recs = [{"sequence": "s0", "index": 0, "source": "x", "frames": [0, 4], "views": ["a", "b"],
             "visible_keypoints": [[3, 0], [0, 5]]},
            {"sequence": "s1", "index": 1, "source": "x", "frames": [0], "views": ["a"]}]
    cols = index_rows(recs, 1, 1, ("png",))
    assert cols["visible_keypoints"] == [3, 0, 0, 5, None]


@pytest.mark.parametrize("bad, column", [([[1]], [1, None]), ("x", [None, None]), ([[1.5, 2]], [None, 2]),
                                         ([[-1, True]], [None, None])])
def test_a_damaged_count_is_left_empty(bad, column):
    from axdf_cli.dataset.index import index_rows

    recs = [{"sequence": "s0", "index": 0, "source": "x", "frames": [0], "views": ["a", "b"], "visible_keypoints": bad}]
    assert index_rows(recs, 1, 1, ("png",))["visible_keypoints"] == column


def test_a_data_sets_ground_plate_lies_under_each_sequences_subject():
    """A data set draws its ground plate as a run does: under the sequence's subject (here a
    walker 10 m from the plate at the origin), not where the skeleton file puts it."""
    from types import SimpleNamespace

    from axdf_cli.dataset.worker import sequence_plates
    from axdf_cli.render.framing import placed_plates
    from axdf_cli.render.scene import Scene, SceneBone

    plate = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.25, 0.25) for z in (-0.01, 0.0)])
    bones = (SimpleNamespace(name="ground", parent=-1, dofs=(), mesh="ground.obj"),
             SimpleNamespace(name="hips", parent=0, dofs=("tx",), mesh=None))
    scene = Scene((), (SceneBone("ground", plate, np.zeros((0, 3), np.int32)),), np.zeros((2, 3)), ())
    ctx = SimpleNamespace(skeleton=SimpleNamespace(bones=bones), scene=scene, scene_bones=[0])
    rng = np.random.default_rng(37)
    subject = rng.uniform([9.0, 1.8, 0.0], [11.0, 2.2, 1.8], size=(4, 20, 3))  # (F, P, 3)
    placed = sequence_plates(ctx, subject)
    moved = placed_plates(placed, np.eye(4)[None])[0]
    v = plate @ moved[:3, :3].T + moved[:3, 3]
    lo, hi = v.min(0), v.max(0)
    assert (lo[:2] <= subject[..., :2].reshape(-1, 2).min(0)).all() and (hi[:2] >= subject[..., :2].reshape(-1, 2).max(0)).all()
    np.testing.assert_allclose([lo[2], hi[2]], [-0.01, 0.0])
    assert sequence_plates(SimpleNamespace(**{**vars(ctx), "scene_bones": []}), subject) is None
