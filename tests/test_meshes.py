"""Mesh topology and the mesh writers.

The tessellation is closed and consistently wound with positive volume; PLY and OBJ files
written by the writers read back (trimesh, ``process=False``; and ``read_triangles``) to the same
vertices, normals and faces; PLY bytes are deterministic.
"""
from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from axdf_cli.formats import WRITERS, ObjWriter, PlyWriter
from axdf_cli.formats import read_triangles
from axdf_cli.model.muscle import grid_faces
from axdf_cli.model.pose import sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics

from conftest import mesh_volume


def grid_to_vertices(g: np.ndarray) -> np.ndarray:
    """(F, U, A, 3) grid with collapsed pole rows → (F, 2 + (U-2) A, 3) vertices."""
    f, u, a, _ = g.shape
    return np.concatenate([g[:, :1, 0], g[:, 1:-1].reshape(f, (u - 2) * a, 3), g[:, -1:, 0]], axis=1)


def _trimesh(v, f):
    return trimesh.Trimesh(vertices=np.asarray(v, dtype=np.float64), faces=f, process=False)


def _demo_frames(demo):
    frames = np.array([0, 16, 32, 72, 120, 136, 168])
    return frames, forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))


# ----------------------------------------------------------------------------- topology


@pytest.mark.parametrize("along,around", [(3, 3), (4, 5), (21, 16), (40, 24)])
def test_grid_faces_close_a_sphere(along, around):
    """The face list alone makes a closed, consistently wound genus-0 surface with outward
    orientation (checked on a sampled unit sphere)."""
    f = grid_faces(along, around)
    assert f.dtype == np.int32
    assert f.shape == (2 * around * (along - 2), 3)
    th = np.linspace(0, np.pi, along)[:, None]
    ph = (np.arange(around) * 2 * np.pi / around)[None, :]
    # the surface runs from the origin pole at -Z to the insertion pole at +Z
    g = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), -np.cos(th) * np.ones_like(ph)], axis=-1)
    v = grid_to_vertices(g[None])[0]
    assert v.shape == (2 + (along - 2) * around, 3)
    m = _trimesh(v, f)
    assert m.is_watertight and m.is_winding_consistent
    assert m.euler_number == 2
    assert m.volume > 0
    assert np.all(np.bincount(f.ravel(), minlength=len(v)) > 0)


def test_demo_meshes_are_closed_and_outward(demo):
    frames, world = _demo_frames(demo)
    for model in demo.models:
        name = model.spec.name
        along, around = model.spec.resolution
        res = model.evaluate(np.concatenate([demo.rest[None], world]), np.linspace(0, 1, len(frames) + 1))
        assert model.faces.shape == (2 * around * (along - 2), 3)
        assert model.n_vertices == 2 + (along - 2) * around == res.vertices.shape[1]
        for v, vol in zip(res.vertices, res.volume):
            m = _trimesh(v.astype(np.float32), model.faces)
            assert m.is_watertight, name
            assert m.is_winding_consistent, name
            assert m.euler_number == 2, name
            assert m.volume > 0, name
            np.testing.assert_allclose(m.volume, vol, rtol=1e-5)  # float32 vertices
            assert np.all(m.area_faces > 0), name
        # same faces every frame, and the rest mesh has no duplicate vertices but the poles'
        rest = res.vertices[0]
        d = np.linalg.norm(rest[:, None] - rest[None], axis=-1) + np.eye(len(rest))
        assert d.min() > 1e-6, name


def test_reported_volume_is_the_mesh_volume(demo):
    frames, world = _demo_frames(demo)
    for model in demo.models:
        res = model.evaluate(world, np.zeros(len(frames)))
        for v, vol in zip(res.vertices, res.volume):
            assert mesh_volume(v, model.faces) == pytest.approx(vol, rel=1e-12)


# ----------------------------------------------------------------------------- writers


@pytest.fixture(scope="module")
def sample_mesh(demo):
    """A deformed demo muscle with precision-stressing extras mixed into its coordinates."""
    model = demo.models[0]
    frames, world = _demo_frames(demo)
    res = model.evaluate(world[2:3], np.ones(1))
    pos = res.vertices[0].copy()
    pos[1] = [-0.0, 1e-7, 123.456789]  # negative zero, tiny, large with many digits
    pos[2] = [-1e-9, 3.0e-5, -7.25]
    return pos, res.normals[0], model.faces, model.spec.name


def test_writers_table():
    assert set(WRITERS) == {"ply", "obj"}
    assert WRITERS["ply"] is PlyWriter and WRITERS["obj"] is ObjWriter
    for ext, cls in WRITERS.items():
        assert cls.extension == ext


def test_ply_round_trip_trimesh(sample_mesh, tmp_path):
    pos, nrm, faces, name = sample_mesh
    data = PlyWriter(faces, name).encode(pos, nrm)
    path = tmp_path / "m.ply"
    path.write_bytes(data)
    m = trimesh.load(path, process=False)
    np.testing.assert_array_equal(m.vertices, pos.astype(np.float32).astype(np.float64))
    np.testing.assert_array_equal(m.faces, faces)
    np.testing.assert_allclose(m.vertex_normals, nrm.astype(np.float32), rtol=0, atol=1e-6)
    # from bytes, too
    m2 = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    np.testing.assert_array_equal(m2.vertices, m.vertices)


def test_ply_round_trip_read_triangles(sample_mesh):
    pos, nrm, faces, name = sample_mesh
    data = PlyWriter(faces, name).encode(pos, nrm)
    p, n, f = read_triangles(data, ".ply")
    assert p.dtype == n.dtype == np.float32 and f.dtype == np.int32
    np.testing.assert_array_equal(p, pos.astype(np.float32))
    np.testing.assert_array_equal(n, nrm.astype(np.float32))
    np.testing.assert_array_equal(f, faces)
    # exact layout: header + 6 float32 per vertex + (uchar + 3 int32) per face
    header = data[: data.index(b"end_header\n") + len(b"end_header\n")]
    assert len(data) == len(header) + 24 * len(pos) + 13 * len(faces)


def test_ply_header_has_no_timestamp_or_path(sample_mesh):
    pos, nrm, faces, name = sample_mesh
    data = PlyWriter(faces, name).encode(pos, nrm)
    header = data[: data.index(b"end_header\n")].decode("ascii").splitlines()
    assert header == ["ply", "format binary_little_endian 1.0", f"comment axdf muscle {name}",
                      f"element vertex {len(pos)}", "property float x", "property float y", "property float z",
                      "property float nx", "property float ny", "property float nz",
                      f"element face {len(faces)}", "property list uchar int vertex_indices"]


def test_ply_bytes_are_deterministic(sample_mesh):
    pos, nrm, faces, name = sample_mesh
    a = PlyWriter(faces, name).encode(pos, nrm)
    b = PlyWriter(faces.copy(), name).encode(pos.copy(), nrm.copy())
    c = PlyWriter(faces, name).encode(pos.astype(np.float32), nrm.astype(np.float32))
    assert a == b == c
    assert PlyWriter(faces, name).encode(pos, nrm) == a


def test_ply_without_normals_reads_back_and_interleaves_with_normals(sample_mesh):
    """Positions only (bone meshes): x y z per vertex; the same writer then writes normals again."""
    pos, nrm, faces, name = sample_mesh
    w = PlyWriter(faces)
    data = w.encode(pos)
    assert b"property float nx" not in data and b"comment" not in data
    v, n, f = read_triangles(data, ".ply")
    assert n is None and np.array_equal(f, faces) and np.allclose(v, pos, atol=1e-6)
    m = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    assert np.allclose(m.vertices, pos, atol=1e-6) and np.array_equal(m.faces, faces)
    assert w.encode(pos, nrm) == PlyWriter(faces).encode(pos, nrm)
    assert w.encode(pos) == data


def test_obj_round_trip_trimesh(sample_mesh, tmp_path):
    pos, nrm, faces, name = sample_mesh
    data = ObjWriter(faces, name).encode(pos, nrm)
    path = tmp_path / "m.obj"
    path.write_bytes(data)
    m = trimesh.load(path, process=False)
    assert isinstance(m, trimesh.Trimesh)
    np.testing.assert_allclose(m.vertices, pos, rtol=0, atol=1e-6)  # 6 decimals
    np.testing.assert_array_equal(m.faces, faces)
    np.testing.assert_allclose(m.vertex_normals, nrm, rtol=0, atol=2e-6)


def test_obj_text(sample_mesh):
    pos, nrm, faces, name = sample_mesh
    data = ObjWriter(faces, name).encode(pos, nrm)
    text = data.decode("ascii")
    lines = text.splitlines()
    assert lines[0] == f"o {name}"
    assert sum(ln.startswith("v ") for ln in lines) == len(pos)
    assert sum(ln.startswith("vn ") for ln in lines) == len(pos)
    assert sum(ln.startswith("f ") for ln in lines) == len(faces)
    assert "-0.000000" not in text
    assert lines[2] == "v 0.000000 0.000000 123.456789"
    first_face = next(ln for ln in lines if ln.startswith("f "))
    a, b, c = faces[0] + 1
    assert first_face == f"f {a}//{a} {b}//{b} {c}//{c}"
    assert ObjWriter(faces, name).encode(pos, nrm) == data
