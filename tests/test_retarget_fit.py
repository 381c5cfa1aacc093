"""``axdf retarget``: a fit that holds, or says why not.

- A turning walk (the shared CMU walk with its root turned about the vertical by a ramp of
  360 degrees over the take) retargeted onto gait2392 with the shipped map pins no root
  coordinate at a range's end (gait2392's file gives pelvis_rotation ±90°: the heading in the
  room is free), its heading follows the turn without jumps, and it fits within 3% of the leg
  (RMS over the take, and every leg joint's), as well as the straight walk; neither is warned.
- A map may widen a range; the room coordinates of gait2392 are its pelvis translations and
  its turn about the vertical.
- Hostile maps: a point `at` in the wrong unit (0.6 m or 6 m for 0.06 m) and one 1e9 m off are refused
  at their line, naming the point; 4,000 points are refused at once; a take whose pose would
  pass the YAML limit is refused before any frame is fitted.
- A bad fit (each knee driven by the other leg's) is warned on stderr with its frames and the fix, and
  ``--strict`` refuses it with nothing written; a scale far from the model's is warned.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from cli_in_folder import run_cli

REPO = Path(__file__).resolve().parents[1]
CMU_BVH = REPO.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"
CMU_MAP = REPO / "poses" / "maps" / "cmu_to_gait2392.yaml"
GAIT = REPO / "poses" / "skeletons" / "gait2392.yaml"
needs_bvh = pytest.mark.skipif(not CMU_BVH.is_file(), reason="the shared CMU BVH is not here")
ROOT = ("pelvis_tilt", "pelvis_list", "pelvis_rotation", "pelvis_tx", "pelvis_ty", "pelvis_tz")


def _rz_ry_rx(a, b, c):
    """(F, 3, 3) Rz(a) Ry(b) Rx(c), degrees (a BVH root's ``Zrotation Yrotation Xrotation``)."""
    a, b, c = (np.radians(v) for v in (a, b, c))
    one, zero = np.ones_like(a), np.zeros_like(a)
    rz = np.array([[np.cos(a), -np.sin(a), zero], [np.sin(a), np.cos(a), zero], [zero, zero, one]])
    ry = np.array([[np.cos(b), zero, np.sin(b)], [zero, one, zero], [-np.sin(b), zero, np.cos(b)]])
    rx = np.array([[one, zero, zero], [zero, np.cos(c), -np.sin(c)], [zero, np.sin(c), np.cos(c)]])
    # r[f] = rz[f] ry[f] rx[f]
    return np.einsum("ijf,jkf,klf->fil", rz, ry, rx)


def turning_walk(path: Path, degrees: float = 360.0) -> Path:
    """The CMU walk turned about BVH's vertical (Y) by a ramp of ``degrees`` over the take: the
    root's position and rotation channels (its first six: X/Y/Z position, Z/Y/X rotation) of
    row k turned by degrees * k / (N - 1)."""
    lines = CMU_BVH.read_text().splitlines()
    k = next(i for i, t in enumerate(lines) if t.startswith("Frame Time")) + 1
    rows = np.array([[float(v) for v in t.split()] for t in lines[k:] if t.strip()])
    t = np.radians(degrees) * np.arange(len(rows)) / (len(rows) - 1)
    turn = np.zeros((len(rows), 3, 3))
    turn[:, 0, 0] = turn[:, 2, 2] = np.cos(t)
    turn[:, 0, 2], turn[:, 2, 0], turn[:, 1, 1] = np.sin(t), -np.sin(t), 1.0
    rows[:, :3] = np.einsum("fij,fj->fi", turn, rows[:, :3])
    r = np.einsum("fij,fjk->fik", turn, _rz_ry_rx(*rows[:, 3:6].T))
    # back to Z-Y-X angles: r = Rz(a) Ry(b) Rx(c)
    b = np.degrees(np.arcsin(np.clip(-r[:, 2, 0], -1, 1)))
    a = np.degrees(np.arctan2(r[:, 1, 0], r[:, 0, 0]))
    c = np.degrees(np.arctan2(r[:, 2, 1], r[:, 2, 2]))
    rows[:, 3], rows[:, 4], rows[:, 5] = a, b, c
    assert np.abs(_rz_ry_rx(a, b, c) - r).max() < 1e-9
    path.write_text("\n".join(lines[:k] + [" ".join(f"{v:.6f}" for v in row) for row in rows]) + "\n")
    return path


def leg_length(res) -> float:
    """The subject's leg: median hip to knee to ankle (the right side), metres."""
    pos, idx = res.mocap.positions, res.mocap.index
    return float(np.median(np.linalg.norm(pos[:, idx["RightHip"]] - pos[:, idx["RightKnee"]], axis=1)
                           + np.linalg.norm(pos[:, idx["RightKnee"]] - pos[:, idx["RightAnkle"]], axis=1)))


@needs_bvh
@pytest.mark.parametrize("turned", [False, True], ids=["walk", "turning walk"])
def test_a_turning_walk_pins_no_root_coordinate_and_fits_within_3_percent(tmp_path, turned):
    from axdf_cli.tools.retarget import build_retarget

    motion = turning_walk(tmp_path / "turn.bvh") if turned else CMU_BVH
    made = build_retarget(motion, CMU_MAP, tmp_path / "out", step=8, name="fit")
    res, rep = made.retargeted, made.report
    for c in ROOT:
        assert rep["coordinates"][c]["frames_at_range_end"] == 0, c
    leg = leg_length(res)
    assert rep["error"]["rms_m"] < 0.03 * leg, (rep["error"], leg)
    names = [p.name for p in res.rmap.points]
    for point in ("femur_r", "femur_l", "tibia_r", "tibia_l", "talus_r", "talus_l"):
        assert np.sqrt(np.mean(res.error[:, names.index(point)] ** 2)) < 0.03 * leg, point
    assert made.warnings == [] and rep["checks"]["warnings"] == []
    heading = res.fit.q[:, res.rmap.skeleton.coord_index["pelvis_rotation"]]
    assert np.abs(np.diff(heading)).max() < 30.0  # unwrapped: no jump of 360
    if turned:  # the ramp's 360 degrees against the walk's own turn: far past the file's ±90
        assert np.ptp(heading) > 300.0 and np.abs(heading).max() > 150.0


def test_a_map_may_widen_a_range_and_the_room_is_free(tmp_path):
    from axdf_cli.tools.retarget import load_map, room_coordinates
    from axdf_cli.specs import load_skeleton

    skel = load_skeleton(GAIT)
    assert set(room_coordinates(skel, {})) == {"pelvis_tx", "pelvis_ty", "pelvis_tz", "pelvis_rotation"}
    (tmp_path / "map.yaml").write_text(f"retarget: wide\nonto: {GAIT}\nranges:\n  knee_angle_r: [-150, 20]\n"
                                       "  pelvis_tx: [-1, 1]\njoints:\n  tibia_r: RightKnee\n  talus_r: RightAnkle\n")
    rmap = load_map(tmp_path / "map.yaml")
    fit = {c.name: c.range for c in rmap.skeleton.coordinates}
    assert fit["knee_angle_r"] == (-150.0, 20.0) and fit["pelvis_tx"] == (-1.0, 1.0)
    assert fit["pelvis_rotation"] is None and fit["pelvis_tz"] is None and fit["pelvis_tilt"] == (-90.0000002, 90.0000002)
    assert rmap.model.coordinates[rmap.model.coord_index["pelvis_rotation"]].range == (-90.0000002, 90.0000002)


def _map_with(tmp_path: Path, old: str, new: str) -> Path:
    text = CMU_MAP.read_text()
    assert old in text
    path = tmp_path / "map.yaml"
    path.write_text(text.replace("onto: ../skeletons/gait2392.yaml", f"onto: {GAIT}").replace(old, new))
    return path


def _line_of(path: Path, word: str) -> int:
    return next(i for i, t in enumerate(path.read_text().splitlines(), 1) if word in t)


@needs_bvh
@pytest.mark.parametrize("at, words", [("[0.6, 0, 0]", ("toe_tip_r", "times the other segments' ratio")),
                                       ("[6, 0, 0]", ("toe_tip_r", "beyond the whole model")),
                                       ("[1000000000, 0, 0]", ("toe_tip_r", "beyond the whole model"))])
def test_a_point_in_the_wrong_unit_is_refused_at_its_line(tmp_path, capsys, at, words):
    path = _map_with(tmp_path, "toe_tip_r: {bone: toes_r, at: [0.06, 0, 0]", f"toe_tip_r: {{bone: toes_r, at: {at}")
    assert run_cli(tmp_path, "retarget", str(CMU_BVH), "--map", "map.yaml", "--out", "out", "--step", "40",
                   "--allow-outside") == 2
    err = capsys.readouterr().err
    assert f"map.yaml:{_line_of(path, 'toe_tip_r')}:" in err and all(w in err for w in words), err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def test_thousands_of_points_are_refused_at_once(tmp_path, capsys):
    lines = [f"retarget: many\nonto: {GAIT}\njoints:"]
    lines += [f"  p{i}: {{bone: femur_r, at: [0, {-i * 1e-4:.4f}, 0], from: j{i % 7}}}" for i in range(4000)]
    (tmp_path / "map.yaml").write_text("\n".join(lines) + "\n")
    np.savez(tmp_path / "m.npz", joints=np.zeros((3, 7, 3)), names=np.array([f"j{i}" for i in range(7)]))
    assert run_cli(tmp_path, "retarget", "m.npz", "--map", "map.yaml", "--out", "out", "--allow-outside") == 2
    err = capsys.readouterr().err
    assert "map.yaml:4:" in err and "4000 points" in err and "at most 256" in err, err


@needs_bvh
def test_a_pose_over_the_yaml_limit_is_refused_before_fitting(tmp_path, capsys, monkeypatch):
    from axdf_cli import tolerances as tol
    from axdf_cli.tools import retarget

    def never(*a, **k):
        raise AssertionError("fitted")

    monkeypatch.setattr(tol, "YAML_MAX_BYTES", 20_000)
    monkeypatch.setattr(retarget, "fit_frames", never)
    assert run_cli(tmp_path, "retarget", str(CMU_BVH), "--map", str(CMU_MAP), "--out", "out", "--step", "4",
                   "--allow-outside") == 2
    err = capsys.readouterr().err
    assert "the pose would be about" in err and "249 frames" in err and "--step" in err, err
    assert not (tmp_path / "out").exists()


@needs_bvh
def test_a_bad_fit_is_warned_and_strict_refuses_it(tmp_path, capsys):
    path = _map_with(tmp_path, "tibia_r: RightKnee\n  tibia_l: LeftKnee", "tibia_r: LeftKnee\n  tibia_l: RightKnee")
    args = ("retarget", str(CMU_BVH), "--map", "map.yaml", "--step", "40", "--allow-outside")
    assert run_cli(tmp_path, *args, "--out", "out") == 0
    err = capsys.readouterr().err
    assert "axdf: warning: the fit misses the motion" in err and "frame(s) beyond" in err and "Fix:" in err, err
    rep = json.loads((tmp_path / "out" / "retarget_report.json").read_text())
    assert rep["checks"]["warnings"] and rep["checks"]["bounds"]["take_rms_m"] < 0.03
    assert run_cli(tmp_path, *args, "--out", "strict", "--strict") == 2
    err = capsys.readouterr().err
    assert "with --strict" in err and "Traceback" not in err and not (tmp_path / "strict").exists()
    assert path.is_file()


@needs_bvh
def test_a_scale_far_from_the_model_is_warned(tmp_path, capsys):
    assert run_cli(tmp_path, "retarget", str(CMU_BVH), "--map", str(CMU_MAP), "--out", "out", "--step", "40",
                   "--scale", "0.4", "--allow-outside") == 0
    err = capsys.readouterr().err
    assert "the fitted scale 0.38" in err and "--units" in err, err
    assert math.isclose(json.loads((tmp_path / "out" / "retarget_report.json").read_text())["similarity"]["scale"],
                        0.4 * 0.9593, rel_tol=0.01)


@needs_bvh
def test_a_data_sets_retargeted_take_is_warned_as_retarget_warns(tmp_path, capsys):
    """A data set that retargets a take prints the fit's warnings, as `axdf retarget` does."""
    import yaml

    from axdf_cli.cli.dataset import warn_ranges
    from axdf_cli.dataset.spec import fit_warnings, load_dataset
    from axdf_cli.specs import RefPolicy

    def spec_with(map_path):
        (tmp_path / "ds.yaml").write_text(yaml.safe_dump({
            "dataset": "cmu", "skeleton": str(GAIT), "muscles": str(REPO / "muscles" / "gait2392" / "vas_int_r.yaml"),
            "motions": {"walk": {"retarget": str(CMU_BVH), "map": str(map_path), "step": 40, "frames": "0:20:10"}},
            "sequences": [{"motion": "walk"}], "cameras": {"sphere": {"views": 1, "distance": [3, 3.5]}}}))
        return load_dataset(tmp_path / "ds.yaml", policy=RefPolicy(allow_outside=True))

    good = tmp_path / "good.yaml"
    good.write_text(CMU_MAP.read_text().replace("onto: ../skeletons/gait2392.yaml", f"onto: {GAIT}"))
    assert fit_warnings(spec_with(good), "walk") == []
    bad = _map_with(tmp_path, "tibia_r: RightKnee\n  tibia_l: LeftKnee", "tibia_r: LeftKnee\n  tibia_l: RightKnee")
    spec = spec_with(bad)
    warns = fit_warnings(spec, "walk")
    assert warns and "the fit misses the motion" in warns[0]

    class Ctx:
        muscles = []
    Ctx.spec = spec
    capsys.readouterr()
    warn_ranges(Ctx, quiet=False)
    err = capsys.readouterr().err
    assert "warning: motion walk (" in err and "): the fit misses the motion" in err, err
