"""Imported muscles: the axis passes through origin, insertion and via points at rest."""
from __future__ import annotations

import numpy as np
import pytest

from osim_common import ARM, GAIT, needs_data, run_import

pytestmark = needs_data

END_TOL = 1e-4  # m: the bound (0.1 mm) for origin / insertion
VIA_TOL = 1e-4  # m: via points (midpoints of control-point pairs at the knots)


@pytest.fixture(scope="module", params=[("arm26", ARM), ("gait2392", GAIT)], ids=["arm26", "gait2392"])
def imported(request, tmp_path_factory):
    from axdf_cli.importers.osim import load_osim

    name, model = request.param
    tmp = tmp_path_factory.mktemp(name)
    rc, out = run_import(tmp, model, "--name", name, "--no-meshes")
    assert rc == 0
    return name, load_osim(model), out


def _world(skel):
    from axdf_cli.skeleton import forward_kinematics

    return forward_kinematics(skel, skel.rest_coordinates()[None])[0]


def _point(world, skel, body, at):
    return (world[skel.bone_index[body]] @ np.append(at, 1.0))[:3]


def test_axis_passes_through_origin_insertion_and_via_points(imported):
    from axdf_cli import bspline
    from axdf_cli.loaders import load_muscle_file, load_skeleton

    name, model, out = imported
    skel = load_skeleton(out / "skeletons" / f"{name}.yaml")
    world = _world(skel)
    assert len(model.muscles) == {"arm26": 6, "gait2392": 92}[name]
    for m in model.muscles:
        (spec,) = load_muscle_file(out / "muscles" / f"{m.name}.yaml")
        ctrl = np.array([_point(world, skel, a.bone, a.at) for a in spec.axis])  # (n, 3) world, rest
        assert len(ctrl) >= 3
        knots = bspline.clamped_knots(len(ctrl), 2)
        ends = bspline.basis_matrix(knots, 2, [0.0, 1.0]) @ ctrl
        active = [p for p in m.points if p.active_at_rest]
        origin = _point(world, skel, active[0].body, active[0].location)
        insertion = _point(world, skel, active[-1].body, active[-1].location)
        assert np.linalg.norm(ends[0] - origin) < END_TOL, m.name
        assert np.linalg.norm(ends[1] - insertion) < END_TOL, m.name
        # every via point lies on the curve: at the knot between its control-point pair
        at_knots = bspline.basis_matrix(knots, 2, np.unique(knots)) @ ctrl
        for p in active[1:-1]:
            x = _point(world, skel, p.body, p.location)
            d = np.linalg.norm(at_knots - x, axis=1).min()
            assert d < VIA_TOL, (m.name, p.name, d)


def test_muscle_sizes_follow_force_and_fibre_length(imported):
    from axdf_cli.importers import emit
    from axdf_cli.loaders import load_muscle_file

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
