"""The skin in every per-sequence format: a run with ``--skin`` and
``--format npz|usd|pc2`` writes ``npz/skin.npz``, ``usd/skin.usdc`` (referenced from
``scene.usda``) and ``pc2/skin.pc2`` with its rest mesh. Each is read back with the real
reader and holds, frame by frame, the points of the same run's ``meshes/skin`` PLY files;
``--jobs 2`` gives the same bytes; the manifest lists the files; ``--resume`` keeps them;
``axdf compare`` passes on the same run and reports a changed skin. Small runs: the shipped
walk, three muscles round the left knee, four frames, the shipped gait2392 skin."""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.formats import load_triangles_and_bytes
from conftest import REPO_ROOT, all_files, run_main

POSE = REPO_ROOT / "poses" / "gait2392_walk.yaml"
PACKED = REPO_ROOT / "muscles" / "gait2392_packed"
SKIN = REPO_ROOT / "skins" / "gait2392" / "skin.yaml"
KNEE = ("rect_fem_l", "vas_lat_l", "med_gas_l")
FRAMES = range(20, 24)
SEQUENCE_FILES = ("npz/skin.npz", "usd/skin.usdc", "pc2/skin.pc2", "pc2/skin.ply")


def run(out: Path, *extra) -> list:
    return ["run", "--pose", POSE, "--muscles", *[PACKED / f"{m}.yaml" for m in KNEE], "--skin", SKIN,
            "--frames", f"{FRAMES[0]}:{FRAMES[-1]}", "--format", "ply", "--format", "npz", "--format", "usd",
            "--format", "pc2", "--out", out, "--quiet", *extra]


def _run(out: Path, *extra) -> Path:
    from axdf_cli.cli.main import main

    assert main([str(a) for a in run(out, *extra)]) == 0
    return out


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("skinout") / "jobs1")


@pytest.fixture(scope="module")
def jobs2(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("skinout") / "jobs2", "--jobs", "2")


def ply_points(run_dir: Path) -> np.ndarray:
    """The skin's per-frame PLY points, (F, V, 3) float32."""
    return np.stack([load_triangles_and_bytes(run_dir / f"meshes/skin/skin_{f:04d}.ply")[0][0]
                     for f in FRAMES]).astype(np.float32)


def test_npz_holds_the_skin(whole):
    from axdf_cli.specs.skin import load_skin

    z = np.load(whole / "npz/skin.npz")
    assert z["frames"].tolist() == list(FRAMES)
    np.testing.assert_array_equal(z["points"], ply_points(whole))
    assert np.array_equal(z["faces"], load_skin(SKIN).faces)
    assert z["normals"].shape == z["points"].shape


def test_pc2_holds_the_skin_with_its_rest_mesh(whole):
    """pc2/skin.ply is the rest mesh as the run wears it: the file's, grown over the few worn
    bone points that lay outside it at rest (skin_stage.worn_rest)."""
    from axdf_cli.formats.pc2 import read_pc2
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.skin_stage import SkinStage
    from axdf_cli.specs.skin import load_skin

    seq = read_pc2(whole / "pc2/skin.pc2")
    np.testing.assert_array_equal(np.asarray(seq.points), ply_points(whole))
    (v, _, faces), _ = load_triangles_and_bytes(whole / "pc2/skin.ply")
    rest = load_skin(SKIN)
    assert np.array_equal(faces, rest.faces)
    plan = plan_run(None, muscle_args=[str(PACKED / f"{m}.yaml") for m in KNEE], pose_arg=str(POSE),
                    skin_arg=str(SKIN), frames_arg="20")
    worn = next(s for s in plan.stages if isinstance(s, SkinStage)).worn(plan)
    np.testing.assert_allclose(v, worn.vertices, atol=1e-6)
    moved = np.linalg.norm(worn.vertices - rest.vertices, axis=1)
    assert worn.grown > 0 and moved.max() < 0.01 and (moved > 1e-6).mean() < 0.1  # a few mm, a few patches


def test_usd_stage_references_the_skin(whole):
    from pxr import Usd, UsdGeom

    from axdf_cli.parts import COLORS, Kind

    stage = Usd.Stage.Open(str(whole / "scene.usda"))
    prim = stage.GetPrimAtPath("/axdf/skin")
    assert prim.IsValid() and prim.IsA(UsdGeom.Mesh)
    assert stage.GetPrimAtPath(f"/axdf/muscles/{KNEE[0]}").IsValid()
    mesh = UsdGeom.Mesh(prim)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    assert len(counts) and (counts == 3).all()
    np.testing.assert_allclose(mesh.GetDisplayColorAttr().Get()[0], COLORS[Kind.SKIN], atol=1e-6)
    pts = ply_points(whole)
    assert mesh.GetPointsAttr().GetNumTimeSamples() == len(FRAMES)
    for k, f in enumerate(FRAMES):
        np.testing.assert_array_equal(np.asarray(mesh.GetPointsAttr().Get(f), np.float32), pts[k])


def test_manifest_lists_the_skin_files(whole):
    files = json.loads((whole / "manifest.json").read_text())["files"]
    for rel in SEQUENCE_FILES:
        assert files[rel] == hashlib.sha256((whole / rel).read_bytes()).hexdigest(), rel


def test_same_bytes_with_jobs_2(whole, jobs2):
    a, b = all_files(whole), all_files(jobs2)
    assert set(a) == set(b)
    for rel in SEQUENCE_FILES + ("scene.usda",):
        assert a[rel] == b[rel], rel
    assert json.loads(a["manifest.json"])["files"] == json.loads(b["manifest.json"])["files"]


def test_resume_keeps_the_skin_files(whole, tmp_path):
    out = tmp_path / "again"
    shutil.copytree(whole, out)
    os.utime(out / "npz/skin.npz", (1, 1))  # a file written again would get a new mtime
    before = all_files(out)
    _run(out, "--resume")
    assert (out / "npz/skin.npz").stat().st_mtime == 1
    after = all_files(out)
    for rel in SEQUENCE_FILES:
        assert after[rel] == before[rel], rel


def test_compare_passes_and_reports_a_changed_skin(whole, jobs2, tmp_path, capsys):
    rc, out, _ = run_main(["compare", whole, jobs2], capsys)
    assert rc == 0, out
    changed = tmp_path / "changed"
    shutil.copytree(whole, changed)
    z = dict(np.load(changed / "npz/skin.npz"))
    z["points"][2, 100] += np.float32(0.01)  # one vertex of frame 22 moved 1 cm
    np.savez(changed / "npz/skin.npz", **z)
    rc, out, err = run_main(["compare", changed, whole], capsys)
    assert rc != 0 and "npz/skin.npz" in out + err, out + err
