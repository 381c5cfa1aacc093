"""Imported muscles: the path is the model's, and the axis follows it at rest."""
from __future__ import annotations

import numpy as np
import pytest

from osim_common import ARM, GAIT, needs_data, run_import

pytestmark = needs_data

END_TOL = 1e-4  # m: the bound (0.1 mm) for origin / insertion


@pytest.fixture(scope="module", params=[("arm26", ARM), ("gait2392", GAIT)], ids=["arm26", "gait2392"])
def imported(request, tmp_path_factory):
    from axdf_cli.importers.osim import load_osim

    name, model = request.param
    tmp = tmp_path_factory.mktemp(name)
    rc, out = run_import(tmp, model, "--name", name, "--no-meshes")
    assert rc == 0
    return name, load_osim(model), out


def _world(skel):
    from axdf_cli.model.skeleton import forward_kinematics

    return forward_kinematics(skel, skel.rest_coordinates()[None])[0]


def _point(world, skel, body, at):
    return (world[skel.bone_index[body]] @ np.append(at, 1.0))[:3]


def test_path_is_the_models_and_the_axis_follows_it(imported):
    """Every OpenSim path point is in the YAML path (conditional ones with their range, in
    degrees); at rest the axis starts at the origin, ends at the insertion and is as long as
    the wrapped path (within 1%)."""
    from axdf_cli.model import bspline
    from axdf_cli.specs import load_muscle_file, load_skeleton
    from axdf_cli.model.paths.path import PathModel

    name, model, out = imported
    skel = load_skeleton(out / "skeletons" / f"{name}.yaml")
    world = _world(skel)
    q = skel.rest_coordinates()[None]
    assert len(model.muscles) == {"arm26": 6, "gait2392": 92}[name]
    for m in model.muscles:
        (spec,) = load_muscle_file(out / "muscles" / f"{m.name}.yaml")
        assert not spec.axis and len(spec.path.points) == len(m.points)
        for p, yp in zip(m.points, spec.path.points):
            assert yp.bone == p.body and (p.moving is not None or np.allclose(yp.at, p.location)), (m.name, p.name)
            assert (yp.active is not None) == (p.kind == "conditional")
        assert [w.name for w in spec.path.wraps] == [w.wrap for w in m.wraps]
        pm = PathModel(spec.path, skel.bone_index, skel.coord_index)
        _, length, _ = pm.wrapped(world[None], q)
        ctrl, _ = pm.control_points(world[None], q)
        knots = bspline.clamped_knots(pm.n, 2)
        ends = bspline.basis_matrix(knots, 2, [0.0, 1.0]) @ ctrl[0]
        active = [p for p in m.points if p.active_at_rest]
        origin = _point(world, skel, active[0].body, active[0].location)
        insertion = _point(world, skel, active[-1].body, active[-1].location)
        assert np.linalg.norm(ends[0] - origin) < END_TOL, m.name
        assert np.linalg.norm(ends[1] - insertion) < END_TOL, m.name
        gt, gw = bspline.gauss_legendre_params(knots, 2, 8)
        arc = np.linalg.norm(bspline.basis_matrix(knots, 2, gt, 1) @ ctrl[0], axis=1) @ gw
        assert abs(arc - length[0]) / length[0] < 0.01, (m.name, arc, length[0])


def test_muscle_sizes_follow_force_and_fibre_length(imported):
    from axdf_cli.importers import emit
    from axdf_cli.specs import load_muscle_file

    name, model, out = imported
    for m in model.muscles:
        (spec,) = load_muscle_file(out / "muscles" / f"{m.name}.yaml")
        assert spec.volume == "exact"
        assert 0.0 <= spec.tendons[0] and 0.0 <= spec.tendons[1] and sum(spec.tendons) <= emit.MAX_TENDON_FRACTION + 1e-12
    import json
    rows = {r["muscle"]: r for r in json.loads((out / "import_report.json").read_text())["muscles"]}
    for m in model.muscles:
        r = rows[m.name]
        assert r["pcsa_m2"] == pytest.approx(m.max_isometric_force / emit.SPECIFIC_TENSION)
        assert r["volume_m3"] == pytest.approx(r["pcsa_m2"] * m.optimal_fiber_length)
        assert 1e-3 < r["belly_radius"] < 0.08, (m.name, r["belly_radius"])


def test_conditional_and_moving_points_at_rest():
    from axdf_cli.importers.osim import evaluate_function, load_osim

    model = load_osim(GAIT)
    cond = [p for m in model.muscles for p in m.points if p.kind == "conditional"]
    moving = [p for m in model.muscles for p in m.points if p.kind == "moving"]
    assert len(cond) == 26 and len(moving) == 8
    for p in cond:
        c, lo, hi = p.condition
        assert p.active_at_rest == (lo <= model.coordinates[c].default <= hi)
    # rect_fem_r's moving point at knee angle 0: the SimmSpline values at x = 0
    assert evaluate_function is not None
    rf = next(m for m in model.muscles if m.name == "rect_fem_r")
    mp = [p for p in rf.points if p.kind == "moving"]
    assert mp and all(np.all(np.isfinite(p.location)) for p in mp)
