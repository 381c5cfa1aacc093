"""`axdf render RUN_DIR`: end to end through main(), and exit 3 without EGL."""
import json

import numpy as np
import pytest
from render_helpers import read_exr, write_run

from axdf_cli.cli import main as main_mod
from axdf_cli.render.runio import load_run_scene


@pytest.fixture
def axdf(monkeypatch):
    # only the render subcommand: the other subcommands live on other branches
    monkeypatch.setattr(main_mod, "COMMANDS", {"render": main_mod.COMMANDS["render"]})
    return main_mod.main


def test_load_run_scene_round_trip(tmp_path):
    scene, chunks = write_run(tmp_path, render={"size": [96, 64], "view": "front"})
    s2, it, settings = load_run_scene(tmp_path)
    assert settings.enabled and settings.size == (96, 64) and settings.view == "front"
    assert [m.name for m in s2.muscles] == [m.name for m in scene.muscles]
    assert s2.frames == scene.frames
    np.testing.assert_allclose(s2.bounds, scene.bounds, rtol=0, atol=1e-7)
    for a, b in zip(it, chunks):
        for pa, pb in zip(a.positions, b.positions):
            np.testing.assert_array_equal(pa, pb)
        np.testing.assert_allclose(a.bone_world, b.bone_world, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(s2.muscles[0].faces, scene.muscles[0].faces)


def test_render_command_writes_frames_and_manifest(tmp_path, axdf, capsys):
    write_run(tmp_path, n_frames=2)
    rc = axdf(["render", str(tmp_path), "--size", "80x60", "--view", "sheet", "--supersample", "2"])
    assert rc == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "frames" in out
    exr = read_exr(tmp_path / "frames" / "0001.exr")
    assert exr["id"].shape == (60, 240)
    cam = json.loads((tmp_path / "camera.json").read_text())
    assert cam["views"] == ["front", "side", "top"] and len(cam["frames"]) == 2
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["gl"]["renderer"] and "frames/0001.png" in manifest["files"]


def test_render_without_egl_exits_3_with_hint(tmp_path, axdf, capsys):
    write_run(tmp_path, n_frames=1)
    rc = axdf(["render", str(tmp_path), "--egl-library", str(tmp_path / "missing" / "libEGL.so.1")])
    err = capsys.readouterr().err
    assert rc == 3
    assert "apt-get install -y libegl1 libegl-mesa0 libgl1-mesa-dri libgles2" in err
    assert "Traceback" not in err
    assert not (tmp_path / "frames").exists()


def test_bad_flag_exits_2(tmp_path, axdf, capsys):
    write_run(tmp_path, n_frames=1)
    assert axdf(["render", str(tmp_path), "--size", "big"]) == 2
    assert "--size" in capsys.readouterr().err
    assert axdf(["render", str(tmp_path / "nope")]) == 2


def test_a_run_with_a_skin_renders_it_and_its_under_skin_pass(tmp_path, capsys):
    """``axdf run --skin ... --render --skin-view opaque``: the frames' id pass holds the skin
    (camera.json names its id) and the EXR carries under.id / under.Z naming muscles of the run
    under it; ``axdf render RUN --skin-view see-through`` reads the skin back from meshes/skin/
    and draws the muscles' ids under it (no under pass); ``--skin-view off`` is the picture of
    the same run drawn as if it had no skin."""
    from conftest import REPO_ROOT, run_main

    skel = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"
    packed = REPO_ROOT / "muscles" / "gait2392_packed"
    knee = [str(packed / f"{m}_l.yaml") for m in ("rect_fem", "vas_lat", "vas_med", "med_gas", "bifemlh")]
    assert run_main(["skin", "--skeleton", str(skel), "--out", str(tmp_path / "skin"), "-q"], capsys)[0] == 0
    run = tmp_path / "run"
    rc, _, err = run_main(["run", "--pose", str(REPO_ROOT / "poses" / "gait2392_walk.yaml"), "--muscles", *knee,
                           "--skin", str(tmp_path / "skin" / "skin.yaml"), "--frames", "22", "--out", str(run),
                           "--render", "--size", "96x128", "--view", "front", "--skin-view", "opaque", "-q"], capsys)
    assert rc == 0, err
    cam = json.loads((run / "camera.json").read_text())
    skin_ids = [int(k) for k, v in cam["ids"].items() if v["kind"] == "skin"]
    muscle_ids = {int(k) for k, v in cam["ids"].items() if v["kind"] == "muscle"}
    assert len(skin_ids) == 1 and len(muscle_ids) == 5
    exr = read_exr(run / "frames" / "0022.exr")
    skin = exr["id"] == skin_ids[0]
    assert skin.sum() > 1000
    named = exr["under.id"][skin]
    assert set(np.unique(named[named > 0]).tolist()) <= muscle_ids and (named > 0).sum() > 100
    assert np.all(exr["under.id"][~skin] == 0) and np.all(exr["under.Z"][skin][named > 0] > 0)
    see = tmp_path / "see"
    assert run_main(["render", str(run), "--out", str(see), "--skin-view", "see-through", "-q"], capsys)[0] == 0
    ex2 = read_exr(see / "frames" / "0022.exr")
    assert "under.id" not in ex2 and not np.isin(ex2["id"], skin_ids).any() and np.isin(ex2["id"], list(muscle_ids)).any()
    off = tmp_path / "off"
    assert run_main(["render", str(run), "--out", str(off), "--skin-view", "off", "-q"], capsys)[0] == 0
    ex3 = read_exr(off / "frames" / "0022.exr")
    assert np.array_equal(ex3["id"], ex2["id"]) and not np.array_equal(ex3["R"], ex2["R"])
