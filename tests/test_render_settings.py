import argparse

import pytest

from axdf_cli.errors import InputError, Mark
from axdf_cli.specs.render import (RenderSettings, add_render_args, parse_render_settings,
                                      settings_from_args)
from axdf_cli.fileio.yamlio import parse_yaml


def parse(text: str) -> RenderSettings:
    doc = parse_yaml(text, "job.yaml")
    return parse_render_settings(doc["render"], Mark("job.yaml"))


def test_defaults_and_absent():
    assert parse_render_settings(None, Mark("job.yaml")) == RenderSettings()
    s = parse("render: {}\n")
    assert s.enabled and s.size == (640, 480) and s.view == "auto" and s.supersample == 3


def test_all_keys():
    s = parse("render:\n  enabled: true\n  size: [320, 240]\n  view: sheet\n  orbit: 2.5\n"
              "  wireframe: true\n  background: transparent\n  bones: false\n  supersample: 2\n"
              "  device: 1\n  fov: 40\n")
    assert s.size == (320, 240) and s.view == "sheet" and s.orbit == 2.5 and s.wireframe
    assert s.transparent and not s.bones and s.supersample == 2 and s.device == 1 and s.fov == 40
    s = parse("render:\n  camera: {position: [0, -2, 1], target: [0, 0, 1], fov: 25}\n  background: [1, 0, 0]\n")
    assert s.camera.position == (0, -2, 1) and s.camera.up == (0, 0, 1) and s.camera.fov == 25
    assert s.background == (1, 0, 0, 1)
    # a bone target: both spellings; a position, an offset or neither (the camera follows)
    for text in ("bone:humerus_r", "{bone: humerus_r}"):
        s = parse(f"render:\n  camera: {{target: {text}}}\n")
        assert s.camera.target_bone == "humerus_r" and s.camera.position is None and s.camera.follows
    s = parse("render:\n  camera: {target: bone:ulna_r, offset: [0.4, -1, 0.3]}\n")
    assert s.camera.offset == (0.4, -1, 0.3) and s.camera.follows
    s = parse("render:\n  camera: {target: bone:ulna_r, position: [0, -3, 1]}\n")
    assert not s.camera.follows


@pytest.mark.parametrize("text, where, words", [
    ("render:\n  sise: [1, 2]\n", "job.yaml:2:3", "unknown key 'sise'"),
    ("render:\n  size: [100]\n", "job.yaml:2:9", "exactly 2"),
    ("render:\n  view: back\n", "job.yaml:2:9", "front"),
    ("render:\n  supersample: 0\n", "job.yaml:2:16", "supersample"),
    ("render:\n  background: [2, 0, 0]\n", "job.yaml:2:16", "background"),
    ("render:\n  device: gpu\n", "job.yaml:2:11", "device"),
    ("render:\n  view: front\n  camera: {position: [0, 0, 1], target: [0, 0, 0]}\n", "job.yaml:3:3", "not both"),
    ("render:\n  camera: {position: [0, 0, 1], target: [0, 0, 0]}\n", "job.yaml:2:22", "parallel"),
    ("render:\n  camera: {target: [0, 0, 0]}\n", "job.yaml:2:11", "position"),
    ("render:\n  camera: {target: [0, 0, 0], offset: [1, 0, 0]}\n", "job.yaml:2:39", "without a bone target"),
    ("render:\n  camera: {target: bone:a, position: [1, 0, 0], offset: [1, 0, 0]}\n", "job.yaml:2:57", "both"),
    ("render:\n  camera: {target: {bone: 'a b'}}\n", "job.yaml:2:20", "bone:NAME"),
    ("render:\n  camera: {target: humerus}\n", "job.yaml:2:20", "bone:NAME"),
])
def test_errors_have_positions(text, where, words):
    with pytest.raises(InputError) as e:
        parse(text)
    assert str(e.value).startswith(where + ":"), str(e.value)
    assert words in str(e.value)


def test_flags_override():
    p = argparse.ArgumentParser()
    add_render_args(p)
    s = settings_from_args(RenderSettings(), p.parse_args(
        ["--size", "512x256", "--view", "top", "--wireframe", "--no-bones", "--background", "0,0,1",
         "--supersample", "1", "--orbit", "3", "--device", "0"]))
    assert s.size == (512, 256) and s.view == "top" and s.wireframe and not s.bones
    assert s.background == (0, 0, 1, 1) and s.supersample == 1 and s.orbit == 3 and s.device == 0
    assert settings_from_args(RenderSettings(), p.parse_args([])) == RenderSettings()
    for bad in (["--size", "512"], ["--background", "red"], ["--supersample", "9"], ["--device", "x"]):
        with pytest.raises(InputError) as e:  # named by the flag, as a YAML error by its position
            settings_from_args(RenderSettings(), p.parse_args(bad))
        assert str(e.value).startswith(bad[0] + ": "), str(e.value)
