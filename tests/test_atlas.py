"""The Visible Human atlas registered onto gait2392 (axdf_cli/tools/atlas.py) and the library
made from it (axdf_cli/tools/atlas_library.py, muscles/gait2392_atlas).

Where ../shared/data has the atlas: the right leg's registration pulls the atlas' bones onto
gait2392's (mean distance of their samples below 0.5 mm per bone, from 7-13 mm after the
landmarks alone) and holds the hip, the other hip, the knee and the ankle on the skeleton's
joint centres; the identity in place of the warp leaves the tibia centimetres off. Without
data: a mesh cut into a group's parts gives closed parts of the whole volume; a point inside a
bone is put outside it; the shipped library keeps every gait2392 muscle's name."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from osim_common import DATA, REPO

ATLAS = DATA / "atlas" / "visible_human_female"
LIB = REPO / "muscles" / "gait2392_atlas"
OLD = REPO / "muscles" / "gait2392"
SKELETON = REPO / "poses" / "skeletons" / "gait2392.yaml"
MAP = REPO / "atlases" / "gait2392.yaml"
needs_atlas = pytest.mark.skipif(not (ATLAS / "Right").is_dir(),
                                 reason=f"the Visible Human atlas not found at {ATLAS} (../shared/data)")


@pytest.fixture(scope="module")
def rest():
    from axdf_cli.tools.atlas_library import rest_state

    return rest_state(SKELETON)


@pytest.fixture(scope="module")
def atlas():
    from axdf_cli.tools.atlas import Atlas
    from axdf_cli.tools.tables import load_atlas_map

    return Atlas(ATLAS, load_atlas_map(MAP))


@pytest.fixture(scope="module")
def registration(rest, atlas):
    from axdf_cli.tools import atlas as at

    skel, pose, bones = rest
    return at.register(atlas, skel, pose, bones, "r")


@needs_atlas
def test_bones_registered_within_half_a_millimetre(registration):
    rep = registration.report
    for bone in ("tibia_r", "talus_r", "calcn_r"):
        assert rep["bones_before"][bone]["mean_mm"] > 5.0  # the landmarks alone leave them apart
        assert rep["bones_after"][bone]["mean_mm"] < 0.5, (bone, rep["bones_after"][bone])
        assert rep["bones_after"][bone]["max_mm"] < 5.0, (bone, rep["bones_after"][bone])


@needs_atlas
def test_warp_puts_the_landmarks_on_the_joints(registration, rest, atlas):
    from axdf_cli.tools import atlas as at

    skel, pose, _ = rest
    model = at.model_landmarks(skel, pose, atlas.map, "r")
    for name, x in registration.landmarks_atlas.items():
        got = registration.apply(x[None])[0]
        assert np.linalg.norm(got - model[name]) < 1e-4, name  # 0.1 mm
    # the similarity alone misses the knee by about a centimetre (the atlas' femur is longer)
    knee = registration.apply(registration.landmarks_atlas["knee"][None], warp=False)[0]
    assert np.linalg.norm(knee - model["knee"]) > 5e-3


@needs_atlas
def test_identity_for_the_warp_leaves_the_tibia_apart(registration, rest, atlas):
    from axdf_cli.tools import atlas as at

    _, _, bones = rest
    v, _ = at.read_atlas_mesh(atlas.path("r", "Bone", "Tibia"))
    v = v[::10]
    warped = at.bone_distance(registration.apply(v), bones["tibia_r"]).mean()
    landmarks_only = at.bone_distance(registration.apply(v, warp=False), bones["tibia_r"]).mean()
    assert warped < 2e-3 < landmarks_only


def test_split_parts_are_closed_and_keep_the_volume():
    import trimesh

    from axdf_cli.tools.atlas_library import split_parts

    m = trimesh.creation.capsule(height=0.2, radius=0.03, count=[24, 24])  # along z
    centres = np.array([[0, 0, -0.08], [0, 0, 0.0], [0, 0, 0.08]])
    parts = split_parts(np.asarray(m.vertices), np.asarray(m.faces), centres, 0.002)
    assert len(parts) == 3
    vols = []
    for v, f in parts:
        t = trimesh.Trimesh(v, f, process=True)
        assert t.is_watertight and t.body_count == 1
        vols.append(abs(t.volume))
    assert sum(vols) == pytest.approx(m.volume, rel=0.03)
    assert vols[1] == pytest.approx(0.08 * np.pi * 0.03 ** 2, rel=0.05)  # the middle slab: a cylinder


def test_pieces_apart_are_joined_into_one_and_one_piece_is_left_as_it_is():
    import trimesh

    from axdf_cli.tools.atlas_library import one_piece, signed_volume

    a = trimesh.creation.box(extents=[0.02, 0.02, 0.04])
    b = a.copy()
    b.apply_translation([0.0, 0.0, 0.046])  # 6 mm apart
    both = trimesh.util.concatenate([a, b])
    v, f, width = one_piece(np.asarray(both.vertices), np.asarray(both.faces), 0.0015)
    t = trimesh.Trimesh(v, f, process=True)
    assert t.is_watertight and t.body_count == 1
    assert 0.0015 <= width <= 0.006
    # the bridge adds volume, but no more than the gap's box
    assert 2 * a.volume * 0.95 <= signed_volume(v, f) <= 2 * a.volume + 0.02 * 0.02 * 0.006 * 1.3
    v1, f1, w1 = one_piece(np.asarray(a.vertices), np.asarray(a.faces), 0.0015)
    assert w1 == 0.0 and v1 is not None and np.array_equal(f1, np.asarray(a.faces))


def test_rigid_icp_finds_a_bone_turned_about_its_long_axis_and_blend_follows_it():
    import trimesh

    from axdf_cli.tools.atlas import Registration, rigid_icp

    bone = trimesh.creation.box(extents=[0.03, 0.015, 0.25])  # flat and long: its turn is seen
    ang = np.radians(20.0)
    R = np.array([[np.cos(ang), -np.sin(ang), 0.0], [np.sin(ang), np.cos(ang), 0.0], [0.0, 0.0, 1.0]])
    t = np.array([0.004, -0.003, 0.01])
    model = (np.asarray(bone.vertices) @ R.T + t, np.asarray(bone.faces))
    x, _ = trimesh.sample.sample_surface_even(bone, 400, seed=1)
    ms, _ = trimesh.sample.sample_surface_even(trimesh.Trimesh(*model), 400, seed=2)
    Rf, tf = rigid_icp(np.asarray(x), model, np.asarray(ms))
    # off by no more than 2 degrees (the samples' spacing, 8 mm, limits point-to-point ICP)
    off = np.degrees(np.arccos(np.clip((np.trace(Rf.T @ R) - 1) / 2, -1, 1)))
    assert off < 2.0
    before = np.degrees(np.arccos((np.trace(R) - 1) / 2))
    assert before == pytest.approx(20.0)
    assert np.abs(tf - t).max() < 0.002
    reg = Registration("r", 1.0, np.eye(3), np.zeros(3), {}, {}, pieces={"bone": (np.asarray(x), Rf, tf)})
    p = np.array([[0.05, 0.0, 0.0], [0.0, 0.04, 0.1]])
    assert reg.apply(p) == pytest.approx(p @ Rf.T + tf, abs=1e-9)  # one bone: its motion
    # along a muscle from that bone to no bone: the origin moves with it, the insertion stays
    ends = (("bone", p[0]), (None, p[1]))
    assert reg.along(p, ends) == pytest.approx(np.stack([p[0] @ Rf.T + tf, p[1]]), abs=1e-9)


def test_push_out_moves_a_point_out_of_a_bone():
    import trimesh

    from axdf_cli.geometry.winding import push_out_of_meshes

    box = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    bones = [(np.asarray(box.vertices), np.asarray(box.faces))]
    pts = np.array([[0.045, 0.0, 0.0], [0.2, 0.0, 0.0]])
    out, moved = push_out_of_meshes(pts, bones, 0.001)
    assert moved == 1
    assert out[0] == pytest.approx([0.051, 0.0, 0.0], abs=1e-9)
    assert out[1] == pytest.approx(pts[1])


@needs_atlas
@pytest.mark.skipif(not LIB.is_dir(), reason="muscles/gait2392_atlas not made (make atlas)")
def test_registered_meshes_are_the_ones_the_library_was_fitted_to(rest, atlas):
    """``registered_meshes`` (what scripts/atlas_sheet.py draws beside the library) gives the
    right leg's muscles the shipped library's report records: the same names, atlas files and
    parts, and the same count of vertices pushed out of the bones; closed meshes that hold a
    volume, each near its fitted muscle."""
    import trimesh

    from axdf_cli.tools.atlas_library import registered_meshes

    skel, pose, bones = rest
    meshes, sides = registered_meshes(atlas, skel, pose, bones, OLD, ("r",))
    recorded = json.loads((LIB / "atlas_report.json").read_text())["sides"]["r"]["muscles"]
    assert sides["r"]["muscles"] == recorded
    assert sorted(name for name, _, _ in meshes) == sorted(recorded)
    fitted = {m["muscle"]: m for m in json.loads((LIB / "atlas_report.json").read_text())["fitted"]}
    for name, v, f in meshes:
        m = trimesh.Trimesh(v, f, process=True)
        assert abs(m.volume) > 1e-6, name
        if name in fitted:
            assert abs(m.volume) * 1e6 == pytest.approx(fitted[name]["mesh_volume_cm3"], rel=0.02), name


@pytest.mark.skipif(not LIB.is_dir(), reason="muscles/gait2392_atlas not made (make atlas)")
def test_library_keeps_every_model_name():
    from axdf_cli.specs import load_muscle_file

    old = sorted(p.name for p in OLD.glob("*.yaml"))
    assert sorted(p.name for p in LIB.glob("*.yaml")) == old
    report = json.loads((LIB / "atlas_report.json").read_text())
    fitted = {m["muscle"] for m in report["fitted"]}
    assert {"vas_lat_r", "med_gas_r", "glut_max1_r", "glut_max3_r", "tib_ant_r"} <= fitted
    for name in old:
        specs = load_muscle_file(LIB / name)
        assert specs[0].name == Path(name).stem
        if specs[0].name in fitted:
            assert specs[0].axis and specs[0].sections[0].outline is not None


@pytest.mark.skipif(not LIB.is_dir(), reason="muscles/gait2392_atlas not made (make atlas)")
def test_library_lengths_are_the_models_paths():
    """Every fitted muscle keeps gait2392's path as its line of action: over walk frames its
    stats length is the imported muscle's (OpenSim's path, within 0.4-0.8% of getLength) to
    the last digit, while its belly is the atlas's (its own axis, shorter and bound to bones)."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
    from axdf_cli.specs.pose import load_pose

    skel = load_skeleton(REPO / "poses" / "skeletons" / "gait2392.yaml", RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    pose = load_pose(REPO / "poses" / "gait2392_walk.yaml")
    q = sample_coordinates(pose, np.arange(18, 84, 11))
    world = forward_kinematics(skel, q)
    fitted = {m["muscle"] for m in json.loads((LIB / "atlas_report.json").read_text())["fitted"]}
    assert len(fitted) >= 70
    for name in sorted(fitted):
        (new,) = load_muscle_file(LIB / f"{name}.yaml")
        (old,) = load_muscle_file(OLD / f"{name}.yaml")
        assert new.axis and new.path is not None, name
        line = MuscleModel(new, skel.bone_index, rest, skel).line_length(world, q)
        np.testing.assert_allclose(line, MuscleModel(old, skel.bone_index, rest, skel).axis_length(world, q),
                                   rtol=1e-12, err_msg=name)


@pytest.mark.skipif(not LIB.is_dir(), reason="muscles/gait2392_atlas not made (make atlas)")
def test_leg_muscles_stay_on_their_segment_over_the_walk():
    """A fitted thigh muscle stays along the thigh and a calf muscle along the shank over the
    walk: the 95th percentile of its vertices' distances from the segment's line (hip -> knee,
    knee -> ankle) grows by at most 20 mm from rest. A belly hung on a bone it does not lie
    along fails: gastrocnemius bound to the femur alone swung 162 mm from the shank in swing
    (48 at rest), the hamstrings on the pelvis and tibia alone 110 mm (57)."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
    from axdf_cli.specs.pose import load_pose

    skel = load_skeleton(SKELETON, RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    pose = load_pose(REPO / "poses" / "gait2392_walk.yaml")
    q = sample_coordinates(pose, np.arange(18, 84, 4))
    world = forward_kinematics(skel, q)

    def spread(v, w, a, b):
        p0, p1 = w[a, :3, 3], w[b, :3, 3]
        e = p1 - p0
        lam = np.clip((v - p0) @ e / (e @ e), 0.0, 1.0)
        return np.percentile(np.linalg.norm(v - (p0 + lam[:, None] * e), axis=1), 95)

    fe, ti, ta = (skel.bone_index[n] for n in ("femur_r", "tibia_r", "talus_r"))
    segments = {**{m: (fe, ti) for m in ("semimem", "semiten", "grac", "sar", "rect_fem", "vas_lat", "vas_med",
                                        "bifemsh", "add_long", "add_mag1")},
                **{m: (ti, ta) for m in ("med_gas", "lat_gas", "soleus", "tib_post", "tib_ant")}}
    fitted = {m["muscle"] for m in json.loads((LIB / "atlas_report.json").read_text())["fitted"]}
    checked = 0
    for short, (a, b) in segments.items():
        name = f"{short}_r"
        if name not in fitted:
            continue
        (spec,) = load_muscle_file(LIB / f"{name}.yaml")
        m = MuscleModel(spec, skel.bone_index, rest, skel)
        at_rest = spread(m.rest_vertices.astype(np.float64), rest, a, b)
        res = m.evaluate(world, np.zeros(len(q)), coords=q)
        walk = max(spread(res.vertices[k], world[k], a, b) for k in range(len(q)))
        assert walk <= at_rest + 0.020, (name, at_rest, walk, sorted({p.bone for p in spec.axis}))
        checked += 1
    assert checked >= 12
