"""BodyParts3D's upper body registered onto myoarm (atlases/myoarm.yaml, an articulated map)
and the library made from it (muscles/myoarm_atlas, CC BY-SA 2.1 JP, `make atlas-myoarm`);
myobody's (muscles/myobody_atlas, `make atlas-myobody`: the same map on both arms, then the
Visible Human's legs by atlases/rajagopal_legs.yaml) where it is made.

Without data: the shipped library keeps every myoarm muscle's name and path (its line of
action's length is the imported muscle's over the elbow's flexion to the last digit) and
credits BodyParts3D under its licence. With ../shared/data's atlas: the registration places
each arm bone within a few millimetres of myoarm's, and carries the muscles without crushing
them: the median volume kept is within 3% of the atlas's, the forearm's too, where BodyParts3D's
radius is turned about 98 degrees against myoarm's."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from osim_common import DATA, REPO

ATLAS = DATA / "atlas" / "bodyparts3d_upper"
LIB = REPO / "muscles" / "myoarm_atlas"
OLD = REPO / "muscles" / "myoarm"
SKELETON = REPO / "poses" / "skeletons" / "myoarm.yaml"
MAP = REPO / "atlases" / "myoarm.yaml"
needs_atlas = pytest.mark.skipif(not (ATLAS / "muscles").is_dir(),
                                 reason=f"the BodyParts3D atlas not found at {ATLAS} (../shared/data)")
needs_lib = pytest.mark.skipif(not LIB.is_dir(), reason="muscles/myoarm_atlas not made (make atlas-myoarm)")
BODY = REPO / "muscles" / "myobody_atlas"
# library, the model's library, its skeleton, a pose and frames of it, the fits' reports, the arms' suffixes
LIBS = {
    "myoarm": (LIB, OLD, SKELETON, "myoarm_elbow.yaml", np.arange(0, 58, 8), ["atlas_report.json"], [""]),
    "myobody": (BODY, REPO / "muscles" / "myobody", REPO / "poses" / "skeletons" / "myobody.yaml",
                "myobody_gait.yaml", np.arange(0, 124, 30), ["atlas_report_upper.json", "atlas_report_legs.json"],
                ["", "_l"]),
}
per_lib = pytest.mark.parametrize("which", [
    "myoarm", pytest.param("myobody", marks=pytest.mark.skipif(not BODY.is_dir(), reason="make atlas-myobody"))])


def _fitted(which: str) -> set:
    lib, _, _, _, _, reports, _ = LIBS[which]
    return {m["muscle"] for r in reports for m in json.loads((lib / r).read_text())["fitted"]}
ADDED = ("TRAP1", "TRAP2", "TRAP3", "RHMAJ", "RHMIN", "LEVSCAP")  # atlases/myoarm.yaml's added:
FOREARM = ("ECRB", "ECRL", "ECU", "EDM", "FCR", "FCU", "PL", "PT", "SUP", "APL", "EPB", "EPL", "FPL", "BRD")


@needs_lib
@per_lib
def test_library_keeps_every_model_name_and_credits_its_atlas(which):
    from axdf_cli.specs import load_muscle_file

    lib, old_dir, _, _, _, _, suffixes = LIBS[which]
    old = sorted(p.name for p in old_dir.glob("*.yaml"))
    added = [f"{n}{sfx}.yaml" for n in ADDED for sfx in suffixes]
    assert sorted(p.name for p in lib.glob("*.yaml")) == sorted(old + added)
    fitted = _fitted(which)
    for sfx in suffixes:
        assert {f"{n}{sfx}" for n in ("DELT1", "DELT2", "DELT3", "PECM1", "PECM2", "PECM3", "LAT1", "LAT2", "LAT3",
                                      "BIClong", "TRIlong", "FCR")} <= fitted
    if which == "myobody":
        assert {"vaslat_r", "vaslat_l", "gasmed_r", "glmax1_l", "tibant_r"} <= fitted
    for name in old:
        (spec,) = load_muscle_file(lib / name)[:1]
        if spec.name in fitted:
            assert spec.axis and spec.sections[0].outline is not None, name
    readme = (lib / "README.md").read_text()
    assert "BodyParts3D" in readme and "CC BY-SA 2.1 JP" in readme
    if which == "myobody":
        assert "Visible Human" in readme


@needs_lib
@per_lib
def test_library_lengths_are_the_models_paths(which):
    """Every fitted muscle keeps the model's path as its line of action (MuJoCo's ten_length,
    which the importer passes): its length over the pose is the imported muscle's."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
    from axdf_cli.specs.pose import load_pose

    lib, old_dir, skeleton, pose, frames, _, _ = LIBS[which]
    skel = load_skeleton(skeleton, RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    q = sample_coordinates(load_pose(REPO / "poses" / pose), frames)
    world = forward_kinematics(skel, q)
    fitted = _fitted(which)
    assert len(fitted) >= 45
    added = set(json.loads((lib / LIBS[which][5][0]).read_text())["added"])  # (no path: theirs is the axis)
    for name in sorted(fitted - added):
        (new,) = load_muscle_file(lib / f"{name}.yaml")
        (old,) = load_muscle_file(old_dir / f"{name}.yaml")
        line = MuscleModel(new, skel.bone_index, rest, skel).line_length(world, q)
        np.testing.assert_allclose(line, MuscleModel(old, skel.bone_index, rest, skel).axis_length(world, q),
                                   rtol=1e-12, err_msg=name)


@needs_lib
@per_lib
def test_the_shoulder_girdle_is_added_as_shape_muscles_on_its_bones(which):
    """The trapezius (three parts), rhomboids and levator scapulae, which myoarm and myobody lack,
    are in the library as shape muscles: no path (their length is their axis'), the axis from
    their first bone to their last (trapezius' transverse part: the thorax to the scapula), each
    within 0.8 IoU of its registered atlas mesh (0.87-0.93 when made), and the README names them."""
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton
    from axdf_cli.tools.tables import load_atlas_map

    lib, _, skeleton, _, _, reports, suffixes = LIBS[which]
    amap = load_atlas_map(MAP)
    skel = load_skeleton(skeleton, RefPolicy())
    fits = {m["muscle"]: m for r in reports for m in json.loads((lib / r).read_text())["fitted"]}
    upper = json.loads((lib / reports[0]).read_text())
    assert sorted(upper["added"]) == sorted(n + sfx for n in ADDED for sfx in suffixes)
    for n in ADDED:
        for sfx, side in zip(suffixes, ("r", "l")):
            (spec,) = load_muscle_file(lib / f"{n}{sfx}.yaml")
            bones = amap.added_bones(n, side, skel.bone_index)
            assert spec.path is None and spec.axis[0].bone == bones[0] and spec.axis[-1].bone == bones[-1], n
            assert {p.bone for p in spec.axis} <= set(bones), n
            assert fits[n + sfx]["iou"] >= 0.8 and 0.9 <= fits[n + sfx]["volume_ratio"] <= 1.1, (n, fits[n + sfx])
    assert "shape muscles" in (lib / "README.md").read_text() and "TRAP2" in (lib / "README.md").read_text()


def _line_col(path: Path, text: str) -> tuple[int, int]:
    line = next(i for i, t in enumerate(path.read_text().splitlines(), 1) if text in t)
    return line, path.read_text().splitlines()[line - 1].index("{atlas") + 1


@needs_atlas
@pytest.mark.parametrize("case", ["has it", "no such bone"])
def test_an_added_muscle_the_model_has_or_on_a_bone_it_lacks_is_refused_at_the_map(tmp_path, capsys, case):
    import shutil

    from cli_in_folder import run_cli

    lib, amap = OLD, MAP
    if case == "has it":
        lib = tmp_path / "lib"
        shutil.copytree(OLD, lib)
        shutil.copy(OLD / "DELT1.yaml", lib / "TRAP2.yaml")
    else:
        amap = tmp_path / "map.yaml"
        amap.write_text(MAP.read_text().replace("bones: [torso, scapula]}\n  TRAP3", "bones: [torso, shoulderblade]}\n"
                                                "  TRAP3"))
    capsys.readouterr()
    rc = run_cli(tmp_path, "atlas", str(ATLAS), "--onto", str(SKELETON), "--map", str(amap), "--muscles", str(lib),
                 "--sides", "r", "--out", "out", "--quiet")
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err and not (tmp_path / "out").exists(), err
    line, col = _line_col(amap, "  TRAP2: {atlas")
    assert err.startswith(f"{amap}:{line}:{col}: added muscle TRAP2: "), err
    assert ("has TRAP2.yaml already; added: names muscles the model lacks" in err if case == "has it" else
            "bone 'shoulderblade' is not a bone with a mesh of" in err), err


@needs_atlas
def test_articulated_registration_places_the_bones_and_keeps_the_volumes():
    from axdf_cli.tools.atlas import Atlas
    from axdf_cli.tools.atlas_library import registered_meshes, rest_state
    from axdf_cli.tools.tables import load_atlas_map

    skel, rest, bones = rest_state(SKELETON)
    meshes, sides = registered_meshes(Atlas(ATLAS, load_atlas_map(MAP)), skel, rest, bones, OLD, ("r",))
    rep = sides["r"]
    for bone, d in rep["bones_after"].items():
        assert d["mean_mm"] < 5.0, (bone, d)
    kept = {n: m["volume_kept"] for n, m in rep["muscles"].items() if "volume_kept" in m}
    assert len(kept) >= 45
    assert abs(np.median(list(kept.values())) - 1.0) < 0.03
    assert abs(np.median([kept[n] for n in FOREARM]) - 1.0) < 0.05
    assert min(kept.values()) > 0.6 and max(kept.values()) < 1.4
    if LIB.is_dir():  # the library was fitted to these meshes
        recorded = json.loads((LIB / "atlas_report.json").read_text())["sides"]["r"]["muscles"]
        assert rep["muscles"] == recorded


def _widest_aspect(meshes) -> float:
    """The aspect ratio (the square root of the principal moments' ratio) of the widest cut
    across a group's principal axis, the group's bundles unioned (inside any by winding
    number): the measure of scripts/atlas_measure.py, over the union."""
    from axdf_cli.geometry.winding import inside

    v = np.concatenate([m[0] for m in meshes])
    c = v.mean(axis=0)
    ax = np.linalg.svd(v - c, full_matrices=False)[2][0]
    a = np.cross(ax, [1.0, 0.0, 0.0] if abs(ax[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(ax, a)
    u = np.arange(-0.25, 0.25 + 1e-9, 0.003)
    U, V = (g.ravel() for g in np.meshgrid(u, u, indexing="ij"))
    s = (v - c) @ ax
    best = (0, 0.0)
    for t in np.linspace(s.min(), s.max(), 32)[1:-1]:
        pts = c + t * ax + U[:, None] * a + V[:, None] * b
        ins = np.zeros(len(pts), bool)
        for m in meshes:
            ins |= inside(*m, pts, signed=True)
        if ins.sum() > best[0]:
            q = np.stack([U[ins], V[ins]], axis=1)
            q = q - q.mean(axis=0)
            ev = np.linalg.eigvalsh(q.T @ q / len(q))
            best = (int(ins.sum()), float(np.sqrt(ev[1] / max(ev[0], 1e-30))))
    return best[1]


@needs_lib
@per_lib
def test_pectoralis_and_latissimus_are_sheets(which):
    """Pectoralis major and latissimus dorsi (their bundles unioned) are sheets at rest, as the
    atlas' are (BodyParts3D registered: 4.3 and 4.4): aspect ratio at least 3.5 at the widest
    cut, where myoarm's imported tubes have 3.0 and 1.5."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton

    lib, old_dir, skeleton, _, _, _, suffixes = LIBS[which]
    skel = load_skeleton(skeleton, RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]

    def group(folder, names):
        out = []
        for n in names:
            (spec,) = load_muscle_file(folder / f"{n}.yaml")
            m = MuscleModel(spec, skel.bone_index, rest, skel)
            out.append((np.asarray(m.rest_vertices, np.float64), np.asarray(m.faces, np.int64)))
        return out

    for sfx in suffixes:
        for names in (["PECM1", "PECM2", "PECM3"], ["LAT1", "LAT2", "LAT3"]):
            assert _widest_aspect(group(lib, [n + sfx for n in names])) >= 3.5, (names, sfx)
    assert _widest_aspect(group(old_dir, ["LAT1", "LAT2", "LAT3"])) < 2.0  # the tubes: the measure can fail


WALK = REPO / "poses" / "jobs" / "myobody_atlas_walk.yaml"
SKIN = REPO / "skins" / "myobody" / "skin.yaml"
RAISE = REPO / "poses" / "jobs" / "myobody_atlas_raise.yaml"


@pytest.mark.skipif(not (BODY.is_dir() and SKIN.is_file()), reason="make atlas-myobody, then make skin")
def _under_the_skin(job: Path, frames: tuple, tmp_path: Path, capsys, monkeypatch) -> list:
    """Run ``job`` at ``frames`` (all 416 atlas muscles and the 12 added, contact, skins/myobody) and measure each
    written frame by libigl's winding numbers: (frame, share of the muscle vertices outside the
    skin, share of the bones' mesh vertices outside it, placed by the run's bones.csv), after
    checking the skin keeps its volume within 3%."""
    import csv

    import trimesh
    from scipy.spatial.transform import Rotation

    from axdf_cli.geometry.winding import inside
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job
    from conftest import run_main

    monkeypatch.chdir(REPO)
    run = tmp_path / job.stem
    spec = ",".join(str(f) for f in frames)
    rc, _, err = run_main(["run", job.relative_to(REPO), "--no-render", "--frames", spec, "--out", run], capsys)
    assert rc == 0, err
    plan = plan_run(load_job(job), frames_arg=str(frames[0]))
    names = {i: n for n, i in plan.pose.skeleton.bone_index.items()}
    rows = list(csv.DictReader((run / "stats.csv").open()))
    n = 416 + 2 * len(ADDED)  # (myobody's muscles and the shoulder girdle's added ones)
    assert len({r["muscle"] for r in rows}) == n and len(rows) == n * len(frames)
    skin = list(csv.DictReader((run / "skin.csv").open()))
    assert [int(r["frame"]) for r in skin] == list(frames)
    assert all(abs(float(r["volume_ratio"]) - 1) <= 0.03 for r in skin), skin
    shares = []
    for frame in frames:
        body = trimesh.load(run / "meshes" / "skin" / f"skin_{frame:04d}.ply", process=False)
        v, f = np.asarray(body.vertices), np.asarray(body.faces)
        points = np.concatenate([trimesh.load(p, process=False).vertices
                                 for p in sorted(run.glob(f"meshes/*/*_{frame:04d}.ply")) if p.parent.name != "skin"])
        assert len(points) > 500_000
        pose = {r["bone"]: r for r in csv.DictReader((run / "bones.csv").open()) if int(r["frame"]) == frame}
        bones = []
        for b, (local, _, _) in sorted(plan.bone_meshes.items()):
            r = pose[names[b]]
            rot = Rotation.from_quat([float(r[k]) for k in ("qx", "qy", "qz", "qw")]).as_matrix()
            bones.append(np.asarray(local, np.float64) @ rot.T + [float(r[k]) for k in "xyz"])
        bones = np.concatenate(bones)
        assert len(bones) > 100_000
        shares.append((frame, float((~inside(v, f, points)).mean()), float((~inside(v, f, bones)).mean())))
    return shares


def test_the_whole_body_walks_under_its_skin(tmp_path, capsys, monkeypatch):
    """skins/myobody (make skin: MakeHuman's body pushed over muscles/myobody_atlas) validates as
    a skin of myobody, and poses/jobs/myobody_atlas_walk.yaml runs all 416 atlas muscles (and the 12 added) with
    contact under it: at the walk's first frame and mid-stride, by winding numbers, at most 0.5%
    of the muscle vertices lie outside the skin (measured: 0.001-0.002%), at most 0.1% of the
    bones' mesh vertices do (measured: none of 132,063; the fingers and patellae were 2.6-6.7%
    before the skin had a segment per phalanx), and the skin keeps its volume within 3%."""
    from conftest import run_main

    rc, out, err = run_main(["validate", SKIN], capsys)
    assert rc == 0 and "13380 vertices on 49 bones of myobody" in out, err  # with every phalanx
    for frame, muscle, bone in _under_the_skin(WALK, (0, 120), tmp_path, capsys, monkeypatch):
        assert muscle <= 0.005 and bone <= 0.001, (frame, muscle, bone)


def test_the_whole_body_raises_its_arm_under_its_skin(tmp_path, capsys, monkeypatch):
    """poses/jobs/myobody_atlas_raise.yaml, the right arm raised sideways to 90 degrees and the
    elbow bent to 30, under skins/myobody: at the raise's middle and end, at most 0.5% of the
    muscle vertices outside the skin (measured: 0.48% and 0.43%, nearly all the right forearm's
    flexors PL, FCU and FCR at the bent elbow) and at most 0.1% of the bone vertices (measured:
    none), the skin's volume within 3%."""
    for frame, muscle, bone in _under_the_skin(RAISE, (20, 40), tmp_path, capsys, monkeypatch):
        assert muscle <= 0.005 and bone <= 0.001, (frame, muscle, bone)
