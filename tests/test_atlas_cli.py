"""`axdf atlas`: an atlas registered onto a skeleton as a command, in process.

Without data: a bad map is refused at its line (FILE:LINE:COL), a landmark's file the atlas
folder lacks at the map's landmark, a model muscle the map names that --muscles lacks at the
map's muscle, a skeleton without a landmark's bone at the landmark; exit 2, no traceback,
nothing written. Where ../shared/data has the Visible Human atlas: the Visible Human's meshes in
their scan frame given to `axdf fit` are refused with `axdf atlas` named; `axdf atlas
--register-only` writes the carried meshes, each side's landmark similarity and the residuals
(bones within a millimetre after the warp), and the carried meshes fit onto the right bones.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from cli_in_folder import run_cli
from osim_common import DATA, REPO

ATLAS = DATA / "atlas" / "visible_human_female"
MAP = REPO / "atlases" / "gait2392.yaml"
SKELETON = REPO / "poses" / "skeletons" / "gait2392.yaml"
OLD = REPO / "muscles" / "gait2392"
needs_atlas = pytest.mark.skipif(not (ATLAS / "Right").is_dir(),
                                 reason=f"the Visible Human atlas not found at {ATLAS} (../shared/data)")


def _atlas(d: Path, capsys, *argv, atlas=ATLAS, map_=MAP, muscles=OLD, skeleton=SKELETON) -> tuple[int, str, str]:
    capsys.readouterr()
    rc = run_cli(d, "atlas", str(atlas), "--onto", str(skeleton), "--map", str(map_), "--muscles", str(muscles),
                 *argv)
    out, err = capsys.readouterr()
    return rc, out, err


def _refused(d: Path, capsys, *argv, **kw) -> str:
    rc, _, err = _atlas(d, capsys, "--out", "out", "--quiet", *argv, **kw)
    assert rc == 2, err
    assert "Traceback" not in err and "internal error" not in err, err
    assert not (d / "out").exists() and not list(d.glob("out*"))
    return err


def _line_of(path: Path, text: str) -> int:
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if line.startswith(text))


def test_a_map_file_pattern_out_of_the_folder_is_refused_at_its_line(tmp_path, capsys):
    bad = tmp_path / "map.yaml"
    bad.write_text(MAP.read_text().replace('files: "{folder}/', 'files: "/abs/{folder}/'))
    err = _refused(tmp_path, capsys, map_=bad)
    assert err.startswith(f"{bad}:{_line_of(bad, 'files: ')}:8: files: '/abs/"), err
    assert "is not an atlas file pattern; a relative path with {name}" in err


def test_a_landmark_file_the_atlas_lacks_is_refused_at_the_landmark(tmp_path, capsys):
    (tmp_path / "atlas").mkdir()
    err = _refused(tmp_path, capsys, "--register-only", atlas=tmp_path / "atlas")
    line = _line_of(MAP, "  hip: {cartilage: FemurHead")
    assert err.startswith(f"{MAP}:{line}:8: landmark hip: no atlas file "), err
    assert "VHF_Right_Cartilage_FemurHead_smooth.ply" in err


def test_a_model_muscle_missing_from_muscles_is_refused_at_the_map(tmp_path, capsys):
    lib = tmp_path / "lib"
    shutil.copytree(OLD, lib)
    (lib / "tib_ant_l.yaml").unlink()
    err = _refused(tmp_path, capsys, muscles=lib)
    line = _line_of(MAP, "  tib_ant: [TibialisAnterior]")
    assert err.startswith(f"{MAP}:{line}:12: muscle tib_ant: "), err
    assert "has no tib_ant_l.yaml" in err
    # one side only: the right leg's files are enough
    assert "tib_ant_l" not in _refused(tmp_path, capsys, "--sides", "r", "--sections", "2", muscles=lib)


def test_sides_and_sections_are_checked_first(tmp_path, capsys):
    assert "--sides 'x'" in _refused(tmp_path, capsys, "--sides", "x")
    assert "--sections 200" in _refused(tmp_path, capsys, "--sections", "200")


@needs_atlas
def test_a_skeleton_without_a_landmarks_bone_is_refused_at_the_landmark(tmp_path, capsys):
    skel = tmp_path / "skel.yaml"
    text = SKELETON.read_text().replace("name: talus_r", "name: astragalus_r")
    skel.write_text(text.replace("parent: talus_r", "parent: astragalus_r")
                    .replace("mesh: meshes/", f"mesh: {SKELETON.parent}/meshes/"))
    err = _refused(tmp_path, capsys, "--register-only", "--sides", "r", skeleton=skel)
    line = _line_of(MAP, "  ankle: {cartilage: Talus")
    assert err.startswith(f"{MAP}:{line}:10: landmark ankle: skeleton "), err
    assert "has no bone 'talus_r'" in err


@needs_atlas
def test_scan_frame_meshes_are_refused_until_registered_by_axdf_atlas(tmp_path, capsys):
    """The Visible Human's meshes in their scan frame (mm) given to gait2392: refused, each named,
    with `axdf atlas` as the route (they lay 0.39 m and more from every bone and were bound to
    torso, pelvis and femur_l). Registered by `axdf atlas --register-only`: the bones meet the
    model's within a millimetre, and soleus and vastus lateralis fit onto the right tibia and
    femur; the landmark similarity it writes is an `axdf fit --transform` file."""
    meshes = [str(ATLAS / "Right" / f"VHF_Right_Muscle_{n}_smooth.ply") for n in ("Soleus", "VastusLateralis")]
    capsys.readouterr()
    assert run_cli(tmp_path, "fit", *meshes, "--skeleton", str(SKELETON), "--out", "scan", "--units", "mm",
                   "--quiet", "--allow-outside") == 2
    err = capsys.readouterr().err
    for m in meshes:
        assert f"{m}: the mesh lies 0." in err
    assert err.count("register the meshes onto the skeleton first (an atlas: `axdf atlas ATLAS_DIR --onto") == 2
    assert not (tmp_path / "scan").exists()

    rc, out, err = _atlas(tmp_path, capsys, "--out", "reg", "--sides", "r", "--register-only")
    assert rc == 0, err
    assert "side r: scale 1.10" in out and "registered " in out
    reg = tmp_path / "reg"
    report = json.loads((reg / "atlas_report.json").read_text())
    side = report["sides"]["r"]
    assert set(side["landmark_residual_mm"]) == {"hip", "hip_other", "knee", "ankle"}
    for bone, e in side["bones_after"].items():
        assert e["mean_mm"] < 1.0 < side["bones_before"][bone]["mean_mm"], (bone, e)
    assert max(side["landmarks_after_mm"].values()) < 0.1
    assert (reg / "registered" / "soleus_r.ply").is_file() and (reg / "registered" / "glut_max2_r.ply").is_file()
    assert not (reg / "muscles").exists() and (reg / "landmarks_r.yaml").is_file()
    assert json.loads((reg / "manifest.json").read_text())["command"] == "atlas"

    capsys.readouterr()
    assert run_cli(tmp_path, "fit", str(reg / "registered" / "soleus_r.ply"),
                   str(reg / "registered" / "vas_lat_r.ply"), "--skeleton", str(SKELETON), "--paths", str(OLD),
                   "--out", "fit", "--quiet", "--allow-outside") == 0, capsys.readouterr().err
    soleus, vastus = json.loads((tmp_path / "fit" / "fit_report.json").read_text())["muscles"]
    assert set(soleus["bones"]) == {"tibia_r"}, soleus["bones"]
    assert set(vastus["bones"]) == {"femur_r"}, vastus["bones"]
    # as the shipped library's fits (16 sections: IoU 0.92 and 0.91)
    assert soleus["iou"] >= 0.88 and vastus["iou"] >= 0.88, (soleus["iou"], vastus["iou"])
    # the landmarks' similarity carries the scan-frame mesh as well (no warp: a looser fit)
    assert run_cli(tmp_path, "fit", meshes[0], "--skeleton", str(SKELETON), "--out", "lm", "--units", "mm",
                   "--transform", str(reg / "landmarks_r.yaml"), "--sections", "6", "--quiet",
                   "--allow-outside") == 0, capsys.readouterr().err
    (lm,) = json.loads((tmp_path / "lm" / "fit_report.json").read_text())["muscles"]
    assert set(lm["bones"]) == {"tibia_r"}, lm["bones"]
