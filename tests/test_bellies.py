"""Anatomical bellies: the slenderness measure, and the shipped gait2392 and arm26
libraries measured with it at rest and over their motions.

The measure (axdf_cli/model/measure.py): along the mesh's principal axis, the length over which the
cross-section's diameter is at least half the widest, divided by the widest diameter.
The aim: none below 1.2, at most 5% of a library below 1.5, at rest and at every measured
frame; every muscle below 1.5 is listed below with its reason, and IMPORT.md explains it.
"""
from __future__ import annotations

import colorsys
import json
from pathlib import Path

import numpy as np
import pytest
import trimesh

from axdf_cli.model.measure import belly_slenderness, cut_widths
from osim_common import ARM, needs_data, run_import

#: the model alone (these tests are about the muscle model; contact has tests/test_contact.py)
MODEL_ONLY = {"contact": False, "penetration": False}

REPO = Path(__file__).resolve().parents[1]

#: Frames measured: the walk's stride (the right knee flexes 70° at 62, the left 62° at 29) and
#: the elbow flexion 0 -> 90°.
MOTIONS = {"gait2392": ("gait2392_walk.yaml", [18, 29, 40, 51, 62, 73]), "arm26": ("arm26_flex.yaml", [0, 19, 38, 57]),
           "myoarm": ("myoarm_elbow.yaml", [0, 19, 38, 57]),
           "myobody": ("myobody_gait.yaml", [0, 20, 40, 60, 80, 100, 123])}

#: Muscles that may go below 1.5 (rest or motion), and why; IMPORT.md explains each.
SQUAT = {
    "ercspn_r": "one actuator for the whole column of spinal extensors (2500 N) over a 15 cm path",
    "ercspn_l": "one actuator for the whole column of spinal extensors (2500 N) over a 15 cm path",
    "quad_fem_r": "quadratus femoris: a short thick block in anatomy too (path 7 cm)",
    "quad_fem_l": "quadratus femoris: a short thick block in anatomy too (path 7 cm)",
    "glut_med1_r": "a third of the gluteus medius fan on a 12 cm path, shortened further by hip extension in the walk",
    "glut_med3_l": "a third of the gluteus medius fan on an 11 cm path",
    "glut_med3_r": "a third of the gluteus medius fan on an 11 cm path",
    # myobody (MuJoCo imports are thinned to 1.5 at rest; these dip below it in the gait cycle)
    "glmed1_r": "a third of the gluteus medius fan; the hip's motion shortens its path",
    "glmed3_r": "a third of the gluteus medius fan; the hip's motion shortens its path",
    "glmed3_l": "a third of the gluteus medius fan; the hip's motion shortens its path",
    "SUBSC": "subscapularis: a broad sheet drawn as one short line (1.49 with the arm at its side)",
    "SUBSC_l": "subscapularis: a broad sheet drawn as one short line (1.49 with the arm at its side)",
}
#: Muscles that may go below 1.2 in motion (never at rest), and why.
BELOW_1_2 = {
    "glut_med1_r": "at walk frame 51 (hip extended) its 12 cm path is at its shortest: 1.19 (1.75 at rest)",
}
VASTI = ("vas_med_r", "vas_int_r", "vas_lat_r", "vas_med_l", "vas_int_l", "vas_lat_l")


# ----------------------------------------------------------------------------- the measure


def test_measure_of_known_shapes():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.05)
    s = belly_slenderness(sphere.vertices, sphere.faces)
    assert s.ratio == pytest.approx(np.sqrt(3) / 2, abs=0.01) and s.width == pytest.approx(0.1, rel=2e-3)
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.3, sections=64)
    s = belly_slenderness(cyl.vertices, cyl.faces)
    assert s.ratio == pytest.approx(7.5, rel=0.01) and s.length == pytest.approx(0.3, rel=0.01)
    # a spindle r = R sin(pi x) over length L: the width is >= half the widest over 2/3 of it
    ring = 48
    x = np.linspace(0.0, 1.0, 201)
    r = 0.02 * np.sin(np.pi * x)
    a = 2 * np.pi * np.arange(ring) / ring
    v = np.concatenate([[[0, 0, 0]], np.stack([np.repeat(0.25 * x[1:-1], ring), np.outer(r[1:-1], np.cos(a)).ravel(),
                                                np.outer(r[1:-1], np.sin(a)).ravel()], 1), [[0.25, 0, 0]]])
    spindle = trimesh.Trimesh(v, trimesh.convex.convex_hull(v).faces, process=False)
    s = belly_slenderness(spindle.vertices, spindle.faces)
    assert s.ratio == pytest.approx(0.25 * (2 / 3) / 0.04, rel=0.02)


def test_measure_is_scale_and_motion_invariant_and_ignores_grazing_slivers():
    rng = np.random.default_rng(7)
    cyl = trimesh.creation.cylinder(radius=0.02, height=0.2, sections=48)
    base = belly_slenderness(cyl.vertices, cyl.faces).ratio
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    moved = 2.5 * cyl.vertices @ q.T + rng.normal(size=3)
    assert belly_slenderness(moved, cyl.faces).ratio == pytest.approx(base, rel=0.01)
    # a thin tendon turning 90° at the end (the peroneus under the foot): the planes that run
    # along it cut a long sliver of little area, which must not count as a wide cross-section
    tendon = trimesh.creation.cylinder(radius=0.002, height=0.06, sections=16)
    tendon.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [0, 1, 0]))
    tendon.apply_translation([0.03, 0.0, -0.103])  # under the belly, along X
    both = trimesh.util.concatenate([cyl, tendon])
    pos, widths = cut_widths(both.vertices, both.faces, np.array([0.0, 0.0, 1.0]))
    assert widths.max() == pytest.approx(0.04, rel=0.02)  # the belly's diameter, not the sliver's 6 cm


# ----------------------------------------------------------------------------- the libraries


def _measure_library(name: str) -> dict:
    """{frame or 'rest': {muscle: Slenderness}} for a shipped library over its motion."""
    from axdf_cli import specs as loaders
    from axdf_cli import pipeline

    pose, frames = MOTIONS[name]
    job = loaders.load_job(REPO / "poses" / "jobs" / pose, loaders.RefPolicy((REPO,)))
    # the bellies as imported (the walk's and the flexion's jobs run them packed: axdf pack
    # reshapes them, test_pack.py; packed, arm26's brachialis is 1.36 at rest, crowded by the
    # humerus and the biceps)
    own = [str(REPO / "muscles" / name)] if name in ("gait2392", "arm26") else None
    plan = pipeline.plan_run(job, muscle_args=own, frames_arg=",".join(map(str, frames)), stages=MODEL_ONLY)
    out = {"rest": {m.spec.name: belly_slenderness(m.rest_vertices, m.faces) for m in plan.models}}
    for sl, _, results in pipeline.evaluate_chunks(plan):
        for j, res in results:
            m = plan.models[j]
            for k, f in enumerate(plan.frames[sl]):
                out.setdefault(int(f), {})[m.spec.name] = belly_slenderness(res.vertices[k], m.faces)
    return out


@pytest.fixture(scope="module")
def measured():
    return {name: _measure_library(name) for name in MOTIONS}


@needs_data
@pytest.mark.parametrize("name", sorted(MOTIONS))
def test_library_bellies_are_slender(measured, name):
    lib = measured[name]
    explained = (REPO / "muscles" / name / "IMPORT.md").read_text()
    for when, shapes in lib.items():
        ratios = {m: s.ratio for m, s in shapes.items()}
        below_12 = {m for m, r in ratios.items() if r < 1.2}
        below_15 = {m for m, r in ratios.items() if r < 1.5}
        assert below_12 <= (set() if when == "rest" else set(BELOW_1_2)), (name, when, {m: ratios[m] for m in below_12})
        assert below_15 <= set(SQUAT), (name, when, {m: ratios[m] for m in below_15 - set(SQUAT)})
        assert len(below_15) <= 0.05 * len(ratios), (name, when, sorted(below_15))
        for m in below_15:
            assert f"**{m}**" in explained, f"{m} is squat ({ratios[m]:.2f}) but muscles/{name}/IMPORT.md does not explain it"


@needs_data
def test_knee_flexed_vasti_do_not_balloon(measured):
    """Before the belly law the vasti were 82-89 mm wide bulbs (slenderness 0.8-0.9); now they
    stay near 6 cm through the stride, knee flexion included, and at least 1.5 long."""
    lib = measured["gait2392"]
    for m in VASTI:
        rest = lib["rest"][m]
        walk = [lib[f][m] for f in MOTIONS["gait2392"][1]]
        assert rest.width < 0.065 and max(w.width for w in walk) <= 1.05 * rest.width, m
        assert rest.ratio >= 1.5 and min(w.ratio for w in walk) >= 1.5, m


@needs_data
def test_pennate_bellies_are_longer_than_their_fibres():
    """Belly length = rest path - free tendon, not the fibre length: the gastrocnemius' and
    soleus' bellies are several times their (pennate, short) fibres; the rest volume the model
    builds is PCSA x fibre length plus the free tendons."""
    from axdf_cli.importers import emit
    from axdf_cli.importers.emit import rest_world
    from axdf_cli.specs import load_muscle_file, load_skeleton
    from axdf_cli.model.muscle import MuscleModel

    report = {r["muscle"]: r for r in json.loads((REPO / "muscles" / "gait2392" / "import_report.json").read_text())["muscles"]}
    for m in ("med_gas_r", "lat_gas_r", "soleus_r", "tib_post_r"):
        r = report[m]
        assert r["belly_length"] > 3.0 * r["optimal_fiber_length"], m
    skel = load_skeleton(REPO / "poses" / "skeletons" / "gait2392.yaml")
    world = rest_world(skel)
    for m, r in report.items():
        free = min(max(min(emit.FREE_TENDON_SHARE * r["tendon_slack_length"], r["rest_path_length"] - r["fibre_projection"]),
                       0.0), emit.MAX_TENDON_FRACTION * r["rest_path_length"])
        assert r["free_tendon"] == pytest.approx(free, rel=1e-6, abs=1e-9), m
        assert r["belly_length"] == pytest.approx(r["rest_path_length"] - free, rel=1e-6), m
        assert r["belly_length"] >= r["fibre_projection"] * (1 - 1e-6) or r["free_tendon"] == 0.0, m
    for m in ("med_gas_r", "vas_lat_r", "sar_r", "ercspn_l"):
        (spec,) = load_muscle_file(REPO / "muscles" / "gait2392" / f"{m}.yaml")
        r = report[m]
        want = r["volume_m3"] + np.pi * r["tendon_radius"] ** 2 * r["free_tendon"]
        assert MuscleModel(spec, skel.bone_index, world, skel).v0 == pytest.approx(want, rel=1e-6), m


# ----------------------------------------------------------------------------- palette


def _srgb(hex_color: str) -> tuple:
    lin = [int(hex_color[i:i + 2], 16) / 255 for i in (1, 3, 5)]
    return tuple(12.92 * c if c <= 0.0031308 else 1.055 * c ** (1 / 2.4) - 0.055 for c in lin)


@needs_data
def test_shipped_library_is_anatomically_coloured():
    import yaml

    colors = {}
    for name in ("gait2392", "arm26"):
        for f in sorted((REPO / "muscles" / name).glob("*.yaml")):
            colors[f.stem] = yaml.safe_load(f.read_text())["color"]
    for m, c in colors.items():
        h, s, v = colorsys.rgb_to_hsv(*_srgb(c))
        assert (h * 360 >= 350 or h * 360 <= 11) and s >= 0.58 and 0.48 <= v <= 0.82, (m, c, h * 360, s, v)
    for m in colors:
        if m.endswith("_r"):
            assert colors[m] == colors[m[:-2] + "_l"], m  # a muscle and its mirror image alike
    assert len(set(colors.values())) >= 45  # 46 gait muscle pairs + 6 arm muscles, varied


@needs_data
def test_palette_option(tmp_path):
    import yaml

    from axdf_cli.importers.emit import anatomical_color, hashed_color

    for palette, fn in (("hashed", hashed_color), ("anatomical", anatomical_color)):
        rc, out = run_import(tmp_path, ARM, "--name", "arm26", "--no-meshes", "--palette", palette, out=palette)
        assert rc == 0
        for f in sorted((out / "muscles").glob("*.yaml")):
            assert yaml.safe_load(f.read_text())["color"] == fn(f.stem), (palette, f.stem)
        assert json.loads((out / "import_report.json").read_text())["settings"]["palette"] == palette
    assert hashed_color("BIClong") != anatomical_color("BIClong")
