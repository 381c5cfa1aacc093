"""Contact (axdf_cli/model/contact.py): muscles push each other, bones push muscles.

Invariants on the demo library (the deltoid's three parts overlap at the shoulder, the
gastrocnemius' heads in the calf): the product's measures agree with an independent
generalized winding number computation (tests/winding.py), also past a neighbour's end;
contact lowers them; the volume is kept exactly; a muscle far from everything is returned bit
for bit; a rigid motion of the whole skeleton moves the result rigidly; --no-contact writes
the meshes of the evaluation alone; --jobs and --frames subsets give the same bytes; a muscle
wholly inside a bone is warned and refused under --strict; the contact keys are read and
checked."""
from __future__ import annotations

import hashlib
import json
import os

import numpy as np
import pytest

from cli_in_folder import run_cli
from conftest import DEMO_JOB, REPO_ROOT
from winding import inside_shares, winding_numbers

from axdf_cli import tolerances as tol
from axdf_cli.model import contact
from axdf_cli.model.muscle import grid_faces
from axdf_cli.pipeline.evaluate import evaluate_plan
from axdf_cli.pipeline.plan import plan_run
from axdf_cli.pipeline.stages import ContactStage
from axdf_cli.specs import RefPolicy, load_job

FRAMES = "20,70"  # knee flexed with plantarflexion; shoulder abducted


@pytest.fixture(scope="module", autouse=True)
def contact_on_by_default():
    """Contact is on by default, its measures alone (`--penetration`) off
    (pipeline.stages.OFF_BY_DEFAULT): here every run and plan has both on unless a test
    switches them off (tests/test_stages.py checks the flags themselves)."""
    from axdf_cli.pipeline import stages

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(stages, "OFF_BY_DEFAULT", frozenset())  # (the penetration stage measures where contact is off)
        yield


TWIN = (REPO_ROOT / "muscles" / "demo" / "biceps_brachii.yaml").read_text().replace(
    "muscle: biceps_brachii", "muscle: biceps_twin").replace("at: [-0.03, -0.02, -0.01]", "at: [-0.026, -0.02, -0.012]").replace(
    "at: [0.0, -0.035, -0.07]", "at: [0.012, -0.03, -0.07]").replace("at: [0.0, -0.04, -0.17]", "at: [0.014, -0.035, -0.17]"
    ).replace("at: [0.012, -0.012, -0.05]", "at: [0.016, -0.01, -0.052]")


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo muscles and a twin of the biceps 1.2-1.4 cm beside it (they overlap), with
    the contact stage, and the no-contact meshes of FRAMES: (plan, world (F, B, 4, 4),
    [[(V, 3)] per muscle] per frame)."""
    twin = tmp_path_factory.mktemp("twin") / "biceps_twin.yaml"
    twin.write_text(TWIN)
    plan = plan_run(load_job(DEMO_JOB), frames_arg=FRAMES, muscle_args=[str(REPO_ROOT / "muscles" / "demo"), str(twin)],
                    policy=RefPolicy(allow_outside=True), stages={"contact": False, "penetration": False})
    (chunk, results), = list(evaluate_plan(plan))
    res = dict(results)
    frames = [[res[j].vertices[f] for j in range(len(plan.models))] for f in range(len(plan.frames))]
    plan.contact = ContactStage().start(plan)  # the stage's state: the run's ContactModel
    return plan, chunk.world, frames


def _volume(v, U, A):
    """The mesh volume of one muscle's (V, 3) vertices at resolution (U, A)."""
    return contact.grid_volume(contact.vertices_to_grid(v, U, A), U, A)


def _bones_world(plan, world):
    return [(v.astype(np.float64) @ world[b, :3, :3].T + world[b, :3, 3], f)
            for b, (v, f, _) in sorted(plan.bone_meshes.items())]


@pytest.mark.parametrize("fi", [0, 1])
def test_measures_match_winding_numbers(demo, fi):
    plan, world, frames = demo
    model = plan.contact
    faces = [m.faces for m in plan.models]
    out = contact.resolve_frame(model, frames[fi], np.linalg.inv(world[fi]))
    assert out[3][:, 0].max() > 0.2  # the twins overlap
    for label in ("before", "after"):
        measured = out[3] if label == "before" else out[4]
        meshes = frames[fi] if label == "before" else out[0]
        ref = inside_shares(list(zip(meshes, faces)), _bones_world(plan, world[fi]), model.allow)
        # the axis-space query reads the rings linearly: it may differ from the exact mesh
        # test for points within a fraction of a millimetre of a surface
        assert np.abs(measured[:, :2] - ref).max() <= 0.03, (label, measured[:, :2], ref)
        assert abs(measured[:, 0].mean() - ref[:, 0].mean()) <= 0.01, label
        assert abs(measured[:, 1].mean() - ref[:, 1].mean()) <= 0.01, label


def test_contact_lowers_penetration_and_keeps_volume(demo):
    plan, world, frames = demo
    for fi in range(len(frames)):
        v, n, touched, before, after = contact.resolve_frame(plan.contact, frames[fi], np.linalg.inv(world[fi]))
        assert touched.any()
        # the default single pass clears part of the twins' overlap and of the bones'; more
        # passes clear more (docs/CONTACT.md: what the passes trade). The deepest point may
        # deepen, by less than a pass's step and a half (no pile-up): the deepest points lie
        # near the other twin's axis, where pushes fade out, while their rings follow their
        # pushed points and the volume's re-solve inflates the other twin
        assert after[:, 0].mean() < 0.95 * before[:, 0].mean() and after[:, 1].mean() < before[:, 1].mean()
        assert after[:, 2].max() <= before[:, 2].max() + 1.5 * tol.CONTACT_MAX_STEP
        more = contact.resolve_frame(plan.contact, frames[fi], np.linalg.inv(world[fi]), iterations=3)[4]
        assert more[:, 0].mean() < 0.75 * before[:, 0].mean()
        assert more[:, 2].max() <= before[:, 2].max() + 1.5 * tol.CONTACT_MAX_STEP
        for k, m in enumerate(plan.models):
            U, A = m.spec.resolution
            assert abs(_volume(v[k], U, A) / _volume(frames[fi][k], U, A) - 1.0) < 1e-9
            assert np.isfinite(v[k]).all() and (n[k] is None or np.allclose(np.linalg.norm(n[k], axis=1), 1.0))


def test_over_relaxed_passes_clear_more_and_keep_volume(demo):
    """tol.CONTACT_RELAX asks for each push more than once over: a pass clears more of the
    twins' overlap and of the bones' than the same pass asking once (the packer's (1, 1, 1)),
    and the volume stays exact."""
    plan, world, frames = demo
    assert min(tol.CONTACT_RELAX) > 1.0
    for fi in range(len(frames)):
        inv = np.linalg.inv(world[fi])
        v, _, touched, before, relaxed = contact.resolve_frame(plan.contact, frames[fi], inv, iterations=1)
        _, _, touched1, _, once = contact.resolve_frame(plan.contact, frames[fi], inv, iterations=1,
                                                        relax=(1.0, 1.0, 1.0))
        assert (touched == touched1).all()
        # one pass: 8.8% of the vertices inside another muscle, asked once 7.4%, over-relaxed
        # 6.5% (frame 1: 8.0%, 6.4%, 5.3%); inside a bone, asked once 1.7%, over-relaxed 1.4%;
        # the deepest 16.7 → 13.9 mm
        assert relaxed[:, 0].mean() < 0.95 * once[:, 0].mean() and once[:, 0].mean() < 0.9 * before[:, 0].mean()
        assert relaxed[:, 1].mean() < 0.9 * once[:, 1].mean()
        assert relaxed[:, 2].max() < before[:, 2].max()
        for k, m in enumerate(plan.models):
            U, A = m.spec.resolution
            assert abs(_volume(v[k], U, A) / _volume(frames[fi][k], U, A) - 1.0) < 1e-9


WALK_JOB = REPO_ROOT / "poses" / "jobs" / "gait2392_walk.yaml"
POP_RATIO = 1.5  # the rule: no vertex steps more than this times its no-contact step


def _steps(plan):
    """Every muscle's largest vertex step between consecutive frames of the plan: (F - 1, M)."""
    per: dict = {}
    for _, results in evaluate_plan(plan):
        for j, r in results:
            per.setdefault(j, []).append(r.vertices)
    return np.stack([np.linalg.norm(np.diff(np.concatenate(per[j]), axis=0), axis=-1).max(axis=-1)
                     for j in sorted(per)], axis=1)


@pytest.mark.skipif(not WALK_JOB.is_file(), reason="the shipped gait2392 library (make import)")
@pytest.mark.parametrize("library", ["gait2392", "gait2392_packed"])
def test_no_pops_on_the_walk(library):
    """The no-pops rule on the shipped walk (67 frames x 92 muscles): with contact, no
    muscle's largest vertex step from one frame to the next exceeds 1.5x its step without;
    with the muscles as imported and with the walk's own, packed by `axdf pack` (worst 1.48x
    and 1.44x)."""
    muscles = [str(REPO_ROOT / "muscles" / library)]
    with_c = _steps(plan_run(load_job(WALK_JOB), muscle_args=muscles, stages={"penetration": False}))
    without = _steps(plan_run(load_job(WALK_JOB), muscle_args=muscles, stages={"contact": False, "penetration": False}))
    ratio = with_c / np.maximum(without, 1e-12)
    assert ratio.max() <= POP_RATIO, (ratio.max(), np.argwhere(ratio > POP_RATIO))
    assert (with_c != without).any()  # contact moved something


def test_far_muscle_unchanged_bit_for_bit(demo):
    plan, world, frames = demo
    verts = [v.copy() for v in frames[1]]
    far = len(verts) - 1
    verts[far] = verts[far] + np.array([5.0, 0.0, 0.0])  # 5 m away from every bone and muscle
    v, n, touched, _, after = contact.resolve_frame(plan.contact, verts, np.linalg.inv(world[1]))
    assert not touched[far] and touched.any()
    assert v[far] is verts[far] and n[far] is None
    assert after[far].tolist() == [0.0, 0.0, 0.0]


def test_rigid_motion_moves_the_result_rigidly(demo):
    plan, world, frames = demo
    c, s = np.cos(0.7), np.sin(0.7)
    T = np.array([[c, -s, 0, 0.3], [s, c, 0, -1.2], [0, 0, 1, 0.5], [0, 0, 0, 1.0]])
    moved = [v @ T[:3, :3].T + T[:3, 3] for v in frames[1]]
    a = contact.resolve_frame(plan.contact, frames[1], np.linalg.inv(world[1]))
    b = contact.resolve_frame(plan.contact, moved, np.linalg.inv(T @ world[1]))
    assert (a[2] == b[2]).all()
    for va, vb in zip(a[0], b[0]):
        # rounding (1e-16) is not amplified: the response is a continuous function of the frame
        assert np.abs(va @ T[:3, :3].T + T[:3, 3] - vb).max() < 1e-9
    assert np.allclose(a[4], b[4], atol=1e-9)


def test_pair_shares_and_mask():
    sh = contact.pair_shares(np.array([0.0, 0.0, 1.0, 5.0]))
    assert np.allclose(sh + sh.T, 1.0)
    assert sh[0, 1] == 0.5 and sh[2, 0] == pytest.approx(0.8) and sh[3, 2] == pytest.approx(0.8)
    from axdf_cli.model.muscle import ContactSpec

    ok = contact.pair_mask(["a", "b", "c", "d"], [ContactSpec(group="g"), ContactSpec(group="g"),
                                                  ContactSpec(ignore=("d",)), ContactSpec()])
    assert ok.tolist() == [[False, False, True, True], [False, False, True, True],
                           [True, True, False, False], [True, True, False, False]]


# ----------------------------------------------------------------------------- the CLI


def _digests(out):
    return {p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(out.rglob("*")) if p.is_file() and p.name != "manifest.json"}


def test_no_contact_writes_the_evaluation_alone(tmp_path):
    """--no-contact: the meshes are those of the evaluation without the stage (today's bytes);
    stats.csv still measures."""
    from axdf_cli.formats import PlyWriter

    out = tmp_path / "nc"
    assert run_cli(REPO_ROOT, "run", str(DEMO_JOB), "--frames", FRAMES, "--no-render", "--no-contact",
                   "--out", str(out), "--quiet") == 0
    plan = plan_run(load_job(DEMO_JOB), frames_arg=FRAMES, stages={"contact": False, "penetration": False})
    (_, results), = list(evaluate_plan(plan))  # no stage at all
    for j, res in results:
        name = plan.names[j]
        w = PlyWriter(plan.models[j].faces, name)
        for i, f in enumerate(plan.frames):
            data = w.encode(res.vertices[i].astype(np.float32), res.normals[i].astype(np.float32))
            assert (out / "meshes" / name / f"{name}_{int(f):04d}.ply").read_bytes() == data
    man = json.loads((out / "manifest.json").read_text())
    assert [s["name"] for s in man["settings"]["stages"]] == ["jiggle", "penetration"]  # (the gastrocnemius jiggles)
    rows = (out / "stats.csv").read_text().splitlines()
    assert rows[0].split(",")[8:11] == ["inside_muscle", "inside_bone", "depth"]
    assert max(float(r.split(",")[9]) for r in rows[1:]) > 0.05  # the deltoid lies partly in the humerus


def test_jobs_and_frames_give_the_same_bytes(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    common = ["run", str(DEMO_JOB), "--no-render", "--quiet"]
    assert run_cli(REPO_ROOT, *common, "--frames", "68:71", "--out", str(a)) == 0
    assert run_cli(REPO_ROOT, *common, "--frames", "68:71", "--out", str(b), "--jobs", "2") == 0
    assert run_cli(REPO_ROOT, *common, "--frames", "70", "--out", str(c)) == 0
    da, db, dc = _digests(a), _digests(b), _digests(c)
    assert da == db
    meshes_c = {k: v for k, v in dc.items() if k.startswith("meshes/")}
    assert meshes_c and all(da[k] == v for k, v in meshes_c.items())
    assert [s["name"] for s in json.loads((a / "manifest.json").read_text())["settings"]["stages"]] == [
        "jiggle", "contact", "penetration"]


def test_rest_pose_writes_the_rest_muscle_after_contact(tmp_path):
    """With contact on, the rest muscle is the rest shape after contact at the rest pose (docs/CONTACT.md):
    frame 0 of the demo pose (the rest pose, zero tension) is written as
    :func:`contact.resolve_frame` makes the models' rest meshes at the rest transforms, to
    float32 rounding; with --no-contact, as the rest meshes themselves."""
    from axdf_cli.formats import read_triangles
    from axdf_cli.model.skeleton import forward_kinematics

    for on in (True, False):
        out = tmp_path / ("on" if on else "off")
        assert run_cli(REPO_ROOT, "run", str(DEMO_JOB), "--frames", "0", "--no-render", "--out", str(out), "--quiet",
                       *(() if on else ("--no-contact",))) == 0
        plan = plan_run(load_job(DEMO_JOB), frames_arg="0", stages={"contact": False, "penetration": False})
        skel = plan.pose.skeleton
        rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
        (_, results), = list(evaluate_plan(plan))  # the rest meshes in float64 (the model's identity)
        verts = [r.vertices[0] for _, r in results]
        for m, x in zip(plan.models, verts):
            np.testing.assert_allclose(x, m.rest_vertices, rtol=0, atol=2e-7)
        v, n, touched, _, _ = contact.resolve_frame(ContactStage().start(plan), verts, np.linalg.inv(rest),
                                                    measure_before=False)
        assert touched.any()  # the demo muscles lie partly in their bones at rest
        for j, m in enumerate(plan.models):
            name = plan.names[j]
            pos, nrm, _ = read_triangles((out / "meshes" / name / f"{name}_0000.ply").read_bytes(), ".ply")
            want_v = v[j] if on else verts[j]
            want_n = (n[j] if n[j] is not None else m.rest_normals) if on else m.rest_normals
            np.testing.assert_allclose(pos, want_v, rtol=0, atol=2e-7, err_msg=name)
            np.testing.assert_allclose(nrm, want_n, rtol=0, atol=1e-6, err_msg=name)


BURIED = """\
muscle: buried
axis:
  - {bone: humerus_r, at: [0, 0, -0.10]}
  - {bone: humerus_r, at: [0, 0, -0.15]}
  - {bone: humerus_r, at: [0, 0, -0.20]}
sections:
  - {t: 0.3, radii: [0.003, 0.003]}
  - {t: 0.7, radii: [0.003, 0.003]}
resolution: [10, 8]
contact: {group: inner, ignore: [deltoid_anterior], yield: 2}
"""


def test_muscle_inside_a_bone_is_warned_and_refused_under_strict(tmp_path):
    (tmp_path / "buried.yaml").write_text(BURIED)
    pose = REPO_ROOT / "poses" / "demo.yaml"
    args = ["run", "--muscles", str(tmp_path / "buried.yaml"), "--pose", str(pose), "--frames", "60",
            "--out", str(tmp_path / "o"), "--quiet"]
    assert run_cli(tmp_path, *args) == 0
    stats = (tmp_path / "o" / "stats.csv").read_text()
    assert "wholly inside a bone" in stats
    man = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert any("wholly inside a bone" in w for w in man["warnings"])
    assert run_cli(tmp_path, *args[:-1], "--out", str(tmp_path / "s"), "--strict") == 2
    assert not (tmp_path / "s").exists()


def test_contact_keys_are_checked(tmp_path, capsys):
    from axdf_cli.specs import load_muscle_file

    f = tmp_path / "m.yaml"
    f.write_text(BURIED)
    spec = load_muscle_file(f)[0]
    assert spec.contact.group == "inner" and spec.contact.ignore == ("deltoid_anterior",)
    assert spec.contact.yield_ == 2.0
    f.write_text(BURIED.replace("yield: 2", "yeld: 2"))
    assert run_cli(tmp_path, "validate", str(f)) == 2
    assert "did you mean 'yield'" in capsys.readouterr().err
    job = tmp_path / "job.yaml"
    job.write_text(f"muscles: [{f}]\npose: {REPO_ROOT / 'poses' / 'demo.yaml'}\ncontact: maybe\n")
    assert run_cli(tmp_path, "validate", str(job), "--allow-outside") == 2
    assert "contact must be true or false" in capsys.readouterr().err


# ----------------------------------------------------------------------------- past an end


def _tube(p0, p1, radius, cap, offset=(0.0, 0.0, 0.0), U=12, A=16):
    """A closed tube mesh from pole p0 to pole p1 (vertices (2 + (U - 2) A, 3) as the surface
    stage writes them): rings of ``radius`` from ``cap`` (m) after p0 to ``cap`` before p1, all
    moved by ``offset``."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    L = np.linalg.norm(p1 - p0)
    t = (p1 - p0) / L
    e1 = np.cross(t, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(t, e1)
    s = np.linspace(cap, L - cap, U - 2)
    th = 2.0 * np.pi * np.arange(A) / A
    # rings[u,a,:] = p0 + s[u] t + radius (cos th[a] e1 + sin th[a] e2)
    rings = p0 + s[:, None, None] * t + radius * (np.cos(th)[None, :, None] * e1 + np.sin(th)[None, :, None] * e2)
    return np.concatenate([p0[None], rings.reshape(-1, 3), p1[None]]) + np.asarray(offset)


def test_a_point_past_a_neighbours_end_is_outside_it():
    """A muscle whose end is blunt (ring 1 5 mm from the pole, 20 mm wide) and lies across the
    axes has a box reaching past its poles; two small muscles just past its two ends, beside
    its axis line and inside its box, lie outside its end caps (the generalized winding
    number), so the product measures them outside and does not push them: the nearest point of
    its centre line is then a pole, not ring 1's centre (read as an endless tube of ring 1's
    radius they were wholly inside). A third small muscle inside its middle is measured inside."""
    d = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    L = 0.1
    side = (0.0, 0.0, 0.01)  # beside the axis line: the push's deep fade does not hide it
    meshes = [_tube(np.zeros(3), L * d, 0.02, 0.005),
              _tube(-0.01 * d, -0.003 * d, 0.002, 0.001, side),  # past the origin pole
              _tube((L + 0.003) * d, (L + 0.01) * d, 0.002, 0.001, side),  # past the insertion pole
              _tube(0.04 * d, 0.06 * d, 0.002, 0.001, side)]  # inside the middle
    faces = grid_faces(12, 16)
    big_box = meshes[0].min(axis=0), meshes[0].max(axis=0)
    for m in meshes[1:3]:
        assert np.all((m >= big_box[0]) & (m <= big_box[1]))  # inside its box: the query is asked
    M = len(meshes)
    model = contact.ContactModel(~np.eye(M, dtype=bool), contact.pair_shares(np.zeros(M)),
                                 contact.BoneFields.pack([]), ((12, 16),) * M, np.zeros(M))
    ref = inside_shares([(v, faces) for v in meshes], [], model.allow)[:, 0]
    assert ref.tolist() == [0.0, 0.0, 0.0, 1.0]
    _, _, touched, before, _ = contact.resolve_frame(model, meshes, np.eye(4)[None])
    np.testing.assert_array_equal(before[:, 0], ref)
    assert before[1:3, 2].tolist() == [0.0, 0.0]  # no depth
    assert not touched[1] and not touched[2] and touched[3]


def _pole_in_bone(depth: float, U: int = 16, A: int = 16):
    """A 40 mm cube of bone about the origin and a 5 mm wide muscle along x whose origin pole
    lies ``depth`` (m) inside the cube's face at x = 20 mm (its rings all outside: ring 1 is
    10 mm past the pole): an attachment point that a model places inside its bone's mesh."""
    import trimesh

    cube = trimesh.creation.box(extents=(0.04, 0.04, 0.04))
    fields = contact.BoneFields.pack([contact.bone_field(0, np.asarray(cube.vertices), np.asarray(cube.faces))])
    m = _tube((0.02 - depth, 0.001, 0.002), (0.2, 0.001, 0.002), 0.005, 0.01, U=U, A=A)
    model = contact.ContactModel(np.zeros((1, 1), bool), contact.pair_shares(np.zeros(1)), fields, ((U, A),),
                                 np.zeros(1))
    return model, m, fields


def _bone_depth(fields, x):
    """Depth (m) of points x (N, 3) inside the cube (0 outside), from its field."""
    g = np.empty(6)
    sel = np.arange(len(fields.bones))
    posed = fields.posed(np.eye(4)[None])
    d = [contact.query.bone_query(p, posed, sel, 0, len(sel), -1e300, g) for p in np.asarray(x, float)]
    return np.maximum(-np.array(d), 0.0)


def test_a_pole_inside_its_bone_is_moved_out_to_the_surface():
    """A muscle's pole (the tip of its end cap, at the attachment) that lies 5 mm inside a bone
    mesh is pushed out along the field's gradient (2 passes, soft-capped at 4 mm each: from 5
    mm deep to outside), as a whole: the far pole stays where it was, the volume is exact,
    the product measures no depth after, and the rings' own positions hardly change. Moved in
    0.5 mm steps from 0 to 9 mm deep, the pole's place changes smoothly (no pop)."""
    U, A = 16, 16
    model, m, fields = _pole_in_bone(0.005)
    assert _bone_depth(fields, m[:1])[0] == pytest.approx(0.005, abs=1e-4)
    assert _bone_depth(fields, m[1:]).max() == 0.0  # only the pole is inside
    v, _, touched, before, after = contact.resolve_frame(model, [m], np.eye(4)[None])
    assert touched[0]
    assert before[0, 2] == pytest.approx(0.005, abs=1e-4) and after[0, 2] == 0.0
    assert _bone_depth(fields, v[0][:1])[0] == 0.0
    shift = v[0][0] - m[0]
    assert 0.005 < shift[0] < 0.007 and np.abs(shift[1:]).max() < 1e-4  # out along +x, the face's normal
    np.testing.assert_array_equal(v[0][-1], m[-1])  # the other pole stays
    vol = [_volume(x, U, A) for x in (m, v[0])]
    assert vol[1] == pytest.approx(vol[0], rel=1e-8)
    prev = None
    for depth in np.arange(0.0, 0.0091, 0.0005):
        model, m, _ = _pole_in_bone(depth)
        out = contact.resolve_frame(model, [m], np.eye(4)[None])[0][0]
        pole = out[0] - m[0]
        if prev is not None:
            assert np.abs(pole - prev).max() < 0.0006, depth  # its push grows by about the step
        prev = pole


def test_a_neighbour_gives_way_to_a_pole_inside_it():
    """A 6 mm wide muscle ends (its pole, an attachment) 8 mm inside a 40 mm wide one, its rings
    all outside: the pole does not move (the attachments hold against muscles; moving it near
    a crowded attachment stepped 2.4x on the walk), the wide one gives way at it, its volume
    exact, and the pole ends shallower. Without the poles' pass (``poles=False``, the packer's)
    nothing moves."""
    U, A = 24, 24
    thick = _tube((0, 0, 0), (0.2, 0, 0), 0.02, 0.01, U=U, A=A)
    thin = _tube((0.1, 0.08, 0.0), (0.1, 0.012, 0.0), 0.003, 0.01, U=U, A=A)
    model = contact.ContactModel(~np.eye(2, dtype=bool), contact.pair_shares(np.zeros(2)), contact.BoneFields.pack([]),
                                 ((U, A), (U, A)), np.zeros(2))
    v, _, touched, before, after = contact.resolve_frame(model, [thick, thin], np.eye(4)[None])
    assert before[1, 0] == pytest.approx(1.0 / len(thin)) and before[1, 2] == pytest.approx(0.008, abs=2e-4)
    assert touched.tolist() == [True, False] and v[1] is thin
    mid = 1 + (U // 2 - 1) * A
    near = mid + thick[mid:mid + A, 1].argmax()
    assert v[0][near, 1] - thick[near, 1] < -0.002  # gives way where the pole is
    vol = [_volume(x, U, A) for x in (thick, v[0])]
    assert vol[1] == pytest.approx(vol[0], rel=1e-8)
    assert after[1, 2] < before[1, 2] - 0.002
    v_off, _, touched_off, _, after_off = contact.resolve_frame(model, [thick, thin], np.eye(4)[None], poles=False)
    assert not touched_off.any() and after_off[1, 2] == pytest.approx(before[1, 2])


def test_a_moved_muscles_normals_are_the_surface_stages(demo):
    """The normals contact writes for a muscle it moved are computed as the surface stage's
    (ring vertices and the poles' fans): on meshes it did not move they equal the
    evaluation's, poles included (the poles' outward directions were once left unnormalized,
    and every pole got the direction from its ring's centre instead of its fan's normal, up to
    20 degrees off)."""
    plan, world, frames = demo
    (chunk, results), = list(evaluate_plan(plan))
    for j, r in results:
        U, A = plan.contact.shapes[j]
        v = r.vertices[0].astype(np.float64)
        grid = contact.vertices_to_grid(v, U, A)
        out_v, out_n = np.empty((1, len(v), 3)), np.empty((1, len(v), 3))
        contact.volume.normals(grid, np.array([0, U * A]), np.array([U]), np.array([A]), 0, out_v, out_n)
        np.testing.assert_array_equal(out_v[0], v)
        np.testing.assert_allclose(out_n[0], r.normals[0], atol=1e-5)


def _thin_in_thick(off_y: float, U: int = 24, A: int = 24):
    """A 40 mm wide muscle along x and a 6 mm wide one inside it, ``off_y`` (m) beside its axis
    (both 20 cm long; ring radii 0.15 of the thick one's: a tendon in a belly)."""
    thick = _tube((0, 0, 0), (0.2, 0, 0), 0.02, 0.01, U=U, A=A)
    thin = _tube((0.01, 0, 0), (0.19, 0, 0), 0.003, 0.01, offset=(0, off_y, 0), U=U, A=A)
    model = contact.ContactModel(~np.eye(2, dtype=bool), contact.pair_shares(np.zeros(2)), contact.BoneFields.pack([]),
                                 ((U, A), (U, A)), np.zeros(2))
    return model, [thick, thin]


def test_a_thick_muscle_gives_way_to_a_thin_one_inside_it(monkeypatch):
    """None of the thick muscle's points is inside the thin one, so only the thin one's samples
    can ask for room: they pull the thick one's section in at their angle (tol.CONTACT_THIN).
    With that, the thin one ends 4% inside (34% asking for each push once, tol.CONTACT_RELAX;
    its own 2 passes alone: 67% inside), the thick one's side facing it gives way (-5.7 mm)
    and the section shifts from it (its far side -4.3 mm), its volume exact; moved across in
    0.5 mm steps, the thick one's vertices change smoothly (no step over 1.5 mm)."""
    U, A = 24, 24
    model, (thick, thin) = _thin_in_thick(0.012)
    v, _, touched, before, after = contact.resolve_frame(model, [thick, thin], np.eye(4)[None])
    assert touched.tolist() == [True, True]
    assert before[1, 0] == 1.0 and after[1, 0] < 0.5
    mid = 1 + (U // 2 - 1) * A  # the thick one's middle ring
    ring = thick[mid:mid + A]
    near, far = mid + ring[:, 1].argmax(), mid + ring[:, 1].argmin()
    d = v[0] - thick
    assert d[near, 1] < -0.003 and d[far, 1] < -0.001  # gives way, and shifts away
    vol = [_volume(x, U, A) for x in (thick, v[0])]
    assert vol[1] == pytest.approx(vol[0], rel=1e-8)
    # without it (no ring counts as thin) the thick one stays, and the thin one stays mostly
    # inside it (its poles, inside the thick one too, left where they are: they would make it
    # give way)
    monkeypatch.setattr(tol, "CONTACT_THIN", (-2.0, -1.0))
    v_off, _, touched_off, _, after_off = contact.resolve_frame(model, [thick, thin], np.eye(4)[None], poles=False)
    monkeypatch.undo()
    assert not touched_off[0] and np.array_equal(v_off[0], thick) and after_off[1, 0] > 0.6 > 0.1 > after[1, 0]
    prev = None
    for oy in np.arange(0.008, 0.0171, 0.0005):
        model, meshes = _thin_in_thick(oy)
        out = contact.resolve_frame(model, meshes, np.eye(4)[None])[0][0]
        if prev is not None:
            assert np.abs(out - prev).max() < 0.0015, oy
        prev = out


def test_the_depth_is_the_distance_to_the_surface_of_a_flat_section():
    """A packed section may be wide and flat. A thin muscle lying along the middle of one (80 x
    20 mm) is 10 mm from its nearest side, though 40 mm from its edges along the wide axis:
    the product's depth (stats.csv's ``depth``) is the distance to the surface, checked against
    libigl's point-to-mesh distance, not the radial ray's length (which read it 4x deeper)."""
    import igl

    U, A = 24, 24
    flat = _tube((0, 0, 0), (0.2, 0, 0), 0.01, 0.01, U=U, A=A)
    flat[:, 1] *= 4.0  # 40 mm along y, 10 mm along z
    thin = _tube((0.03, 0, 0), (0.17, 0, 0), 0.002, 0.01, offset=(0, 0.004, 0), U=U, A=A)
    model = contact.ContactModel(~np.eye(2, dtype=bool), contact.pair_shares(np.zeros(2)), contact.BoneFields.pack([]),
                                 ((U, A), (U, A)), np.zeros(2))
    _, _, _, before, _ = contact.resolve_frame(model, [flat, thin], np.eye(4)[None], 0)
    assert before[1, 0] == 1.0  # wholly inside
    faces = np.asarray(grid_faces(U, A), np.int64)
    d2, _, _ = igl.point_mesh_squared_distance(thin, flat, faces)
    true = float(np.sqrt(d2).max())
    assert 0.007 < true < 0.0105
    assert before[1, 2] == pytest.approx(true, abs=1e-3)


def test_a_section_oblique_to_the_line_of_its_centres_is_read_across_its_own_plane():
    """A packed section may leave the line of action: a wide, flat muscle whose rings stand
    square to x while their centres drift sideways as fast as they advance (the line of
    centres at 45 degrees to the rings, as Rajagopal's packed soleus by the ankle). Points
    1 to 10 mm from its surface are read inside or outside as the generalized winding number
    reads them but for 1.3% (the rings read linearly between them); read across the plane
    square to the line of centres, from its nearest point, 3.2% were misread."""
    import igl

    U, A = 24, 24
    flat = _tube((0, 0, 0), (0.2, 0, 0), 0.01, 0.01, U=U, A=A)
    flat[:, 1] *= 4.0  # 80 x 20 mm
    flat[:, 1] += flat[:, 0] - 0.1  # each ring's centre 1 m sideways per metre along x
    model = contact.ContactModel(np.zeros((1, 1), bool), contact.pair_shares(np.zeros(1)),
                                 contact.BoneFields.pack([]), ((U, A),), np.zeros(1))
    rng = np.random.default_rng(11)
    lo, hi = flat.min(axis=0), flat.max(axis=0)
    pts = lo + (hi - lo) * rng.random((3000, 3))
    faces = np.asarray(grid_faces(U, A), np.int64)
    gwn = winding_numbers(pts, flat, faces) > 0.5
    d2, _, _ = igl.point_mesh_squared_distance(pts, flat, faces)
    clear = (np.sqrt(d2) > 0.001) & (np.sqrt(d2) < 0.01)
    grid = contact.vertices_to_grid(flat, U, A)
    off, nu, na = np.array([0, U * A]), np.array([U]), np.array([A])
    cen = np.zeros((U, contact.CEN_COLUMNS))
    contact.query.centres(grid, off, nu, na, cen, np.array([0, U]))
    q = np.empty(contact.QUERY_SIZE)
    read = np.array([contact.query.muscle_query(x, grid, 0, U, A, cen, 0, 0.0, q) and q[0] < q[1] for x in pts])
    assert gwn[clear].sum() > 200 and (~gwn[clear]).sum() > 200
    assert (read != gwn)[clear].mean() < 0.02


def _thin_beside_thick_frames():
    """Three muscles where thin ones lie in a thick one (the thick one's pulls are recorded:
    :func:`contact.rings.point_push`), and their models."""
    model, (thick, thin) = _thin_in_thick(0.012)
    _, (_, thin2) = _thin_in_thick(-0.009)
    U, A = 24, 24
    m3 = contact.ContactModel(~np.eye(3, dtype=bool), contact.pair_shares(np.zeros(3)), contact.BoneFields.pack([]),
                              ((U, A),) * 3, np.zeros(3))
    return m3, [thick, thin, thin2]


def test_the_bytes_do_not_depend_on_threads_or_the_room_for_records(demo, monkeypatch):
    """Contact runs muscle by muscle on numba's threads; each muscle's pulls on thick
    neighbours are recorded in its own rows and added up in muscle order. One thread or
    all, the kernels compiled without threads (a worker's), and with no room for a record
    (every pass runs again with room for all), the result is the same to the bit, the demo's
    frames and a thick muscle with two thin ones in it."""
    import numba

    from axdf_cli import runtime
    from axdf_cli.workers import THREADS_VAR

    plan, world, frames = demo
    m3, meshes = _thin_beside_thick_frames()
    cases = [(plan.contact, frames[fi], np.linalg.inv(world[fi])) for fi in range(len(frames))]
    cases.append((m3, meshes, np.eye(4)[None]))

    def all_out():
        outs = []
        for model, verts, inv in cases:
            vol = np.zeros(len(verts))
            v, n, touched, before, after = contact.resolve_frame(model, verts, inv, volumes=vol,
                                                                 threads=runtime.use_threads())
            outs.append(([x.copy() for x in v], [None if x is None else x.copy() for x in n], touched.copy(), after,
                         vol))
        return outs

    monkeypatch.setenv(THREADS_VAR, "")
    ref = all_out()
    assert ref[-1][2].tolist() == [True, True, True]  # the thick one gave way: records were added up
    before_threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = all_out()
    finally:
        numba.set_num_threads(before_threads)
    monkeypatch.setenv(THREADS_VAR, "1")
    assert not runtime.use_threads()
    serial = all_out()
    monkeypatch.setenv(THREADS_VAR, "")
    monkeypatch.setattr(contact.query, "REACTION_RECORDS", 0)
    no_room = all_out()
    for other in (one, serial, no_room):
        for a, b in zip(ref, other):
            for x, y in zip(a[0] + a[1], b[0] + b[1]):
                assert (x is None and y is None) or np.array_equal(x, y)
            assert np.array_equal(a[2], b[2]) and np.array_equal(a[3], b[3]) and np.array_equal(a[4], b[4])


def test_contact_in_forked_workers_after_this_process_used_its_threads(demo):
    """This process runs contact on numba's threads, then forked workers (as `axdf run
    --jobs`) run it again, each on its own thread (GNU OpenMP, numba's threading layer here,
    stops a forked child that starts its threads), to the same bytes."""
    from axdf_cli import runtime
    from axdf_cli.workers import process_map

    plan, world, frames = demo
    inv = np.linalg.inv(world[0])
    here = contact.resolve_frame(plan.contact, frames[0], inv, threads=runtime.use_threads())[0]
    there = process_map(_contact_in_worker, [0, 1], (plan.contact, frames[0], inv), jobs=2)
    for v in there:
        assert all(np.array_equal(a, b) for a, b in zip(here, v))


def test_a_forked_process_keeps_contact_on_its_thread(demo, tmp_path):
    """Any process forked from one that used numba's threads (not only axdf's workers, which
    say so: AXDF_NUM_THREADS) runs contact on its own thread: GNU OpenMP would stop it
    ("fork() called from a process already using GNU OpenMP"). The same bytes."""
    import pickle

    from axdf_cli import runtime

    plan, world, frames = demo
    inv = np.linalg.inv(world[0])
    assert runtime.use_threads() or os.environ.get("AXDF_NUM_THREADS") == "1"
    here = contact.resolve_frame(plan.contact, frames[0], inv, threads=runtime.use_threads())[0]  # (on its threads)
    out = tmp_path / "child.pkl"
    pid = os.fork()
    if pid == 0:  # the child: no AXDF_NUM_THREADS set for it
        code = 1
        try:
            os.environ.pop("AXDF_NUM_THREADS", None)
            assert not runtime.use_threads()
            out.write_bytes(pickle.dumps(contact.resolve_frame(plan.contact, frames[0], inv,
                                                               threads=runtime.use_threads())[0]))
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    there = pickle.loads(out.read_bytes())
    assert all(np.array_equal(a, b) for a, b in zip(here, there))


def _contact_in_worker(shared, _item):
    from axdf_cli import runtime

    model, verts, inv = shared
    return contact.resolve_frame(model, verts, inv, threads=runtime.use_threads())[0]


def test_a_worker_keeps_contact_on_its_thread(monkeypatch):
    """A worker process (the workers are the parallelism) runs contact's kernels on its own
    thread, a single process on numba's threads; the switch is AXDF_NUM_THREADS."""
    import numba

    from axdf_cli import runtime
    from axdf_cli.workers import THREADS_VAR, one_thread

    monkeypatch.setenv(THREADS_VAR, "")  # (restored after the test, as it was)
    assert runtime.use_threads() == (numba.config.NUMBA_NUM_THREADS > 1)
    one_thread()
    assert os.environ[THREADS_VAR] == "1" and not runtime.use_threads()


def test_the_kernel_cache_follows_every_model_source(tmp_path, monkeypatch):
    """numba keys a cached kernel by its own file, while pack.py's kernels hold contact.py's
    query: axdf keeps numba's cache in a folder keyed by every source under axdf_cli/model
    and tolerances.py (a packed library made with pack's kernels cached before a change of the query was not
    what the code makes). The folder is this process's (NUMBA_CACHE_DIR); others unused for
    30 days are removed, recent ones kept."""
    import hashlib
    import time

    from axdf_cli import runtime

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    base = tmp_path / "axdf" / "numba"
    old, recent = base / "0", base / "1"
    for d in (old, recent):
        d.mkdir(parents=True)
    os.utime(old, (time.time() - 40 * 86400,) * 2)
    here = runtime.kernel_cache()
    model = REPO_ROOT / "axdf_cli" / "model"
    h = hashlib.sha256()
    # tolerances.py too: the kernels read its constants as compile-time globals
    for f in [*sorted(model.rglob("*.py")), model.parent / "tolerances.py"]:
        h.update(str(f.relative_to(model.parent)).encode() + b"\0" + f.read_bytes() + b"\0")
    assert here == str(base / h.hexdigest()[:16])
    assert not old.exists() and recent.is_dir() and os.path.isdir(here)
    # what numba is told in a process that configures axdf's runtime (the command line's entry)
    import subprocess
    import sys

    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    got = subprocess.run([sys.executable, "-c", "import os; from axdf_cli import runtime; runtime.configure(); print(os.environ['NUMBA_CACHE_DIR'])"],
                         env=env, capture_output=True, text=True, check=True, cwd=REPO_ROOT).stdout.strip()
    assert got == here


def test_a_bone_field_computed_by_another_libigl_is_not_read_back(tmp_path, monkeypatch):
    """The bone fields' disk cache is keyed by the mesh, the grid and libigl's version: a
    field another release computed (kept in ~/.cache across installs) is computed again, and
    the same release reads its own back (the same values)."""
    from axdf_cli.fileio import fieldcache

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    v = np.array([[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0, 0, 0.02]], float)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    fieldcache.clear()
    a = contact.bone_field(0, v, f, h=0.005, pad=0.01, cache=fieldcache.cached)
    files = sorted((tmp_path / "axdf" / "sdf").glob("*.npz"))
    assert len(files) == 1 and fieldcache.igl_version().startswith("libigl ")
    fieldcache.clear()
    again = contact.bone_field(0, v, f, h=0.005, pad=0.01, cache=fieldcache.cached)  # read back: no new file
    assert sorted((tmp_path / "axdf" / "sdf").glob("*.npz")) == files
    assert np.array_equal(a.values, again.values)
    assert np.array_equal(contact.bone_field(0, v, f, h=0.005, pad=0.01).values, a.values)  # (no cache)
    monkeypatch.setattr(fieldcache, "igl_version", lambda: "libigl 0.0.0")
    fieldcache.clear()
    other = contact.bone_field(0, v, f, h=0.005, pad=0.01, cache=fieldcache.cached)
    assert len(list((tmp_path / "axdf" / "sdf").glob("*.npz"))) == 2  # computed again, kept apart
    assert np.array_equal(other.values, a.values)
    fieldcache.clear()


def test_muscles_that_overlap_in_bulk_are_told_to_pack(tmp_path, capsys):
    """arm26 as imported (generic sections through each other): after contact ~30% of its
    vertices lie inside another muscle, more than contact clears; the run says so once, with
    the `axdf pack` command for its folder, skeleton and pose (stderr and the manifest), and
    --strict refuses it before writing. Packed (the job's own muscles/arm26_packed), or
    without contact, the run has no such warning."""
    from axdf_cli.pipeline.overlap import BULK_OVERLAP

    arm = ["--frames", "0:4", "--no-render", "--quiet"]
    job = str(REPO_ROOT / "poses" / "jobs" / "arm26_flex.yaml")
    imported = ["--muscles", str(REPO_ROOT / "muscles" / "arm26")]
    assert run_cli(REPO_ROOT, "run", job, *imported, *arm, "--out", str(tmp_path / "imp")) == 0
    err = capsys.readouterr().err
    assert err.count("overlap in bulk") == 1
    assert ("axdf pack muscles/arm26 --skeleton poses/skeletons/arm26.yaml --pose poses/arm26_flex.yaml "
            "--out muscles/arm26_packed") in err
    man = json.loads((tmp_path / "imp" / "manifest.json").read_text())
    bulk = [w for w in man["warnings"] if "overlap in bulk" in w]
    assert len(bulk) == 1 and "arm26" not in bulk[0]  # (the manifest names no path: the terminal has the command)
    stats = (tmp_path / "imp" / "stats.csv").read_text()
    share = float(bulk[0].split("after contact ")[1].split("%")[0]) / 100
    inside = np.array([float(r.split(",")[8]) for r in stats.splitlines()[1:]])
    assert share > BULK_OVERLAP and abs(share - inside.mean()) < 0.05  # (weighted by vertices)
    assert "overlap in bulk" not in stats  # a run's warning, not a frame's
    assert run_cli(REPO_ROOT, "run", job, *imported, *arm, "--out", str(tmp_path / "strict"), "--strict") == 2
    assert "overlap in bulk" in capsys.readouterr().err
    assert not (tmp_path / "strict").exists()
    assert run_cli(REPO_ROOT, "run", job, *imported, *arm, "--out", str(tmp_path / "nc"), "--no-contact") == 0
    assert "overlap in bulk" not in capsys.readouterr().err
    assert not any("overlap in bulk" in w for w in json.loads((tmp_path / "nc" / "manifest.json").read_text())["warnings"])
    assert run_cli(REPO_ROOT, "run", job, *arm, "--out", str(tmp_path / "packed"), "--strict") == 0
    assert "overlap in bulk" not in capsys.readouterr().err
    inside = np.array([float(r.split(",")[8]) for r in (tmp_path / "packed" / "stats.csv").read_text().splitlines()[1:]])
    assert inside.mean() < 0.2 * BULK_OVERLAP


ARM_DATASET = """\
dataset: arm_bulk
seed: 3
skeleton: {root}/poses/skeletons/arm26.yaml
muscles: {root}/muscles/{muscles}
coordinates:
  r_elbow_flex: {{range: [0, 90]}}
sequences:
  - {{sample: uniform, count: 2, frames: 1}}
  - {{sample: uniform, count: 1, frames: 2, keys: 2}}
activation: {{sample: uniform, range: [0, 1]}}
cameras:
  sphere: {{views: 1, distance: [1.0, 1.2], fov: 40}}
render: {{size: [24, 24], supersample: 1}}
format: ply
{extra}"""


def test_a_data_set_whose_muscles_overlap_in_bulk_is_told_to_pack(tmp_path, capsys):
    """axdf dataset build tells a data set of muscles that overlap in bulk (arm26 as imported)
    once, on stderr even with -q, with the share over the frames it made, how many sequences'
    manifests say so and the `axdf pack` command for its muscle folder and skeleton (the poses
    are sampled: packed at rest); packed muscles, or contact off, are not told."""
    def build(name: str, muscles: str, extra: str = "") -> tuple[int, str]:
        (tmp_path / f"{name}.yaml").write_text(ARM_DATASET.format(root=REPO_ROOT.as_posix(), muscles=muscles,
                                                                  extra=extra))
        rc = run_cli(REPO_ROOT, "dataset", "build", str(tmp_path / f"{name}.yaml"), "--out", str(tmp_path / name),
                     "--allow-outside", "-q")
        return rc, capsys.readouterr().err

    rc, err = build("imp", "arm26")
    assert rc == 0 and err.count("overlap in bulk") == 1, err
    assert "3 of 3 sequence(s) made say so in their manifests" in err
    assert err.rstrip().endswith("axdf pack muscles/arm26 --skeleton poses/skeletons/arm26.yaml "
                                 "--out muscles/arm26_packed")
    assert "over the 4 frame(s) made" in err
    share = float(err.split("after contact ")[1].split("%")[0]) / 100
    inside = []
    for seq in sorted(p for p in (tmp_path / "imp").iterdir() if (p / "manifest.json").exists()):
        warns = json.loads((seq / "manifest.json").read_text())["warnings"]
        assert sum("overlap in bulk" in w for w in warns) == 1
        inside += [float(r.split(",")[8]) for r in (seq / "stats.csv").read_text().splitlines()[1:]]
    assert len(inside) == 4 * 6 and abs(share - np.mean(inside)) < 0.05  # (weighted by vertices)
    rc, err = build("packed", "arm26_packed")
    assert rc == 0 and "overlap in bulk" not in err
    rc, err = build("nc", "arm26", "contact: false\n")
    assert rc == 0 and "overlap in bulk" not in err
