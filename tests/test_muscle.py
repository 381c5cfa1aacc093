"""Geometry invariants of the AxDf muscle (SPEC "Geometry guarantees").

Binding round trip, rest identity (model and pipeline), rigid invariance, finite output on
extreme poses, volume (paper exact for uniform stretch, exact within 0.5% on written
files), tension, twist (continuous past 180 degrees, frame subsets identical) and normals.
"""
from __future__ import annotations

import csv
import dataclasses
import json

import numpy as np
import pytest

from axdf_cli.model import bspline
from axdf_cli import tolerances as tol
from axdf_cli.formats import read_triangles
from axdf_cli.specs import load_muscle_file
from axdf_cli.model.muscle import OCT, MuscleModel, Section, ellipse_outline, grid_faces
from axdf_cli.model.skeleton import forward_kinematics

from conftest import (CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML, DEMO_MUSCLE_FILES, demo_extreme_coordinates,
                      mesh_volume,
                      random_rigid, ring_vector_area, rings, run_main, write_pose)


# ----------------------------------------------------------------------------- helpers


def evaluate_with_control_points(model, world, tension, monkeypatch, **kw):
    """Evaluate and also return the deformed section control points (F, 8N, 3): the compiled
    pass writes the ``fixed + s * scaled`` it tessellates (the real code path)."""
    cp = np.full((len(world), len(model.bind_t), 3), np.nan)
    res = model.evaluate(world, tension, control_points=cp, **kw)
    return cp, res


def tessellate_net(model, control_points, axis_points):
    """Independent tessellation of a muscle from its control net: (V, 3).

    Net rows: origin pole (8 copies of C(0)), the sections, insertion pole; along a clamped
    quadratic NURBS with the spec's weights, around a closed quadratic B-spline."""
    spec = model.spec
    along, around = spec.resolution
    m = len(spec.sections) + 2
    net = np.empty((m, OCT, 3))
    net[0] = axis_points[0]
    net[-1] = axis_points[-1]
    net[1:-1] = control_points.reshape(-1, OCT, 3)
    w = np.ones(m)
    if spec.weights is not None:
        w[1:-1] = spec.weights
    bu = bspline.basis_matrix(bspline.clamped_knots(m, 2), 2, np.linspace(0, 1, along))
    bu = bu * w / (bu * w).sum(axis=1, keepdims=True)
    bv = bspline.periodic_quadratic_basis(OCT, np.arange(around) / around)
    g = np.einsum("um,mjc,aj->uac", bu, net, bv)
    return np.concatenate([g[:1, 0], g[1:-1].reshape(-1, 3), g[-1:, 0]])


def rest_axis_points(model, rest_world):
    return model._axis_points(rest_world[None])[0]


def chain_variants(spec):
    """The chain muscle under every option that changes binding or shape."""
    return {
        "plain": spec,
        "paper": dataclasses.replace(spec, volume="paper"),
        "none": dataclasses.replace(spec, volume="none"),
        "twisted": dataclasses.replace(spec, twist=135.0),
        "tendons": dataclasses.replace(spec, tendons=(0.15, 0.25)),
        "strong": dataclasses.replace(spec, strength=2.5),
        "weights": dataclasses.replace(spec, weights=(1.0, 2.0, 0.5, 1.5)),
    }


def all_models(demo, chain_spec, chain_model):
    models = [(m.spec.name, m, demo.rest) for m in demo.models]
    for k, s in chain_variants(chain_spec).items():
        m = chain_model(s)
        models.append((f"chain-{k}", m, None))
    return models


# ----------------------------------------------------------------------------- binding


def test_binding_round_trip(demo, chain_spec, chain_model, chain_world, monkeypatch):
    """Deforming with the rest axis gives back the rest control points and the rest mesh."""
    for name, model, rest in all_models(demo, chain_spec, chain_model):
        rest = chain_world()[0] if rest is None else rest
        cp, res = evaluate_with_control_points(model, rest[None], np.zeros(1), monkeypatch)
        np.testing.assert_allclose(cp[0], model.rest_control_points, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(res.scale, 1.0, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(res.twist, 0.0, rtol=0, atol=1e-9, err_msg=name)
        # the whole rest mesh is the surface of the rest control net
        direct = tessellate_net(model, model.rest_control_points, rest_axis_points(model, rest))
        np.testing.assert_allclose(res.vertices[0], direct, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(model.rest_vertices, direct, rtol=0, atol=2e-7, err_msg=name)
        np.testing.assert_allclose(res.volume[0], model.v0, rtol=1e-12, err_msg=name)


def test_binding_is_the_closest_point_on_the_axis(demo, chain_spec, chain_model, chain_world):
    """(P - C(t)) . C'(t) = 0 at each bound parameter: the tangential coordinate u is 0."""
    for name, model, rest in all_models(demo, chain_spec, chain_model):
        rest = chain_world()[0] if rest is None else rest
        p = rest_axis_points(model, rest)
        c = bspline.basis_matrix(model.knots, 2, model.bind_t) @ p
        d = bspline.basis_matrix(model.knots, 2, model.bind_t, 1) @ p
        inner = (model.bind_t > 1e-9) & (model.bind_t < 1 - 1e-9)
        assert inner.all(), name
        g = np.einsum("qc,qc->q", model.rest_control_points - c, d / np.linalg.norm(d, axis=1, keepdims=True))
        np.testing.assert_allclose(g, 0.0, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(model.uvw[:, 0], 0.0, rtol=0, atol=1e-12, err_msg=name)
        # (t, u, v, w) reproduce the point in the rest frame at t
        np.testing.assert_allclose(np.linalg.norm(model.uvw, axis=1),
                                   np.linalg.norm(model.rest_control_points - c, axis=1), rtol=0, atol=1e-12)


def test_sections_are_placed_as_specified(demo, chain_spec, chain_model, chain_world):
    """Each ellipse section lies in the normal plane at its t, centred on the axis, with the
    outline's radii scaled by sqrt(strength)."""
    for name, model, rest in all_models(demo, chain_spec, chain_model):
        rest = chain_world()[0] if rest is None else rest
        p = rest_axis_points(model, rest)
        spec = model.spec
        cps = model.rest_control_points.reshape(-1, OCT, 3)
        for sec, pts in zip(spec.sections, cps):
            c = bspline.basis_matrix(model.knots, 2, [sec.t]) @ p
            d = bspline.basis_matrix(model.knots, 2, [sec.t], 1) @ p
            d /= np.linalg.norm(d)
            off = pts - c
            np.testing.assert_allclose(off @ d[0], 0.0, rtol=0, atol=1e-12, err_msg=name)
            if sec.outline is None:
                a, b = sec.radii if sec.radii is not None else (0.08 * model.l0, 0.06 * model.l0)
                o = ellipse_outline(a, b, sec.angle) * np.sqrt(spec.strength)
                np.testing.assert_allclose(off.mean(axis=0), 0.0, rtol=0, atol=1e-12, err_msg=name)
                np.testing.assert_allclose(np.linalg.norm(off, axis=1), np.linalg.norm(o, axis=1),
                                           rtol=0, atol=1e-12, err_msg=name)


def test_ellipse_outline_touches_the_ellipse():
    """The closed quadratic B-spline of the 8 outline points touches the ellipse at the edge
    midpoints (the points at v = j/8)."""
    a, b = 0.03, 0.017
    o = ellipse_outline(a, b, 0.0)
    mid = bspline.periodic_quadratic_basis(OCT, np.arange(OCT) / OCT) @ o
    np.testing.assert_allclose((mid[:, 0] / a) ** 2 + (mid[:, 1] / b) ** 2, 1.0, rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- rest identity


def test_rest_pose_through_the_pipeline_equals_rest(demo, repo_root):
    """Frame 0 of the demo pose is the rest pose with zero activation: every muscle equals
    its rest shape (plan_run + evaluate_chunks, the code path of `axdf run`; the model alone:
    contact, on by default, pushes the demo muscles off their bones, tests/test_contact.py)."""
    from axdf_cli import pipeline
    from axdf_cli.specs import RefPolicy, load_job

    policy = RefPolicy.for_command(["poses/jobs/demo.yaml"])  # as `axdf run` does
    plan = pipeline.plan_run(load_job("poses/jobs/demo.yaml", policy), frames_arg="0",
                             stages={"contact": False, "penetration": False})
    (_, world, results), = list(pipeline.evaluate_chunks(plan))
    np.testing.assert_allclose(world[0], demo.rest, rtol=0, atol=1e-15)
    for spec, model, (_, res) in zip(plan.muscles, plan.models, results):
        direct = tessellate_net(model, model.rest_control_points, rest_axis_points(model, demo.rest))
        np.testing.assert_allclose(res.vertices[0], direct, rtol=0, atol=1e-12, err_msg=spec.name)
        assert res.tension[0] == 0.0
        np.testing.assert_allclose(res.twist, 0.0, atol=1e-9)


def test_rest_pose_written_by_the_cli_equals_rest(demo, repo_root, tmp_path, capsys):
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--out", tmp_path / "o", "--frames", "0", "-q", "--no-contact"],
                          capsys)
    assert rc == 0, err
    for model in demo.models:
        name = model.spec.name
        ply = tmp_path / "o" / "meshes" / name / f"{name}_0000.ply"
        pos, nrm, faces = read_triangles(ply.read_bytes(), ".ply")
        direct = tessellate_net(model, model.rest_control_points, rest_axis_points(model, demo.rest))
        np.testing.assert_allclose(pos, direct, rtol=0, atol=2e-7, err_msg=name)  # float32 rounding
        np.testing.assert_allclose(nrm, model.rest_normals, rtol=0, atol=1e-6, err_msg=name)
        np.testing.assert_array_equal(faces, model.faces)


# ----------------------------------------------------------------------------- rigid motion

DEMO_NAMES = [s.name for f in DEMO_MUSCLE_FILES for s in load_muscle_file(f)]
ALIGNED_SECTIONS = tuple(Section(t, (0.02, 0.012), 15.0) for t in (0.25, 0.5, 0.75))


def _case(name, demo, chain_spec, chain_model, chain_world):
    """(model, rest world, a block of test poses) for a demo muscle or a chain variant."""
    if name in DEMO_NAMES:
        (model,) = [m for m in demo.models if m.spec.name == name]
        q = demo_extreme_coordinates(demo.skel, np.random.default_rng(DEMO_NAMES.index(name)), n_random=6)
        return model, demo.rest, forward_kinematics(demo.skel, q)
    variants = chain_variants(chain_spec)
    variants["aligned"] = dataclasses.replace(chain_spec, sections=ALIGNED_SECTIONS)
    model = chain_model(variants[name.split("-", 1)[1]])
    block = chain_world(bend=np.array([0.0, 45.0, 120.0, 150.0]), stretch=np.array([0.0, 0.3, -0.3, 0.5]),
                        roll=np.array([0.0, 200.0, -90.0, 30.0]))
    return model, chain_world()[0], block


RIGID_CASES = ([n for n in DEMO_NAMES]
               + [f"chain-{k}" for k in ("plain", "paper", "none", "twisted", "tendons", "strong", "weights")]
               + ["chain-aligned"])


@pytest.mark.parametrize("name", RIGID_CASES)
def test_rigid_invariance(name, demo, chain_spec, chain_model, chain_world):
    """Pre-multiplying every bone's world transform by one rigid motion moves the muscle
    rigidly (1e-9 m), normals rotate, and length, volume, scale and twist do not change."""
    model, _, world = _case(name, demo, chain_spec, chain_model, chain_world)
    rng = np.random.default_rng(30)
    tension = np.linspace(0.0, 1.0, len(world))
    a = model.evaluate(world, tension)
    for _ in range(3):
        m = random_rigid(rng, scale=2.0)
        moved = np.einsum("ij,fbjk->fbik", m, world)  # every bone pre-multiplied by m
        b = model.evaluate(moved, tension)
        np.testing.assert_allclose(b.vertices, a.vertices @ m[:3, :3].T + m[:3, 3], rtol=0, atol=1e-9)
        # normals are unit sums of face normals that nearly cancel where a pose folds the
        # surface: rounding is amplified there (seen 6e-9); they are written as float32
        np.testing.assert_allclose(b.normals, a.normals @ m[:3, :3].T, rtol=0, atol=1e-7)
        np.testing.assert_allclose(b.length, a.length, rtol=1e-12)
        np.testing.assert_allclose(b.volume, a.volume, rtol=1e-9)
        np.testing.assert_allclose(b.twist, a.twist, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.scale, a.scale, rtol=1e-9)


def test_demo_biceps_has_no_frame_to_frame_jitter(demo):
    """During the demo's shoulder abduction (frames 48..94) the biceps moves smoothly: the
    largest second difference of any vertex between consecutive frames stays below 5 mm
    (the smooth motion itself needs ~3 mm; a spinning section gives ~2 cm)."""
    from axdf_cli.model.pose import sample_coordinates

    frames = np.arange(48, 95)
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    (biceps,) = [m for m in demo.models if m.spec.name == "biceps_brachii"]
    v = biceps.evaluate(world, np.zeros(len(frames))).vertices
    jitter = np.abs(v[2:] - 2 * v[1:-1] + v[:-2]).max()
    assert jitter < 5e-3, jitter


@pytest.mark.parametrize("name", DEMO_NAMES)
def test_rest_shape_is_independent_of_the_skeleton_placement(name, demo):
    """Binding a muscle on a rigidly moved rest skeleton gives the moved rest muscle."""
    (model,) = [m for m in demo.models if m.spec.name == name]
    m = random_rigid(np.random.default_rng(31))
    moved_rest = np.einsum("ij,bjk->bik", m, demo.rest)
    other = MuscleModel(model.spec, demo.skel.bone_index, moved_rest)
    res = other.evaluate(moved_rest[None], np.zeros(1))
    base = model.evaluate(demo.rest[None], np.zeros(1))
    np.testing.assert_allclose(other.v0, model.v0, rtol=1e-9)
    np.testing.assert_allclose(res.vertices[0], base.vertices[0] @ m[:3, :3].T + m[:3, 3], rtol=0, atol=1e-9)


def test_rest_shape_is_independent_of_a_skeleton_translation(demo):
    """A pure translation of the rest skeleton (no rotation) translates the rest muscle."""
    m = np.eye(4)
    m[:3, 3] = [0.3, -1.2, 0.7]
    moved_rest = np.einsum("ij,bjk->bik", m, demo.rest)
    for model in demo.models:
        other = MuscleModel(model.spec, demo.skel.bone_index, moved_rest)
        np.testing.assert_allclose(other.rest_control_points, model.rest_control_points + m[:3, 3],
                                   rtol=0, atol=1e-9, err_msg=model.spec.name)


# ----------------------------------------------------------------------------- extreme poses


def test_finite_output_on_extreme_poses(demo):
    skel = demo.skel
    rest = skel.rest_coordinates()
    ci = skel.coord_index
    qs = []
    for i in range(len(rest)):
        for v in (720.0, -720.0, 359.0, 181.0):
            q = rest.copy()
            q[i] = v
            qs.append(q)
    for v in (720.0, -720.0):
        qs.append(np.full(len(rest), v))
    q = rest.copy()
    q[ci["knee_flexion_r"]] = 179.0
    q[ci["elbow_flexion_r"]] = 179.0
    qs.append(q)
    rng = np.random.default_rng(32)
    qs += list(rng.uniform(-720, 720, size=(8, len(rest))))
    world = forward_kinematics(skel, np.array(qs))
    for model in demo.models:
        res = model.evaluate(world, np.linspace(0, 1, len(qs)))
        for field in ("vertices", "normals", "length", "volume", "scale", "twist", "tension"):
            assert np.all(np.isfinite(getattr(res, field))), (model.spec.name, field)
        np.testing.assert_allclose(np.linalg.norm(res.normals, axis=-1), 1.0, rtol=0, atol=1e-9)
        assert res.vertices.shape == (len(qs), model.n_vertices, 3)


def test_degenerate_axis_is_finite_and_warned(chain_spec, chain_model, chain_world):
    """stretch = -1 collapses the chain to a point: still finite output, with a warning."""
    model = chain_model(chain_spec)
    res = model.evaluate(chain_world(stretch=np.array([-1.0, -0.999999])), np.zeros(2))
    for field in ("vertices", "normals", "length", "volume", "scale"):
        assert np.all(np.isfinite(getattr(res, field))), field
    assert any(i == 0 for i, _ in res.warnings)


# ----------------------------------------------------------------------------- volume


STRETCHES = np.array([-0.4, -0.2, 0.0, 0.25, 0.5])  # lengths 0.6 .. 1.5 of rest


def test_paper_volume_is_exact_for_uniform_straight_stretching(chain_spec, chain_model, chain_world):
    model = chain_model(chain_spec, volume="paper")
    res = model.evaluate(chain_world(stretch=STRETCHES), np.zeros(len(STRETCHES)))
    np.testing.assert_allclose(res.length, model.l0 * (1 + STRETCHES), rtol=1e-12)
    np.testing.assert_allclose(res.scale, np.sqrt(1.0 / (1 + STRETCHES)), rtol=1e-12)
    np.testing.assert_allclose(res.volume / model.v0, 1.0, rtol=0, atol=1e-9)
    faces = model.faces
    for v, vol in zip(res.vertices, res.volume):
        np.testing.assert_allclose(mesh_volume(v, faces), vol, rtol=1e-12)


def test_volume_none_scales_with_length_for_uniform_stretching(chain_spec, chain_model, chain_world):
    model = chain_model(chain_spec, volume="none")
    res = model.evaluate(chain_world(stretch=STRETCHES), np.zeros(len(STRETCHES)))
    np.testing.assert_array_equal(res.scale, 1.0)
    np.testing.assert_allclose(res.volume / model.v0, 1 + STRETCHES, rtol=1e-9)


def test_exact_volume_where_paper_drifts(chain_spec, chain_model, chain_world):
    """Bending changes the paper model's volume by several percent; exact holds it."""
    world = chain_world(bend=np.array([90.0, 150.0]))
    paper = chain_model(chain_spec, volume="paper").evaluate(world, np.zeros(2))
    exact = chain_model(chain_spec).evaluate(world, np.zeros(2))
    v0 = chain_model(chain_spec).v0
    assert np.abs(paper.volume / v0 - 1).max() > 0.01
    np.testing.assert_allclose(exact.volume / v0, 1.0, rtol=0, atol=1e-9)


@pytest.fixture
def chain_project(tmp_path, monkeypatch):
    """A writable copy of the chain skeleton and muscle as cwd (the CLI's project root)."""
    (tmp_path / "chain.yaml").write_text(CHAIN_SKELETON_YAML)
    (tmp_path / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def read_stats(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_exact_volume_on_written_meshes(chain_project, capsys):
    """Bends up to 150 degrees, stretches 0.6 .. 1.5, tension 0 -> 1: every written PLY
    (float32, read back) keeps the rest volume within VOLUME_EXACT_PROMISE (0.5%)."""
    keys = {0: {"bend": 0, "stretch": 0}, 4: {"bend": 150, "stretch": 0}, 8: {"bend": 150, "stretch": 0.5},
            12: {"bend": 150, "stretch": -0.4}, 16: {"bend": 75, "stretch": -0.4}, 20: {"bend": 30, "stretch": 0.5}}
    write_pose(chain_project, "vol", keys, [0, 20], activation={"chainm": {0: 0, 20: 1}})
    rc, _, err = run_main(["run", "--muscles", "chainm.yaml", "--pose", "vol.yaml", "--out", "out", "-q"], capsys)
    assert rc == 0, err
    man = json.loads((chain_project / "out" / "manifest.json").read_text())
    (mus,) = man["muscles"]
    v0 = mus["rest_volume"]
    stats = read_stats(chain_project / "out" / "stats.csv")
    assert len(stats) == 21
    lengths = []
    for row in stats:
        f = int(row["frame"])
        ply = chain_project / "out" / "meshes" / "chainm" / f"chainm_{f:04d}.ply"
        pos, _, faces = read_triangles(ply.read_bytes(), ".ply")
        assert pos.dtype == np.float32
        ratio = mesh_volume(pos, faces) / v0
        assert abs(ratio - 1.0) < tol.VOLUME_EXACT_PROMISE, (f, ratio)
        assert abs(ratio - 1.0) < 1e-5, (f, ratio)  # in fact only float32 rounding remains
        assert abs(float(row["volume_ratio"]) - 1.0) < 1e-8
        assert row["warning"] == ""
        lengths.append(float(row["length"]))
    # the sequence really covers the promised range of stretch and tension
    lengths = np.array(lengths) / mus["rest_length"]
    assert lengths.min() < 0.62 and lengths.max() > 1.45
    assert float(stats[0]["tension"]) == 0.0 and float(stats[-1]["tension"]) == 1.0


def test_exact_volume_over_the_demo_sequence(demo):
    """Every frame of the demo pose, in float32 as written: within 0.5% of rest."""
    from axdf_cli.model.pose import effective_tension, sample_activation, sample_coordinates

    pose = demo.pose
    frames = pose.frames
    world = forward_kinematics(demo.skel, sample_coordinates(pose, frames))
    act = sample_activation(pose, [s.name for s in demo.specs], frames)
    for j, model in enumerate(demo.models):
        res = model.evaluate(world, effective_tension(model.spec.tension, act[:, j]))
        assert res.warnings == []
        np.testing.assert_allclose(res.volume / model.v0, 1.0, rtol=0, atol=1e-9)
        v32 = np.array([mesh_volume(v.astype(np.float32), model.faces) for v in res.vertices[::7]])
        assert np.abs(v32 / model.v0 - 1.0).max() < tol.VOLUME_EXACT_PROMISE


# ----------------------------------------------------------------------------- tension


def mid_belly_ring(model, rest_world):
    """Index of the tessellation ring closest to the middle of the belly at rest."""
    a0, a1 = model.spec.tendons
    lam = a0 + 0.5 * (1.0 - a0 - a1)
    t_mid = np.interp(lam, model.arc, model.ts)
    c = bspline.basis_matrix(model.knots, 2, [t_mid]) @ rest_axis_points(model, rest_world)
    rest = model.evaluate(rest_world[None], np.zeros(1)).vertices[0]
    centres = rings(rest, model.spec.resolution).mean(axis=1)
    return int(np.argmin(np.linalg.norm(centres - c, axis=1)))


def tension_cases(demo, chain_spec, chain_model, chain_world):
    chain = chain_model(chain_spec)
    bent_demo = forward_kinematics(demo.skel, np.array([[30, 60, 20, 45, 30, 90, 40]], dtype=float))[0]
    cases = [(chain, chain_world()[0], chain_world()[0]),
             (chain, chain_world()[0], chain_world(bend=60.0, stretch=0.2)[0])]
    cases += [(m, demo.rest, demo.rest) for m in demo.models]
    cases += [(m, demo.rest, bent_demo) for m in demo.models]
    return cases


def test_tension_keeps_length_and_volume_and_grows_the_belly(demo, chain_spec, chain_model, chain_world):
    for model, rest, pose_world in tension_cases(demo, chain_spec, chain_model, chain_world):
        name = model.spec.name
        i = mid_belly_ring(model, rest)
        res = model.evaluate(np.stack([pose_world] * 3), np.array([0.0, 0.5, 1.0]))
        np.testing.assert_array_equal(res.length, res.length[0])  # isometric: the axis does not move
        np.testing.assert_allclose(res.volume / model.v0, 1.0, rtol=0, atol=1e-9, err_msg=name)
        np.testing.assert_allclose(res.tension, [0.0, 0.5, 1.0])
        area = [ring_vector_area(rings(v, model.spec.resolution)[i]) for v in res.vertices]
        assert area[0] < area[1] < area[2], name
        # the axis control points (and so the poles) do not move with tension
        np.testing.assert_allclose(res.vertices[:, [0, -1]], res.vertices[:1, [0, -1]].repeat(3, 0), atol=1e-15)


def test_tension_one_adds_15_percent_mid_belly_area(demo, chain_spec, chain_model, chain_world):
    gains = {}
    for model, rest, pose_world in tension_cases(demo, chain_spec, chain_model, chain_world):
        i = mid_belly_ring(model, rest)
        res = model.evaluate(np.stack([pose_world] * 2), np.array([0.0, 1.0]))
        a0, a1 = (ring_vector_area(rings(v, model.spec.resolution)[i]) for v in res.vertices)
        gains[model.spec.name] = a1 / a0 - 1.0
    assert min(gains.values()) >= 0.15, gains


def test_tension_is_clipped_to_0_1(chain_spec, chain_model, chain_world):
    model = chain_model(chain_spec)
    w = np.stack([chain_world()[0]] * 4)
    res = model.evaluate(w, np.array([-1.0, 0.0, 1.0, 3.0]))
    np.testing.assert_array_equal(res.tension, [0.0, 0.0, 1.0, 1.0])
    np.testing.assert_array_equal(res.vertices[0], res.vertices[1])
    np.testing.assert_array_equal(res.vertices[2], res.vertices[3])


# ----------------------------------------------------------------------------- twist

ROLL = np.arange(0.0, 401.0, 10.0)  # insertion roll 0 -> 400 degrees, 10 per frame


@pytest.mark.parametrize("bend", [0.0, 60.0])
def test_twist_follows_the_insertion_roll_past_180(chain_spec, chain_model, chain_world, bend):
    """Rolling the insertion bone about the muscle's tangent by 0..400 degrees: the reported
    twist follows it exactly (straight or bent axis: the roll does not move the axis),
    continuously, with no flip at 180 or 360."""
    model = chain_model(chain_spec)
    res = model.evaluate(chain_world(roll=ROLL, bend=np.full(len(ROLL), bend)), np.zeros(len(ROLL)))
    np.testing.assert_allclose(res.twist - res.twist[0], ROLL, rtol=0, atol=1e-6)
    if bend == 0.0:
        np.testing.assert_allclose(res.twist, ROLL, rtol=0, atol=1e-9)
    assert np.abs(np.diff(res.twist)).max() < 10.0 + 1e-6
    np.testing.assert_allclose(res.volume / model.v0, 1.0, atol=1e-9)


def test_twist_is_spread_along_the_axis(chain_spec, chain_model, chain_world, monkeypatch):
    """With a straight axis, a control point bound at rest arc fraction lam turns by
    lam * roll about the axis (the Z axis, pointing down: roll about -Z). (volume: none, as
    twisting elliptic sections changes the mesh volume and ``exact`` would rescale them.)"""
    from axdf_cli.model.skeleton import axis_angle

    model = chain_model(chain_spec, volume="none")
    rolls = np.array([0.0, 90.0, 250.0])
    cp, res = evaluate_with_control_points(model, chain_world(roll=rolls), np.zeros(3), monkeypatch)
    np.testing.assert_allclose(res.twist, rolls, rtol=0, atol=1e-9)
    lam = model.lam
    # lam is the rest arc fraction (the axis runs from z = 0 down to z = -l0), linearly
    # interpolated in t between the RMF samples: O(h^2) ~ 2e-5 here
    np.testing.assert_allclose(lam, -model.rest_control_points[:, 2] / model.l0, rtol=0, atol=5e-5)
    for f, roll in enumerate(rolls):
        rot = axis_angle(np.array([0.0, 0.0, -1.0]), np.radians(roll * lam))  # (Q, 3, 3)
        want = np.einsum("qij,qj->qi", rot, model.rest_control_points)
        np.testing.assert_allclose(cp[f], want, rtol=0, atol=1e-12)


def test_twist_in_the_pipeline_and_frame_subsets(chain_project, capsys):
    """Through `axdf run`: stats.csv twist follows the roll past 180 degrees, and a
    `--frames` subset writes byte-identical meshes (the twist branch does not depend on
    which frames are written)."""
    keys = {0: {"roll": 0, "bend": 40}, 40: {"roll": 400, "bend": 40}}
    write_pose(chain_project, "roll", keys, [0, 40])
    base = ["run", "--muscles", "chainm.yaml", "--pose", "roll.yaml", "-q"]
    rc, _, err = run_main(base + ["--out", "full"], capsys)
    assert rc == 0, err
    rc, _, err = run_main(base + ["--out", "part", "--frames", "19,37:40"], capsys)
    assert rc == 0, err
    stats = read_stats(chain_project / "full" / "stats.csv")
    twist = np.array([float(r["twist"]) for r in stats])
    np.testing.assert_allclose(twist - twist[0], ROLL, rtol=0, atol=1e-5)
    part = chain_project / "part" / "meshes" / "chainm"
    written = sorted(p.name for p in part.iterdir())
    assert written == [f"chainm_{f:04d}.ply" for f in (19, 37, 38, 39, 40)]
    for name in written:
        assert (part / name).read_bytes() == (chain_project / "full" / "meshes" / "chainm" / name).read_bytes(), name
    part_stats = {r["frame"]: r for r in read_stats(chain_project / "part" / "stats.csv")}
    for r in stats:
        if r["frame"] in part_stats:
            assert part_stats[r["frame"]] == r


def test_demo_biceps_twist_is_continuous(demo):
    """Forearm pronation (-60 .. 85 degrees) twists the biceps smoothly."""
    from axdf_cli.model.pose import sample_coordinates

    frames = np.arange(96, 144)
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    (biceps,) = [m for m in demo.models if m.spec.name == "biceps_brachii"]
    res = biceps.evaluate(world, np.zeros(len(frames)))
    assert np.ptp(res.twist) > 60.0  # it really twists
    assert np.abs(np.diff(res.twist)).max() < 20.0
    # one block, or single frames given the block's twist as reference: the same meshes
    one = np.concatenate([biceps.evaluate(world[i:i + 1], np.zeros(1), np.radians(res.twist[i:i + 1])).vertices
                          for i in range(0, len(frames), 7)])
    np.testing.assert_allclose(one, res.vertices[::7], rtol=0, atol=1e-12)


# ----------------------------------------------------------------------------- normals


def normal_cases(demo, chain_spec, chain_model, chain_world):
    q = demo_extreme_coordinates(demo.skel, np.random.default_rng(33), n_random=4)
    world = forward_kinematics(demo.skel, q)
    cases = [(m, world) for m in demo.models]
    cw = chain_world(bend=np.array([0.0, 90.0, 150.0]), stretch=np.array([0.0, 0.5, -0.4]),
                     roll=np.array([0.0, 120.0, 300.0]))
    cases += [(chain_model(s), cw) for s in chain_variants(chain_spec).values()]
    return cases


def test_normals_unit_and_outward(demo, chain_spec, chain_model, chain_world):
    for model, world in normal_cases(demo, chain_spec, chain_model, chain_world):
        name = model.spec.name
        res = model.evaluate(world, np.linspace(0, 1, len(world)))
        np.testing.assert_allclose(np.linalg.norm(res.normals, axis=-1), 1.0, rtol=0, atol=1e-12, err_msg=name)
        rv = rings(res.vertices, model.spec.resolution)  # (F, U-2, A, 3)
        rn = rings(res.normals, model.spec.resolution)
        centre = rv.mean(axis=2, keepdims=True)
        outward = np.einsum("furc,furc->fur", rn, rv - centre) > 0
        # the chain at 150 degrees of bend and 0.6 of its length creases on the inside
        assert outward.mean() > (0.95 if name == "chainm" else 0.98), (name, outward.mean())
        assert np.all(res.volume > 0), name


def test_pole_normals_point_away_over_the_demo_sequence(demo):
    """The pole normals point away from the neighbouring ring (checked on the demo's poses;
    at range ends the deltoid folds over the shoulder and its origin pole may tilt)."""
    from axdf_cli.model.pose import sample_coordinates

    frames = demo.pose.frames[::3]
    world = forward_kinematics(demo.skel, sample_coordinates(demo.pose, frames))
    for model in demo.models:
        res = model.evaluate(world, np.zeros(len(frames)))
        v, n = res.vertices, res.normals
        rv = rings(v, model.spec.resolution)
        assert np.all(np.einsum("fc,fc->f", n[:, 0], v[:, 0] - rv[:, 0].mean(axis=1)) > 0), model.spec.name
        assert np.all(np.einsum("fc,fc->f", n[:, -1], v[:, -1] - rv[:, -1].mean(axis=1)) > 0), model.spec.name


def test_normals_agree_with_face_orientation(demo):
    """Vertex normals agree with the area-weighted face normals of the written triangles."""
    for model in demo.models:
        res = model.evaluate(demo.rest[None], np.zeros(1))
        v, f = res.vertices[0], model.faces
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        acc = np.zeros_like(v)
        for k in range(3):
            np.add.at(acc, f[:, k], fn)
        acc /= np.linalg.norm(acc, axis=1, keepdims=True)
        cos = np.einsum("vc,vc->v", acc, res.normals[0])
        assert cos.min() > 0.99, (model.spec.name, cos.min())


def test_grid_volume_matches_the_faces(demo):
    """The reported volume is the volume of the triangles that are written."""
    for model in demo.models:
        res = model.evaluate(demo.rest[None], np.zeros(1))
        assert mesh_volume(res.vertices[0], model.faces) == pytest.approx(res.volume[0], rel=1e-12)
        along, around = model.spec.resolution
        np.testing.assert_array_equal(model.faces, grid_faces(along, around))


def test_rmf_frames_of_the_model_are_used(chain_spec, chain_model, chain_world):
    """Sanity: a straight stretched axis keeps its rest frame (no spurious rotation)."""
    model = chain_model(chain_spec)
    res = model.evaluate(chain_world(stretch=np.array([0.0, 0.5])), np.zeros(2))
    r0, r1 = rings(res.vertices, model.spec.resolution)
    a0 = np.arctan2(r0[:, :, 1], r0[:, :, 0])
    a1 = np.arctan2(r1[:, :, 1], r1[:, :, 0])
    np.testing.assert_allclose(np.angle(np.exp(1j * (a1 - a0))), 0.0, atol=1e-9)


def test_a_pickled_model_evaluates_the_same(chain_spec, chain_model, chain_world):
    """A model sent to another process (pickle) or copied keeps everything it evaluates with:
    its sparse bases are keyed by name, not by the id() of arrays that a copy replaces."""
    import copy
    import pickle

    m = chain_model(chain_spec)
    w = chain_world(bend=np.linspace(0.0, 80.0, 5), roll=np.linspace(0.0, 40.0, 5))
    ref = m.evaluate(w, np.zeros(5))
    for other in (pickle.loads(pickle.dumps(m)), copy.deepcopy(m)):
        got = other.evaluate(w, np.zeros(5))
        assert np.array_equal(got.vertices, ref.vertices)
        assert np.array_equal(got.length, ref.length)
