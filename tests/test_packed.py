"""Per-sequence (packed) outputs: ``--format usd,pc2,mdd,npz``, read back by their own
libraries (pxr, numpy, struct per the file specs) and compared with the PLY of the same frames;
several formats at once; --jobs and --resume give the same bytes; a failed sequence leaves
nothing; ``axdf render`` and ``axdf compare`` on packed runs."""
from __future__ import annotations

import csv
import json
import shutil
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.formats import read_triangles

from conftest import REPO_ROOT, all_files, run_main

FRAMES = "40:56:2"  # knee flexion into shoulder abduction: every demo muscle moves somewhere
FRAME_LIST = list(range(40, 57, 2))
ALL = "ply,usd,pc2,mdd,npz"
FPS = 24.0  # poses/demo.yaml

pxr = pytest.importorskip("pxr", reason="usd-core is a test dependency (pip install -e '.[test]')")


def _run(out: Path, *extra) -> None:
    from axdf_cli.cli.main import main

    assert main(["run", "poses/jobs/demo.yaml", "--out", str(out), "--frames", FRAMES, "--no-render", "-q",
                 *map(str, extra)]) == 0


@pytest.fixture(scope="module")
def packed(tmp_path_factory):
    """The demo over FRAMES in every format, with one process and with three."""
    import os

    base = tmp_path_factory.mktemp("packed")
    old = os.getcwd()
    os.chdir(REPO_ROOT)
    try:
        _run(base / "one", "--format", "ply,usd", "--format", "pc2,mdd,npz")
        _run(base / "three", "--format", ALL, "--jobs", "3")
    finally:
        os.chdir(old)
    return base / "one", base / "three"


def _muscles(run: Path) -> list[str]:
    return [m["name"] for m in json.loads((run / "manifest.json").read_text())["muscles"]]


def _ply(run: Path, m: str, f: int):
    return read_triangles((run / "meshes" / m / f"{m}_{f:04d}.ply").read_bytes(), ".ply")


# ----------------------------------------------------------------------------- layout


def test_every_format_written_once_per_muscle_and_hashed(packed):
    run, _ = packed
    man = json.loads((run / "manifest.json").read_text())
    assert man["settings"]["format"] == ALL
    names = _muscles(run)
    expected = {"scene.usda", "usd/bones.usdc"}
    for m in names:
        expected |= {f"usd/{m}.usdc", f"pc2/{m}.pc2", f"pc2/{m}.ply", f"mdd/{m}.mdd", f"mdd/{m}.ply",
                     f"npz/{m}.npz"}
        expected |= {f"meshes/{m}/{m}_{f:04d}.ply" for f in FRAME_LIST}
    on_disk = {k for k in all_files(run) if not k.startswith("bones/")} - {"manifest.json", "stats.csv", "bones.csv"}
    assert on_disk == expected
    import hashlib
    for rel in expected:
        assert man["files"][rel] == hashlib.sha256((run / rel).read_bytes()).hexdigest(), rel
    assert not list(run.rglob(".axdf-tmp-*"))


def test_jobs_give_the_same_bytes(packed):
    one, three = packed
    assert all_files(one) == all_files(three)


# ----------------------------------------------------------------------------- NPZ


def test_npz_holds_the_ply_frames_and_is_byte_deterministic(packed):
    run, _ = packed
    for m in _muscles(run):
        with np.load(run / "npz" / f"{m}.npz") as z:
            assert sorted(z.files) == ["faces", "fps", "frames", "normals", "points"]
            assert z["points"].dtype == np.float32 and z["points"].shape[0] == len(FRAME_LIST)
            assert z["frames"].tolist() == FRAME_LIST and float(z["fps"]) == FPS
            for k, f in enumerate(FRAME_LIST):
                v, n, faces = _ply(run, m, f)
                np.testing.assert_array_equal(z["points"][k], v)  # both are the same float32 values
                np.testing.assert_array_equal(z["normals"][k], n)
                np.testing.assert_array_equal(z["faces"], faces)
        with zipfile.ZipFile(run / "npz" / f"{m}.npz") as zf:
            assert zf.testzip() is None  # every CRC-32 right
            assert {i.date_time for i in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}
            assert {i.compress_type for i in zf.infolist()} == {zipfile.ZIP_STORED}


def test_npz_zip64_records_read_by_zipfile_and_numpy(tmp_path, monkeypatch):
    """Entries past 4 GiB use ZIP64 records; forced here with a tiny limit."""
    from axdf_cli.formats import npz
    from axdf_cli.formats.packed import SequenceInfo

    monkeypatch.setattr(npz, "ZIP32_MAX", 64)
    rng = np.random.default_rng(5)
    p = rng.standard_normal((7, 11, 3)).astype(np.float32)
    n = rng.standard_normal((7, 11, 3)).astype(np.float32)
    w = npz.NpzWriter(tmp_path / "x.npz", SequenceInfo(np.arange(7) * 3, 30.0, "x"), rng.integers(0, 11, (4, 3)), 11)
    w.append(p[:5], n[:5])
    w.append(p[5:], n[5:])
    w.finish()
    with zipfile.ZipFile(tmp_path / "x.npz") as zf:
        assert zf.testzip() is None
    with np.load(tmp_path / "x.npz") as z:
        np.testing.assert_array_equal(z["points"], p)
        np.testing.assert_array_equal(z["normals"], n)
    seq = npz.read_npz(tmp_path / "x.npz")  # memory-mapped through the ZIP64 local headers
    np.testing.assert_array_equal(seq.points, p)


# ----------------------------------------------------------------------------- PC2, MDD


def test_pc2_header_points_and_rest_mesh(packed):
    run, _ = packed
    for m in _muscles(run):
        data = (run / "pc2" / f"{m}.pc2").read_bytes()
        magic, version, n_points, start, rate, n_samples = struct.unpack("<12siiffi", data[:32])
        v0, _, faces = _ply(run, m, FRAME_LIST[0])
        assert (magic, version, n_points, start, rate, n_samples) == (b"POINTCACHE2\0", 1, len(v0), 40.0, 2.0,
                                                                      len(FRAME_LIST))
        pts = np.frombuffer(data, "<f4", offset=32).reshape(len(FRAME_LIST), n_points, 3)
        for k, f in enumerate(FRAME_LIST):
            np.testing.assert_array_equal(pts[k], _ply(run, m, f)[0])
        rest_v, rest_n, rest_f = read_triangles((run / "pc2" / f"{m}.ply").read_bytes(), ".ply")
        np.testing.assert_array_equal(rest_f, faces)  # same topology, same vertex order
        assert (run / "pc2" / f"{m}.ply").read_bytes() == (run / "mdd" / f"{m}.ply").read_bytes()


def test_mdd_header_times_and_points(packed):
    run, _ = packed
    for m in _muscles(run):
        data = (run / "mdd" / f"{m}.mdd").read_bytes()
        n_frames, n_points = struct.unpack(">ii", data[:8])
        assert n_frames == len(FRAME_LIST)
        times = np.frombuffer(data, ">f4", n_frames, 8)
        np.testing.assert_allclose(times, np.array(FRAME_LIST) / FPS, rtol=1e-7)
        pts = np.frombuffer(data, ">f4", offset=8 + 4 * n_frames).reshape(n_frames, n_points, 3)
        for k, f in enumerate(FRAME_LIST):
            np.testing.assert_array_equal(pts[k], _ply(run, m, f)[0])


# ----------------------------------------------------------------------------- USD


def _bones_csv(run: Path) -> dict:
    out = {}
    with open(run / "bones.csv", newline="") as fh:
        for r in csv.DictReader(fh):
            out[(int(r["frame"]), r["bone"])] = np.array([float(r[k]) for k in ("x", "y", "z", "qw", "qx", "qy", "qz")])
    return out


def _quat_matrix(q) -> np.ndarray:
    """(w, x, y, z) -> (3, 3), by scipy (an independent implementation)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def test_usd_stage_through_pxr_equals_the_ply_frames(packed):
    """The composed stage as any USD client sees it: metadata, every muscle's points and
    normals at every frame's time code equal the PLY of that frame (max error printed), the
    topology written once, the bones' world transforms those of bones.csv, and the camera
    sees every muscle at every frame."""
    from pxr import Gf, Usd, UsdGeom

    run, _ = packed
    stage = Usd.Stage.Open(str(run / "scene.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == FPS and stage.GetFramesPerSecond() == FPS
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (FRAME_LIST[0], FRAME_LIST[-1])
    worst = 0.0
    all_points = {f: [] for f in FRAME_LIST}
    for m in _muscles(run):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/axdf/muscles/{m}"))
        assert mesh, m
        assert mesh.GetPointsAttr().GetTimeSamples() == FRAME_LIST
        assert mesh.GetFaceVertexIndicesAttr().GetNumTimeSamples() == 0  # topology once
        assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
        assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
        faces = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
        xf = np.array(UsdGeom.Xformable(mesh).ComputeLocalToWorldTransform(Usd.TimeCode(FRAME_LIST[0])))
        np.testing.assert_array_equal(xf, np.eye(4))  # muscles are in world coordinates
        for f in FRAME_LIST:
            v, n, ply_faces = _ply(run, m, f)
            p = np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode(f)))
            worst = max(worst, float(np.abs(p - v).max()))
            np.testing.assert_array_equal(p, v)
            np.testing.assert_array_equal(np.asarray(mesh.GetNormalsAttr().Get(Usd.TimeCode(f))), n)
            np.testing.assert_array_equal(faces, ply_faces)
            all_points[f].append(p)
    print(f"USD (pxr) vs PLY: max vertex error {worst:.3g} m over {len(_muscles(run))} muscles x {len(FRAME_LIST)} frames")

    poses = _bones_csv(run)
    for f in FRAME_LIST:
        for bone in ("femur_r", "humerus_r", "radius_r"):
            prim = stage.GetPrimAtPath(f"/axdf/bones/{bone}")
            M = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode(f))).T  # column vectors
            row = poses[(f, bone)]
            np.testing.assert_allclose(M[:3, 3], row[:3], atol=1e-12)
            np.testing.assert_allclose(M[:3, :3], _quat_matrix(row[3:]), atol=1e-12)
            local = read_triangles((run / "bones" / f"{bone}.ply").read_bytes(), ".ply")[0]
            pts = np.asarray(UsdGeom.Mesh(stage.GetPrimAtPath(f"/axdf/bones/{bone}/{bone}_mesh")).GetPointsAttr().Get())
            np.testing.assert_array_equal(pts, local)

    cam = UsdGeom.Camera(stage.GetPrimAtPath("/axdf/camera"))
    for f in FRAME_LIST:
        frustum = cam.GetCamera(Usd.TimeCode(f)).frustum
        # clip[v] = [p, 1] @ view @ proj (USD row vectors)
        vp = np.array(frustum.ComputeViewMatrix()) @ np.array(frustum.ComputeProjectionMatrix())
        p = np.concatenate(all_points[f]).astype(np.float64)
        clip = np.c_[p, np.ones(len(p))] @ vp
        ndc = clip[:, :3] / clip[:, 3:]
        assert np.all(np.abs(ndc[:, :2]) <= 1.0), f"a muscle vertex is outside the USD camera's view at frame {f}"
        assert np.all(clip[:, 3] > 0)
    assert isinstance(Gf.Vec2f(cam.GetClippingRangeAttr().Get())[0], float)


def test_usd_layer_opens_alone(packed):
    """Each muscle's layer carries the stage metadata and a Mesh default prim, so it opens without the root."""
    from pxr import Usd, UsdGeom

    run, _ = packed
    stage = Usd.Stage.Open(str(run / "usd" / "biceps_brachii.usdc"))
    assert stage.GetDefaultPrim().IsA(UsdGeom.Mesh)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z and stage.GetTimeCodesPerSecond() == FPS


# ----------------------------------------------------------------------------- choosing formats


def test_formats_from_a_job_list_and_aliases(repo_root, tmp_path, capsys):
    job = tmp_path / "job.yaml"
    job.write_text(f"muscles: {REPO_ROOT / 'muscles/demo/biceps_brachii.yaml'}\npose: {REPO_ROOT / 'poses/demo.yaml'}\n"
                   "format: [npz, 'usdc,ply', npz]\nframes: '0:2'\n")
    rc, _, err = run_main(["run", job, "--out", tmp_path / "o", "-q", "--allow-outside"], capsys)
    assert rc == 0, err
    man = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert man["settings"]["format"] == "npz,usd,ply"  # the order given, each once, usdc -> usd
    assert (tmp_path / "o" / "npz" / "biceps_brachii.npz").is_file()
    assert (tmp_path / "o" / "scene.usda").is_file()
    assert (tmp_path / "o" / "meshes" / "biceps_brachii" / "biceps_brachii_0002.ply").is_file()


@pytest.mark.parametrize("args, where, what", [
    (["--format", "ply,stl"], "--format", "unknown format 'stl'; one or more of ply, obj, usd, pc2, mdd, npz"),
    (["--format", "pc2", "--frames", "0,1,5"], "--frames", "frames 0,1,5 for pc2; point caches"),
    (["--format", "npz,mdd", "--frames", "3,7,10:12"], "--frames", "for mdd"),
])
def test_bad_format_choices_are_exit_2_and_write_nothing(repo_root, tmp_path, capsys, args, where, what):
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", *args], capsys)
    assert rc == 2
    assert err.startswith(f"{where}: ") and what in err, err
    assert not (tmp_path / "o").exists()


def test_format_error_in_a_job_names_its_position(repo_root, tmp_path, capsys):
    job = tmp_path / "job.yaml"
    job.write_text(f"muscles: {REPO_ROOT / 'muscles/demo'}\npose: {REPO_ROOT / 'poses/demo.yaml'}\nformat: [ply, fbx]\n")
    rc, _, err = run_main(["run", job, "--out", tmp_path / "o", "--allow-outside"], capsys)
    assert rc == 2 and err.startswith(f"{job}:3:9: unknown format 'fbx'"), err


def test_usd_without_pxr_is_exit_3_before_writing(repo_root, tmp_path, capsys, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "pxr", None)  # import pxr fails as when usd-core is absent
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", "--format", "ply,usd"], capsys)
    assert rc == 3 and "pip install usd-core" in err
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- whole or absent, resume


def test_a_failing_sequence_leaves_no_file_and_no_temporary(repo_root, tmp_path, monkeypatch):
    from axdf_cli.cli.main import main
    from axdf_cli.formats.npz import NpzWriter

    calls = {"n": 0}
    real = NpzWriter._chunk

    def failing(self, *a):
        calls["n"] += 1
        if calls["n"] == 4:
            raise OSError(28, "No space left on device")
        return real(self, *a)

    monkeypatch.setattr(NpzWriter, "_chunk", failing)
    monkeypatch.setattr("axdf_cli.pipeline.evaluate.CHUNK_FRAMES", 2)  # several chunks per muscle
    monkeypatch.setattr("axdf_cli.pipeline.evaluate.chunk_frames", lambda plan: 2)
    rc = main(["run", "poses/jobs/demo.yaml", "--out", str(tmp_path / "o"), "--frames", "0:5", "--format", "usd,npz",
               "-q"])
    assert rc != 0
    assert not list((tmp_path / "o").rglob("*.npz")) and not list((tmp_path / "o").rglob("*.usdc"))
    assert not list((tmp_path / "o").rglob(".axdf-tmp-*"))


def test_resume_redoes_an_incomplete_sequence_file(packed, tmp_path, repo_root, capsys):
    """A killed run: one muscle's npz and usdc missing (a temporary of each left behind), the
    manifest not complete. --resume writes them again, keeps the rest (skipped), and the
    folder equals an uninterrupted run byte for byte."""
    run, _ = packed
    out = tmp_path / "o"
    shutil.copytree(run, out)
    m = _muscles(run)[2]
    for rel in (f"npz/{m}.npz", f"usd/{m}.usdc"):
        data = (out / rel).read_bytes()
        (out / rel).unlink()
        (out / rel).with_name(f".axdf-tmp-999-{Path(rel).name}").write_bytes(data[: len(data) // 3])
    man = json.loads((out / "manifest.json").read_text())
    man["complete"] = False
    (out / "manifest.json").write_text(json.dumps(man))
    rc, stdout, err = run_main(["run", "poses/jobs/demo.yaml", "--out", out, "--frames", FRAMES, "--no-render",
                                "--format", ALL, "--resume"], capsys)
    assert rc == 0, err
    assert all_files(out) == all_files(run)
    n_seq = 5 * len(_muscles(run)) + 2  # usd, pc2 (+ply), mdd (+ply), npz per muscle; stage, bones layer
    assert "already complete" in stdout and int(stdout.split(", ")[-1].split()[0]) >= n_seq - 2


# ----------------------------------------------------------------------------- render and compare


def test_render_reads_a_packed_only_run(repo_root, tmp_path, capsys):
    """A run with only npz (or usd, or pc2) renders as the same run with PLY: npz and usd carry
    the normals (the same bytes); pc2 does not (normals recomputed from the faces: the PNGs
    within compare's tolerance; the EXR normal pass differs by more than its 0.01 at some
    silhouette pixels, as it should)."""
    from axdf_cli.compare import compare_paths

    for fmt in ("ply", "npz", "pc2", "usd"):
        rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / fmt, "--frames", "44:46:2",
                               "--format", fmt, "--no-render", "-q"], capsys)
        assert rc == 0, err
        rc, _, err = run_main(["render", tmp_path / fmt, "--size", "64x64", "-q"], capsys)
        assert rc == 0, err
    ref = all_files(tmp_path / "ply" / "frames")
    assert all_files(tmp_path / "npz" / "frames") == ref
    assert all_files(tmp_path / "usd" / "frames") == ref
    for png in sorted((tmp_path / "ply" / "frames").glob("*.png")):
        rep = compare_paths(tmp_path / "pc2" / "frames" / png.name, png)
        assert rep.passed, [f.reasons for f in rep.files if f.failed]


def test_compare_names_the_worst_frame_of_a_sequence(packed, tmp_path):
    from axdf_cli.compare import compare_paths

    run, _ = packed
    out = tmp_path / "o"
    shutil.copytree(run, out)
    m = _muscles(run)[0]
    # move one vertex of frame 46 (index 3) by 1 mm in the npz and the pc2
    npz = out / "npz" / f"{m}.npz"
    with np.load(npz) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["points"][3, 10, 2] += 1e-3
    np.savez(npz, **arrays)
    pc2 = bytearray((out / "pc2" / f"{m}.pc2").read_bytes())
    off = 32 + (3 * arrays["points"].shape[1] + 10) * 12 + 8
    pc2[off:off + 4] = (np.frombuffer(pc2[off:off + 4], "<f4") + np.float32(1e-3)).tobytes()
    (out / "pc2" / f"{m}.pc2").write_bytes(pc2)
    rep = compare_paths(out, run)
    failed = {f.path: f for f in rep.files if f.failed}
    assert set(failed) == {f"npz/{m}.npz", f"pc2/{m}.pc2"}
    for f in failed.values():
        assert f.metrics["worst_frame"] == 46 and f.metrics["worst_vertex"] == 10
        assert f.metrics["frames_over"] == 1 and len(f.metrics["per_frame_max"]) == len(FRAME_LIST)
        assert f.metrics["per_frame_max"][3] == pytest.approx(1e-3, rel=1e-3)
        assert "at frame 46 (vertex 10)" in f.reasons[0]
    ok = [f for f in rep.files if f.kind in ("sequence", "stage")]
    assert len(ok) == len(list(run.rglob("*.usd[ac]"))) + 3 * len(_muscles(run))


def test_compare_usd_stage_by_value(packed, tmp_path):
    """scene.usda: same prims and fields; a bone moved beyond the tolerance fails, naming the value."""
    from axdf_cli.compare import compare_paths

    run, _ = packed
    text = (run / "scene.usda").read_text()
    a = tmp_path / "a.usda"
    g = tmp_path / "g.usda"
    g.write_text(text)
    a.write_text(text.replace("timeCodesPerSecond = 24", "timeCodesPerSecond = 25"))
    rep = compare_paths(a, g)
    assert not rep.passed and "timeCodesPerSecond" in " ".join(rep.files[0].reasons)
    a.write_text(text)
    assert compare_paths(a, g).passed
