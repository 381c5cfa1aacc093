"""``axdf retarget``: motion (BVH, npz joints) fitted onto a muscle model's skeleton.

- The analytic Jacobian of posed points equals central differences (coupled knee splines
  included), and every coordinate function's derivative does too.
- Joint positions computed from a known gait2392 pose (the measured walk), written as an npz,
  give that pose back; moved by a similarity (scaled 1.15, turned, shifted), the same joint
  angles and the scale come back.
- CMU subject 131's walk on gait2392 (what `make import` ships): hips, knees and ankles within
  3% of the leg length (RMS), every coordinate inside its range, no jump above 15 deg in a 30th
  of a second (the map's max_speed; the source's own knee turns 31 deg there); all 92 muscles
  run over it with plausible lengths.
- A speed limit is followed: a target that jumps is reached in steps of at most max_step, and
  the fit without the limit is unchanged.
- Bad BVH, npz and map input: exit 2 with the position (FILE:LINE:COL for a map and a BVH,
  the array and index for an npz), nothing written. Same inputs, same bytes.
"""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_in_folder import run_cli

REPO = Path(__file__).resolve().parents[1]
GAIT = REPO / "poses" / "skeletons" / "gait2392.yaml"
WALK = REPO / "poses" / "gait2392_walk.yaml"
CMU_BVH = REPO.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"
CMU_MAP = REPO / "poses" / "maps" / "cmu_to_gait2392.yaml"
SHIPPED = REPO / "poses" / "retargeted" / "cmu_131_01_walk_gait2392"
CMU_JOB = REPO / "poses" / "jobs" / "gait2392_cmu_walk.yaml"

needs_bvh = pytest.mark.skipif(not CMU_BVH.is_file(), reason="the shared CMU BVH is not here")


# ----------------------------------------------------------------------------- derivatives


def test_function_derivatives_match_central_differences():
    from axdf_cli.model.skeleton import Constant, Linear, Multiplier, Polynomial, Spline

    x = np.linspace(-130.0, 130.0, 521)  # beyond the knots on both sides too
    xs = np.array([-120.0, -70.0, -30.0, -20.0, -10.0, 9.1, 120.0])
    ys = np.array([-0.4226, -0.4082, -0.399, -0.3976, -0.3966, -0.3953, -0.396])
    h = 1e-5
    for fn in (Constant(0.3), Linear(0.02, -1.0), Polynomial((0.1, -0.2, 3e-3, 4e-5)), Spline(xs, ys, "fmm"),
               Spline(xs, ys, "natural"), Multiplier(2.5, Spline(xs, ys, "fmm"))):
        fd = (fn(x + h) - fn(x - h)) / (2 * h)
        assert np.allclose(fn.derivative(x), fd, atol=1e-8, rtol=1e-6), fn


def test_point_jacobian_matches_central_differences():
    from axdf_cli.model.skeleton import dof_frames, forward_kinematics, point_jacobian
    from axdf_cli.specs import load_skeleton

    skel = load_skeleton(GAIT)
    rng = np.random.default_rng(3)
    q = np.array([[rng.uniform(*c.range) if c.range else rng.uniform(-0.5, 0.5) for c in skel.coordinates]
                  for _ in range(4)])
    bones = np.array([skel.bone_index[b] for b in ("pelvis", "tibia_r", "talus_l", "toes_r", "torso", "calcn_l")])
    local = rng.normal(size=(len(bones), 3)) * 0.05
    world, frames = dof_frames(skel, q)
    assert np.array_equal(world, forward_kinematics(skel, q))
    _, jac = point_jacobian(skel, frames, world, bones, local)

    def posed(qq):
        w = forward_kinematics(skel, qq)[:, bones]
        return np.einsum("fpij,pj->fpi", w[..., :3, :3], local) + w[..., :3, 3]

    h = 1e-6
    for c in range(q.shape[1]):
        dq = np.zeros_like(q)
        dq[:, c] = h
        fd = (posed(q + dq) - posed(q - dq)) / (2 * h)
        assert np.abs(jac[..., c] - fd).max() < 1e-7, skel.coordinates[c].name


# ----------------------------------------------------------------------------- a known pose


#: Points of gait2392 that decide every coordinate: joint centres, a heel and a lateral point
#: on each foot, the toe tips, three on the trunk and one behind the hips.
KNOWN_POINTS = {
    "pelvis": None, "femur_r": None, "femur_l": None, "tibia_r": None, "tibia_l": None, "talus_r": None,
    "talus_l": None, "calcn_r": None, "calcn_l": None, "toes_r": None, "toes_l": None, "torso": None,
    "heel_r": ("calcn_r", [0.0, -0.01, 0.03]), "heel_l": ("calcn_l", [0.0, -0.01, -0.03]),
    "side_r": ("calcn_r", [0.12, 0.0, 0.05]), "side_l": ("calcn_l", [0.12, 0.0, -0.05]),
    "tip_r": ("toes_r", [0.06, 0.0, 0.0]), "tip_l": ("toes_l", [0.06, 0.0, 0.0]),
    "neck": ("torso", [-0.03, 0.4, 0.0]), "shoulder_r": ("torso", [-0.02, 0.36, 0.17]),
    "shoulder_l": ("torso", [-0.02, 0.36, -0.17]), "sacrum": ("pelvis", [-0.11, 0.03, 0.0]),
}


def known_map(path: Path, **top) -> Path:
    joints = {}
    for name, where in KNOWN_POINTS.items():
        joints[name] = name if where is None else {"bone": where[0], "at": where[1], "from": name}
    doc = {"retarget": "known", "onto": str(GAIT), "scale": "none", "align": "none", "smooth": 0, **top,
           "joints": joints}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def known_positions(frames=range(0, 211, 3)):
    """The measured walk's coordinates (F, C) and the KNOWN_POINTS they put in the world (F, P, 3)."""
    from axdf_cli.model.ik import pose_points
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    pose = load_pose(WALK)
    skel = pose.skeleton
    q = sample_coordinates(pose, np.asarray(list(frames)))
    bones = np.array([skel.bone_index[w[0] if w else n] for n, w in KNOWN_POINTS.items()])
    local = np.array([w[1] if w else skel.bones[skel.bone_index[n]].post_offset for n, w in KNOWN_POINTS.items()])
    return skel, q, pose_points(skel, q, bones, local)


def write_npz(path: Path, joints, names, fps=20.0) -> Path:
    np.savez(path, joints=np.asarray(joints), names=np.array(names), fps=np.array(fps))
    return path


def test_known_pose_is_recovered_from_npz_joints(tmp_path):
    skel, q, pts = known_positions()
    write_npz(tmp_path / "walk.npz", pts, list(KNOWN_POINTS))
    known_map(tmp_path / "map.yaml")
    assert run_cli(tmp_path, "retarget", "walk.npz", "--map", "map.yaml", "--out", "out", "-q",
                   "--allow-outside") == 0
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    pose = load_pose(tmp_path / "out" / "walk_gait2392.yaml")
    assert pose.fps == 20 and pose.last == len(q) - 1
    got = sample_coordinates(pose, pose.frames)
    for c, coord in enumerate(skel.coordinates):
        tol_c = 1e-3 if coord.type == "rotation" else 1e-5  # degrees, metres (the fit stops at ~1 µm)
        assert np.abs(got[:, c] - q[:, c]).max() < tol_c, coord.name
    rep = json.loads((tmp_path / "out" / "retarget_report.json").read_text())
    assert rep["error"]["max_m"] < 1e-4 and rep["similarity"]["scale"] == 1.0
    rows = list(csv.DictReader((tmp_path / "out" / "retarget.csv").open()))
    assert len(rows) == len(q) and float(max(r["max_m"] for r in rows)) < 1e-4


def test_a_similarity_is_undone(tmp_path):
    """The same walk, 1.15 times larger, turned 70 deg about the vertical and shifted: the
    joint angles come back exactly (``scale: 1.15``; the turn and shift are found by ``align:
    centre``), and ``scale: fit`` finds 1.15."""
    skel, q, pts = known_positions(range(0, 211, 6))
    t = np.radians(70.0)
    rot = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    moved = 1.15 * np.einsum("ij,fpj->fpi", rot, pts) + np.array([3.0, -2.0, 0.05])
    write_npz(tmp_path / "walk.npz", moved, list(KNOWN_POINTS))
    known_map(tmp_path / "map.yaml", scale=1.15, align="centre")
    assert run_cli(tmp_path, "retarget", "walk.npz", "--map", "map.yaml", "--out", "out", "-q",
                   "--allow-outside") == 0
    rep = json.loads((tmp_path / "out" / "retarget_report.json").read_text())
    assert rep["error"]["max_m"] < 1e-5 and rep["similarity"]["scale_from"] == "map"
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    got = sample_coordinates(load_pose(tmp_path / "out" / "walk_gait2392.yaml"), np.arange(len(q)))
    for c, coord in enumerate(skel.coordinates):
        if not coord.name.startswith("pelvis_"):
            assert np.abs(got[:, c] - q[:, c]).max() < 1e-3, coord.name

    known_map(tmp_path / "map.yaml", scale="fit", align="centre")
    assert run_cli(tmp_path, "retarget", "walk.npz", "--map", "map.yaml", "--out", "fit", "-q",
                   "--allow-outside") == 0
    rep = json.loads((tmp_path / "fit" / "retarget_report.json").read_text())
    # the segments' model lengths are the rest pose's: the hip-knee distance moves by up to 2.5%
    # with gait2392's coupled knee translation, so the walk's median reads 0.07% long
    assert abs(rep["similarity"]["scale"] - 1.15) < 2e-3 and rep["similarity"]["scale_from"] == "fit"
    assert {(s["a"], s["b"]) for s in rep["segments"]} >= {("femur_r", "femur_l"), ("tibia_r", "talus_r")}


def test_y_up_npz_and_units(tmp_path):
    """An npz in centimetres with Y up (``--up y --scale cm``) is the same motion."""
    skel, q, pts = known_positions(range(0, 211, 30))
    to_y_up = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])  # axdf (x, y, z) -> (x, z, -y)
    write_npz(tmp_path / "cm.npz", 100.0 * np.einsum("ij,fpj->fpi", to_y_up, pts), list(KNOWN_POINTS))
    known_map(tmp_path / "map.yaml")
    assert run_cli(tmp_path, "retarget", "cm.npz", "--map", "map.yaml", "--out", "out", "-q", "--up", "y",
                   "--scale", "cm", "--allow-outside") == 0
    rep = json.loads((tmp_path / "out" / "retarget_report.json").read_text())
    assert rep["error"]["max_m"] < 1e-4


def test_same_inputs_same_bytes(tmp_path):
    _, _, pts = known_positions(range(0, 211, 10))
    write_npz(tmp_path / "walk.npz", pts, list(KNOWN_POINTS))
    known_map(tmp_path / "map.yaml", scale="fit", align="centre")
    outs = []
    for out in ("a", "b"):
        assert run_cli(tmp_path, "retarget", "walk.npz", "--map", "map.yaml", "--out", out, "-q",
                       "--allow-outside") == 0
        outs.append({p.name: p.read_bytes() for p in sorted((tmp_path / out).iterdir())})
    assert outs[0] == outs[1]
    assert sorted(outs[0]) == ["manifest.json", "retarget.csv", "retarget_report.json", "walk_gait2392.yaml"]
    for data in outs[0].values():
        assert str(tmp_path).encode() not in data  # no absolute paths


# ----------------------------------------------------------------------------- the CMU walk


@pytest.fixture(scope="module")
def cmu_walk():
    from axdf_cli.tools.retarget import build_retarget

    return build_retarget(CMU_BVH, CMU_MAP, SHIPPED, step=4, name="cmu_131_01_walk_gait2392")


def source_turns(step: int = 4) -> np.ndarray:
    """(F - 1,) the largest rotation (degrees) of any leg or trunk joint of the CMU take
    against its parent between consecutive frames (1/30 s at step 4)."""
    from axdf_cli.importers.bvh import bone_names, coordinate_name, read_bvh
    from axdf_cli.importers.mocap import bvh_skeleton
    from axdf_cli.model.skeleton import forward_kinematics

    bvh = read_bvh(CMU_BVH)
    skel = bvh_skeleton(bvh, 1.0)
    names = bone_names(bvh)
    rows = bvh.data[::step]
    q = np.zeros((len(rows), len(skel.coordinates)))
    for (j, c), v in zip(bvh.columns, rows.T):
        q[:, skel.coord_index[coordinate_name(names[j], c)]] = v
    w = forward_kinematics(skel, q)
    joints = [skel.bone_index[b] for b in ("Hips", "LeftHip", "LeftKnee", "LeftAnkle", "LeftToe", "RightHip",
                                           "RightKnee", "RightAnkle", "RightToe", "lowerback", "Chest", "Chest2")]
    parents = [skel.bones[b].parent for b in joints]
    # rel[f, b] = R_parent^T R_joint;  d = rel[f]^T rel[f + 1]
    rel = np.einsum("fbji,fbjk->fbik", w[:, parents, :3, :3], w[:, joints, :3, :3])
    d = np.einsum("fbji,fbjk->fbik", rel[:-1], rel[1:])
    return np.degrees(np.arccos(np.clip((np.trace(d, axis1=2, axis2=3) - 1) / 2, -1, 1))).max(axis=1)


def leg_joint_errors(res) -> dict:
    """Hips, knees and ankles (the points femur_*, tibia_*, talus_* of a CMU map): RMS error over
    the take as a fraction of the subject's leg (median hip to knee to ankle)."""
    pos, idx = res.mocap.positions, res.mocap.index
    leg = np.median(np.linalg.norm(pos[:, idx["RightHip"]] - pos[:, idx["RightKnee"]], axis=1)
                    + np.linalg.norm(pos[:, idx["RightKnee"]] - pos[:, idx["RightAnkle"]], axis=1))
    names = [p.name for p in res.rmap.points]
    return {point: float(np.sqrt(np.mean(res.error[:, names.index(point)] ** 2))) / leg
            for point in ("femur_r", "femur_l", "tibia_r", "tibia_l", "talus_r", "talus_l")}


@needs_bvh
def test_cmu_walk_joint_centres_within_3_percent_of_the_leg(cmu_walk):
    res = cmu_walk.retargeted
    errors = leg_joint_errors(res)
    assert max(errors.values()) < 0.03, errors
    # the error is the subject's: the model's points times the scale against the motion's
    assert 0.9 < res.world.scale < 1.0


@needs_bvh
def test_cmu_walk_coordinates_in_range_and_without_jumps(cmu_walk):
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    res = cmu_walk.retargeted
    pose = load_pose(SHIPPED / "cmu_131_01_walk_gait2392.yaml")
    q = sample_coordinates(pose, pose.frames)
    skel = pose.skeleton
    fit_ranges = res.rmap.skeleton.coordinates
    at_end = np.zeros(len(q), bool)
    for c, coord in enumerate(skel.coordinates):
        if coord.range is not None:
            assert coord.range[0] - 1e-9 <= q[:, c].min() and q[:, c].max() <= coord.range[1] + 1e-9, coord.name
        lo, hi = fit_ranges[c].range or (-np.inf, np.inf)
        width = hi - lo if np.isfinite(hi - lo) else 1.0
        at_end |= (q[:, c] <= lo + 1e-6 * width) | (q[:, c] >= hi - 1e-6 * width)
    rotations = [c for c, coord in enumerate(skel.coordinates) if coord.type == "rotation"]
    jump = np.abs(np.diff(q[:, rotations], axis=0)).max(axis=1)  # degrees in 1/30 s
    assert res.rmap.max_speed == 450.0 and res.mocap.fps == 30.0
    assert jump.max() <= 15.0 + 1e-6, np.nonzero(jump > 15.0 + 1e-6)[0]
    # the limit holds where the source turns faster (its knee 31 deg, toes 63 in 1/30 s)
    assert source_turns().max() > 30.0


def test_a_speed_limit_is_followed_and_caught_up():
    """A knee whose target jumps by 60 degrees in one frame: with max_step 10 the fit moves
    10 degrees a frame until it is there, then holds; without a limit it jumps at once."""
    from axdf_cli.model.ik import fit_frames, pose_points

    skel, q, _ = known_positions(frames=[0])
    knee = skel.coord_index["knee_angle_r"]
    qs = np.repeat(q, 10, axis=0)
    lo, hi = skel.coordinates[knee].range
    qs[3:, knee] += 60.0 if q[0, knee] + 60.0 < hi else -60.0
    assert lo < qs[3, knee] < hi
    bones = np.array([skel.bone_index[b] for b in ("femur_r", "tibia_r", "talus_r")])
    local = np.array([skel.bones[b].post_offset for b in bones])
    targets = pose_points(skel, qs, bones, local)
    free = np.array([knee])
    free_fit = fit_frames(skel, bones, local, np.ones(3), targets, free, q[0], smooth=0.0)
    assert np.abs(free_fit.q[:, knee] - qs[:, knee]).max() < 1e-3
    slow = fit_frames(skel, bones, local, np.ones(3), targets, free, q[0], smooth=0.0, max_step=10.0)
    steps = np.abs(np.diff(slow.q[:, knee]))
    assert steps.max() <= 10.0 + 1e-9
    np.testing.assert_allclose(steps[2:8], 10.0, atol=0.01)  # follows at the limit for 6 frames (trf stays just inside)
    assert np.abs(slow.q[8:, knee] - qs[8:, knee]).max() < 0.01 and abs(slow.q[9, knee] - qs[9, knee]) < 1e-3  # there
    assert slow.error[3].max() > 0.05  # and the residual says what the lag costs


def assert_shipped_as_made(made, skeleton_ref: str) -> None:
    """The shipped retargeted files are what ``make import`` makes now (``made``: a
    build_retarget result): the same frames and coordinates, values within 1e-3 (the
    optimizer's last bits may differ across CPUs), the same report but for the last digits."""
    for path, data in made.files.items():
        shipped = Path(path).read_bytes()
        if path.endswith(".yaml"):
            a, b = yaml.safe_load(shipped), yaml.safe_load(data)
            assert a["skeleton"] == b["skeleton"] == skeleton_ref
            frames = sorted(b["keys"])
            assert sorted(a["keys"]) == frames
            for f in frames:
                assert a["keys"][f].keys() == b["keys"][f].keys()
                assert max(abs(a["keys"][f][c] - b["keys"][f][c]) for c in b["keys"][f]) < 1e-3
        elif path.endswith(".json"):
            a, b = json.loads(shipped), json.loads(data)
            assert a["files"] == b["files"] and a["motion"] == b["motion"] and a["map"] == b["map"]
            assert abs(a["error"]["rms_m"] - b["error"]["rms_m"]) < 1e-5


def run_job_stats(job: Path, frames: str, out: Path, monkeypatch) -> list[dict]:
    """``axdf run JOB --no-render --frames FRAMES`` from the repository: stats.csv's rows, after
    checking that no row carries a warning (no coordinate out of range, no degenerate frame)."""
    from axdf_cli.cli.main import main

    monkeypatch.chdir(REPO)
    assert main(["run", str(job.relative_to(REPO)), "--no-render", "--frames", frames, "--out", str(out), "-q"]) == 0
    rows = list(csv.DictReader((out / "stats.csv").open()))
    assert not [r for r in rows if r["warning"]]
    return rows


@needs_bvh
def test_shipped_cmu_walk_is_what_make_import_makes(cmu_walk):
    """`make import` regenerates poses/retargeted/...: the shipped files are this code's."""
    assert_shipped_as_made(cmu_walk, "../../skeletons/gait2392.yaml")


@needs_bvh
def test_all_92_muscles_follow_the_retargeted_walk(tmp_path, monkeypatch):
    rows = run_job_stats(CMU_JOB, "0:248:8", tmp_path / "walk", monkeypatch)
    assert len({r["muscle"] for r in rows}) == 92 and len(rows) == 92 * 32
    vas = np.array([float(r["length"]) for r in rows if r["muscle"] == "vas_int_r"])
    # gait2392's own measured walk (knee to 70 deg): 0.181-0.234 m; this take bends the knee to
    # its 120 deg limit: longer, never shorter than standing (transferring the muscles to the
    # BVH skeleton instead gave 0.176-0.385 m)
    assert 0.17 < vas.min() < 0.20 and 0.23 < vas.max() < 0.27


# ----------------------------------------------------------------------------- bad input


def _retarget(tmp_path, motion, map_path, *extra):
    return run_cli(tmp_path, "retarget", str(motion), "--map", str(map_path), "--out", "out", "--allow-outside",
                   *extra)


MAP_CASES = {
    "unknown bone": ("  femur_x: RightHip\n", "femur_x"),
    "unknown bone of a point": ("  p: {bone: femr_r, from: RightHip}\n", "femr_r"),
    "unknown mocap joint": ("  femur_r: RightHipp\n", "RightHipp"),
    "bad blend weight": ("  femur_r: {from: {RightHip: -1}}\n", "blend weight"),
    "unknown key": ("  femur_r: {from: RightHip, wieght: 2}\n", "wieght"),
    "at is not 3 numbers": ("  p: {bone: pelvis, at: [0, 1], from: Hips}\n", "at"),
}


@needs_bvh
@pytest.mark.parametrize("case", sorted(MAP_CASES))
def test_bad_map_entries_exit_2_at_their_position(tmp_path, capsys, case):
    line, word = MAP_CASES[case]
    text = (f"retarget: bad\nonto: {GAIT}\njoints:\n  tibia_r: RightKnee\n  talus_r: RightAnkle\n" + line)
    (tmp_path / "map.yaml").write_text(text)
    assert _retarget(tmp_path, CMU_BVH, tmp_path / "map.yaml", "--step", "40") == 2
    err = capsys.readouterr().err
    assert "map.yaml:6:" in err and word in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("top, word", [
    ("scale: big\n", "scale is 'big'"), ("align: left\n", "align"), ("hold: {knee_angel_r: 0}\n", "knee_angel_r"),
    ("ranges: {knee_angle_r: [0, -130]}\n", "with lo < hi"), ("smooth: -1\n", "smooth"), ("max_speed: 0\n", "max_speed"),
])
def test_bad_map_settings_exit_2(tmp_path, capsys, top, word):
    _, _, pts = known_positions(range(0, 10))
    write_npz(tmp_path / "walk.npz", pts, list(KNOWN_POINTS))
    (tmp_path / "map.yaml").write_text(f"retarget: bad\nonto: {GAIT}\n{top}joints:\n  tibia_r: tibia_r\n"
                                       "  talus_r: talus_r\n")
    assert _retarget(tmp_path, "walk.npz", tmp_path / "map.yaml") == 2
    err = capsys.readouterr().err
    assert "map.yaml:3:" in err and word in err, err
    assert not (tmp_path / "out").exists()


def _npz_cases(pts, names):
    bad = pts.copy()
    bad[3, 1, 2] = np.nan
    return {
        "nan": ({"joints": bad, "names": names}, "joints[3, 1, 2]"),
        "shape": ({"joints": pts[..., :2], "names": names}, "joints: is float64 of shape"),
        "names count": ({"joints": pts, "names": names[:-1]}, "names: is"),
        "repeated name": ({"joints": pts, "names": np.array(list(names[:-1]) + [names[0]])},
                          f"names[{len(names) - 1}]"),
        "bad name": ({"joints": pts, "names": np.array(["a b"] + list(names[1:]))}, "names[0]"),
        "no names": ({"joints": pts}, "no array 'names'"),
        "fps": ({"joints": pts, "names": names, "fps": np.array(-3.0)}, "fps: is"),
        "unknown array": ({"joints": pts, "names": names, "confidence": np.ones(3)}, "'confidence'"),
        "objects": ({"joints": pts, "names": np.array([object()] * len(names))}, "names"),
    }


@pytest.mark.parametrize("case", ["nan", "shape", "names count", "repeated name", "bad name", "no names", "fps",
                                  "unknown array", "objects"])
def test_bad_npz_exits_2_naming_the_array_and_index(tmp_path, capsys, case):
    _, _, pts = known_positions(range(0, 30, 3))
    arrays, word = _npz_cases(pts, np.array(list(KNOWN_POINTS)))[case]
    np.savez(tmp_path / "bad.npz", **arrays)
    known_map(tmp_path / "map.yaml")
    assert _retarget(tmp_path, "bad.npz", tmp_path / "map.yaml") == 2
    err = capsys.readouterr().err
    assert "bad.npz" in err and word in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


def test_not_an_npz_and_not_a_motion(tmp_path, capsys):
    known_map(tmp_path / "map.yaml")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not really a zip")
    assert _retarget(tmp_path, "junk.npz", tmp_path / "map.yaml") == 2
    assert "junk.npz" in capsys.readouterr().err
    (tmp_path / "walk.mot").write_text("x")
    assert _retarget(tmp_path, "walk.mot", tmp_path / "map.yaml") == 2
    assert "walk.mot" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


@needs_bvh
def test_bad_bvh_exits_2_at_its_line(tmp_path, capsys):
    lines = CMU_BVH.read_text().splitlines()
    head = next(i for i, t in enumerate(lines) if t.startswith("Frame Time"))
    lines[head + 3] = lines[head + 3] + " 1.0"  # a motion row with one value too many
    (tmp_path / "bad.bvh").write_text("\n".join(lines) + "\n")
    assert _retarget(tmp_path, "bad.bvh", CMU_MAP) == 2
    err = capsys.readouterr().err
    assert f"bad.bvh:{head + 4}:" in err and "Traceback" not in err, err
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- data sets


@needs_bvh
def test_a_data_set_takes_a_retargeted_take(tmp_path):
    from axdf_cli.dataset.spec import load_dataset, load_motion, motion_frames
    from axdf_cli.specs import RefPolicy

    (tmp_path / "ds.yaml").write_text(yaml.safe_dump({
        "dataset": "cmu", "skeleton": str(GAIT), "muscles": str(REPO / "muscles" / "gait2392" / "vas_int_r.yaml"),
        "motions": {"walk": {"retarget": str(CMU_BVH), "map": str(CMU_MAP), "step": 8, "frames": "0:120:60"}},
        "sequences": [{"motion": "walk"}], "cameras": {"sphere": {"views": 1, "distance": [3, 3.5]}}}))
    spec = load_dataset(tmp_path / "ds.yaml", policy=RefPolicy(allow_outside=True))
    pose = load_motion(spec, "walk")
    assert pose.fps == 15 and pose.last == 124 and list(motion_frames(spec, "walk")) == [0, 60, 120]
    assert "knee_angle_r" in pose.keys and "subtalar_angle_r" in pose.keys


def test_npz_headers_are_checked_before_reading(tmp_path, capsys, monkeypatch):
    """An array past the size limit (or of pickled objects) is refused from its header."""
    from axdf_cli.importers import mocap

    _, _, pts = known_positions(range(0, 30, 3))
    np.savez_compressed(tmp_path / "big.npz", joints=pts, names=np.array(list(KNOWN_POINTS)))
    known_map(tmp_path / "map.yaml")
    monkeypatch.setattr(mocap, "NPZ_MAX_VALUES", pts.size - 1)
    assert _retarget(tmp_path, "big.npz", tmp_path / "map.yaml") == 2
    err = capsys.readouterr().err
    assert "big.npz: joints: has shape (10, 22, 3)" in err, err


def test_validate_knows_a_retarget_map(capsys):
    from axdf_cli.cli.main import main

    assert main(["validate", str(CMU_MAP)]) == 0
    assert "retarget map cmu_to_gait2392: 15 points of gait2392" in capsys.readouterr().out


def test_an_input_is_never_overwritten(tmp_path, capsys):
    _, _, pts = known_positions(range(0, 30, 3))
    write_npz(tmp_path / "walk.npz", pts, list(KNOWN_POINTS))
    known_map(tmp_path / "walk_gait2392.yaml")  # the map where the pose would go
    before = (tmp_path / "walk_gait2392.yaml").read_bytes()
    assert run_cli(tmp_path, "retarget", "walk.npz", "--map", "walk_gait2392.yaml", "--out", ".",
                   "--allow-outside") == 2
    assert "is an input of this command" in capsys.readouterr().err
    assert (tmp_path / "walk_gait2392.yaml").read_bytes() == before
    assert not (tmp_path / "retarget.csv").exists()
