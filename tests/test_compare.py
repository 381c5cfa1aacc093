"""`axdf compare`: verdicts on synthetic run folders, in process through the CLI."""
from __future__ import annotations

import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from axdf_cli.cli.main import main
from axdf_cli.compare import thresholds as T
from axdf_cli.compare.images import read_exr
from compare_helpers import (SIZE, blob, exr_channels, make_run, tree_bytes, tube, write_exr, write_obj,
                             write_png, write_ply)


@pytest.fixture()
def runs(tmp_path):
    golden = make_run(tmp_path / "golden")
    actual = make_run(tmp_path / "actual")
    return actual, golden


def _report(tmp_path, actual, golden, *extra):
    rpt = tmp_path / "out" / "report.json"
    code = main(["compare", str(actual), str(golden), "--report", str(rpt), *extra])
    return code, json.loads(rpt.read_text())


def _failing(doc):
    return sorted(f["path"] for f in doc["files"] if f["verdict"] != "pass")


def _read_ply_vertices(path: Path):
    from axdf_cli.formats.ply import read_ply
    return read_ply(path.read_bytes())


# ----------------------------------------------------------------------------- whole runs
def test_identical_folders_pass(runs, tmp_path, capsys):
    actual, golden = runs
    code, doc = _report(tmp_path, actual, golden)
    assert code == 0
    assert doc["verdict"] == "same" and _failing(doc) == []
    assert "SAME" in capsys.readouterr().out


def test_json_report_lists_every_file(runs, tmp_path):
    actual, golden = runs
    (actual / "notes.txt").write_text("extra")
    (golden / "old.txt").write_text("gone")
    code, doc = _report(tmp_path, actual, golden)
    assert code == 1
    listed = [f["path"] for f in doc["files"]]
    expected = sorted(set(tree_bytes(actual)) | set(tree_bytes(golden)))
    assert listed == expected
    verdicts = {f["path"]: f["verdict"] for f in doc["files"]}
    assert verdicts["notes.txt"] == "extra" and verdicts["old.txt"] == "missing"
    assert doc["counts"]["total"] == len(expected)
    for f in doc["files"]:
        assert set(f) >= {"path", "kind", "verdict", "reasons", "metrics", "tolerance"}


def test_vertex_moved_by_twice_the_tolerance_fails_that_file_only(runs, tmp_path, capsys):
    actual, golden = runs
    target = actual / "meshes/m1/m1_0002.ply"
    v, n, f = tube(2, 1)
    v = v.astype(np.float64)
    v[7, 1] += 2 * T.MESH_MAX_DISTANCE
    write_ply(target, v.astype(np.float32), n, f)
    moved = np.linalg.norm(_read_ply_vertices(target).vertices[7] - _read_ply_vertices(
        golden / "meshes/m1/m1_0002.ply").vertices[7])
    assert 1.5 * T.MESH_MAX_DISTANCE < moved < 2.5 * T.MESH_MAX_DISTANCE  # float32 rounding
    code, doc = _report(tmp_path, actual, golden)
    assert code == 1
    assert _failing(doc) == ["meshes/m1/m1_0002.ply"]
    bad = next(f for f in doc["files"] if f["verdict"] != "pass")
    assert bad["metrics"]["worst_vertex"] == 7
    assert bad["metrics"]["max_distance"] == pytest.approx(moved, rel=1e-6)
    out = capsys.readouterr().out
    assert "meshes/m1/m1_0002.ply" in out and "max vertex distance" in out


def test_vertex_moved_within_tolerance_passes(runs, tmp_path):
    actual, golden = runs
    v, n, f = tube(0, 0)
    v = v.astype(np.float64)
    v[3, 2] += 0.4 * T.MESH_MAX_DISTANCE
    write_ply(actual / "meshes/m0/m0_0000.ply", v.astype(np.float32), n, f)
    code, doc = _report(tmp_path, actual, golden)
    assert code == 0
    entry = next(f for f in doc["files"] if f["path"] == "meshes/m0/m0_0000.ply")
    assert entry["metrics"]["identical"] is False and 0 < entry["metrics"]["max_distance"] < T.MESH_MAX_DISTANCE


def test_missing_file_fails_and_is_named(runs, tmp_path, capsys):
    actual, golden = runs
    (actual / "frames/0002.png").unlink()
    code = main(["compare", str(actual), str(golden)])
    out = capsys.readouterr().out
    assert code == 1
    assert "MISSING" in out and "frames/0002.png" in out


def test_one_changed_pixel_passes_within_the_allowed_fraction(runs, tmp_path):
    actual, golden = runs
    img = blob(SIZE * 0.45 + 1, SIZE * 0.5, SIZE * 0.2)
    img[10, 12] = [1, 1, 1, 1]  # full contrast, one pixel of 4096
    write_png(actual / "frames/0001.png", img)
    code, doc = _report(tmp_path, actual, golden)
    assert code == 0
    entry = next(f for f in doc["files"] if f["path"] == "frames/0001.png")
    assert entry["metrics"]["failing_pixels"] == 1
    # PSNR for every image; FLIP (costly) only for failing ones
    assert entry["metrics"]["psnr_db"] is not None and entry["metrics"]["flip_mean"] is None


def test_muscle_shifted_by_two_pixels_fails_with_a_diff_picture(runs, tmp_path):
    actual, golden = runs
    g = np.asarray(Image.open(golden / "frames/0003.png"))
    Image.fromarray(np.roll(g, 2, axis=1)).save(actual / "frames/0003.png")
    ch = read_exr(golden / "frames/0003.exr")
    write_exr(actual / "frames/0003.exr", {k: np.roll(v, 2, axis=1) for k, v in ch.items()})
    code, doc = _report(tmp_path, actual, golden)
    assert code == 1
    assert _failing(doc) == ["frames/0003.exr", "frames/0003.png"]
    for path in ("frames/0003.png", "frames/0003.exr"):
        entry = next(f for f in doc["files"] if f["path"] == path)
        assert entry["metrics"]["failing_fraction"] > 10 * T.FAIL_FRACTION
        assert entry["metrics"]["flip_mean"] > 0
        pic = Path(entry["diff_picture"])
        assert pic.is_file() and pic.parent.parent.name == "report-diffs"
        arr = np.asarray(Image.open(pic))
        assert arr.shape == (SIZE, 3 * SIZE + 8, 3)


def test_llvmpipe_like_noise_passes(runs, tmp_path):
    """Shading off by up to 2/255 everywhere and 3 silhouette pixels flipped: must pass."""
    actual, golden = runs
    rng = np.random.default_rng(7)
    g = np.asarray(Image.open(golden / "frames/0000.png")).astype(int)
    noise = rng.integers(-2, 3, g.shape)
    noise[..., 3] = 0
    a = np.clip(g + noise, 0, 255)
    edge = np.argwhere((g[..., 3] > 0) & (np.roll(g[..., 3], 1, axis=1) == 0))[:3]
    a[edge[:, 0], edge[:, 1]] = 0
    Image.fromarray(a.astype(np.uint8)).save(actual / "frames/0000.png")
    code, doc = _report(tmp_path, actual, golden)
    assert code == 0, _failing(doc)


def test_junit_parses_and_counts_match(runs, tmp_path):
    actual, golden = runs
    (actual / "stats.csv").write_text((actual / "stats.csv").read_text().replace("0.301", "0.401"))
    (actual / "frames/0001.exr").unlink()
    (actual / "frames/0002.png").write_bytes(b"not a png")
    junit = tmp_path / "junit.xml"
    code = main(["compare", str(actual), str(golden), "--junit", str(junit)])
    assert code == 1
    root = ET.parse(junit).getroot()
    suite = root.find("testsuite")
    cases = suite.findall("testcase")
    n_files = len(set(tree_bytes(actual)) | set(tree_bytes(golden)))
    assert int(suite.get("tests")) == len(cases) == n_files == int(root.get("tests"))
    failures = [c for c in cases if c.find("failure") is not None]
    errors = [c for c in cases if c.find("error") is not None]
    assert int(suite.get("failures")) == len(failures) == 2
    assert int(suite.get("errors")) == len(errors) == 1
    assert {c.get("name") for c in failures} == {"stats.csv", "frames/0001.exr"}
    assert errors[0].get("name") == "frames/0002.png"


def test_update_makes_golden_equal_to_actual(runs, tmp_path, capsys):
    actual, golden = runs
    v, n, f = tube(1, 2)
    write_ply(actual / "meshes/m2/m2_0001.ply", v + 0.01, n, f)
    (actual / "frames/0003.png").unlink()
    (actual / "new.txt").write_text("new\n")
    code = main(["compare", str(actual), str(golden), "--update"])
    out = capsys.readouterr().out
    assert code == 0
    assert tree_bytes(golden) == tree_bytes(actual)
    assert "replaced" in out and "meshes/m2/m2_0001.ply" in out and "beyond tolerance" in out
    assert "removed" in out and "frames/0003.png" in out
    assert "added" in out and "new.txt" in out
    assert main(["compare", str(actual), str(golden)]) == 0


@pytest.mark.parametrize("stop", [KeyboardInterrupt, OSError])
def test_an_interrupted_update_leaves_golden_as_it_was(runs, tmp_path, capsys, monkeypatch, stop):
    """Ctrl-C (or a read error) while --update writes its new files: GOLDEN keeps every old
    byte, gains no file, loses none, and no temporary is left; the update then completes."""
    from axdf_cli.compare import bless

    actual, golden = runs
    v, n, f = tube(1, 2)
    write_ply(actual / "meshes/m2/m2_0001.ply", v + 0.01, n, f)
    (actual / "frames/0003.png").unlink()
    (actual / "new/deep.txt").parent.mkdir()
    (actual / "new/deep.txt").write_text("new\n")
    before = tree_bytes(golden)
    real = bless.read_compared

    def breaks(path, root):
        if Path(path).name == "deep.txt":  # the last file: meshes/m2/m2_0001.ply is written by now
            raise stop("stopped")
        return real(path, root)

    monkeypatch.setattr(bless, "read_compared", breaks)
    with pytest.raises(stop):
        bless.bless(actual, golden, T.Tolerances())
    assert tree_bytes(golden) == before
    assert not [p for p in golden.rglob("*") if p.name.startswith(".axdf-tmp-")]
    assert not (golden / "new").exists()
    monkeypatch.setattr(bless, "read_compared", real)
    assert main(["compare", str(actual), str(golden), "--update"]) == 0
    assert tree_bytes(golden) == tree_bytes(actual)


def test_update_creates_a_new_golden_folder(runs, tmp_path, capsys):
    actual, _ = runs
    fresh = tmp_path / "fresh-golden"
    assert main(["compare", str(actual), str(fresh), "--update"]) == 0
    assert tree_bytes(fresh) == tree_bytes(actual)
    assert "added" in capsys.readouterr().out


def test_report_inside_actual_is_not_compared(runs):
    actual, golden = runs
    assert main(["compare", str(actual), str(golden), "--report", str(actual / "report.json"),
                 "--junit", str(actual / "junit.xml")]) == 0


def test_manifest_input_change_is_a_likely_cause(runs, tmp_path, capsys):
    actual, golden = runs
    m = json.loads((actual / "manifest.json").read_text())
    m["inputs"][0]["sha256"] = "d" * 64
    m["gl_renderer"] = "another GPU"  # not compared
    m["outputs"] = {}
    (actual / "manifest.json").write_text(json.dumps(m))
    (actual / "stats.csv").write_text((actual / "stats.csv").read_text().replace("0.000123", "0.000124"))
    code, doc = _report(tmp_path, actual, golden)
    out = capsys.readouterr().out
    assert code == 1 and _failing(doc) == ["stats.csv"]
    assert doc["likely_causes"] == [f"manifest inputs.muscles/m0.yaml.sha256: {json.dumps('d' * 64)} "
                                    f"vs golden {json.dumps('a' * 64)}"]
    assert "likely causes" in out and "muscles/m0.yaml" in out
    assert "gl_renderer" not in out


# ----------------------------------------------------------------------------- tables, json
def test_csv_numbers_within_tolerance_pass_and_beyond_fail(runs, tmp_path):
    actual, golden = runs
    text = (golden / "bones.csv").read_text()
    (actual / "bones.csv").write_text(text.replace("0.99", "0.9900000001"))
    assert main(["compare", str(actual / "bones.csv"), str(golden / "bones.csv")]) == 0
    (actual / "bones.csv").write_text(text.replace("0.99", "0.991"))
    code, doc = _report(tmp_path, actual / "bones.csv", golden / "bones.csv")
    assert code == 1
    assert "column qw" in " ".join(doc["files"][0]["reasons"])
    (actual / "bones.csv").write_text(text.replace("humerus", "ulna"))
    assert main(["compare", str(actual / "bones.csv"), str(golden / "bones.csv")]) == 1


def test_camera_json_numeric(runs):
    actual, golden = runs
    cam = json.loads((golden / "camera.json").read_text())
    cam["K"][0][0] += 1e-8
    (actual / "camera.json").write_text(json.dumps(cam))
    assert main(["compare", str(actual / "camera.json"), str(golden / "camera.json")]) == 0
    cam["world_to_camera"]["1"][2][3] = -2.01
    (actual / "camera.json").write_text(json.dumps(cam))
    assert main(["compare", str(actual / "camera.json"), str(golden / "camera.json")]) == 1


def test_other_files_bytewise(tmp_path):
    (tmp_path / "a.txt").write_text("hello\n")
    (tmp_path / "b.txt").write_text("hellO\n")
    assert main(["compare", str(tmp_path / "a.txt"), str(tmp_path / "a.txt")]) == 0
    assert main(["compare", str(tmp_path / "a.txt"), str(tmp_path / "b.txt")]) == 1
