"""`axdf fit` (axdf_cli/tools/fit.py, cli/fit.py): closed muscle meshes → AxDf muscle files.

Through the real CLI in process: a bent tube of elliptic section (known volume) is fitted to
IoU ≥ 0.9 and its volume within 5%; the written file loads through the muscle spec and runs
through `axdf run` at the rest pose; an atlas muscle (Visible Human, where ../shared/data has
it) fits at IoU ≥ 0.85; a mesh that is open or without volume, a missing mesh and an unknown
unit are refused by name with exit 2 and nothing written."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from cli_in_folder import run_cli
from osim_common import DATA

ATLAS = DATA / "atlas" / "visible_human_female" / "Right"

# a thigh: hip, knee and ankle on a straight line down z (metres)
SKELETON = """\
skeleton: leg
coordinates:
  hip: {type: rotation, range: [-30, 120]}
  knee: {type: rotation, range: [0, 150]}
bones:
  - name: pelvis
    offset: [0, 0, 1.0]
  - name: femur
    parent: pelvis
    offset: [0, 0, -0.05]
    dofs:
      - {coord: hip, type: rotation, axis: [1, 0, 0]}
  - name: tibia
    parent: femur
    offset: [0, 0, -0.42]
    dofs:
      - {coord: knee, type: rotation, axis: [1, 0, 0]}
"""

# the atlas' right leg in its own frame (metres): hip, knee and ankle from its cartilages
ATLAS_SKELETON = """\
skeleton: atlas_right
coordinates:
  hip_r: {type: rotation, range: [-30, 120]}
  knee_r: {type: rotation, range: [0, 150]}
  ankle_r: {type: rotation, range: [-30, 50]}
bones:
  - name: pelvis
    offset: [0.55, 0.50, 0.95]
  - name: femur_r
    parent: pelvis
    offset: [0.081, -0.048, -0.062]
    dofs:
      - {coord: hip_r, type: rotation, axis: [1, 0, 0]}
  - name: tibia_r
    parent: femur_r
    offset: [-0.025, -0.02, -0.40]
    dofs:
      - {coord: knee_r, type: rotation, axis: [1, 0, 0]}
  - name: foot_r
    parent: tibia_r
    offset: [-0.016, -0.024, -0.328]
    dofs:
      - {coord: ankle_r, type: rotation, axis: [1, 0, 0]}
"""


def bent_tube(length=0.30, a=0.03, b=0.015, bend=0.04, rows=60, around=48):
    """A closed tube along z from 0.92 to 0.62 m, bent by ``bend`` in x, of elliptic section
    (semi-axes a in x, b in y) tapering as sin(pi s)^0.5 to its capped tips: (vertices, faces)."""
    import trimesh

    s = np.linspace(0.0, 1.0, rows)[1:-1]
    k = np.sin(np.pi * s) ** 0.5
    th = np.arange(around) * 2 * np.pi / around
    cx = bend * np.sin(np.pi * s)
    z = 0.92 - length * s
    ring = np.stack([cx[:, None] + a * k[:, None] * np.cos(th), b * k[:, None] * np.sin(th),
                     np.broadcast_to(z[:, None], (len(s), around))], axis=-1).reshape(-1, 3)
    v = np.concatenate([[[0.0, 0.0, 0.92]], ring, [[0.0, 0.0, 0.92 - length]]])
    n = len(s)
    f = [[0, 1 + (j + 1) % around, 1 + j] for j in range(around)]
    for i in range(n - 1):
        for j in range(around):
            p, q = 1 + i * around + j, 1 + i * around + (j + 1) % around
            f += [[p, q, p + around], [p + around, q, q + around]]
    last = len(v) - 1
    base = 1 + (n - 1) * around
    f += [[base + j, base + (j + 1) % around, last] for j in range(around)]
    mesh = trimesh.Trimesh(v, np.array(f), process=True)
    if mesh.volume < 0:
        mesh.invert()
    return mesh


@pytest.fixture(scope="module")
def tube_fit(tmp_path_factory):
    d = tmp_path_factory.mktemp("fit")
    (d / "leg.yaml").write_text(SKELETON)
    mesh = bent_tube()
    mesh.apply_scale(1000.0)  # written in millimetres
    mesh.export(d / "tube.stl")
    rc = run_cli(d, "fit", "tube.stl", "--skeleton", "leg.yaml", "--out", "out", "--units", "mm", "--sections", "12",
                 "--quiet")
    return d, rc, mesh


def test_tube_fits_and_keeps_its_volume(tube_fit):
    d, rc, mesh = tube_fit
    assert rc == 0
    rep = json.loads((d / "out" / "fit_report.json").read_text())
    (m,) = rep["muscles"]
    assert m["muscle"] == "tube" and m["file"] == "muscles/tube.yaml"
    assert m["iou"] >= 0.9, m
    assert abs(m["volume_ratio"] - 1.0) <= 0.05, m
    assert m["distance_median_mm"] <= 1.0, m
    assert abs(m["mesh_volume_cm3"] - mesh.volume / 1000.0) < 1e-6 * mesh.volume
    assert set(m["bones"]) <= {"pelvis", "femur", "tibia"} and "femur" in m["bones"]
    assert "| tube |" in (d / "out" / "FIT.md").read_text()


def test_written_file_is_an_ordinary_muscle(tube_fit):
    """It loads through the muscle spec (an axis of 5 bound points, outlines of 8), and the model
    at the rest pose has the mesh's volume: `axdf run` at rest writes it."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton

    d, rc, mesh = tube_fit
    assert rc == 0
    (spec,) = load_muscle_file(d / "out" / "muscles" / "tube.yaml")
    assert len(spec.axis) == 5 and len(spec.sections) == 12
    assert all(len(s.outline) == 8 for s in spec.sections)
    skel = load_skeleton(d / "leg.yaml", RefPolicy(allow_outside=True))
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    model = MuscleModel(spec, skel.bone_index, rest, skel)
    assert abs(model.v0 / (mesh.volume * 1e-9) - 1.0) <= 0.05
    (d / "rest.yaml").write_text("pose: rest\nskeleton: leg.yaml\nfps: 30\nframes: [0, 1]\n"
                                 "keys:\n  0: {hip: 0, knee: 0}\n")
    assert run_cli(d, "validate", "out/muscles/tube.yaml") == 0
    assert run_cli(d, "run", "--muscles", "out/muscles", "--pose", "rest.yaml", "--out", "run", "--quiet") == 0
    assert (d / "run" / "stats.csv").is_file()


def test_same_input_same_bytes(tube_fit, tmp_path):
    d, rc, _ = tube_fit
    assert rc == 0
    assert run_cli(d, "fit", "tube.stl", "--skeleton", "leg.yaml", "--out", str(tmp_path / "again"), "--units", "mm",
                   "--sections", "12", "--quiet", "--allow-outside") == 0
    assert (tmp_path / "again" / "muscles" / "tube.yaml").read_bytes() == \
        (d / "out" / "muscles" / "tube.yaml").read_bytes()


def _refused(d: Path, capsys, *argv) -> str:
    capsys.readouterr()
    rc = run_cli(d, "fit", *argv, "--skeleton", "leg.yaml", "--out", "bad", "--quiet")
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    assert not (d / "bad").exists()
    return err


def test_refusals_write_nothing(tube_fit, capsys):
    import trimesh

    d, _, mesh = tube_fit
    trimesh.Trimesh(mesh.vertices, mesh.faces[:-5], process=False).export(d / "open.ply")
    err = _refused(d, capsys, "tube.stl", "open.ply", "--units", "mm")
    assert "open.ply: mesh is not closed" in err
    err = _refused(d, capsys, "tube.stl", "--units", "furlong")
    assert "furlong" in err and "mm, cm or m" in err
    err = _refused(d, capsys, "missing.stl")
    assert "missing.stl: mesh file not found" in err
    err = _refused(d, capsys, "leg.yaml")
    assert "leg.yaml: .yaml is not a mesh format" in err


def test_meshes_that_are_not_one_finite_muscle_of_a_muscle_size_are_refused_by_name(tube_fit, capsys):
    """A NaN vertex (trimesh would drop it and the mesh read "not closed"), a vertex at 1e300,
    two separate pieces in one file, and the tube read in the wrong unit (metres as mm: a
    thousand times too small; mm as metres: too large): each refused by name, --units named."""
    import trimesh

    d, _, mesh = tube_fit
    v = mesh.vertices.copy()
    v[3] = np.nan
    trimesh.Trimesh(v, mesh.faces, process=False).export(d / "nan.ply")
    v[3] = 1e300
    trimesh.Trimesh(v, mesh.faces, process=False).export(d / "far.obj")
    trimesh.util.concatenate([mesh, mesh.copy().apply_translation([300.0, 0, 0])]).export(d / "two.stl")
    assert "nan.ply: has non-finite vertex coordinates" in _refused(d, capsys, "nan.ply", "--units", "mm")
    assert "far.obj: mesh is 1e+297 m across" in _refused(d, capsys, "far.obj", "--units", "mm")
    assert "two.stl: mesh is 2 separate closed pieces" in _refused(d, capsys, "two.stl", "--units", "mm")
    err = _refused(d, capsys, "tube.stl", "--units", "m")  # the tube is in millimetres: read as metres, too large
    assert "read in m;" in err and "check --units" in err
    trimesh.Trimesh(mesh.vertices / 1000.0, mesh.faces).export(d / "metres.stl")
    assert "check --units" in _refused(d, capsys, "metres.stl", "--units", "mm")


def test_zero_volume_mesh_is_refused(tube_fit, capsys):
    """A closed surface without volume: a triangle and its back face (every edge bounds two)."""
    import trimesh

    d, _, _ = tube_fit
    trimesh.Trimesh([[0, 0, 0], [10, 0, 0], [0, 10, 0]], [[0, 1, 2], [0, 2, 1]], process=False).export(d / "flat.obj")
    err = _refused(d, capsys, "tube.stl", "flat.obj", "--units", "mm")
    assert "flat.obj: mesh encloses no volume" in err


def test_a_shape_the_model_cannot_follow_is_warned_of(tmp_path, capsys):
    """A ring (a torus) is closed and has volume, but no axis runs through it: written, warned."""
    import trimesh

    (tmp_path / "leg.yaml").write_text(SKELETON)
    t = trimesh.creation.torus(0.06, 0.015)
    t.apply_translation([0, 0, 0.7])
    t.export(tmp_path / "ring.stl")
    capsys.readouterr()
    assert run_cli(tmp_path, "fit", "ring.stl", "--skeleton", "leg.yaml", "--out", "out", "--sections", "4",
                   "--quiet") == 0
    assert "axdf: warning: ring.stl: the fitted muscle overlaps its mesh by IoU" in capsys.readouterr().err
    assert (tmp_path / "out" / "muscles" / "ring.yaml").is_file()


@pytest.mark.skipif(not ATLAS.is_dir(), reason=f"the Visible Human atlas not found at {ATLAS}")
def test_atlas_muscle_fits(tmp_path):
    src = next(ATLAS.glob("*Muscle_TibialisAnterior_*.ply"))
    (tmp_path / "atlas.yaml").write_text(ATLAS_SKELETON)
    rc = run_cli(tmp_path, "fit", str(src), "--skeleton", "atlas.yaml", "--out", "out", "--units", "mm",
                 "--sections", "8", "--quiet", "--allow-outside")
    assert rc == 0
    (m,) = json.loads((tmp_path / "out" / "fit_report.json").read_text())["muscles"]
    assert m["iou"] >= 0.85, m
    assert abs(m["volume_ratio"] - 1.0) <= 0.05, m
    assert set(m["bones"]) == {"tibia_r"}


def test_paths_bind_a_muscle_to_the_bones_its_path_crosses(tube_fit, capsys):
    """--paths: the tube (hip to above the knee) fitted with a model's path from the pelvis to
    the tibia hangs only on the bones that path spans: those two and the femur between them
    (the tube lies along the femur), in the model muscle's colour; with a path on the pelvis
    alone, only on the pelvis. A
    mesh with no muscle file of its name there is refused."""
    d, rc, _ = tube_fit
    assert rc == 0
    from axdf_cli.specs import load_muscle_file

    assert "femur" in {p.bone for p in load_muscle_file(d / "out" / "muscles" / "tube.yaml")[0].axis}
    (d / "model").mkdir(exist_ok=True)
    (d / "model" / "tube.yaml").write_text("muscle: tube\ncolor: '#4e0304'\npath:\n  - {bone: pelvis, at: [0, 0, -0.02]}\n"
                                           "  - {bone: tibia, at: [0, 0, 0.05]}\nsections:\n"
                                           "  - {t: 0.3, radii: [0.02, 0.02], angle: 0}\n"
                                           "  - {t: 0.7, radii: [0.02, 0.02], angle: 0}\n")
    assert run_cli(d, "fit", "tube.stl", "--skeleton", "leg.yaml", "--out", "paths", "--units", "mm",
                   "--sections", "6", "--paths", "model", "--quiet") == 0
    (spec,) = load_muscle_file(d / "paths" / "muscles" / "tube.yaml")
    bones = [p.bone for p in spec.axis]
    assert "femur" in bones and set(bones) <= {"pelvis", "femur", "tibia"}, bones
    assert spec.color == load_muscle_file(d / "model" / "tube.yaml")[0].color  # the model's colour kept
    # the model's path is kept as the line of action: the run's length is the path's, not the axis's
    assert spec.path is not None and [p.bone for p in spec.path.points] == ["pelvis", "tibia"]
    (d / "bend.yaml").write_text("pose: bend\nskeleton: leg.yaml\nfps: 10\nframes: [0, 4]\nkeys:\n"
                                 "  0: {knee: 0}\n  4: {knee: 90}\n")
    for name, muscles in (("fitted", "paths/muscles/tube.yaml"), ("model", "model/tube.yaml")):
        assert run_cli(d, "run", "--pose", "bend.yaml", "--muscles", muscles, "--out", f"run_{name}", "--quiet") == 0
    lengths = {name: np.loadtxt(d / f"run_{name}" / "stats.csv", delimiter=",", skiprows=1, usecols=2)
               for name in ("fitted", "model")}
    assert np.ptp(lengths["model"]) > 0.01  # the knee's bend shortens the path
    np.testing.assert_allclose(lengths["fitted"], lengths["model"], rtol=1e-12)
    manifest = json.loads((d / "paths" / "manifest.json").read_text())
    assert "model/tube.yaml" in [i["file"] for i in manifest["inputs"]], manifest["inputs"]
    (d / "pelvic").mkdir(exist_ok=True)
    (d / "pelvic" / "tube.yaml").write_text((d / "model" / "tube.yaml").read_text().replace("bone: tibia", "bone: pelvis"))
    assert run_cli(d, "fit", "tube.stl", "--skeleton", "leg.yaml", "--out", "pelvic_fit", "--units", "mm",
                   "--sections", "6", "--paths", "pelvic", "--quiet") == 0
    assert {p.bone for p in load_muscle_file(d / "pelvic_fit" / "muscles" / "tube.yaml")[0].axis} == {"pelvis"}
    (d / "other.stl").write_bytes((d / "tube.stl").read_bytes())
    err = _refused(d, capsys, "other.stl", "--units", "mm", "--paths", "model")
    assert "no muscle file other.yaml in --paths model" in err


# ----------------------------------------------------------------------------- hostile meshes and frames


def test_slivers_are_dropped_and_a_second_piece_is_refused_every_refusal_at_once(tube_fit, capsys):
    """A piece under 5% of the volume (FIT_MIN_PIECE_SHARE) is dropped, said on stderr and in
    the report; a second tube is a second muscle, refused; every refused mesh of the batch is
    named in one error and nothing is written."""
    import trimesh

    d, _, mesh = tube_fit
    blob = trimesh.creation.icosphere(2, 3.0)  # 113 mm^3 of a ~40,000 mm^3 tube
    blob.apply_translation([200.0, 0, 800.0])
    trimesh.util.concatenate([mesh, blob]).export(d / "sliver.stl")
    capsys.readouterr()
    assert run_cli(d, "fit", "sliver.stl", "--skeleton", "leg.yaml", "--out", "sliver", "--units", "mm",
                   "--sections", "4", "--quiet") == 0
    err = capsys.readouterr().err
    assert "axdf: note: sliver.stl: 1 closed pieces under 5% of its volume dropped as slivers" in err, err
    (m,) = json.loads((d / "sliver" / "fit_report.json").read_text())["muscles"]
    share = blob.volume / (blob.volume + mesh.volume)
    assert m["dropped_pieces"] == 1 and m["dropped_volume_share"] == pytest.approx(share, rel=1e-6)
    assert m["mesh_volume_cm3"] == pytest.approx(mesh.volume / 1000.0, rel=1e-6)
    assert "Slivers dropped" in (d / "sliver" / "FIT.md").read_text()
    trimesh.util.concatenate([mesh, mesh.copy().apply_translation([100.0, 0, 0])]).export(d / "pair.stl")
    trimesh.Trimesh(mesh.vertices, mesh.faces[:-5], process=False).export(d / "holed.ply")
    capsys.readouterr()
    assert run_cli(d, "fit", "tube.stl", "pair.stl", "holed.ply", "--skeleton", "leg.yaml", "--out", "batch",
                   "--units", "mm", "--quiet") == 2
    err = capsys.readouterr().err
    assert "pair.stl: mesh is 2 separate closed pieces, 2 of them at least 5% of its volume (50.0%, 50.0%)" in err
    assert "holed.ply: mesh is not closed" in err
    assert len(err.strip().splitlines()) == 2 and "Traceback" not in err
    assert not (d / "batch").exists()


def test_a_mesh_far_from_every_bone_is_refused_and_a_transform_brings_it_home(tube_fit, capsys):
    """The tube a metre off the skeleton: refused with the distance and the way out (--transform,
    --units); a --transform file that moves it back fits it as the tube itself; a transform that
    is not one is refused by position."""
    d, _, mesh = tube_fit
    mesh.copy().apply_translation([1000.0, 0, 0]).export(d / "away.stl")
    err = _refused(d, capsys, "away.stl", "--units", "mm")
    assert "away.stl: the mesh lies 0.9" in err and "from the nearest bone of leg at rest" in err
    assert "--transform FILE" in err and "check --units" in err
    (d / "home.yaml").write_text("matrix:\n  - [1, 0, 0, -1.0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 0, 1]\n")
    assert run_cli(d, "fit", "away.stl", "--transform", "home.yaml", "--skeleton", "leg.yaml", "--out", "home",
                   "--units", "mm", "--sections", "12", "--quiet") == 0
    (m,) = json.loads((d / "home" / "fit_report.json").read_text())["muscles"]
    assert m["iou"] >= 0.9 and abs(m["volume_ratio"] - 1.0) <= 0.05, m
    assert json.loads((d / "home" / "fit_report.json").read_text())["transform"] == "home.yaml"
    (d / "flat.yaml").write_text("matrix:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 0, 0]\n  - [0, 0, 0, 1]\n")
    assert "flat.yaml:2:3: the matrix's 3x3 part is singular" in _refused(d, capsys, "tube.stl", "--units", "mm",
                                                                         "--transform", "flat.yaml")
    (d / "row.yaml").write_text("matrix:\n  - [1, 0, 0, 0]\n  - [0, 1, 0, 0]\n  - [0, 0, 1, 0]\n  - [0, 0, 1, 1]\n")
    assert "row.yaml:5:5: the last row is [0.0, 0.0, 1.0, 1.0]" in _refused(d, capsys, "tube.stl", "--units", "mm",
                                                                            "--transform", "row.yaml")
