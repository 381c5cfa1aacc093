"""``axdf transfer`` carries path muscles: path points (fixed, moving, conditional) and wrap
surfaces go through each bone's similarity map.

Invariant: onto a copy of the skeleton scaled by k (every offset and every coupled translation
times k), with the identity bone map, every muscle is the same muscle scaled by k: its wrapped
path (hence its axis) is k times as long at every frame, its wrap surfaces k times as large,
its sections k times as wide. arm26 has the wraps (TRIlong over three surfaces, BIClong over
the humeral head, TRIlat, TRImed and BRA over the elbow); gait2392 has the moving points (the
knee extensors' patellar points) and the conditional ones. Also: the exact recombination of
moving-point functions under a rest rotation, and a path muscle whose coordinate the target
skeleton lacks is skipped with the reason.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_in_folder import run_cli

REPO = Path(__file__).resolve().parents[1]
SKELETONS = REPO / "poses" / "skeletons"


def scaled_skeleton(src: Path, dst: Path, k: float) -> Path:
    """``src`` scaled by k about the world origin's frame: offsets, post offsets and coupled
    translations (their functions' outputs) times k; meshes dropped. Plain translation
    coordinates (the pelvis' position) move the whole body rigidly and are left alone."""
    doc = yaml.safe_load(src.read_text())
    doc["skeleton"] = doc["skeleton"] + "_scaled"
    for b in doc["bones"]:
        b.pop("mesh", None)
        for key in ("offset", "post_offset"):
            if key in b:
                b[key] = [k * v for v in b[key]]
        for d in b.get("dofs", []):
            if d["type"] == "translation" and "function" in d:
                d["function"] = {"multiplier": {"scale": k, "function": d["function"]}}
    dst.write_text(yaml.safe_dump(doc, sort_keys=False))
    return dst


def identity_map(path: Path, skel: Path) -> Path:
    bones = [b["name"] for b in yaml.safe_load(skel.read_text())["bones"]]
    path.write_text(yaml.safe_dump({"transfer": "identity", "bones": {b: b for b in bones}}, sort_keys=False))
    return path


def _models(folder: Path, skel_path: Path):
    from axdf_cli.importers.emit import rest_world
    from axdf_cli.specs import load_muscle_file, load_skeleton
    from axdf_cli.model.muscle import MuscleModel

    skel = load_skeleton(skel_path)
    world = rest_world(skel)
    specs = {s.name: s for f in sorted(folder.glob("*.yaml")) for s in load_muscle_file(f)}
    return skel, {n: MuscleModel(s, skel.bone_index, world, skel) for n, s in specs.items()}


def _lengths(skel, models, pose_path: Path, frames) -> dict:
    """Axis lengths (F,) of every model over a pose's frames, on ``skel`` (the pose's keys are
    coordinates: the same numbers drive either skeleton)."""
    from axdf_cli.specs import load_pose
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics

    q = sample_coordinates(load_pose(pose_path), np.asarray(frames))
    world = forward_kinematics(skel, q)
    return {n: m.axis_length(world, q) for n, m in models.items()}


@pytest.mark.parametrize("model,pose,frames,k", [
    ("arm26", "arm26_flex.yaml", [0, 20, 40, 60, 80, 100], 1.3),
    ("gait2392", "gait2392_walk.yaml", [0, 30, 62, 100, 171], 0.85),
])
def test_scaled_skeleton_scales_path_muscles(tmp_path, model, pose, frames, k):
    src = SKELETONS / f"{model}.yaml"
    big = scaled_skeleton(src, tmp_path / f"{model}_k.yaml", k)
    rc = run_cli(tmp_path, "transfer", str(REPO / "muscles" / model), "--from", str(src), "--to", str(big),
                 "--map", str(identity_map(tmp_path / "id.yaml", src)), "--out", "out", "-q", "--allow-outside")
    assert rc == 0
    out = tmp_path / "out"
    report = json.loads((out / "transfer_report.json").read_text())
    assert report["skipped"] == []
    skel_a, ma = _models(REPO / "muscles" / model, src)
    skel_b, mb = _models(out, big)
    assert sorted(ma) == sorted(mb) and len(ma) == {"arm26": 6, "gait2392": 92}[model]
    wraps = 0
    for name, a in ma.items():
        pa, pb = a.spec.path, mb[name].spec.path
        assert pb is not None and len(pb.points) == len(pa.points) and [p.bone for p in pb.points] == \
            [p.bone for p in pa.points]
        for p, q in zip(pa.points, pb.points):
            assert np.allclose(np.multiply(p.at, k), q.at, atol=2e-7), (name, p.at, q.at)
            assert (p.active is None) == (q.active is None) and (p.active is None or p.active == q.active)
            assert (p.moving is None) == (q.moving is None)
            for ma_, mb_ in zip(p.moving or (), q.moving or ()):
                assert (ma_ is None) == (mb_ is None)
                if ma_ is not None:
                    x = np.linspace(-120, 120, 41)
                    assert mb_.coord == ma_.coord and np.allclose(mb_.function(x), k * ma_.function(x), atol=1e-7)
        for w, v in zip(pa.wraps, pb.wraps):
            wraps += 1
            assert (v.name, v.shape, v.bone, v.quadrant, v.method, v.range, v.active) == \
                   (w.name, w.shape, w.bone, w.quadrant, w.method, w.range, w.active)
            assert np.allclose(np.multiply(w.size, k), v.size, rtol=1e-8)
            assert np.allclose(np.multiply(w.at, k), v.at, atol=2e-7)
            from axdf_cli.model.skeleton import euler_xyz
            assert np.allclose(euler_xyz(w.orient), euler_xyz(v.orient), atol=1e-9)  # same frame, maybe other angles
        ra = [s.radii for s in a.spec.sections]
        rb = [s.radii for s in mb[name].spec.sections]
        assert np.allclose(np.multiply(ra, k), rb, rtol=1e-8)
    assert wraps == {"arm26": 7, "gait2392": 0}[model]  # arm26: TRIlong 3; BIClong, TRIlat, TRImed, BRA 1 each
    # the same muscles, k times as long, at every frame of the motion (wrapping and moving points included)
    la = _lengths(skel_a, ma, REPO / "poses" / pose, frames)
    lb = _lengths(skel_b, mb, REPO / "poses" / pose, frames)
    for name in la:
        assert np.allclose(lb[name], k * la[name], rtol=2e-6), (name, lb[name] / la[name])
    for r in report["muscles"]:
        assert r["length_ratio"] == pytest.approx(k, rel=2e-6) and r["radius_scale"] == pytest.approx(k, rel=1e-9)


def test_moving_point_functions_recombine_exactly():
    """A rest rotation that mixes a moving point's axes: the location along each axis of B is
    a weighted sum of A's functions of the same coordinate, written exactly as one function."""
    from axdf_cli.model.skeleton import Constant, Linear, Multiplier, Polynomial, Spline
    from axdf_cli.tools.transfer import combine_functions

    x = np.linspace(-150, 150, 301)
    knots = np.array([-120.0, -60.0, 0.0, 10.0, 120.0])
    s1 = Spline(knots, np.array([0.01, 0.03, 0.06, 0.065, 0.05]), "fmm")
    s2 = Spline(knots, np.array([0.02, 0.023, 0.019, 0.015, -0.06]), "fmm")
    flat = Spline(np.array([-120.0, 120.0]), np.array([0.0165, 0.0165]), "fmm")  # a constant written as a spline
    f = combine_functions([(0.6, s1), (-0.8, Multiplier(2.0, s2)), (0.5, flat)], 0.003)
    assert isinstance(f, Spline)
    assert np.allclose(f(x), 0.6 * s1(x) - 1.6 * s2(x) + 0.5 * 0.0165 + 0.003, atol=1e-12)
    g = combine_functions([(2.0, Linear(0.5, 1.0)), (1.0, Polynomial((0.0, 0.0, 3.0))), (3.0, Constant(1.0))], 1.0)
    assert np.allclose(g(x), 2.0 * (0.5 * x + 1.0) + 3.0 * x ** 2 + 3.0 + 1.0)
    assert isinstance(combine_functions([(1.0, Linear(0.5, 1.0))], 0.0), Linear)
    other = Spline(np.array([-100.0, 0.0, 100.0]), np.array([0.0, 0.01, 0.0]), "fmm")
    assert combine_functions([(1.0, s1), (1.0, other)], 0.0) is None  # different knots: not one spline
    assert combine_functions([(1.0, s1), (1.0, Linear(1.0, 0.0))], 0.0) is None


def test_path_muscle_on_a_skeleton_without_its_coordinate_is_skipped(tmp_path, capsys):
    """gait2392's vasti follow knee_angle_r: on a skeleton that calls it knee_r they are skipped
    with the reason; muscles whose paths need no coordinate still go."""
    src = SKELETONS / "gait2392.yaml"
    text = scaled_skeleton(src, tmp_path / "b.yaml", 1.0).read_text().replace("knee_angle_r", "knee_r")
    (tmp_path / "b.yaml").write_text(text)
    folder = tmp_path / "in"
    folder.mkdir()
    for n in ("vas_lat_r", "soleus_r"):
        (folder / f"{n}.yaml").write_text((REPO / "muscles" / "gait2392" / f"{n}.yaml").read_text())
    rc = run_cli(tmp_path, "transfer", str(folder), "--from", str(src), "--to", str(tmp_path / "b.yaml"),
                 "--map", str(identity_map(tmp_path / "id.yaml", src)), "--out", "out", "--allow-outside")
    assert rc == 0
    err = capsys.readouterr().err
    assert "vas_lat_r.yaml: muscle vas_lat_r skipped: coordinates its path points follow are not coordinates " \
           "of the target skeleton: knee_angle_r" in err
    report = json.loads((tmp_path / "out" / "transfer_report.json").read_text())
    assert [s["muscle"] for s in report["skipped"]] == ["vas_lat_r"]
    assert [m["muscle"] for m in report["muscles"]] == ["soleus_r"]
    assert (tmp_path / "out" / "soleus_r.yaml").exists() and not (tmp_path / "out" / "vas_lat_r.yaml").exists()


@pytest.mark.parametrize("y1", [0.0, 8.673617379884035e-19, -1e-30, 1e-9])
def test_ellipsoid_closest_point_off_a_pole(y1):
    """Found carrying arm26's BIClong onto a scaled arm: the humeral head (two equal shortest
    semi-axes) and a point whose coordinate along them is 1e-18 m made the Newton start land
    on the pole t = -a_k^2 and divide by zero (a ZeroDivisionError out of the compiled path)."""
    from axdf_cli.model.paths.opensim_shapes import closest_xyz

    a = (0.0325, 0.026, 0.026)
    y = (0.015061078825635527, y1, 0.034729132694275154)
    x = np.array(closest_xyz(*a, *y))
    assert np.isfinite(x).all()
    assert abs(np.sum((x / np.array(a)) ** 2) - 1.0) < 1e-9  # on the surface
    # the closest point: y - x is along the surface normal at x
    n = x / np.square(a)
    d = np.array(y) - x
    assert np.linalg.norm(np.cross(d, n)) < 1e-9 * np.linalg.norm(n)


def test_moving_point_through_a_rotation_that_mixes_its_axes():
    """A bone whose rest frame on B is turned (30° about Z, 20° about X) and scaled: the moving
    point's location on B equals the map applied to its location on A, at every coordinate value."""
    from axdf_cli.model.paths import Moving, PathPoint
    from axdf_cli.model.skeleton import Linear, Spline, euler_xyz
    from axdf_cli.tools.transfer import NotCarried, PairTransform, _carry_point

    knots = np.array([-120.0, -60.0, 0.0, 10.0, 120.0])
    fx = Spline(knots, np.array([0.01, 0.03, 0.06, 0.065, 0.05]), "fmm")
    fy = Spline(knots, np.array([0.02, 0.023, 0.019, 0.015, -0.06]), "fmm")
    p = PathPoint("tibia_r", (0.05, 0.02, 0.0165), (Moving("knee", fx), Moving("knee", fy), None))
    m = np.eye(4)
    m[:3, :3] = 1.1 * euler_xyz([20.0, 0.0, 30.0])
    m[:3, 3] = [0.01, -0.02, 0.03]
    t = PairTransform("tibia_r", "shin", m, 1.1, np.eye(3), None)
    q = _carry_point(p, t, 0)
    x = np.linspace(-130, 130, 53)
    loc_a = np.stack([fx(x), fy(x), np.full_like(x, 0.0165)], axis=1)
    want = loc_a @ m[:3, :3].T + m[:3, 3]
    got = np.stack([mv.function(x) if mv is not None else np.full_like(x, q.at[i])
                    for i, mv in enumerate(q.moving)], axis=1)
    assert q.bone == "shin" and all(mv is not None and mv.coord == "knee" for mv in q.moving)
    assert np.allclose(got, want, atol=1e-12)
    # axes driven by two coordinates cannot mix into one function: refused with the reason
    p2 = PathPoint("tibia_r", (0.05, 0.02, 0.0), (Moving("knee", fx), Moving("hip", Linear(0.001, 0.0)), None))
    with pytest.raises(NotCarried, match="path point 4 moves along axes"):
        _carry_point(p2, t, 3)
