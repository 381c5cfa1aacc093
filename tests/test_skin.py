"""`axdf skin` through the command line, in process: the skin file
for gait2392 and the CMU skeleton, read back by its loader; the muscles outside the rest skin
before and after --push; refusals (exit 2, nothing written, FILE:LINE:COL)."""
from __future__ import annotations

import io
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml

from axdf_cli.errors import InputError
from axdf_cli.specs import load_skeleton
from axdf_cli.specs.skin import load_skin
from axdf_cli.tools import skin as sk
from conftest import REPO_ROOT, run_main

SKELETONS = REPO_ROOT / "poses" / "skeletons"


@pytest.fixture(scope="module")
def gait_skin(tmp_path_factory):
    out = tmp_path_factory.mktemp("skin") / "gait2392"
    from axdf_cli.cli.main import main

    assert main(["skin", "--skeleton", str(SKELETONS / "gait2392.yaml"), "--out", str(out), "--quiet"]) == 0
    return out


def test_gait2392_skin_round_trip(gait_skin):
    skel = load_skeleton(SKELETONS / "gait2392.yaml")
    skin = load_skin(gait_skin / "skin.yaml", skel)
    assert skin.skeleton == "gait2392" and skin.family == "gait2392"
    assert skin.vertices.shape == (13380, 3)
    assert trimesh.Trimesh(skin.vertices, skin.faces, process=False).is_watertight
    np.testing.assert_allclose(skin.weights.sum(axis=1), 1.0, atol=1e-4)
    assert set(skin.bones) <= set(skel.bone_index) and "femur_l" in skin.bones
    assert abs(np.ptp(skin.vertices[:, 2]) / skin.stature - 1) < 0.03  # gait2392 stands upright at rest
    assert set(skin.regions) == set(sk.REGIONS) and skin.fat.shape == (13380,)
    doc = yaml.safe_load((gait_skin / "skin.yaml").read_text())
    assert doc["skin"] == "makehuman_gait2392" and doc["mesh"] == "skin_rest.ply"
    assert abs(doc["height"] / doc["stature"] - 1) < 0.03
    assert {p.name for p in gait_skin.iterdir()} == {"skin.yaml", "skin_rest.ply", "skin_weights.npz",
                                                     "skin_fat.npz", "skin_report.json", "manifest.json"}


def test_same_bytes_twice(gait_skin, tmp_path):
    from axdf_cli.cli.main import main

    assert main(["skin", "--skeleton", str(SKELETONS / "gait2392.yaml"), "--out", str(tmp_path / "again"), "--quiet"]) == 0
    for name in ("skin.yaml", "skin_rest.ply", "skin_weights.npz", "skin_fat.npz"):
        assert (tmp_path / "again" / name).read_bytes() == (gait_skin / name).read_bytes(), name


def test_cmu_skin_with_muscles_pushed_inside(tmp_path, capsys):
    out = tmp_path / "cmu"
    rc, stdout, err = run_main(["skin", "--skeleton", SKELETONS / "cmu_131_01.yaml", "--muscles",
                                REPO_ROOT / "muscles" / "cmu", "--push", "--out", out], capsys)
    assert rc == 0, err
    import json

    report = json.loads((out / "skin_report.json").read_text())
    m = report["muscles"]
    assert m["outside_before"] > 0 and m["outside_after"] == 0  # the push puts every muscle vertex inside
    assert f"{m['outside_before']} of {m['vertices']}" in stdout
    assert abs(report["height_off"]) < 0.03 and report["family"] == "CMU"
    skin = load_skin(out / "skin.yaml", load_skeleton(SKELETONS / "cmu_131_01.yaml"))
    assert "LeftKnee" in skin.bones and "lhand" in skin.bones


def test_validate_reads_a_skin_file(gait_skin, tmp_path, capsys):
    rc, out, err = run_main(["validate", gait_skin / "skin.yaml"], capsys)
    assert rc == 0 and "skin makehuman_gait2392: 13380 vertices on 10 bones of gait2392" in out, err
    path = _copy(gait_skin, tmp_path / "s")
    path.write_text(path.read_text().replace("mesh: skin_rest.ply", "mesh: skin_gone.ply"))
    rc, out, err = run_main(["validate", path], capsys)
    line = 1 + next(i for i, l in enumerate(path.read_text().splitlines()) if l.startswith("mesh:"))
    assert rc == 2 and f"{path}:{line}:7: mesh file skin_gone.ply not found" in err


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst / "skin.yaml"


def test_bad_key_refused_at_its_line(gait_skin, tmp_path):
    path = _copy(gait_skin, tmp_path / "s")
    lines = path.read_text().splitlines()
    k = next(i for i, l in enumerate(lines) if l.startswith("weights:"))
    lines.insert(k, "wieghts_extra: 3")
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputError) as e:
        load_skin(path)
    assert str(e.value).startswith(f"{path}:{k + 1}:1: unknown key 'wieghts_extra'")


def test_vertex_count_mismatch_refused(gait_skin, tmp_path):
    path = _copy(gait_skin, tmp_path / "s")
    w = dict(np.load(path.parent / "skin_weights.npz"))
    w["vertex_count"] = np.array(100)
    buf = io.BytesIO()
    np.savez(buf, **w)
    (path.parent / "skin_weights.npz").write_bytes(buf.getvalue())
    line = 1 + next(i for i, l in enumerate(path.read_text().splitlines()) if l.startswith("weights:"))
    with pytest.raises(InputError, match=r"weighs 100 vertices, the mesh skin_rest.ply has 13380") as e:
        load_skin(path)
    assert str(e.value).startswith(f"{path}:{line}:")


def test_missing_file_and_other_skeleton_refused(gait_skin, tmp_path):
    path = _copy(gait_skin, tmp_path / "s")
    with pytest.raises(InputError, match="not 'cmu_131_01'"):
        load_skin(path, load_skeleton(SKELETONS / "cmu_131_01.yaml"))
    (path.parent / "skin_fat.npz").unlink()
    with pytest.raises(InputError, match="fat file skin_fat.npz not found"):
        load_skin(path)


def test_bones_the_skeleton_lacks_refused(gait_skin, tmp_path):
    path = _copy(gait_skin, tmp_path / "s")
    w = dict(np.load(path.parent / "skin_weights.npz"))
    w["bones"] = np.array([("humerus_x" if b == "torso" else str(b)) for b in w["bones"]])
    buf = io.BytesIO()
    np.savez(buf, **w)
    (path.parent / "skin_weights.npz").write_bytes(buf.getvalue())
    with pytest.raises(InputError, match="lacks: humerus_x"):
        load_skin(path, load_skeleton(SKELETONS / "gait2392.yaml"))


def test_refusals_write_nothing(tmp_path, capsys, monkeypatch):
    out = tmp_path / "o"
    rc, _, err = run_main(["skin", "--skeleton", SKELETONS / "arm26.yaml", "--out", out], capsys)
    assert rc == 2 and "no family" in err and not out.exists()
    rc, _, err = run_main(["skin", "--skeleton", SKELETONS / "gait2392.yaml", "--push", "--out", out], capsys)
    assert rc == 2 and "--push needs --muscles" in err and not out.exists()
    # a gait2392 whose right heel bone is renamed: the nearest family and the bone it lacks are named
    text = (SKELETONS / "gait2392.yaml").read_text().replace("calcn_r", "heel_r")
    (tmp_path / "g.yaml").write_text(text.replace("mesh: meshes/", f"mesh: {SKELETONS / 'meshes'}/"))
    rc, _, err = run_main(["skin", "--skeleton", tmp_path / "g.yaml", "--out", out, "--allow-outside"], capsys)
    assert rc == 2 and "(the nearest, gait2392, needs bone calcn_r)" in err and not out.exists(), err
    monkeypatch.setattr(sk, "BODY_FILE", tmp_path / "nowhere" / "body.npz")
    rc, _, err = run_main(["skin", "--skeleton", SKELETONS / "gait2392.yaml", "--out", out], capsys)
    assert rc == 2 and "the body assets are missing" in err and "extract_makehuman" in err and not out.exists()
    assert "Traceback" not in err


def test_the_shipped_skin_and_its_walk_job_validate(capsys, tmp_path):
    """skins/gait2392 (make skin) is a valid skin of gait2392; poses/jobs/gait2392_walk_skin.yaml
    validates as a job (its skin: key names the skin it wears, not a skin file); the same job
    with a skin: that does not exist is refused at the key's position."""
    from conftest import REPO_ROOT, run_main

    rc, out, err = run_main(["validate", str(REPO_ROOT / "skins" / "gait2392" / "skin.yaml")], capsys)
    assert rc == 0 and "13380 vertices on 10 bones of gait2392" in out, err
    job = REPO_ROOT / "poses" / "jobs" / "gait2392_walk_skin.yaml"
    rc, out, err = run_main(["validate", str(job)], capsys)
    assert rc == 0 and "(job: 92 muscles x 67 frames)" in out, err
    text = job.read_text().replace("skin: ../../skins/gait2392/skin.yaml", "skin: ../../skins/nobody/skin.yaml")
    jobs = tmp_path / "poses" / "jobs"  # the job's relative paths, beside copies of what they name
    jobs.mkdir(parents=True)
    (tmp_path / "muscles").mkdir()
    shutil.copytree(REPO_ROOT / "muscles" / "gait2392_packed", tmp_path / "muscles" / "gait2392_packed")
    shutil.copy(REPO_ROOT / "poses" / "gait2392_walk.yaml", tmp_path / "poses")
    shutil.copytree(REPO_ROOT / "poses" / "skeletons", tmp_path / "poses" / "skeletons")
    bad = jobs / "_test_missing_skin.yaml"
    bad.write_text(text)
    rc, out, err = run_main(["validate", str(bad), "--allow-outside"], capsys)
    line = text.splitlines().index("skin: ../../skins/nobody/skin.yaml") + 1
    assert rc == 2 and f"_test_missing_skin.yaml:{line}:" in err and "Traceback" not in err, err
