"""Cameras that hold still and frame the subject: the automatic camera depends on
the skeleton and the whole pose only; it fits tightly and centred; camera flags; sticks for
bones without meshes. Runs render at small sizes through llvmpipe."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from conftest import CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML, REPO_ROOT, run_main

DEMO = ["run", "poses/jobs/demo.yaml", "--size", "64x64", "--supersample", "1"]


def _cams(out: Path) -> dict[int, list]:
    cam = json.loads((out / "camera.json").read_text())
    return {f["frame"]: f["cameras"] for f in cam["frames"]}


def _project(cam: dict, P: np.ndarray) -> np.ndarray:
    K, M = np.array(cam["K"]), np.array(cam["world_to_camera"])
    pc = P @ M[:3, :3].T + M[:3, 3]
    uvw = pc @ K.T
    return uvw[:, :2] / uvw[:, 2:3]


def test_camera_ignores_the_frame_subset_and_frames_the_muscles(repo_root, tmp_path, capsys):
    """The same camera for frame 100 whichever frames are written; other muscles, another
    framing (the camera frames the run's muscles)."""
    runs = {
        "one": DEMO + ["--frames", "100"],
        "many": DEMO + ["--frames", "0,100,150"],
        "other muscles": DEMO + ["--frames", "100", "--muscles", "muscles/demo/biceps_brachii.yaml"],
        "orbit": DEMO + ["--frames", "100", "--orbit", "3"],
        "orbit subset": DEMO + ["--frames", "90:100:5", "--orbit", "3"],
    }
    cams = {}
    for name, argv in runs.items():
        rc, _, err = run_main(argv + ["--out", tmp_path / name, "-q"], capsys)
        assert rc == 0, err
        cams[name] = _cams(tmp_path / name)[100]
    for a, b in (("one", "many"), ("orbit", "orbit subset")):
        np.testing.assert_allclose(np.array(cams[a][0]["world_to_camera"]), np.array(cams[b][0]["world_to_camera"]),
                                   rtol=0, atol=1e-12, err_msg=f"{a} vs {b}")
    assert not np.allclose(cams["one"][0]["world_to_camera"], cams["orbit"][0]["world_to_camera"])
    assert not np.allclose(cams["one"][0]["world_to_camera"], cams["other muscles"][0]["world_to_camera"])
    # the framing is recorded, so `axdf render` of the run gives the same camera
    manifest = json.loads((tmp_path / "one" / "manifest.json").read_text())
    assert manifest["framing"]["first_frame"] == 0 and len(manifest["framing"]["points"]) > 8


def test_fit_is_tight_and_centred():
    from axdf_cli.render.camera import FRAME_MARGIN, VIEW_AXES, sequence_cameras
    from axdf_cli.specs.render import RenderSettings
    from axdf_cli.render.scene import Scene

    rng = np.random.default_rng(7)
    pts = rng.normal(size=(400, 3)) * [0.2, 0.3, 0.8] + [1.0, -2.0, 0.9]
    W, H = 160, 120
    for view in list(VIEW_AXES) + ["sheet"]:
        s = RenderSettings(enabled=True, size=(W, H), view=view)
        scene = Scene((), (), np.zeros((2, 3)), (0,), framing=pts)
        (cams,) = sequence_cameras(scene, s)
        spans = []
        for c in cams:
            x0 = c.viewport[0]
            uv = _project(c.to_json(), pts) - [x0, 0]
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            m = [FRAME_MARGIN * W, FRAME_MARGIN * H]
            assert np.all(lo >= np.array(m) - 0.6) and np.all(hi <= np.array([W, H]) - m + 0.6), (view, lo, hi)
            np.testing.assert_allclose(0.5 * (lo + hi), [W / 2, H / 2], atol=0.6, err_msg=view)  # centred
            spans.append((hi - lo) / (np.array([W, H]) * (1 - 2 * FRAME_MARGIN)))
        # tight: one panel fills its image (less the margin) in one direction
        assert max(float(sp.max()) for sp in spans) > 0.99, (view, spans)


def test_every_demo_muscle_stays_in_view(repo_root, tmp_path, capsys):
    """The framing carries each muscle's rest mesh on its anchors' bones; every vertex of every
    frame stays inside the image."""
    from axdf_cli.formats.ply import read_ply

    out = tmp_path / "o"
    rc, _, err = run_main(DEMO + ["--frames", "0:191:19", "--out", out, "-q"], capsys)
    assert rc == 0, err
    for f, cams in _cams(out).items():
        for ply in (out / "meshes").rglob(f"*_{f:04d}.ply"):
            uv = _project(cams[0], read_ply(ply.read_bytes()).vertices.astype(np.float64))
            assert uv.min() >= 0 and uv.max() <= 64, (ply.name, uv.min(), uv.max())


def test_render_from_the_run_folder_uses_the_same_cameras(repo_root, tmp_path, capsys):
    out = tmp_path / "o"
    assert run_main(DEMO + ["--frames", "30,40", "--no-render", "--out", out, "-q"], capsys)[0] == 0
    assert run_main(DEMO + ["--frames", "30,40", "--out", tmp_path / "r", "-q"], capsys)[0] == 0
    rc, _, err = run_main(["render", out, "--size", "64x64", "--supersample", "1", "-q"], capsys)
    assert rc == 0, err
    a, b = _cams(out), _cams(tmp_path / "r")
    for f in (30, 40):
        np.testing.assert_allclose(np.array(a[f][0]["world_to_camera"]), np.array(b[f][0]["world_to_camera"]),
                                   rtol=0, atol=1e-12)


def test_camera_flags_place_the_camera(repo_root, tmp_path, capsys):
    out = tmp_path / "o"
    rc, _, err = run_main(DEMO + ["--frames", "0", "--camera-position=0.5,-3,1.2", "--camera-target", "0,0,1",
                                  "--fov", "20", "--out", out, "-q"], capsys)
    assert rc == 0, err
    (cam,) = _cams(out)[0]
    M = np.array(cam["world_to_camera"])
    np.testing.assert_allclose(-M[:3, :3].T @ M[:3, 3], [0.5, -3, 1.2], atol=1e-12)  # camera centre
    np.testing.assert_allclose(_project(cam, np.array([[0.0, 0.0, 1.0]])), [[32, 32]], atol=1e-9)
    assert cam["K"][1][1] == pytest.approx(32 / math.tan(math.radians(10)))
    rc, _, err = run_main(DEMO + ["--frames", "0", "--fov", "200", "--out", tmp_path / "x"], capsys)
    assert rc == 2 and err.startswith("--fov: ") and not (tmp_path / "x").exists()


def test_bones_without_meshes_render_as_sticks(tmp_path, monkeypatch, capsys):
    from render_helpers import read_exr

    (tmp_path / "chain.yaml").write_text(CHAIN_SKELETON_YAML)
    (tmp_path / "m.yaml").write_text(CHAIN_MUSCLE_YAML.replace("at: [0, 0, 0]", "at: [0, 0.05, 0]"))  # beside the sticks
    (tmp_path / "p.yaml").write_text("pose: p\nskeleton: chain.yaml\nframes: [0, 1]\nkeys:\n  1: {bend: 60}\n")
    monkeypatch.chdir(tmp_path)
    base = ["run", "--muscles", "m.yaml", "--pose", "p.yaml", "--render", "--size", "64x64", "--view", "side"]
    assert run_main(base + ["--out", "with"], capsys)[0] == 0
    assert run_main(base + ["--out", "without", "--no-bones"], capsys)[0] == 0
    ids = json.loads((tmp_path / "with" / "camera.json").read_text())["ids"]
    assert [v["name"] for v in ids.values() if v["kind"] == "bone"] == ["b1", "b2", "b3", "b4"]
    for f in (0, 1):
        seen = np.unique(read_exr(tmp_path / "with" / "frames" / f"{f:04d}.exr")["id"])
        assert {2, 3, 4, 5} <= set(seen.tolist()), seen  # every stick is visible
        assert set(np.unique(read_exr(tmp_path / "without" / "frames" / f"{f:04d}.exr")["id"]).tolist()) <= {0, 1}


def test_stick_matrices_map_the_unit_stick_between_joints():
    from axdf_cli.render.renderer import stick_matrices, unit_stick

    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    v, f = unit_stick()
    M = stick_matrices(a, b, 0.01)
    for k in range(5):
        w = v @ M[k, :3, :3].T + M[k, :3, 3]
        ab = (b[k] - a[k]) / np.linalg.norm(b[k] - a[k])
        t = (w - a[k]) @ ab
        assert t.min() == pytest.approx(0, abs=1e-6) and t.max() == pytest.approx(np.linalg.norm(b[k] - a[k]))
        radial = np.linalg.norm((w - a[k]) - np.outer(t, ab), axis=1)
        assert radial.max() == pytest.approx(0.01, rel=1e-6)
    # outward and closed: positive volume of the unit stick ~ pi r^2 h (a 12-gon)
    tri = v[f].astype(np.float64)
    vol = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
    assert vol == pytest.approx(0.5 * 12 * math.sin(2 * math.pi / 12), rel=1e-6)


def test_floating_base_gets_no_stick_and_the_world_origin_is_not_framed(tmp_path):
    from axdf_cli.specs import load_pose
    from axdf_cli.model.pose import subject_points

    (tmp_path / "s.yaml").write_text("""skeleton: s
bones:
  - name: ground
  - name: hips
    parent: ground
    dofs:
      - {coord: tx, type: translation, axis: [1, 0, 0]}
  - name: knee
    parent: hips
    offset: [0, 0, -0.4]
""")
    (tmp_path / "p.yaml").write_text("pose: p\nskeleton: s.yaml\nframes: [0, 2]\nkeys:\n  0: {tx: 5}\n  2: {tx: 6}\n")
    pose = load_pose(tmp_path / "p.yaml")
    assert pose.skeleton.stick_parents() == [-1, -1, 1]  # hips floats: no stick from the origin
    pts = subject_points(pose, {})
    assert pts[:, 0].min() > 4.9 and pts[:, 0].max() < 6.1  # the walk, not the world origin
    assert pts[:, 2].min() < -0.4 < 0.0 < pts[:, 2].max()


def _vertices(out: Path, frame: int) -> np.ndarray:
    from axdf_cli.formats.ply import read_ply

    return np.concatenate([read_ply(p.read_bytes()).vertices.astype(np.float64)
                           for p in sorted((out / "meshes").rglob(f"*_{frame:04d}.ply"))])


def test_few_muscles_are_framed_on_them_not_on_the_skeleton(repo_root, tmp_path, capsys):
    """The paper's deltoid on arm26 (once a 20 px blob at 512x512 when the whole arm and
    trunk were framed): its vertices over the whole elevation span most of the image, and
    stay inside it at every frame."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.model.pose import subject_points
    from axdf_cli.specs import load_job

    out = tmp_path / "d"
    argv = ["run", "poses/jobs/paper_deltoid_arm26.yaml", "--size", "96x96", "--supersample", "1",
            "--frames", "0:47:6", "--out", out, "-q"]
    rc, _, err = run_main(argv, capsys)
    assert rc == 0, err
    cams = _cams(out)
    uv = np.concatenate([_project(cams[f][0], _vertices(out, f)) for f in cams])
    assert uv.min() >= 0 and uv.max() <= 96
    span = (uv.max(0) - uv.min(0)) / 96
    assert span.max() > 0.7, span  # the deltoid over its sampled frames spans most of the image
    # the skeleton's framing (bones over the pose) would have shown it several times smaller
    plan = plan_run(load_job("poses/jobs/paper_deltoid_arm26.yaml"))
    bones = subject_points(plan.pose, {i: v for i, (v, _, _) in plan.bone_meshes.items()})
    muscles = np.array(json.loads((out / "manifest.json").read_text())["framing"]["points"])
    assert np.ptp(bones, axis=0).max() > 4 * np.ptp(muscles, axis=0).max()


def _centre(cam: dict) -> np.ndarray:
    M = np.array(cam["world_to_camera"])
    return -M[:3, :3].T @ M[:3, 3]


def _bone_origins(out: Path, bone: str) -> dict[int, np.ndarray]:
    import csv

    with open(out / "bones.csv", newline="") as fh:
        return {int(r["frame"]): np.array([float(r[k]) for k in "xyz"]) for r in csv.DictReader(fh) if r["bone"] == bone}


@pytest.mark.parametrize("how", ["follow", "offset", "fixed", "job"])
def test_camera_aims_at_a_bone_at_every_frame(repo_root, tmp_path, capsys, how):
    """--camera-target bone:NAME: the bone's origin projects to the image centre at every frame;
    with no position the camera moves with the bone (a constant offset: automatic, or
    --camera-offset), with --camera-position it stays put and turns; in a job's render: block
    too; the camera of a frame never depends on the --frames subset."""
    frames = "0,60,75,100"
    extra = {"follow": ["--camera-target", "bone:ulna_r"],
             "offset": ["--camera-target", "bone:ulna_r", "--camera-offset", "0.4,-0.9,0.3"],
             "fixed": ["--camera-target", "bone:ulna_r", "--camera-position=0.5,-2.5,1.6"],
             "job": []}[how]
    argv = DEMO + extra
    if how == "job":
        job = tmp_path / "job.yaml"
        job.write_text(f"muscles: [{REPO_ROOT}/muscles/demo]\npose: {REPO_ROOT}/poses/demo.yaml\n"
                       "render: {size: [64, 64], supersample: 1, camera: {target: {bone: ulna_r}}}\n")
        argv = ["run", job, "--allow-outside"]
    out = tmp_path / "o"
    rc, _, err = run_main(argv + ["--frames", frames, "--out", out, "-q"], capsys)
    assert rc == 0, err
    cams, origin = _cams(out), _bone_origins(out, "ulna_r")
    offsets = []
    for f, (cam,) in cams.items():
        np.testing.assert_allclose(_project(cam, origin[f][None]), [[32, 32]], atol=1e-6)
        offsets.append(_centre(cam) - origin[f])
    assert np.ptp([np.linalg.norm(origin[f] - origin[0]) for f in cams]) > 0.01  # the bone moves
    if how == "fixed":
        for cam in cams.values():
            np.testing.assert_allclose(_centre(cam[0]), [0.5, -2.5, 1.6], atol=1e-12)
    else:
        np.testing.assert_allclose(offsets, np.broadcast_to(offsets[0], (len(offsets), 3)), atol=1e-9)
        if how == "offset":
            np.testing.assert_allclose(offsets[0], [0.4, -0.9, 0.3], atol=1e-12)
    if how == "follow":
        rc, _, err = run_main(argv + ["--frames", "75", "--out", tmp_path / "one", "-q"], capsys)
        assert rc == 0, err
        np.testing.assert_allclose(_cams(tmp_path / "one")[75][0]["world_to_camera"], cams[75][0]["world_to_camera"],
                                   rtol=0, atol=1e-12)
        # axdf render of a run rendered without it aims the same way
        plain = tmp_path / "plain"
        assert run_main(DEMO + ["--frames", frames, "--no-render", "--out", plain, "-q"], capsys)[0] == 0
        rc, _, err = run_main(["render", plain, "--size", "64x64", "--supersample", "1", "--camera-target",
                               "bone:ulna_r", "-q"], capsys)
        assert rc == 0, err
        for f, (cam,) in _cams(plain).items():
            # bones.csv holds the positions to 9 significant digits
            np.testing.assert_allclose(cam["world_to_camera"], cams[f][0]["world_to_camera"], rtol=0, atol=1e-7)


def test_a_bone_target_that_is_not_a_bone_is_refused_before_writing(repo_root, tmp_path, capsys):
    rc, _, err = run_main(DEMO + ["--frames", "0", "--camera-target", "bone:humerus_x", "--out", tmp_path / "x"],
                          capsys)
    assert rc == 2 and err.startswith("--camera-target: ") and "humerus_r" in err and not (tmp_path / "x").exists()
    rc, _, err = run_main(DEMO + ["--frames", "0", "--camera-offset", "1,0,0", "--out", tmp_path / "y"], capsys)
    assert rc == 2 and err.startswith("--camera-offset: ") and not (tmp_path / "y").exists()
    out = tmp_path / "o"
    assert run_main(DEMO + ["--frames", "0", "--no-render", "--out", out, "-q"], capsys)[0] == 0
    before = sorted(p.name for p in out.rglob("*"))
    rc, _, err = run_main(["render", out, "--camera-target", "bone:nope"], capsys)
    assert rc == 2 and "nope" in err and sorted(p.name for p in out.rglob("*")) == before
