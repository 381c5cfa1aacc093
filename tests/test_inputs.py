"""Inputs accepted silently or refused wrongly, the explicit path policy
and validate = run's planning. Small synthetic projects in tmp folders; the CLI is
called in process."""
from __future__ import annotations

import csv
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML, REPO_ROOT, run_main

RANGED_SKELETON = CHAIN_SKELETON_YAML.replace(
    "  bend: {type: rotation, default: 0}\n", "  bend: {type: rotation, default: 0}\n").replace(
    "      - {coord: bend, type: rotation, axis: [1, 0, 0]}",
    "      - {coord: bend, type: rotation, axis: [1, 0, 0], range: [-140, 0]}")


def _pose(keys: dict, frames=(0, 4), extra: str = "") -> str:
    lines = ["pose: p", "skeleton: chain.yaml", f"frames: [{frames[0]}, {frames[1]}]", "keys:"]
    lines += [f"  {f}: {{{', '.join(f'{c}: {v}' for c, v in kv.items())}}}" for f, kv in keys.items()]
    return "\n".join(lines) + "\n" + extra


@pytest.fixture
def proj(tmp_path, monkeypatch):
    """A project folder (the current folder): chain.yaml with a ranged bend, m/chainm.yaml, p.yaml."""
    (tmp_path / "chain.yaml").write_text(RANGED_SKELETON)
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    (tmp_path / "p.yaml").write_text(_pose({0: {"bend": 0}, 4: {"bend": -60}}))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _error_at(err: str, path: Path | str, text: str, needle: str) -> None:
    """``err`` names FILE:LINE:COL of ``needle``'s first line in ``text``."""
    line = text[: text.index(needle)].count("\n") + 1
    assert re.search(re.escape(str(path)) + rf":{line}:\d+: ", err), err
    assert "Traceback" not in err


# ----------------------------------------------------------------------------- activation names


def test_misspelt_activation_is_a_warning_naming_the_muscle_and_strict_refuses_it(proj, capsys):
    (proj / "p.yaml").write_text(_pose({0: {"bend": 0}, 4: {"bend": -60}}, extra="activation:\n  chainn: {0: 0, 4: 1}\n"))
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o", "--no-render"], capsys)
    assert rc == 0
    assert "warning:" in err and "'chainn'" in err and "did you mean 'chainm'" in err
    assert any("chainn" in w for w in json.loads((proj / "o" / "manifest.json").read_text())["warnings"])
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o2", "--no-render", "--strict"],
                          capsys)
    assert rc == 2 and "--strict" in err and "chainm" in err
    assert not (proj / "o2").exists()  # refused before anything is written
    rc, _, err = run_main(["validate", "--strict", "m/chainm.yaml", "p.yaml"], capsys)
    assert rc == 2 and "did you mean 'chainm'" in err


def test_activation_of_another_muscle_set_stays_a_note(proj, capsys):
    """A pose shared by several muscle sets names muscles that are not in this run."""
    (proj / "p.yaml").write_text(_pose({0: {"bend": 0}}, extra="activation:\n  soleus_r: {0: 1}\n"))
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o", "--no-render", "--strict", "-v"],
                          capsys)
    assert rc == 0, err
    assert "note:" in err and "soleus_r" in err and "warning" not in err


# ----------------------------------------------------------------------------- ranges


def _stats(out: Path) -> list[dict]:
    return list(csv.DictReader((out / "stats.csv").open()))


def test_coordinate_outside_its_dof_range_warns_per_frame(proj, capsys):
    (proj / "p.yaml").write_text(_pose({0: {"bend": 0}, 4: {"bend": -400}}))
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o", "--no-render"], capsys)
    assert rc == 0, err
    # bend(f) = -100 f: frames 2, 3, 4 lie outside [-140, 0]
    rows = _stats(proj / "o")
    warned = {int(r["frame"]) for r in rows if "outside its range [-140, 0]" in r["warning"]}
    assert warned == {2, 3, 4}
    assert "bend = -400" in rows[4]["warning"]
    manifest = json.loads((proj / "o" / "manifest.json").read_text())
    assert sum("bend = " in w for w in manifest["warnings"]) == 3
    assert "warning: bend is outside its range [-140, 0] in 3 of 5 frames: 2-4 (keyed -400 to -200" in err, err
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o2", "--no-render", "--strict"],
                          capsys)
    assert rc == 2 and "bend = -200" in err and not (proj / "o2").exists()


def test_clamp_ranges_flag_and_pose_key_hold_the_range_end(proj, capsys):
    from axdf_cli.formats.ply import read_ply

    (proj / "p.yaml").write_text(_pose({0: {"bend": 0}, 4: {"bend": -400}}))
    (proj / "edge.yaml").write_text(_pose({0: {"bend": -140}}).replace("pose: p", "pose: edge"))
    assert run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "c", "--no-render", "--clamp-ranges",
                     "--strict"], capsys)[0] == 0
    assert all(r["warning"] == "" for r in _stats(proj / "c"))
    assert run_main(["run", "--muscles", "m", "--pose", "edge.yaml", "--out", "e", "--no-render"], capsys)[0] == 0
    held = read_ply((proj / "c" / "meshes" / "chainm" / "chainm_0004.ply").read_bytes()).vertices
    edge = read_ply((proj / "e" / "meshes" / "chainm" / "chainm_0000.ply").read_bytes()).vertices
    np.testing.assert_allclose(held, edge, atol=1e-6)  # -400 is held at -140
    (proj / "k.yaml").write_text(_pose({0: {"bend": 0}, 4: {"bend": -400}}, extra="clamp_ranges: true\n"))
    assert run_main(["run", "--muscles", "m", "--pose", "k.yaml", "--out", "k", "--no-render", "--strict"],
                    capsys)[0] == 0
    assert (proj / "k" / "meshes" / "chainm" / "chainm_0004.ply").read_bytes() == \
        (proj / "c" / "meshes" / "chainm" / "chainm_0004.ply").read_bytes()


def test_ranges_of_a_coordinate_intersect_and_must_be_ordered(tmp_path):
    from axdf_cli.errors import InputError
    from axdf_cli.specs import load_skeleton

    p = tmp_path / "s.yaml"
    p.write_text(RANGED_SKELETON.replace("  bend: {type: rotation, default: 0}",
                                         "  bend: {type: rotation, default: 0, range: [-90, 30]}"))
    assert load_skeleton(p).coordinates[1].range == (-90.0, 0.0)
    p.write_text(RANGED_SKELETON.replace("range: [-140, 0]", "range: [0, -140]"))
    with pytest.raises(InputError, match=r"range is \[0.0, -140.0\]"):
        load_skeleton(p)


# ----------------------------------------------------------------------------- keys outside frames


@pytest.mark.parametrize("extra, needle", [
    ("", "  9: {bend: -10}"),
    ("activation:\n  chainm: {0: 0, 7: 1}\n", "7: 1"),
])
def test_keys_outside_the_pose_frames_are_refused_with_position(proj, capsys, extra, needle):
    text = _pose({0: {"bend": 0}, 4: {"bend": -60}}) + ("  9: {bend: -10}\n" if not extra else "") + extra
    (proj / "p.yaml").write_text(text)
    rc, _, err = run_main(["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o", "--no-render"], capsys)
    assert rc == 2 and "outside the pose's frames [0, 4]" in err
    _error_at(err, "p.yaml", text, needle)
    assert not (proj / "o").exists()


# ----------------------------------------------------------------------------- misspelt keys


def test_misspelt_key_is_reported_as_unknown_with_the_nearest_key(proj, capsys):
    text = CHAIN_MUSCLE_YAML.replace("{t: 0.2, radii: [0.02, 0.015], angle: 0}", "{t: 0.2, radius: [0.02, 0.015]}")
    (proj / "m" / "chainm.yaml").write_text(text)
    rc, _, err = run_main(["validate", "m/chainm.yaml"], capsys)
    assert rc == 2 and "unknown key 'radius' in section" in err and "did you mean 'radii'" in err, err
    _error_at(err, "m/chainm.yaml", text, "radius")
    # unknown keys come before missing ones, even far from any allowed key
    (proj / "m" / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML.replace("radii: [0.02, 0.015], angle: 0", "zzz: 1"))
    rc, _, err = run_main(["validate", "m/chainm.yaml"], capsys)
    assert rc == 2 and "unknown key 'zzz'" in err and "has no" not in err


@pytest.mark.parametrize("command", ["validate", "run"])
def test_misspelt_kind_key_names_the_key(proj, capsys, command):
    text = CHAIN_MUSCLE_YAML.replace("muscle: chainm", "muscel: chainm")
    (proj / "m" / "chainm.yaml").write_text(text)
    argv = ["validate", "m/chainm.yaml"] if command == "validate" else \
        ["run", "--muscles", "m", "--pose", "p.yaml", "--out", "o", "--no-render"]
    rc, _, err = run_main(argv, capsys)
    assert rc == 2 and "unknown key 'muscel'" in err and "did you mean 'muscle'" in err, err
    _error_at(err, "m/chainm.yaml", text, "muscel")


def test_fields_suggest_in_done_and_schema_first():
    from axdf_cli.errors import InputError
    from axdf_cli.fileio.yamlio import Fields, parse_yaml

    doc = parse_yaml("a: 1\ncolour: 2\n", "x.yaml")
    f = Fields(doc, None, "thing")
    f.number("a")
    f.raw("color")
    with pytest.raises(InputError, match=r"x.yaml:2:1: unknown key 'colour' in thing; did you mean 'color'\?"):
        f.done()
    with pytest.raises(InputError, match="unknown key 'colour'"):
        Fields(doc, None, "thing", keys=("a", "color", "b"))


# ----------------------------------------------------------------------------- validate = run's planning


def _job(proj: Path, render: str = "") -> Path:
    job = proj / "job.yaml"
    job.write_text("muscles: m\npose: p.yaml\nout: o\n" + render)
    return job


def test_validate_refuses_the_render_block_run_refuses(proj, capsys):
    _job(proj, "render:\n  size: [8, 8]\n")
    rc_v, _, err_v = run_main(["validate", "job.yaml"], capsys)
    rc_r, _, err_r = run_main(["run", "job.yaml"], capsys)
    assert rc_v == rc_r == 2
    assert err_v.strip() == err_r.strip() and err_v.startswith("job.yaml:5:")
    assert not (proj / "o").exists()


def test_validate_cross_checks_muscles_on_the_pose_bones(proj, capsys):
    (proj / "m" / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML.replace("{bone: b4,", "{bone: b5,"))
    rc, out, err = run_main(["validate", "m/chainm.yaml", "p.yaml"], capsys)
    assert rc == 2 and "unknown bone 'b5'" in err
    assert "m/chainm.yaml: ok" in out and "p.yaml: ok" in out  # each alone is fine


@pytest.mark.parametrize("mesh", [
    b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
    b"element face 0\nproperty list uchar int vertex_indices\nend_header\n",
    b"ply\nformat binary_little_endian 1.0\nelement vertex 9\nproperty float x\nend_header\n\x00",
], ids=["empty", "truncated"])
def test_corrupt_bone_mesh_is_bad_input_for_validate_and_run(proj, capsys, mesh):
    (proj / "bone.ply").write_bytes(mesh)
    (proj / "chain.yaml").write_text(RANGED_SKELETON.replace("  - name: b1\n", "  - name: b1\n    mesh: bone.ply\n"))
    _job(proj, "render: {size: [32, 32]}\n")
    for argv in (["validate", "job.yaml"], ["validate", "chain.yaml"], ["validate", "p.yaml"], ["run", "job.yaml"]):
        rc, _, err = run_main(argv, capsys)
        assert rc == 2, (argv, err)
        assert "bone.ply" in err and "internal error" not in err
    assert not (proj / "o").exists()


def test_overlong_names_are_refused_before_anything_is_written(proj, capsys):
    long = "m" * 250
    (proj / "m" / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML.replace("muscle: chainm", f"muscle: {long}"))
    _job(proj)
    rc, _, err = run_main(["validate", "job.yaml"], capsys)
    assert rc == 2 and "at most 200 characters" in err
    rc, _, err = run_main(["run", "job.yaml"], capsys)
    assert rc == 2 and not (proj / "o").exists()


def test_longest_name_gives_file_names_that_fit():
    """Every file a run writes, under its temporary name too, fits 255 bytes."""
    from axdf_cli.fileio import atomic
    from axdf_cli.fileio.runfolder import bone_mesh_relpath, mesh_relpath
    from axdf_cli.fileio.yamlio import NAME_MAX

    name = "n" * NAME_MAX
    for rel in (mesh_relpath(name, 10_000_000, "ply"), mesh_relpath(name, 10_000_000, "obj"),
                bone_mesh_relpath(name)):
        tmp = f"{atomic.TMP_PREFIX}{4 * 1024 * 1024}-{Path(rel).name}"  # pid_max is at most 2^22
        assert len(tmp.encode()) <= 255, len(tmp)


# ----------------------------------------------------------------------------- path policy


def test_files_named_on_the_command_line_are_trusted_from_anywhere(proj, tmp_path_factory, monkeypatch, capsys):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    monkeypatch.chdir(elsewhere)
    rc, _, err = run_main(["run", "--muscles", proj / "m", "--pose", proj / "p.yaml", "--out", "o", "--no-render"],
                          capsys)
    assert rc == 0, err  # the skeleton beside the pose, the current folder elsewhere
    rc, _, err = run_main(["validate", proj / "p.yaml", proj / "m" / "chainm.yaml"], capsys)
    assert rc == 0, err


def test_shipped_skeleton_from_a_users_own_folder(tmp_path, monkeypatch, capsys):
    shipped = REPO_ROOT / "poses" / "skeletons" / "human_r.yaml"
    (tmp_path / "mine.yaml").write_text(f"pose: mine\nskeleton: {os.path.relpath(shipped, tmp_path)}\n"
                                        "frames: [0, 1]\nkeys:\n  1: {elbow_flexion_r: 30}\n")
    (tmp_path / "abs.yaml").write_text(f"pose: abs\nskeleton: {shipped}\nframes: [0, 1]\nkeys:\n  0: {{}}\n")
    monkeypatch.chdir(tmp_path)
    for pose in ("mine.yaml", "abs.yaml"):
        rc, _, err = run_main(["run", "--muscles", REPO_ROOT / "muscles" / "demo" / "biceps_brachii.yaml",
                               "--pose", pose, "--out", f"o-{pose}", "--no-render"], capsys)
        assert rc == 0, err


@pytest.mark.parametrize("entry", ["lib", "lib/*.yaml", "lib/**/*.yaml"])
def test_symlink_out_of_the_tree_is_refused_in_folders_and_globs(tmp_path_factory, monkeypatch, capsys, entry):
    proj = tmp_path_factory.mktemp("proj")
    outside = tmp_path_factory.mktemp("outside")
    (outside / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    (proj / "chain.yaml").write_text(RANGED_SKELETON)
    (proj / "p.yaml").write_text(_pose({0: {"bend": 0}}))
    (proj / "lib").mkdir()
    (proj / "lib" / "chainm.yaml").symlink_to(outside / "chainm.yaml")
    (proj / "job.yaml").write_text(f"muscles: {entry}\npose: p.yaml\nout: o\n")
    (proj / "direct.yaml").write_text(f"muscles: {outside / 'chainm.yaml'}\npose: p.yaml\nout: o\n")
    monkeypatch.chdir(proj)
    for job in ("job.yaml", "direct.yaml"):
        rc, _, err = run_main(["run", job, "--no-render"], capsys)
        assert rc == 2 and "leaves the project folder tree" in err and f"{job}:1:" in err, err
        assert not (proj / "o").exists()
    rc, _, err = run_main(["run", "job.yaml", "--no-render", "--allow-outside"], capsys)
    assert rc == 0, err


def test_policy_is_an_argument_not_global_state(proj):
    from axdf_cli.errors import InputError
    from axdf_cli.specs import RefPolicy, load_pose

    (proj / "sub").mkdir()
    (proj / "sub" / "p.yaml").write_text(_pose({0: {"bend": 0}}).replace("skeleton: chain.yaml",
                                                                         "skeleton: ../chain.yaml"))
    with pytest.raises(InputError, match="leaves the project folder tree"):
        load_pose(proj / "sub" / "p.yaml", RefPolicy((proj / "sub",)))
    assert load_pose(proj / "sub" / "p.yaml", RefPolicy((proj,))).skeleton.name == "chain"
    assert load_pose(proj / "sub" / "p.yaml", RefPolicy((proj / "sub",), allow_outside=True))
    import axdf_cli.specs as loaders

    assert not hasattr(loaders, "POLICY") and not hasattr(loaders, "set_ref_policy")


# ----------------------------------------------------------------------------- job keys


def test_job_out_is_relative_to_the_job(proj, tmp_path_factory, monkeypatch, capsys):
    (proj / "jobs").mkdir()
    (proj / "jobs" / "j.yaml").write_text("muscles: ../m\npose: ../p.yaml\nout: ../results/a\n")
    elsewhere = tmp_path_factory.mktemp("cwd")
    monkeypatch.chdir(elsewhere)
    rc, _, err = run_main(["run", proj / "jobs" / "j.yaml", "--no-render"], capsys)
    assert rc == 2 and "leaves the project folder tree" in err  # ../results is outside jobs/ and the cwd
    monkeypatch.chdir(proj)
    rc, _, err = run_main(["run", "jobs/j.yaml", "--no-render"], capsys)
    assert rc == 0, err
    assert (proj / "results" / "a" / "manifest.json").is_file()
    assert not (proj / "jobs" / "results").exists()


@pytest.mark.parametrize("frames, expect", [("[1, 3]", [1, 2, 3]), ('"1:3"', [1, 2, 3]), ('"1,3"', [1, 3]),
                                            ("2", [2])])
def test_job_frames_list_is_a_range_as_in_a_pose(proj, frames, expect):
    from axdf_cli.specs import load_job
    from axdf_cli.pipeline import plan_run

    (proj / "job.yaml").write_text(f"muscles: m\npose: p.yaml\nframes: {frames}\n")
    assert plan_run(load_job(proj / "job.yaml")).frames.tolist() == expect


def test_job_frames_list_of_three_is_refused(proj, capsys):
    (proj / "job.yaml").write_text("muscles: m\npose: p.yaml\nframes: [1, 2, 3]\n")
    rc, _, err = run_main(["validate", "job.yaml"], capsys)
    assert rc == 2 and err.startswith("job.yaml:3:9:") and "'1,2,3'" not in err and "[first, last]" in err


# ----------------------------------------------------------------------------- render settings


def test_job_render_block_is_parsed_by_the_loader(proj):
    from axdf_cli.specs import load_job
    from axdf_cli.specs.render import RenderSettings

    job = load_job(_job(proj, "render:\n  size: 96x64\n  fov: 20\n"))
    assert isinstance(job.render, RenderSettings) and job.render.enabled
    assert job.render.size == (96, 64) and job.render.fov == 20
    assert load_job(_job(proj)).render == RenderSettings()


@pytest.mark.parametrize("flag, yaml_value", [("96x64", "[96, 64]"), ("[96, 64]", "96x64"), ("96,64", "96x64")])
def test_size_in_either_spelling_in_both_places(flag, yaml_value):
    import argparse

    from axdf_cli.errors import Mark
    from axdf_cli.specs.render import RenderSettings, add_render_args, parse_render_settings, settings_from_args
    from axdf_cli.fileio.yamlio import parse_yaml

    p = argparse.ArgumentParser()
    add_render_args(p)
    assert settings_from_args(RenderSettings(), p.parse_args(["--size", flag])).size == (96, 64)
    doc = parse_yaml(f"render:\n  size: {yaml_value}\n", "j.yaml")
    assert parse_render_settings(doc["render"], Mark("j.yaml")).size == (96, 64)


@pytest.mark.parametrize("key, bad", [("fov", "200"), ("size", "8x8"), ("supersample", "9"), ("orbit", "400"),
                                      ("background", "[2, 0, 0]")])
def test_one_table_of_ranges_for_yaml_and_flags(key, bad):
    """The same value is refused with the same words from the job file and from a flag."""
    import argparse

    from axdf_cli.errors import InputError, Mark
    from axdf_cli.specs.render import RenderSettings, add_render_args, parse_render_settings, settings_from_args
    from axdf_cli.fileio.yamlio import parse_yaml

    p = argparse.ArgumentParser()
    add_render_args(p)
    with pytest.raises(InputError) as flag_err:
        settings_from_args(RenderSettings(), p.parse_args([f"--{key}", bad]))
    with pytest.raises(InputError) as yaml_err:
        parse_render_settings(parse_yaml(f"render:\n  {key}: {bad}\n", "j.yaml")["render"], Mark("j.yaml"))
    assert str(flag_err.value).startswith(f"--{key}: ")
    assert str(flag_err.value).split(": ", 1)[1] == str(yaml_err.value).split(": ", 1)[1]


def test_camera_flags(proj):
    import argparse

    from axdf_cli.errors import InputError
    from axdf_cli.specs.render import RenderSettings, add_render_args, settings_from_args

    p = argparse.ArgumentParser()
    add_render_args(p)
    s = settings_from_args(RenderSettings(), p.parse_args(["--camera-position=1,-2,0.5", "--camera-target",
                                                           "[0, 0, 0.5]", "--fov", "25"]))
    assert s.camera.position == (1, -2, 0.5) and s.camera.target == (0, 0, 0.5) and s.camera.fov == 25
    s = settings_from_args(RenderSettings(), p.parse_args(["--camera-position=1,-2,0.5"]))
    assert s.camera.target is None  # the centre of the automatic framing
    for bad in (["--camera-target", "0,0,0"], ["--camera-position", "0,0,1", "--camera-target", "0,0,0"],
                ["--camera-position", "1,2"], ["--view", "top", "--camera-position", "0,-1,0"]):
        with pytest.raises(InputError):
            settings_from_args(RenderSettings(), p.parse_args(bad))
