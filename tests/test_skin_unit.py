"""`axdf skin`'s parts in process: the CC0 body, its fit to a
skeleton's rest pose, the fat map, inside/outside and the push (axdf_cli/tools/skin*.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from axdf_cli.errors import InputError, Mark
from axdf_cli.specs import load_skeleton
from axdf_cli.tools import skin as sk
from axdf_cli.geometry.winding import inside
from axdf_cli.geometry.grow import grow_over
from conftest import REPO_ROOT

SKELETONS = REPO_ROOT / "poses" / "skeletons"


@pytest.fixture(scope="module")
def body():
    return sk.load_body()


@pytest.fixture(scope="module", params=["gait2392", "cmu_131_01"])
def fitted(request, body):
    skel = load_skeleton(SKELETONS / f"{request.param}.yaml")
    return skel, sk.fit_body(skel, body, Mark(request.param))


def test_body_is_makehumans_closed_body(body):
    assert body.vertices.shape == (13380, 3)
    m = trimesh.Trimesh(body.vertices, body.faces, process=False)
    assert m.is_watertight and m.volume > 0
    height = np.ptp(body.vertices[:, 2])
    assert 1.6 < height < 1.7  # hm08's base mesh, 16.66 dm
    np.testing.assert_allclose(body.weights.sum(axis=1), 1.0, atol=1e-9)
    assert (sk.ASSETS / "LICENSE.md").read_text().startswith("# Creative Commons CC0")


def test_missing_body_is_refused(tmp_path):
    with pytest.raises(InputError, match="body assets are missing") as e:
        sk.load_body(tmp_path / "body.npz")
    assert "extract_makehuman.py" in str(e.value)


def test_fitted_height_within_3_percent_of_the_stature(fitted):
    skel, fit = fitted
    assert abs(fit.height / fit.stature - 1.0) < 0.03
    assert 1.4 < fit.stature < 1.9
    assert abs(fit.rest_height / fit.stature - 1.0) < 0.05  # posed: CMU's rest pose spreads the legs


def test_fitted_skin_is_one_closed_surface(fitted):
    _, fit = fitted
    m = trimesh.Trimesh(fit.vertices, fit.faces, process=False)
    assert m.is_watertight and m.volume > 0.03  # litres of a person, not a crumpled sheet
    assert len(m.split(only_watertight=False)) == 1


def test_weights_sum_to_one_on_skeleton_bones_only(fitted):
    skel, fit = fitted
    np.testing.assert_allclose(fit.weights.sum(axis=1), 1.0, atol=1e-9)
    assert (fit.weights >= 0).all()
    assert set(fit.bones) <= set(skel.bone_index)
    assert fit.weights.shape == (len(fit.vertices), len(fit.bones))


def test_fitted_joints_land_on_the_skeletons_joints(fitted, body):
    """The knees of the fitted body (MakeHuman's knee landmark carried by the blend) lie
    within a few centimetres of the skeleton's knees."""
    skel, fit = fitted
    fam = sk.family_of(skel, Mark("x"))
    lm, _ = sk.skeleton_landmarks(skel, fam)
    mh = sk.mh_landmarks(body)
    for side in "lr":
        near = np.argsort(np.linalg.norm(body.vertices - mh[f"knee_{side}"], axis=1))[:40]  # the knee's ring
        centre = fit.vertices[near].mean(axis=0)
        assert np.linalg.norm(centre - lm[f"knee_{side}"]) < 0.05


def test_a_skeleton_of_no_family_is_refused():
    skel = load_skeleton(SKELETONS / "arm26.yaml")
    with pytest.raises(InputError, match="no family"):
        sk.family_of(skel, Mark("arm26.yaml"))


def test_stature_from_the_legs_alone():
    lm = {f"{k}_{s}": np.array(p) for s, x in (("l", 0.1), ("r", -0.1))
          for k, p in (("hip", [x, 0, 0.9]), ("knee", [x, 0, 0.5]), ("ankle", [x, 0, 0.1]))}
    lm["hip_c"] = np.array([0, 0, 0.9])
    assert sk.stature(lm) == pytest.approx(0.8 / 0.491)


def test_fat_map_follows_the_table(body):
    skel = load_skeleton(SKELETONS / "gait2392.yaml")
    fit = sk.fit_body(skel, body, Mark("x"))
    region, fat = sk.fat_map(body, fit)
    assert fat.shape == (13380,) and (fat > 0).all()
    r = {name: np.median(fat[region == i]) for i, name in enumerate(sk.REGIONS)}
    assert r["abdomen"] > r["thigh"] > r["forearm"]
    assert r["abdomen"] == pytest.approx(sk.FAT_MM["abdomen"][0] / 1000 * fit.scale, rel=0.2)


def test_outside_and_push():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    rng = np.random.default_rng(7)
    pts = rng.normal(size=(200, 3))
    pts = pts / np.linalg.norm(pts, axis=1, keepdims=True) * rng.uniform(0.02, 0.13, size=(200, 1))
    out = ~inside(sphere.vertices, sphere.faces, pts)
    np.testing.assert_array_equal(out, np.linalg.norm(pts, axis=1) > 0.1 * 0.999)
    pushed = grow_over(sphere.vertices, sphere.faces, pts)
    assert out.sum() > 50 and inside(pushed, sphere.faces, pts).all()
    assert trimesh.Trimesh(pushed, sphere.faces, process=False).is_watertight


def test_the_volume_steps_common_depth_takes_the_excess_exactly():
    """uniform_depth: every vertex in by min(d, its slack) takes exactly the volume asked
    (sum of area * min(d, slack)); where even the largest slack falls short, d is that slack."""
    from axdf_cli.pipeline.skin_stage import uniform_depth

    rng = np.random.default_rng(7)
    area, slack = rng.uniform(1e-4, 4e-4, 500), rng.uniform(0.0, 0.008, 500)
    slack[:100] = 0.0  # held at their floor
    full = float(np.sum(area * slack))
    for share in (0.05, 0.5, 0.95):
        d = uniform_depth(area, slack, share * full)
        assert np.sum(area * np.minimum(d, slack)) == pytest.approx(share * full, rel=1e-9)
    assert uniform_depth(area, slack, 2 * full) == pytest.approx(slack.max())
    assert uniform_depth(area, slack, 0.0) == 0.0


def test_a_point_sliding_and_rising_moves_its_push_continuously():
    """push_floor: a point's push is a continuous function of where it is. Sliding across a
    flat patch of skin it hands its push from vertex to vertex without a jump (the vertex under
    it pushed in full); rising through SKIN_MAX_HEIGHT (a crease) it lets go gradually. Without
    either, 0.1 mm of motion dropped a whole push (~40 mm): a pop."""
    from axdf_cli import tolerances as tol
    from axdf_cli.model import skin as kernels

    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0), indexing="ij"), -1).reshape(-1, 2) * 0.01
    x = np.c_[g, np.zeros(len(g))]  # a 5 x 5 patch, 1 cm spacing, normals +z
    n = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    cand = np.argsort(np.linalg.norm(x[:, None] - x[None], axis=2), axis=1)[12][None, :9].astype(np.int64)
    spread_in, spread_out = np.full(len(x), 0.01), np.full(len(x), 0.02)
    room = np.full(len(x), 0.004)
    target = np.full(cand.shape, 0.005)

    def floor_at(p):
        out = np.empty(len(x))
        kernels.push_floor(np.array([p]), x, n, cand, target, spread_in, spread_out, room,
                           tol.SKIN_SOFT_HEIGHT, tol.SKIN_MAX_HEIGHT, out)
        return out

    slide = np.array([floor_at([0.015 + s, 0.02, 0.01]) for s in np.linspace(0.0, 0.01, 200)])
    assert slide[0, 12] == pytest.approx(0.015) and slide[-1, 17] == pytest.approx(0.015)  # under it: in full
    assert np.abs(np.diff(slide, axis=0)).max() < 0.001  # 0.05 mm of sliding never moves a push by 1 mm
    rise = np.array([floor_at([0.02, 0.02, h]) for h in np.linspace(0.0, tol.SKIN_MAX_HEIGHT + 0.005, 400)])
    assert rise[0, 12] == pytest.approx(0.005) and rise[:, 12].max() > tol.SKIN_SOFT_HEIGHT  # it pushes below
    assert rise[-1, 12] == pytest.approx(-0.004)  # above the limit it asks nothing: the vertex's room
    assert np.abs(np.diff(rise, axis=0)).max() < 0.002  # 0.1 mm of height never moves a push by 2 mm
