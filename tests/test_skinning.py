"""The skin stage's skinning methods (axdf_cli/model/skinning.py) and the fold measure
(axdf_cli/geometry/winding.py) on closed forms: a twisted cylinder (the candy wrapper), delta
mush at rest, two spheres through each other; and the skin file's ``skinning:`` key."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.errors import InputError
from axdf_cli.geometry.winding import folded, folded_share
from axdf_cli.model.skin import normals_volume
from axdf_cli.model.skinning import SKINNING, dual_quaternions, mush_rest, skin_points
from axdf_cli.pipeline.skin_stage import ring

ROOT = Path(__file__).resolve().parents[1]


def cylinder(radius=0.05, length=0.4, rings=41, around=24):
    """A closed tube along z (0..length), capped by a vertex at each end, wound outward →
    (vertices (V, 3), faces (T, 3))."""
    a = 2 * np.pi * np.arange(around) / around
    z = np.linspace(0.0, length, rings)
    v = np.stack([np.tile(radius * np.cos(a), rings), np.tile(radius * np.sin(a), rings), np.repeat(z, around)], 1)
    f = []
    for r in range(rings - 1):
        for k in range(around):
            p, q = r * around + k, r * around + (k + 1) % around
            f += [(p, q, q + around), (p, q + around, p + around)]
    bottom, top = len(v), len(v) + 1
    v = np.concatenate([v, [[0, 0, 0], [0, 0, length]]])
    top0 = (rings - 1) * around
    f += [(bottom, (k + 1) % around, k) for k in range(around)]
    f += [(top, top0 + k, top0 + (k + 1) % around) for k in range(around)]
    return v, np.array(f, np.int64)


def two_bone_weights(v, length):
    """Weights on two bones along z: the first's below the middle fifth, the second's above,
    a linear ramp between."""
    t = np.clip((v[:, 2] / length - 0.4) / 0.2, 0.0, 1.0)
    return np.ascontiguousarray(np.stack([1 - t, t], axis=1))


def twist(angle):
    """(2, 3, 4): the first bone at rest, the second turned by ``angle`` about the tube's axis."""
    c, s = np.cos(angle), np.sin(angle)
    rel = np.zeros((2, 3, 4))
    rel[0, :, :3] = np.eye(3)
    rel[1, :, :3] = [[c, -s, 0], [s, c, 0], [0, 0, 1]]
    return rel


def volume(v, f):
    return normals_volume(np.ascontiguousarray(v), f, np.empty_like(v))


def test_dual_quaternions_keep_a_twisted_cylinder_where_linear_blend_collapses_it():
    v, f = cylinder()
    w = two_bone_weights(v, 0.4)
    rest = volume(v, f)
    out = {}
    for method in ("linear", "dual_quaternion"):
        x = np.empty_like(v)
        skin_points(method, w, twist(np.radians(170)), v, x)
        out[method] = volume(x, f) / rest
    # the candy wrapper: at 170 degrees LBS pinches the twisting fifth towards its axis (13%
    # of the tube's volume lost)
    assert out["linear"] < 0.9
    assert abs(out["dual_quaternion"] - 1.0) < 0.01
    # every DQS vertex keeps its distance from the axis (a rigid turn about it)
    x = np.empty_like(v)
    skin_points("dual_quaternion", w, twist(np.radians(170)), v, x)
    np.testing.assert_allclose(np.hypot(x[:, 0], x[:, 1]), np.hypot(v[:, 0], v[:, 1]), rtol=0, atol=1e-12)


def test_dual_quaternions_of_one_bone_are_its_rigid_transform():
    rng = np.random.default_rng(7)
    from scipy.spatial.transform import Rotation

    rel = np.zeros((3, 3, 4))
    rel[:, :, :3] = Rotation.from_rotvec(rng.normal(size=(3, 3)) * 2).as_matrix()
    rel[:, :, 3] = rng.normal(size=(3, 3))
    p = rng.normal(size=(20, 3))
    for k in range(3):
        w = np.zeros((20, 3))
        w[:, k] = 1.0
        x = np.empty_like(p)
        skin_points("dual_quaternion", w, rel, p, x)
        np.testing.assert_allclose(x, p @ rel[k, :, :3].T + rel[k, :, 3], rtol=0, atol=1e-12)
    assert (dual_quaternions(rel)[:, 0] >= 0).all()


def _mush(v, f, iterations=10, step=0.5):
    ptr, idx = ring(f, len(v))
    return (f, ptr, idx, iterations, step, mush_rest(v, f, ptr, idx, iterations, step))


def test_delta_mush_at_rest_and_under_one_rigid_motion_is_exact():
    v, f = cylinder()
    w = two_bone_weights(v, 0.4)
    mush = _mush(v, f)
    rest = np.zeros((2, 3, 4))
    rest[:, :, :3] = np.eye(3)
    x = np.empty_like(v)
    skin_points("delta_mush", w, rest, v, x, mush)
    np.testing.assert_allclose(x, v, rtol=0, atol=1e-12)
    # both bones turned and moved alike: the mesh moves rigidly, detail and all
    rel = twist(np.radians(60))
    rel[0] = rel[1]
    rel[:, :, 3] = [0.1, -0.2, 0.3]
    skin_points("delta_mush", w, rel, v, x, mush)
    np.testing.assert_allclose(x, v @ rel[0, :, :3].T + rel[0, :, 3], rtol=0, atol=1e-12)


def test_delta_mush_differs_from_linear_blend_only_where_it_bends():
    v, f = cylinder()
    w = two_bone_weights(v, 0.4)
    rel = twist(np.radians(90))
    lbs, dm = np.empty_like(v), np.empty_like(v)
    skin_points("linear", w, rel, v, lbs)
    skin_points("delta_mush", w, rel, v, dm, _mush(v, f))
    moved = np.linalg.norm(dm - lbs, axis=1)
    assert moved[(v[:, 2] > 0.18) & (v[:, 2] < 0.22)].max() > 1e-3  # the twist's middle
    assert moved[v[:, 2] < 0.05].max() < 1e-9  # far from it, where every neighbour is rigid


def icosphere(level=3):
    t = (1 + 5 ** 0.5) / 2
    v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]]
    f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6],
         [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10],
         [8, 6, 7], [9, 8, 1]]
    v = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(level):
        mid, nf = {}, []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = v[a] + v[b]
                v.append(p / np.linalg.norm(p))
                mid[k] = len(v) - 1
            return mid[k]
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        f = nf
    return np.array(v), np.array(f, np.int64)


def test_the_fold_measure_finds_skin_through_skin_and_nothing_on_a_sphere():
    v, f = icosphere()
    v = v * 0.1
    assert folded_share(v, f) == 0.0
    # two spheres of 10 cm through each other, one mesh: a vertex of one inside the other is
    # folded (its point 2 mm out lies inside the skin), the others are not
    both = np.concatenate([v, v + [0.12, 0, 0]])
    faces = np.concatenate([f, f + len(v)])
    got = folded(both, faces)
    n = np.concatenate([v, v]) / 0.1
    probe = both + 0.002 * n
    centre = np.repeat([[0, 0, 0], [0.12, 0, 0]], len(v), axis=0)[::-1]  # the other sphere's centre
    d = np.linalg.norm(probe - centre, axis=1)
    sure = np.abs(d - 0.1) > 0.002  # away from the other sphere's faceted surface
    assert sure.mean() > 0.9
    np.testing.assert_array_equal(got[sure], d[sure] < 0.1)
    assert 0.1 < got.mean() < 0.5


def test_a_bent_tube_folds_its_crease_under_linear_blend():
    """A tube bent 150 degrees about an axis across it at its middle: linear blend collapses
    the inside of the bend into itself (folded vertices); the fold measure sees them."""
    v, f = cylinder(rings=61)
    w = two_bone_weights(v, 0.4)
    a = np.radians(150)
    c, s = np.cos(a), np.sin(a)
    rel = np.zeros((2, 3, 4))
    rel[0, :, :3] = np.eye(3)
    r = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # about y, through the middle (0, 0, 0.2)
    rel[1, :, :3] = r
    rel[1, :, 3] = [0, 0, 0.2] - r @ [0, 0, 0.2]
    x = np.empty_like(v)
    skin_points("linear", w, rel, v, x)
    assert folded_share(x, f) > 0.005
    assert folded_share(v, f) == 0.0


def test_the_skin_files_skinning_key_is_checked(tmp_path):
    from axdf_cli.specs.skin import load_skin

    shutil.copytree(ROOT / "skins" / "gait2392", tmp_path / "skin")
    path = tmp_path / "skin" / "skin.yaml"
    text = path.read_text()
    assert load_skin(path).skinning is None
    for method in SKINNING:
        path.write_text(text + f"skinning: {method}\n")
        assert load_skin(path).skinning == method
    path.write_text(text + "skinning: quaternions\n")
    line = len(text.splitlines()) + 1
    with pytest.raises(InputError) as e:
        load_skin(path)
    msg = str(e.value)
    assert f"skin.yaml:{line}:11" in msg, msg
    assert "linear, dual_quaternion, delta_mush" in msg, msg
