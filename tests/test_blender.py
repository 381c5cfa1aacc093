"""Checked in the real client: Blender (``bpy``) reads our USD stage and point caches, and the
vertices it evaluates equal the PLY of the same frames.

bpy lives in a side environment, ``.venv-blender`` (``make test`` creates it: bpy 5 needs
numpy<2, axdf uses numpy 2), and ``tests/blender_check.py`` runs there as a subprocess. Where
bpy cannot be installed the test says so and skips.

The run: arm26's elbow flexion (60 fps, bone meshes) over frames 20..40 step 4, as usd, pc2
and mdd. Blender frame f is our frame f once the scene runs at the pose's fps (Blender's USD
import leaves the scene's fps alone; a user sets it, as the script does). Frames on a sample
must equal the PLY of that frame; a frame between two samples (22) must equal their mean
(USD and the Mesh Cache modifier both interpolate linearly). Blender keeps the vertex order
of all three (no triangulation or reordering: our faces are triangles already), so vertices
are compared by index.
"""
from __future__ import annotations

import csv
import subprocess
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.formats import read_triangles

from conftest import REPO_ROOT, run_main

BLENDER_PY = REPO_ROOT / ".venv-blender" / "bin" / "python"
SCRIPT = Path(__file__).with_name("blender_check.py")
SAMPLES = (20, 24, 40)
BETWEEN = 22
# float32 coordinates near 0.5 m are spaced 6e-8 m; Blender's float32 interpolation and
# world-matrix products add a few roundings. 1e-6 m is ~16 such steps, 10^4 below a pixel.
ATOL = 1e-6


def _blender_or_skip() -> None:
    if not BLENDER_PY.is_file():
        pytest.skip(f"{BLENDER_PY.relative_to(REPO_ROOT)} missing: `make test` creates it "
                    "(python3 -m venv .venv-blender; .venv-blender/bin/pip install bpy usd-core)")
    r = subprocess.run([str(BLENDER_PY), "-c", "import bpy"], capture_output=True, text=True, timeout=300)
    if r.returncode:
        pytest.skip(f"bpy does not import in .venv-blender: {r.stderr.strip().splitlines()[-1:]}")


@pytest.fixture(scope="module")
def blender_result(tmp_path_factory):
    _blender_or_skip()
    import os

    from axdf_cli.cli.main import main

    out = tmp_path_factory.mktemp("blender") / "arm26"
    old = os.getcwd()
    os.chdir(REPO_ROOT)
    try:
        assert main(["run", "poses/jobs/arm26_flex.yaml", "--out", str(out), "--frames", "20:40:4",
                     "--format", "ply,usd,pc2,mdd", "--no-render", "-q"]) == 0
    finally:
        os.chdir(old)
    npz = out.parent / "blender.npz"
    r = subprocess.run([str(BLENDER_PY), str(SCRIPT), str(out), str(npz), *map(str, (*SAMPLES, BETWEEN))],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    with np.load(npz) as z:
        return out, {k: z[k] for k in z.files}


def _ply(run: Path, m: str, f: int) -> np.ndarray:
    return read_triangles((run / "meshes" / m / f"{m}_{f:04d}.ply").read_bytes(), ".ply")[0]


def _muscles(run: Path) -> list[str]:
    import json

    return [m["name"] for m in json.loads((run / "manifest.json").read_text())["muscles"]]


@pytest.mark.parametrize("fmt", ["usd", "pc2", "mdd"])
def test_blender_evaluates_our_frames(blender_result, fmt):
    run, got = blender_result
    worst = 0.0
    for m in _muscles(run):
        for f in SAMPLES:
            v = got[f"{fmt}/{m}/{f}"]
            expected = _ply(run, m, f)
            assert v.shape == expected.shape, f"{fmt} {m}: Blender has {v.shape[0]} vertices, the PLY {len(expected)}"
            worst = max(worst, float(np.abs(v - expected).max()))
            np.testing.assert_allclose(v, expected, rtol=0, atol=ATOL, err_msg=f"{fmt} {m} frame {f}")
        mid = 0.5 * (_ply(run, m, BETWEEN - 2).astype(np.float64) + _ply(run, m, BETWEEN + 2))
        np.testing.assert_allclose(got[f"{fmt}/{m}/{BETWEEN}"], mid, rtol=0, atol=ATOL,
                                   err_msg=f"{fmt} {m} frame {BETWEEN} (between samples)")
    print(f"Blender {fmt} vs PLY: max vertex error {worst:.3g} m")


def test_blender_moves_the_bones_as_bones_csv(blender_result):
    """The stage's bone Xforms (time-sampled translate + orient), as Blender evaluates them
    over the bone meshes, put each bone's PLY where bones.csv says."""
    run, got = blender_result
    rows = {}
    with open(run / "bones.csv", newline="") as fh:
        for r in csv.DictReader(fh):
            rows[(int(r["frame"]), r["bone"])] = [float(r[k]) for k in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    bones = sorted({k.split("/")[1] for k in got if k.startswith("usd_bone/")})
    assert bones, "no bone meshes came through Blender's USD import"
    worst = 0.0
    for b in bones:
        local = read_triangles((run / "bones" / f"{b}.ply").read_bytes(), ".ply")[0].astype(np.float64)
        for f in SAMPLES:
            x, y, z, qw, qx, qy, qz = rows[(f, b)]
            R = _quat_matrix(np.array([qw, qx, qy, qz]))
            expected = local @ R.T + [x, y, z]  # p_world[v] = R @ p[v] + t
            v = got[f"usd_bone/{b}/{f}"]
            worst = max(worst, float(np.abs(v - expected).max()))
            np.testing.assert_allclose(v, expected, rtol=0, atol=ATOL, err_msg=f"bone {b} frame {f}")
    print(f"Blender USD bones vs bones.csv: max vertex error {worst:.3g} m")


def test_blender_takes_the_frame_range_from_the_stage(blender_result):
    _, got = blender_result
    assert got["frame_range"].tolist() == [20, 40]
    assert float(got["pose_fps"]) == 60.0


def _quat_matrix(q) -> np.ndarray:
    """(w, x, y, z) -> (3, 3), by scipy (an independent implementation)."""
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat([q[1], q[2], q[3], q[0]]).as_matrix()


def test_pxr_and_blender_read_the_same_stage(blender_result, capsys):
    """The main venv's pxr reads the stage Blender read: the same points at the sample frames."""
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    run, got = blender_result
    stage = Usd.Stage.Open(str(run / "scene.usda"))
    for m in _muscles(run):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/axdf/muscles/{m}"))
        for f in SAMPLES:
            np.testing.assert_allclose(np.asarray(mesh.GetPointsAttr().Get(Usd.TimeCode(f))), got[f"usd/{m}/{f}"],
                                       rtol=0, atol=ATOL)
