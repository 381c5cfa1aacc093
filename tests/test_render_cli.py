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
