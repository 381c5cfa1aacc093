"""Data-set keypoints: anatomical names from the skeleton's joints, no world
origin, no coincident duplicates, and the head, hands and toes where a skeleton has them."""
from __future__ import annotations

import functools
import itertools

import numpy as np
import pytest

from conftest import REPO_ROOT

SKELETONS = REPO_ROOT / "poses" / "skeletons"


@functools.lru_cache(maxsize=None)
def _keypoints(name: str):
    from axdf_cli.formats import load_triangles
    from axdf_cli.model.keypoints import skeleton_keypoints
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import load_skeleton

    skel = load_skeleton(SKELETONS / f"{name}.yaml")
    verts = {i: load_triangles(b.mesh)[0] for i, b in enumerate(skel.bones) if b.mesh}
    kp = skeleton_keypoints(skel, verts)
    rest = kp.positions(forward_kinematics(skel, skel.rest_coordinates()[None]))[0]
    return skel, kp, {n: rest[j] for j, n in enumerate(kp.names)}


# The names each shipped skeleton must label (anatomical, from its own joint centres).
EXPECTED = {
    "human_r": {"hip_r", "knee_r", "ankle_r", "toe_tip_r", "shoulder_r", "elbow_r"},
    "gait2392": {"pelvis", "lumbar", "head_top"} | {f"{j}_{s}" for s in "rl" for j in
                                                    ("hip", "knee", "ankle", "subtalar", "toe_base", "toe_tip")},
    "arm26": {"shoulder_r", "elbow_r", "fingertips_r"},
    "cmu_131_01": {"pelvis", "spine", "chest", "neck", "head", "head_top"} | {
        f"{j}_{s}" for s in "rl" for j in ("hip", "knee", "ankle", "toe_base", "toe_tip", "shoulder", "elbow",
                                            "wrist", "knuckles", "fingertips", "thumb_tip")},
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_shipped_skeletons_get_anatomical_names_and_no_bone_names(name):
    from axdf_cli.tolerances import KEYPOINT_MERGE

    skel, kp, pos = _keypoints(name)
    assert set(kp.names) == EXPECTED[name]
    # no world origin: no keypoint rides on a root without DOFs (ground), and none is a bone's name
    roots = {i for i, b in enumerate(skel.bones) if b.parent < 0 and not b.dofs}
    assert not roots & set(kp.bones.tolist())
    assert not set(kp.names) & {b.name for b in skel.bones} - {"pelvis"}
    # no duplicates: every pair at least the merge distance apart at rest
    for a, b in itertools.combinations(kp.names, 2):
        assert np.linalg.norm(pos[a] - pos[b]) >= KEYPOINT_MERGE, (a, b)
    # a tree: each parent comes before its child
    assert all(p < j for j, p in enumerate(kp.parents))


@pytest.mark.parametrize("name", ["gait2392", "cmu_131_01", "human_r"])
def test_legs_are_in_anatomical_order(name):
    """Each leg runs hip, knee, ankle, toe tip downwards and ends forward (-Y: the body faces -Y)."""
    _, kp, pos = _keypoints(name)
    for s in "rl" if name != "human_r" else "r":
        hip, knee, ankle, toe = (pos[f"{j}_{s}"] for j in ("hip", "knee", "ankle", "toe_tip"))
        assert hip[2] > knee[2] + 0.3 > ankle[2] + 0.6 and toe[2] < knee[2]
        assert toe[1] < ankle[1] - 0.05  # the toes are in front of the ankle
        assert np.sign(hip[0]) == (-1 if s == "r" else 1)  # the right side is -X


def test_head_and_hands_where_the_skeleton_has_them():
    _, _, g = _keypoints("gait2392")
    assert g["head_top"][2] > 1.6 and all(g["head_top"][2] > v[2] for k, v in g.items() if k != "head_top")
    _, _, c = _keypoints("cmu_131_01")
    assert c["head_top"][2] > c["head"][2] > c["neck"][2] > c["chest"][2]
    for s in "rl":
        # fingertips below the wrist in the rest pose (arms hanging), thumb beside the fingers
        assert c[f"fingertips_{s}"][2] < c[f"knuckles_{s}"][2] < c[f"wrist_{s}"][2] < c[f"elbow_{s}"][2]
    _, _, a = _keypoints("arm26")
    assert a["elbow_r"][2] - a["fingertips_r"][2] > 0.35  # forearm and hand: ~42 cm below the elbow


def test_coincident_joints_merge_into_the_first(tmp_path):
    """human_r's radius joins the ulna 2 cm from the elbow: one keypoint, the elbow, on the ulna;
    CMU's helper joints at offset 0 (LHipJoint, lowerback, lowerneck, collars) likewise."""
    skel, kp, _ = _keypoints("human_r")
    assert "radioulnar_r" not in kp.names
    assert skel.bones[kp.bones[kp.names.index("elbow_r")]].name == "ulna_r"
    skel, kp, _ = _keypoints("cmu_131_01")
    assert skel.bones[kp.bones[kp.names.index("pelvis")]].name == "Hips"
    assert not {"pelvis_l", "lumbar", "neck_base", "clavicle_l", "hand_l", "thumb_base_l"} & set(kp.names)


def test_unknown_bones_fall_back_to_the_bones_they_join(chain_skeleton):
    """A joint the tables do not name is ``<parent>_<bone>``; a repeat gets ``_2``."""
    from dataclasses import replace

    from axdf_cli.model.keypoints import skeleton_keypoints

    kp = skeleton_keypoints(chain_skeleton)
    assert kp.names == ("b0_b1", "b1_b2", "b2_b3", "b3_b4") and kp.kinds == ("joint",) * 4
    bones = list(chain_skeleton.bones)
    bones[2] = replace(bones[2], name="femur_r")
    bones[4] = replace(bones[4], name="femur_l")
    kp = skeleton_keypoints(replace(chain_skeleton, bones=tuple(bones)))
    assert kp.names == ("b0_b1", "hip_r", "femur_r_b3", "hip_l")


def test_keypoints_move_with_their_bones(chain_skeleton):
    """Positions are the bones' frames applied to the fixed local points, at every frame."""
    from axdf_cli.model.keypoints import skeleton_keypoints
    from axdf_cli.model.skeleton import forward_kinematics

    kp = skeleton_keypoints(chain_skeleton)
    rng = np.random.default_rng(4)
    q = rng.uniform([0, -50, -80], [0.3, 50, 80], size=(6, 3))
    world = forward_kinematics(chain_skeleton, q)
    np.testing.assert_allclose(kp.positions(world), world[:, kp.bones][..., :3, 3], rtol=0, atol=1e-12)
