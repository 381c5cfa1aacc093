"""The geometry room (axdf_cli/geometry): one inside rule by the winding number, either
winding; holes capped; the bone meshes of a skeleton read and placed at rest."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh

from axdf_cli.geometry.mesh import capped
from axdf_cli.geometry.winding import inside, inside_share, push_out_of_meshes, winding_numbers
from conftest import REPO_ROOT


@pytest.fixture(scope="module")
def box():
    b = trimesh.creation.box(extents=[0.1, 0.1, 0.1])
    return np.asarray(b.vertices, np.float64), np.asarray(b.faces, np.int64)


@pytest.mark.parametrize("exact", [False, True])
def test_a_mesh_wound_inward_is_inside_the_same(box, exact):
    v, f = box
    pts = np.array([[0.0, 0.0, 0.0], [0.04, 0.01, -0.02], [0.2, 0.0, 0.0], [0.0, -0.06, 0.0]])
    want = [True, True, False, False]
    assert inside(v, f, pts, exact).tolist() == want
    assert inside(v, f[:, ::-1], pts, exact).tolist() == want  # (w near -1 inside)
    assert winding_numbers(v, f[:, ::-1], pts[:1], exact)[0] == pytest.approx(-1.0, abs=1e-6)
    assert inside_share(v, f, pts) == 0.5


def test_a_point_pushed_out_of_a_mesh_wound_inward(box):
    v, f = box
    out, moved = push_out_of_meshes(np.array([[0.045, 0.0, 0.0]]), [(v, f[:, ::-1])], 0.001)
    assert moved == 1 and out[0] == pytest.approx([0.051, 0.0, 0.0], abs=1e-9)


def test_capped_closes_each_hole_as_its_triangles_wind(box):
    v, f = box
    keep = np.ones(len(f), bool)
    keep[:2] = False  # two triangles gone: one hole of four edges
    cv, cf = capped(v, f[keep])
    assert len(cv) == len(v) + 1 and len(cf) == len(f) - 2 + 4
    m = trimesh.Trimesh(cv, cf, process=False)
    assert m.is_watertight and 0.5e-3 < m.volume < 1e-3  # (wound outward, as the box: a positive volume)
    assert inside(cv, cf, np.zeros((1, 3))).all()
    same_v, same_f = capped(v, f)  # (closed already)
    assert np.array_equal(same_v, v) and np.array_equal(same_f, f)


def test_rest_bone_meshes_capped_or_as_read():
    from axdf_cli.geometry.bones import rest_bone_meshes
    from axdf_cli.specs import load_skeleton

    path = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"
    skel = load_skeleton(path)
    plain = rest_bone_meshes(skel, str(path), lambda b: b.name in ("torso", "femur_r"))
    closed = rest_bone_meshes(skel, str(path), lambda b: b.name in ("torso", "femur_r"), cap=True)
    assert sorted(plain) == sorted(closed) == ["femur_r", "torso"]
    v, f, p = plain["torso"]
    assert v.dtype == np.float64 and f.dtype == np.int64 and p.name == "torso.ply"
    cv, cf, _ = closed["torso"]  # (open at the neck)
    assert len(cf) > len(f) and np.array_equal(cv[:len(v)], v)
    assert set(rest_bone_meshes(skel, str(path))) == {b.name for b in skel.bones if b.mesh}


def test_signed_keeps_the_older_rule_for_meshes_wound_inward(box):
    v, f = box
    pts = np.zeros((1, 3))
    assert inside(v, f, pts, signed=True).all() and not inside(v, f[:, ::-1], pts, signed=True).any()
    assert push_out_of_meshes(pts, [(v, f[:, ::-1])], 0.001, signed=True)[1] == 0
