"""A frame whose path cannot wrap (an end point inside the wrap surface), through ``axdf run``:
the frame is finite, warned in stats.csv's ``warning`` column and in the manifest's
``warnings``, and ``--strict`` refuses the run (exit 2, nothing written).

The muscle runs from the back of the femur to the back of the tibia over a sphere fixed to
the tibia behind the knee. Straight (demo pose frame 0) the path wraps over the sphere; as the
knee flexes past about 75° (frames ~22-38 of the demo pose) the sphere swings up onto the
femoral origin, which ends inside it.
"""
from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from axdf_cli.formats import load_triangles
from conftest import REPO_ROOT, run_main
from test_paths import project  # noqa: F401 (the fixture this file's project extends)

MUSCLE = """# an origin that the tibia's sphere swallows as the knee flexes
muscle: knee_ball
color: "#b03a2e"
path:
  - {bone: femur_r, at: [0.0, 0.03, -0.36]}
  - {bone: tibia_r, at: [0.0, 0.03, -0.25]}
wrap:
  - {name: ball, shape: sphere, bone: tibia_r, radius: 0.03, at: [0.0, 0.05, -0.05]}
sections:
  - {t: 0.3, radii: [0.008, 0.008]}
  - {t: 0.6, radii: [0.01, 0.01]}
resolution: [16, 8]
"""
FRAMES = "0:44:4"
MESSAGE = "path cannot wrap over 'ball': an end point lies inside it; kept the straight segment"


@pytest.fixture
def inside_project(project):
    """test_paths' project (the poses copied, the current folder there) with this muscle."""
    (project / "m.yaml").write_text(MUSCLE)
    return project


def _origin_inside(frames) -> np.ndarray:
    """Ground truth from the skeleton alone: is the origin inside the sphere at each frame?"""
    from axdf_cli.specs import load_pose
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics

    pose = load_pose(REPO_ROOT / "poses" / "demo.yaml")
    world = forward_kinematics(pose.skeleton, sample_coordinates(pose, np.asarray(frames)))
    bi = pose.skeleton.bone_index
    origin = world[:, bi["femur_r"]] @ np.array([0.0, 0.03, -0.36, 1.0])
    centre = world[:, bi["tibia_r"]] @ np.array([0.0, 0.05, -0.05, 1.0])
    return np.linalg.norm(origin[:, :3] - centre[:, :3], axis=1) < 0.03


def test_unwrappable_frames_are_finite_and_warned(inside_project, capsys):
    rc, out, err = run_main(["run", "--muscles", "m.yaml", "--pose", "poses/demo.yaml", "--out", "out",
                             "--no-render", "--frames", FRAMES], capsys)
    assert rc == 0, err
    frames = list(range(0, 45, 4))
    inside = _origin_inside(frames)
    assert inside.any() and not inside.all()  # the case happens, and not everywhere
    with open(inside_project / "out" / "stats.csv", newline="") as fh:
        rows = {int(r["frame"]): r for r in csv.DictReader(fh)}
    assert sorted(rows) == frames
    for f, ins in zip(frames, inside):
        assert (MESSAGE in rows[f]["warning"]) == bool(ins), (f, rows[f]["warning"])
        assert np.isfinite(float(rows[f]["length"])) and float(rows[f]["length"]) > 0.1
        pos, _, faces = load_triangles(inside_project / "out" / "meshes" / "knee_ball" / f"knee_ball_{f:04d}.ply")
        assert np.isfinite(pos).all() and len(faces) > 0
    manifest = json.loads((inside_project / "out" / "manifest.json").read_text())
    warned = [w for w in manifest["warnings"] if MESSAGE in w]
    assert warned == [f"knee_ball frame {f}: {MESSAGE}" for f, ins in zip(frames, inside) if ins]


def test_unwrappable_frames_are_refused_under_strict(inside_project, capsys):
    rc, out, err = run_main(["run", "--muscles", "m.yaml", "--pose", "poses/demo.yaml", "--out", "out",
                             "--no-render", "--frames", FRAMES, "--strict"], capsys)
    assert rc == 2
    assert "with --strict" in err and MESSAGE in err and "Traceback" not in err
    assert not (inside_project / "out").exists()
