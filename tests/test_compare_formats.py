"""`axdf compare`: mesh readers, topology, EXR channels, tolerance YAML and bad usage."""
from __future__ import annotations

import json

import numpy as np
import pytest

from axdf_cli.cli.main import main
from axdf_cli.compare import thresholds as T
from axdf_cli.compare.images import channel_class, read_exr
from axdf_cli.formats.obj import read_obj
from axdf_cli.formats.ply import read_ply
from compare_helpers import blob, exr_channels, make_run, tube, write_exr, write_obj, write_ply


# ----------------------------------------------------------------------------- mesh readers
def test_ply_and_obj_readers_keep_vertex_order(tmp_path):
    v, n, f = tube(3, 5)
    write_ply(tmp_path / "m.ply", v, n, f)
    write_obj(tmp_path / "m.obj", v, n, f)
    for m in (read_ply((tmp_path / "m.ply").read_bytes()), read_obj((tmp_path / "m.obj").read_bytes())):
        # OBJ text has 9 significant digits: it round-trips float32 exactly
        np.testing.assert_array_equal(m.vertices.astype(np.float32), v)
        np.testing.assert_array_equal(m.normals.astype(np.float32), n)
        np.testing.assert_array_equal(m.face_indices.reshape(-1, 3), f)
        assert np.all(m.face_sizes == 3)
    # a PLY and an OBJ of the same mesh compare equal
    assert main(["compare", str(tmp_path / "m.obj"), str(tmp_path / "m.ply")]) == 0


def test_ply_mixed_polygons_and_ascii(tmp_path):
    text = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 2\nproperty list uchar int vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 2 0\n4 0 1 2 3\n3 3 2 4\n")
    m = read_ply(text.encode())
    assert m.face_sizes.tolist() == [4, 3] and m.face_indices.tolist() == [0, 1, 2, 3, 3, 2, 4]
    assert m.normals is None and m.vertices.shape == (5, 3)


def test_different_topology_is_reported_with_hausdorff(tmp_path, capsys):
    v, n, f = tube(0, 0)
    write_ply(tmp_path / "g.ply", v, n, f)
    v2, n2, f2 = tube(0, 0, along=11)
    write_ply(tmp_path / "a.ply", v2, n2, f2)
    rpt = tmp_path / "r.json"
    assert main(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply"), "--report", str(rpt)]) == 1
    doc = json.loads(rpt.read_text())
    m = doc["files"][0]["metrics"]
    assert m["actual_vertices"] == len(v2) and m["vertices"] == len(v) and m["hausdorff"] > 0
    assert "topology differs" in capsys.readouterr().out
    # same counts, one face rewired
    f3 = f.copy()
    f3[5] = f3[5][[0, 2, 1]]
    write_ply(tmp_path / "a.ply", v, n, f3)
    assert main(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 1
    assert "face 5" in capsys.readouterr().out


def test_flipped_normals_fail(tmp_path):
    v, n, f = tube(0, 0)
    write_ply(tmp_path / "g.ply", v, n, f)
    write_ply(tmp_path / "a.ply", v, -n, f)
    assert main(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 1


def test_truncated_mesh_is_an_error_not_a_crash(tmp_path, capsys):
    v, n, f = tube(0, 0)
    write_ply(tmp_path / "g.ply", v, n, f)
    (tmp_path / "a.ply").write_bytes((tmp_path / "g.ply").read_bytes()[:-100])
    assert main(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 1
    out = capsys.readouterr().out
    assert "ERROR" in out and "actual:" in out


# ----------------------------------------------------------------------------- EXR
def test_exr_channels_and_tolerances(tmp_path):
    img = blob(30, 32, 12)
    ch = exr_channels(img)
    write_exr(tmp_path / "g.exr", ch)
    assert set(read_exr(tmp_path / "g.exr")) == set(ch)
    assert [channel_class(c) for c in ("R", "A", "Z", "N.X", "N.Z", "id", "mask")] == \
        ["color", "color", "depth", "normal", "normal", "id", "other"]
    # depth within 1 mm passes; an id label change over a 10x10 block fails though values are "close"
    near = dict(ch, Z=(ch["Z"] + np.float32(5e-4)).astype(np.float32))
    write_exr(tmp_path / "a.exr", near)
    assert main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "g.exr")]) == 0
    ids = ch["id"].copy()
    ids[25:35, 25:35] = 4
    write_exr(tmp_path / "a.exr", dict(ch, id=ids))
    assert main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "g.exr")]) == 1
    # a missing channel fails
    write_exr(tmp_path / "a.exr", {k: v for k, v in ch.items() if k != "N.Y"})
    assert main(["compare", str(tmp_path / "a.exr"), str(tmp_path / "g.exr")]) == 1


def test_image_size_mismatch_is_reported(tmp_path, capsys):
    from compare_helpers import write_png
    write_png(tmp_path / "a.png", blob(10, 10, 5, size=32))
    write_png(tmp_path / "g.png", blob(10, 10, 5, size=64))
    assert main(["compare", str(tmp_path / "a.png"), str(tmp_path / "g.png")]) == 1
    assert "32x32" in capsys.readouterr().out


# ----------------------------------------------------------------------------- tolerances
def test_tolerance_yaml_overrides_per_pattern(tmp_path):
    golden = make_run(tmp_path / "g", muscles=2, frames=2)
    actual = make_run(tmp_path / "a", muscles=2, frames=2)
    for name in ("m0", "m1"):
        v, n, f = tube(1, int(name[1]))
        write_ply(actual / f"meshes/{name}/{name}_0001.ply", v + np.float32(5e-5), n, f)
    assert main(["compare", str(actual), str(golden)]) == 1
    tol = tmp_path / "tol.yaml"
    tol.write_text("mesh: {rms_distance: 1.0e-4}\noverrides:\n  - match: 'meshes/m0/*'\n"
                   "    mesh: {max_distance: 1.0e-4}\n")
    rpt = tmp_path / "r.json"
    assert main(["compare", str(actual), str(golden), "--tolerances", str(tol), "--report", str(rpt)]) == 1
    doc = json.loads(rpt.read_text())
    assert [f["path"] for f in doc["files"] if f["verdict"] != "pass"] == ["meshes/m1/m1_0001.ply"]
    m0 = next(f for f in doc["files"] if f["path"] == "meshes/m0/m0_0001.ply")
    assert m0["tolerance"]["max_distance"] == 1e-4
    # a flag sets the top level; the pattern override still wins for m0
    assert main(["compare", str(actual), str(golden), "--tolerances", str(tol), "--mesh-max", "1e-3"]) == 0
    assert main(["compare", str(actual), str(golden), "--mesh-max", "1e-3", "--mesh-rms", "1e-3"]) == 0
    # ignore globs
    assert main(["compare", str(actual), str(golden), "--ignore", "meshes/*/*_0001.ply"]) == 0


def test_tolerance_resolution_order():
    tol = T.Tolerances(overrides=(T.Override("*.png", None, {"png": {"threshold": 0.1}}),
                                  T.Override("frames/0001.png", None, {"png": {"threshold": 0.2}})))
    tol = tol.with_flags({"png": {"threshold": 0.05, "fail_fraction": 0.5}})
    assert tol.for_path("frames/0000.png").png.threshold == 0.1
    assert tol.for_path("frames/0001.png").png.threshold == 0.2
    assert tol.for_path("frames/0001.png").png.fail_fraction == 0.5
    assert tol.for_path("stats.csv").png.threshold == 0.05


# ----------------------------------------------------------------------------- bad usage
@pytest.mark.parametrize("yaml_text, where", [
    ("mesh: {max_distanse: 1}\n", ":1:8: unknown key 'max_distanse'"),
    ("png:\n  threshold: 2\n", ":2:14: threshold is 2"),
    ("overrides:\n  - mesh: {max_distance: 1}\n", "override has no 'match'"),
    ("exr:\n  depth: {atol: -1}\n", ":2:17: atol is -1"),
])
def test_bad_tolerance_yaml_is_exit_2_with_position(tmp_path, capsys, yaml_text, where):
    run = make_run(tmp_path / "r", muscles=1, frames=1)
    tol = tmp_path / "tol.yaml"
    tol.write_text(yaml_text)
    rpt = tmp_path / "report.json"
    assert main(["compare", str(run), str(run), "--tolerances", str(tol), "--report", str(rpt)]) == 2
    err = capsys.readouterr().err
    assert f"{tol}" in err and where in err
    assert not rpt.exists()  # nothing written


def test_bad_usage_exit_2(tmp_path, capsys):
    run = make_run(tmp_path / "r", muscles=1, frames=1)
    assert main(["compare", str(tmp_path / "nope"), str(run)]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["compare", str(run), str(run / "stats.csv")]) == 2
    assert "is a folder but GOLDEN" in capsys.readouterr().err
    assert main(["compare", str(run / "stats.csv"), str(run / "camera.json")]) == 2
    assert main(["compare", str(run), str(run), "--report", str(tmp_path)]) == 2
    assert main(["compare", str(run), str(run), "--fail-fraction", "2"]) == 2
    assert main(["compare", str(run), str(tmp_path / "nope"), "--tolerances", str(tmp_path / "no.yaml")]) == 2


def test_readme_tolerance_example_loads(tmp_path):
    from pathlib import Path
    readme = (Path(__file__).parents[1] / "docs" / "COMPARE.md").read_text()
    block = readme.split("## Tolerance file", 1)[1].split("```yaml\n", 1)[1].split("```", 1)[0]
    (tmp_path / "tol.yaml").write_text(block)
    tol = T.load_tolerances(tmp_path / "tol.yaml")
    assert tol.base == T.FileTol(png=T.PngTol(threshold=0.0196), exr=T.ExrTol(color=T.ChannelTol(0.0196, 0.02)))
    assert tol.for_path("meshes/tiny_a/tiny_a_0001.ply").mesh.max_distance == 1e-4
    assert tol.ignored("logs/run.log")


def test_update_of_one_file_and_quiet_output(tmp_path, capsys):
    v, n, f = tube(0, 0)
    write_ply(tmp_path / "g.ply", v, n, f)
    write_ply(tmp_path / "a.ply", v + np.float32(1e-3), n, f)
    assert main(["compare", "-q", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 1
    out = capsys.readouterr().out
    assert out.splitlines()[0] == "  FAIL    g.ply" and out.splitlines()[-1].startswith("DIFFERENT: 1 of 1 files")
    assert main(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply"), "--update"]) == 0
    assert "replaced" in capsys.readouterr().out
    assert (tmp_path / "g.ply").read_bytes() == (tmp_path / "a.ply").read_bytes()
    assert main(["compare", "-q", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 1 and lines[0].startswith("SAME: 1 files within tolerance (1 identical)")
