"""One person, one height: ``axdf retarget`` (its printout and
retarget_report.json) and ``axdf skin`` (its printout and skin_report.json) state the height
that :func:`axdf_cli.model.stature.stature` defines, head top to sole from the skeleton's joints
at rest. The CLI in process."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from conftest import REPO_ROOT, run_main
from test_retarget import CMU_BVH, CMU_MAP, GAIT, known_map, known_positions, needs_bvh, write_npz

CMU_SKELETON = REPO_ROOT / "poses" / "skeletons" / "cmu_131_01.yaml"


def skin_height(tmp_path, capsys, skeleton) -> tuple[float, float]:
    """(stature in skin_report.json, stature in the printout) of ``axdf skin``."""
    out = tmp_path / f"skin_{skeleton.stem}"
    rc, stdout, err = run_main(["skin", "--skeleton", skeleton, "--out", out], capsys)
    assert rc == 0, err
    printed = float(re.search(r"skeleton's stature ([0-9.]+) m", stdout).group(1))
    return json.loads((out / "skin_report.json").read_text())["stature"], printed


def retarget_height(tmp_path, capsys, *argv) -> tuple[dict, float, str]:
    """(checks.bounds of retarget_report.json, the printed height, stdout) of ``axdf retarget``."""
    rc, stdout, err = run_main(["retarget", *argv, "--out", tmp_path / "rt", "--allow-outside"], capsys)
    assert rc == 0, err
    bounds = json.loads((tmp_path / "rt" / "retarget_report.json").read_text())["checks"]["bounds"]
    return bounds, float(re.search(r"subject ([0-9.]+) m tall, head top to sole", stdout).group(1)), stdout


@needs_bvh
def test_the_cmu_subject_has_one_height(tmp_path, capsys):
    """The CMU take's subject: its own skeleton's stature in retarget's printout and report,
    and in axdf skin's on the skeleton imported from the same take (1.540 m; it was 1.59 m,
    1.33 m and 1.54 m)."""
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.model.stature import stature
    from axdf_cli.tools.skin import family_of, skeleton_landmarks

    mocap = read_motion(CMU_BVH, step=30)
    fam = family_of(mocap.skeleton, None)
    expected = stature(skeleton_landmarks(mocap.skeleton, fam)[0])
    assert expected == pytest.approx(1.540, abs=5e-4)
    bounds, printed, stdout = retarget_height(tmp_path, capsys, CMU_BVH, "--map", CMU_MAP, "--step", "30")
    assert bounds["body_height_from"] == "motion" and bounds["body_height_m"] == pytest.approx(expected, abs=1e-9)
    assert printed == round(expected, 3)
    assert "m person" not in stdout, stdout  # the unit's guess states no second height
    reported, shown = skin_height(tmp_path, capsys, CMU_SKELETON)
    assert reported == pytest.approx(expected, abs=1e-4) and shown == printed


def test_points_alone_give_the_model_s_height_times_the_scale(tmp_path, capsys, monkeypatch):
    """An npz take (points, no skeleton) of a subject 1.15 times gait2392: retarget states
    gait2392's stature (as axdf skin states it) times the fitted scale."""
    skel, q, pts = known_positions(range(0, 211, 30))
    write_npz(tmp_path / "big.npz", 1.15 * pts, [n for n in __import__("test_retarget").KNOWN_POINTS])
    known_map(tmp_path / "map.yaml", scale="fit")
    monkeypatch.chdir(tmp_path)
    bounds, printed, _ = retarget_height(tmp_path, capsys, "big.npz", "--map", "map.yaml")
    scale = json.loads((tmp_path / "rt" / "retarget_report.json").read_text())["similarity"]["scale"]
    assert scale == pytest.approx(1.15, abs=1e-3)
    reported, shown = skin_height(tmp_path, capsys, GAIT)
    assert bounds["body_height_from"] == "model"
    assert bounds["body_height_m"] == pytest.approx(reported * scale, abs=1e-4 * scale)
    assert printed == pytest.approx(shown * scale, abs=2e-3)
    assert bounds["take_rms_m"] == pytest.approx(0.015 * bounds["body_height_m"])
    assert not np.isnan(bounds["body_height_m"])
