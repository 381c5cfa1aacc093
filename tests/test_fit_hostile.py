"""Hostile inputs to `axdf fit`, each refused with exit 2 by the file's name, no
traceback, nothing written; and the costs a hostile `--sections` could run up, bounded.

- a PLY face naming vertex 10^6 of a 642-vertex mesh (was exit 70, an IndexError);
- a binary STL whose header counts more triangles than it holds (was "holds no triangles", or
  "No module named 'charset_normalizer'" where that was not installed);
- a closed mesh with half its triangles flipped (was fitted at volume ratio 19.9);
- a mesh stem ending in a newline (`$` matched before it: muscles/nl\\n.yaml was written);
- `--paths` holding a link to a muscle file outside the folder tree (`run --muscles` refuses it);
- an axis on femur_l under a path on femur_r (passed silently);
- --sections 64: the rows' solve no longer builds a dense design of 3 P x 2 N k (830 MB).
"""
from __future__ import annotations

import struct
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from cli_in_folder import run_cli

SKELETON = """\
skeleton: leg
coordinates:
  hip: {type: rotation, range: [-30, 120]}
bones:
  - name: pelvis
    offset: [0, 0, 1.0]
  - name: femur
    parent: pelvis
    offset: [0, 0, -0.05]
    dofs:
      - {coord: hip, type: rotation, axis: [1, 0, 0]}
"""


def _ellipsoid(subdiv: int = 3):
    """A closed 642-vertex (subdiv 3) ellipsoid 0.24 m long beside the femur (metres)."""
    import trimesh

    m = trimesh.creation.icosphere(subdiv, 1.0)
    m.apply_scale([0.02, 0.02, 0.12])
    m.apply_translation([0.03, 0.0, 0.7])
    return m


@pytest.fixture()
def leg(tmp_path):
    (tmp_path / "leg.yaml").write_text(SKELETON)
    return tmp_path


def _refused(d: Path, capsys, *argv) -> str:
    capsys.readouterr()
    rc = run_cli(d, "fit", *argv, "--skeleton", "leg.yaml", "--out", "bad", "--quiet")
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err and "internal error" not in err, err
    assert not (d / "bad").exists()
    return err


def test_a_face_naming_a_vertex_the_file_lacks_is_refused(leg, capsys):
    import trimesh

    m = _ellipsoid()
    assert len(m.vertices) == 642
    f = m.faces.copy()
    f[5, 1] = 10**6
    trimesh.Trimesh(m.vertices, f, process=False).export(leg / "badface.ply")
    err = _refused(leg, capsys, "badface.ply")
    assert "badface.ply: face 5 (of 1280, counted from 0) names vertex 1000000, but the file has 642 vertices" in err


def test_a_binary_stl_with_a_lying_triangle_count_is_refused(leg, capsys):
    _ellipsoid().export(leg / "good.stl")
    data = bytearray((leg / "good.stl").read_bytes())
    data[80:84] = struct.pack("<I", 5000)
    (leg / "lie.stl").write_bytes(bytes(data))
    err = _refused(leg, capsys, "lie.stl")
    assert f"lie.stl: the binary STL's header counts 5000 triangles ({84 + 50 * 5000} bytes) but the file has " \
           f"{len(data)} bytes" in err
    (leg / "short.stl").write_bytes(bytes(data[:40]))
    assert "short.stl: a binary STL of 40 bytes" in _refused(leg, capsys, "short.stl")


def test_a_mesh_with_flipped_triangles_is_refused_and_one_inside_out_is_turned(leg, capsys):
    import trimesh

    from axdf_cli.tools.fit_mesh import read_mesh

    m = _ellipsoid()
    f = m.faces.copy()
    f[::2] = f[::2, ::-1]  # half of them
    trimesh.Trimesh(m.vertices, f, process=False).export(leg / "half.ply")
    err = _refused(leg, capsys, "half.ply")
    assert "half.ply: mesh is not consistently oriented:" in err and "some triangles are flipped" in err
    trimesh.Trimesh(m.vertices, m.faces[:, ::-1], process=False).export(leg / "inside_out.ply")
    got = read_mesh(leg / "inside_out.ply", 1.0)
    assert got.mesh.volume == pytest.approx(m.volume, rel=1e-6)  # turned outwards as a whole


def test_a_stem_ending_in_a_newline_names_no_muscle(leg, capsys):
    from axdf_cli.fileio.yamlio import is_name

    assert not is_name("nl\n") and not is_name("a\nb") and is_name("nl")
    _ellipsoid().export(leg / "nl\n.ply")
    err = _refused(leg, capsys, "nl\n.ply")
    assert "cannot name a muscle" in err and "'nl\\n'" in err


def test_paths_refuse_a_link_out_of_the_folder_tree(leg, tmp_path_factory, capsys):
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    (elsewhere / "ell.yaml").write_text("muscle: ell\npath:\n  - {bone: pelvis, at: [0, 0, -0.02]}\n"
                                        "  - {bone: femur, at: [0, 0, -0.3]}\n"
                                        "sections:\n  - {t: 0.5, radii: [0.02, 0.02], angle: 0}\n")
    (leg / "model").mkdir()
    (leg / "model" / "ell.yaml").symlink_to(elsewhere / "ell.yaml")
    _ellipsoid().export(leg / "ell.ply")
    (leg / "rest.yaml").write_text("pose: rest\nskeleton: leg.yaml\nfps: 30\nframes: [0, 1]\nkeys:\n  0: {hip: 0}\n")
    capsys.readouterr()
    assert run_cli(leg, "run", "--muscles", "model", "--pose", "rest.yaml", "--out", "r", "--quiet") == 2
    assert "leaves the project folder tree" in capsys.readouterr().err  # as run refuses it
    err = _refused(leg, capsys, "ell.ply", "--paths", "model", "--sections", "4")
    assert "model/ell.yaml: muscle file" in err and "leaves the project folder tree" in err


def test_an_axis_off_its_paths_bones_is_refused():
    from axdf_cli.errors import InputError
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs.muscle import parse_muscle_text
    from axdf_cli.specs.skeleton import parse_skeleton_text

    skel = parse_skeleton_text("skeleton: legs\nbones:\n  - name: pelvis\n    offset: [0, 0, 1]\n"
                               "  - {name: femur_r, parent: pelvis, offset: [0.08, 0, -0.05]}\n"
                               "  - {name: femur_l, parent: pelvis, offset: [-0.08, 0, -0.05]}\n", "legs.yaml")
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]

    def muscle(axis_bone: str):
        text = ("muscle: m\naxis:\n" + "".join(f"  - {{bone: {axis_bone}, at: [0, 0, {-0.05 * k - 0.02}]}}\n"
                                               for k in range(3)) +
                "path:\n  - {bone: femur_r, at: [0, 0, -0.02]}\n  - {bone: femur_r, at: [0, 0, -0.3]}\n")
        return parse_muscle_text(text, "m.yaml")[0]

    MuscleModel(muscle("femur_r"), skel.bone_index, rest, skel)  # the axis on its path's bone
    with pytest.raises(InputError) as e:
        MuscleModel(muscle("femur_l"), skel.bone_index, rest, skel)
    assert str(e.value).startswith("m.yaml:3:")
    assert "axis point on bone 'femur_l', which its path does not span; an axis on the bones of its path: femur_r" \
        in str(e.value)


def test_many_sections_cost_in_proportion(leg):
    """64 sections: the refinement's solve (the size fit_rows gives it) stays within 300 MB
    (180 MB measured; the dense design took 830 MB, and its two halves 830 MB more), and the
    sparse design is the dense one's entries."""
    from axdf_cli.tools import constants as tol
    from axdf_cli.tools import fit_sections as fs

    n = 64
    rng = np.random.default_rng(4)
    t = fs.greville(n)
    c = np.stack([np.zeros(n), np.zeros(n), 0.9 - 0.3 * t], axis=1)
    r = np.tile([1.0, 0, 0], (n, 1))
    s = np.tile([0, 1.0, 0], (n, 1))
    rows = fs.RowFit(c, r, s, np.array([[0, 0, 0.9], [0, 0, 0.6]]))
    m = tol.FIT_PLANES_PER_SECTION * n + 2 * tol.FIT_PLANES_PER_SECTION
    gu = np.repeat((np.arange(2 * m) + 0.5) / (2 * m), 2 * tol.FIT_AROUND)
    gv = np.tile(np.arange(2 * tol.FIT_AROUND) / (2 * tol.FIT_AROUND), 2 * m)
    xy = 0.02 * (1 + 0.1 * rng.random((n, rows.k, 2)))
    target = rows.evaluate(xy, gu, gv)
    normals = rng.standard_normal(target.shape)
    tracemalloc.start()
    try:
        got = rows.solve([(gu, gv, target, 1.0, normals), (gu, gv, target, tol.FIT_POINT_WEIGHT, None)])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 300 * 2**20, peak / 2**20
    assert np.abs(rows.evaluate(got, gu, gv) - target).max() < 1e-3
    # the same entries as the dense design (on a part small enough for both)
    old = tol.FIT_DENSE_DESIGN_BYTES
    try:
        tol.FIT_DENSE_DESIGN_BYTES = 0
        a_sparse, fixed = rows.design(gu[:2000], gv[:2000])
        tol.FIT_DENSE_DESIGN_BYTES = 1 << 40
        a_dense, fixed_dense = rows.design(gu[:2000], gv[:2000])
    finally:
        tol.FIT_DENSE_DESIGN_BYTES = old
    assert not isinstance(a_sparse, np.ndarray) and isinstance(a_dense, np.ndarray)
    np.testing.assert_array_equal(a_sparse.toarray(), a_dense)
    np.testing.assert_array_equal(fixed, fixed_dense)
