"""Anatomical keypoints of a skeleton: named joints and end points, fixed in bones.

A **joint** is where a child bone attaches to its parent: the origin of the child's joint
frame, ``world_b @ [post_offset_b, 1]``. It is a keypoint only where the skeleton
articulates (the bone has DOFs): a welded bone (a scapula fixed to the thorax) and a root
without DOFs (OpenSim's and BVH's ``ground``: the world origin) give none. An **end point**
is the far end of a chain: a BVH end site (a leaf bone without DOFs or mesh: its joint), or,
for a leaf bone whose mesh ends the head, a hand or the toes, the mesh vertex farthest from
the bone's joint (the top of the skull, the fingertips, the tip of the toes).

Names come from :data:`JOINT_NAMES` and :data:`END_NAMES`, written for the naming schemes of
the shipped skeletons (OpenSim gait2392/gait2354/Rajagopal and arm26, CMU BVH, ``human_r``)
with both sides expanded; a joint the tables do not name is called ``<parent>_<bone>`` (the
two bones it joins), an end site keeps its bone's name, and a leaf mesh the tables do not
name gives no end point.

Keypoints closer than :data:`axdf_cli.tolerances.KEYPOINT_MERGE` at the rest pose are one
point (BVH helper joints at offset 0 from their parent, the radius's head 2 cm beside the
humero-ulnar joint): the first in bone order (parents before children) is kept, with its
name and bone, and the others are left out. Names are unique (a repeat gets ``_2``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from axdf_cli.tolerances import KEYPOINT_MERGE


def _sided(table: dict[str, str]) -> dict[str, str]:
    """Expand ``{S}`` (side letter r/l), ``{SIDE}`` (Right/Left), ``{Sd}`` (R/L), ``{sd}``
    (r/l as a prefix) in keys and values; the joint name always ends in ``_r`` / ``_l``."""
    out = {}
    for key, name in table.items():
        if "{" not in key:
            out[key] = name
            continue
        for s, side, sd in (("r", "Right", "R"), ("l", "Left", "L")):
            out[key.format(S=s, SIDE=side, Sd=sd, sd=s)] = name.format(S=s)
    return out


#: Bone name -> the name of the joint at its proximal end (where it attaches to its parent).
JOINT_NAMES: dict[str, str] = _sided({
    # OpenSim gait2392 / gait2354 / Rajagopal2016 (bodies named after bones)
    "pelvis": "pelvis", "torso": "lumbar",
    "femur_{S}": "hip_{S}", "tibia_{S}": "knee_{S}", "talus_{S}": "ankle_{S}",
    "calcn_{S}": "subtalar_{S}", "toes_{S}": "toe_base_{S}",
    "humerus_{S}": "shoulder_{S}", "ulna_{S}": "elbow_{S}", "radius_{S}": "radioulnar_{S}",
    "hand_{S}": "wrist_{S}", "foot_{S}": "ankle_{S}",
    # OpenSim arm26
    "{sd}_humerus": "shoulder_{S}", "{sd}_ulna_radius_hand": "elbow_{S}",
    # CMU BVH (joints named after the joint at the bone's start)
    "Hips": "pelvis", "lowerback": "lumbar", "Chest": "spine", "Chest2": "chest",
    "lowerneck": "neck_base", "Neck": "neck", "Head": "head",
    "{Sd}HipJoint": "pelvis_{S}", "{SIDE}Hip": "hip_{S}", "{SIDE}Knee": "knee_{S}",
    "{SIDE}Ankle": "ankle_{S}", "{SIDE}Toe": "toe_base_{S}",
    "{SIDE}Collar": "clavicle_{S}", "{SIDE}Shoulder": "shoulder_{S}", "{SIDE}Elbow": "elbow_{S}",
    "{SIDE}Wrist": "wrist_{S}", "{sd}hand": "hand_{S}", "{Sd}Fingers": "knuckles_{S}",
    "{Sd}Thumb": "thumb_base_{S}",
})

#: Leaf bone name -> the name of its end point (an end site's joint, or a leaf mesh's far end).
END_NAMES: dict[str, str] = _sided({
    # CMU BVH end sites
    "Head_end": "head_top", "{SIDE}Toe_end": "toe_tip_{S}", "{Sd}Fingers_end": "fingertips_{S}",
    "{Sd}Thumb_end": "thumb_tip_{S}",
    # OpenSim meshes that end a chain: the torso's skull, the toes, a hand
    "torso": "head_top", "head": "head_top", "toes_{S}": "toe_tip_{S}", "foot_{S}": "toe_tip_{S}",
    "hand_{S}": "fingertips_{S}", "{sd}_ulna_radius_hand": "fingertips_{S}",
})


@dataclass(frozen=True)
class Keypoints:
    """A skeleton's keypoints: each a point fixed in one bone.

    ``names`` (J,); ``bones`` (J,) int: the bone each rides on; ``local`` (J, 3) float64: its
    position in that bone's frame; ``parents`` (J,) int: the keypoint it hangs from (-1: none),
    for drawing; ``kinds`` (J,): ``joint`` or ``end``."""

    names: tuple[str, ...]
    bones: np.ndarray
    local: np.ndarray
    parents: np.ndarray
    kinds: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.names)

    def positions(self, world: np.ndarray) -> np.ndarray:
        """(F, J, 3) world positions from bone frames ``world`` (F, B, 4, 4)."""
        w = world[:, self.bones]  # (F, J, 4, 4)
        # p[f,j,i] = sum_k R[f,j,i,k] local[j,k] + t[f,j,i]
        return np.einsum("fjik,jk->fji", w[..., :3, :3], self.local) + w[..., :3, 3]


def skeleton_keypoints(skel, bone_vertices: dict | None = None) -> Keypoints:
    """The keypoints of ``skel`` (module docstring); ``bone_vertices``: bone index -> (V, 3)
    bone-local mesh vertices (leaf meshes give end points)."""
    from axdf_cli.model.skeleton import forward_kinematics

    bone_vertices = bone_vertices or {}
    bones = skel.bones
    children = [0] * len(bones)
    for b in bones:
        if b.parent >= 0:
            children[b.parent] += 1
    cand = []  # (name, bone, local, kind)
    for i, b in enumerate(bones):
        post = np.asarray(b.post_offset, dtype=np.float64)
        if b.dofs:
            parent = bones[b.parent].name if b.parent >= 0 else None
            name = JOINT_NAMES.get(b.name) or (f"{parent}_{b.name}" if parent else b.name)
            cand.append((name, i, post, "joint"))
        if children[i]:
            continue
        if not b.dofs and i not in bone_vertices and b.mesh is None and b.parent >= 0:
            cand.append((END_NAMES.get(b.name, b.name), i, post, "end"))  # an end site
        elif b.name in END_NAMES and i in bone_vertices and len(bone_vertices[i]):
            v = np.asarray(bone_vertices[i], dtype=np.float64)
            far = v[int(np.argmax(np.linalg.norm(v - post, axis=1)))]
            cand.append((END_NAMES[b.name], i, far, "end"))
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]  # (B, 4, 4)
    # p[c,i] = sum_k R[bone_c,i,k] local[c,k] + t[bone_c,i]
    idx = np.array([c[1] for c in cand], dtype=np.int64)
    loc = np.array([c[2] for c in cand], dtype=np.float64).reshape(-1, 3)
    pos = np.einsum("cik,ck->ci", rest[idx, :3, :3], loc) + rest[idx, :3, 3] if len(cand) else np.zeros((0, 3))
    kept: list[int] = []
    for c in range(len(cand)):
        if all(np.linalg.norm(pos[c] - pos[k]) >= KEYPOINT_MERGE for k in kept):
            kept.append(c)
    names, seen = [], set()
    for c in kept:
        name, n = cand[c][0], 2
        while name in seen:
            name, n = f"{cand[c][0]}_{n}", n + 1
        seen.add(name)
        names.append(name)
    # parent keypoint: for a joint, the nearest ancestor bone's joint; for an end point, its
    # own bone's joint (or the nearest ancestor's)
    joint_of = {}  # bone -> kept keypoint index of its joint
    for k, c in enumerate(kept):
        if cand[c][3] == "joint":
            joint_of[cand[c][1]] = k
    parents = []
    for k, c in enumerate(kept):
        b = cand[c][1]
        b = bones[b].parent if cand[c][3] == "joint" else b
        while b >= 0 and b not in joint_of:
            b = bones[b].parent
        parents.append(joint_of[b] if b >= 0 else -1)
    return Keypoints(names=tuple(names), bones=idx[kept] if kept else np.zeros(0, np.int64),
                     local=loc[kept] if kept else np.zeros((0, 3)), parents=np.array(parents, dtype=np.int64),
                     kinds=tuple(cand[c][3] for c in kept))
