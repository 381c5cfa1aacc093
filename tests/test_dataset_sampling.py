"""The sampler: poses stay within each coordinate's range, draws depend only on (seed,
sequence, frame, view), sphere cameras keep their distance and elevation, and OpenSim
motions come in through the importer's reader."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from dataset_helpers import BALL_R, DATASET_YAML, write_tiny
from hypothesis import given, settings
from hypothesis import strategies as st


@pytest.fixture(scope="module")
def tiny_spec(tmp_path_factory):
    from axdf_cli.dataset.worker import build_context

    d = tmp_path_factory.mktemp("spec")
    write_tiny(d, DATASET_YAML.replace("  roll: {range: [-80, 80]}\n", "  roll: {fixed: 30}\n"))
    return build_context(d / "tiny.yaml")


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**63 - 1), frames=st.integers(1, 12), keys=st.integers(1, 12))
def test_uniform_poses_stay_within_ranges(tiny_spec, seed, frames, keys):
    from axdf_cli.dataset.sampling import sample_pose
    from axdf_cli.dataset.spec import Entry, Sequence
    from axdf_cli.model.pose import sample_coordinates

    ctx = tiny_spec
    entry = Entry("uniform", 1, None, frames, min(keys, frames), {})
    spec = dataclasses.replace(ctx.spec, seed=seed, entries=(entry,))
    fr = np.arange(frames)
    pose = sample_pose(spec, Sequence(0, "s", 0, frames), ctx.plan_skeleton, None, fr)
    q = sample_coordinates(pose, np.linspace(0, frames - 1, 4 * frames))  # between the keys too
    idx = ctx.plan_skeleton.coord_index
    assert (q[:, idx["stretch"]] >= 0.0).all() and (q[:, idx["stretch"]] <= 0.4).all()
    assert (np.abs(q[:, idx["bend"]]) <= 50.0).all()
    assert (q[:, idx["roll"]] == 30.0).all()  # fixed


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**63 - 1), spread=st.floats(0.0, 200.0), keys=st.sampled_from([None, 1, 2, 3]))
def test_perturbed_poses_stay_within_ranges(tiny_spec, seed, spread, keys):
    from axdf_cli.dataset.sampling import sample_pose
    from axdf_cli.dataset.spec import Entry, Sequence, load_motion, motion_frames
    from axdf_cli.model.pose import sample_coordinates

    ctx = tiny_spec
    entry = Entry("perturb", 1, "walk", None, keys, {"default": spread, "stretch": spread / 100})
    spec = dataclasses.replace(ctx.spec, seed=seed, entries=(entry,))
    base = load_motion(spec, "walk")
    fr = motion_frames(spec, "walk")
    pose = sample_pose(spec, Sequence(0, "s", 0, len(fr)), ctx.plan_skeleton, base, fr)
    q = sample_coordinates(pose, base.frames)
    idx = ctx.plan_skeleton.coord_index
    assert (q[:, idx["stretch"]] >= 0.0).all() and (q[:, idx["stretch"]] <= 0.4).all()
    assert (np.abs(q[:, idx["bend"]]) <= 50.0).all()
    assert (q[:, idx["roll"]] == 30.0).all()
    if spread == 0.0:  # no noise: the base motion itself
        b = sample_coordinates(base, base.frames)
        np.testing.assert_allclose(q[:, idx["bend"]], b[:, idx["bend"]], atol=1e-12)


def test_draws_depend_only_on_seed_sequence_frame_view(tiny_spec):
    from axdf_cli.dataset.sampling import STREAM_CAMERA, STREAM_POSE, rng_for, sphere_draw
    from axdf_cli.dataset.spec import Sequence

    spec = tiny_spec.spec
    a = rng_for(7, STREAM_POSE, 3, 2).random(4)
    np.testing.assert_array_equal(a, rng_for(7, STREAM_POSE, 3, 2).random(4))
    for other in ((8, STREAM_POSE, 3, 2), (7, STREAM_CAMERA, 3, 2), (7, STREAM_POSE, 4, 2), (7, STREAM_POSE, 3, 1)):
        assert not np.allclose(a, rng_for(*other).random(4))
    s = Sequence(5, "seq_00005", 0, 1)
    assert sphere_draw(spec, s, 0, 1) == sphere_draw(spec, s, 0, 1) != sphere_draw(spec, s, 0, 0)


def test_sphere_cameras_keep_distance_elevation_and_look_at_the_target(tiny_spec):
    from axdf_cli.dataset import labels as lab
    from axdf_cli.dataset.spec import Sequence
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.render.framing import skeleton_points

    ctx = tiny_spec
    sph = ctx.spec.sphere
    skel = ctx.skeleton
    q = np.tile(skel.rest_coordinates(), (3, 1))
    q[:, skel.coord_index["bend"]] = [0, 20, 40]
    world = forward_kinematics(skel, q)
    subject = skeleton_points(skel, world, ctx.bone_meshes)
    # the fixed root b0 is left out; its children's balls are in
    assert subject.shape == (3, 4 + 4 * 8, 3)
    np.testing.assert_allclose(subject[0, 4:12].min(0), world[0, 1, :3, 3] - BALL_R, atol=2e-3)
    target = 0.5 * (subject.reshape(-1, 3).min(0) + subject.reshape(-1, 3).max(0))
    for k in range(20):
        K, w2c, clip = lab.view_cameras(ctx.spec, Sequence(k, "s", 0, 3), np.arange(3), subject, world, skel)
        assert (w2c == w2c[:1]).all()  # per: sequence
        for v in range(sph.views):
            R, t = w2c[0, v, :3, :3], w2c[0, v, :3, 3]
            centre = -R.T @ t
            d = np.linalg.norm(centre - target)
            assert sph.distance[0] - 1e-9 <= d <= sph.distance[1] + 1e-9
            el = np.degrees(np.arcsin((centre - target)[2] / d))
            assert sph.elevation[0] - 1e-6 <= el <= sph.elevation[1] + 1e-6
            p = R @ target + t
            np.testing.assert_allclose((K[v] @ p)[:2] / p[2], np.array(ctx.spec.render.size) / 2, atol=1e-9)
            assert 0 < clip[0, v, 0] < p[2] - 0.3 and clip[0, v, 1] > p[2] + 0.3


def test_opensim_motion_through_the_importers_reader(tmp_path, monkeypatch, capsys):
    from conftest import run_main

    d = tmp_path
    mot = ("walk\nversion=1\nnRows=3\nnColumns=3\ninDegrees=no\nendheader\n"
           "time\tbend\tstretch\n0.0\t0.0\t0.1\n0.5\t0.5\t0.2\n1.0\t1.0\t0.3\n")
    (d / "walk.mot").parent.mkdir(parents=True, exist_ok=True)
    yaml = DATASET_YAML.replace("  walk: {pose: walk.yaml, frames: \"0:8:4\"}",
                                "  walk: {motion: walk.mot, fps: 4}")
    write_tiny(d, yaml)
    (d / "walk.mot").write_text(mot)
    monkeypatch.chdir(d)
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "o", "-q"], capsys)
    assert rc == 0, err
    lab = np.load(d / "o" / "seq_00005" / "labels.npz")  # {motion: walk}: resampled to 4 fps
    assert list(lab["frames"]) == [0, 1, 2, 3, 4]
    names = list(lab["coord_names"])
    np.testing.assert_allclose(lab["coords"][:, names.index("bend")], np.degrees(np.linspace(0, 1, 5)), atol=1e-9)
    np.testing.assert_allclose(lab["coords"][:, names.index("stretch")], np.linspace(0.1, 0.3, 5), atol=1e-12)
    # a column the skeleton does not have is refused at its position in the .mot file
    (d / "walk.mot").write_text(mot.replace("\tstretch\n", "\tknee\n"))
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "o2"], capsys)
    assert rc == 2 and "walk.mot:7:" in err and "knee" in err and not (d / "o2").exists()


def test_perturb_default_spread_moves_rotations_only(tiny_spec):
    from axdf_cli.dataset.sampling import sample_pose
    from axdf_cli.dataset.spec import Entry, Sequence, load_motion, motion_frames
    from axdf_cli.model.pose import sample_coordinates

    ctx = tiny_spec
    spec = dataclasses.replace(ctx.spec, entries=(Entry("perturb", 1, "walk", None, None, {"default": 10.0}),))
    base = load_motion(spec, "walk")
    fr = motion_frames(spec, "walk")
    q = sample_coordinates(sample_pose(spec, Sequence(0, "s", 0, len(fr)), ctx.plan_skeleton, base, fr), base.frames)
    b = sample_coordinates(base, base.frames)
    idx = ctx.plan_skeleton.coord_index
    np.testing.assert_array_equal(q[:, idx["stretch"]], b[:, idx["stretch"]])  # metres: not named, not moved
    assert np.abs(q[:, idx["bend"]] - b[:, idx["bend"]]).max() > 1.0  # degrees: the default spread


def test_index_rows_shard_column_and_missing_passes():
    from axdf_cli.dataset.index import index_bytes, index_rows

    recs = [{"sequence": f"seq_{i:05d}", "index": i, "source": "uniform", "frames": [0, 2], "views": ["a"]}
            for i in range(4)]
    cols = index_rows(recs, seed=5, shards=3, passes=("png",))
    assert cols["shard"] == [0, 0, 1, 1, 2, 2, 0, 0]
    assert cols["frame_index"] == [0, 1] * 4 and cols["exr"] == [None] * 8
    assert cols["png"][3] == "seq_00001/views/a/0002.png"
    assert index_bytes(recs, 5, 3, ("png",)) == index_bytes(recs, 5, 3, ("png",))
