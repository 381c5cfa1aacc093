"""Packing (axdf_cli/model/pack.py, `axdf pack`): the rest shapes made to share space.

On the demo library with a twin of the biceps 1.2-1.4 cm beside it (they overlap in bulk):
the fit through the surface basis is exact on the muscle's own rest mesh (rest identity);
territories never overlap; after packing, an independent generalized winding number count
(tests/winding.py) finds almost no vertex inside another muscle, and the volumes are kept;
the packed files are valid muscle files, the same inputs give the same bytes, and the
command follows the output rule."""
from __future__ import annotations

import json

import numpy as np
import pytest

from cli_in_folder import run_cli
from conftest import DEMO_JOB, REPO_ROOT
from test_contact import TWIN
from winding import inside_shares

from axdf_cli import tolerances as tol
from axdf_cli.model import contact, pack
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.plan import plan_run
from axdf_cli.specs import RefPolicy, load_job, load_muscle_file
from axdf_cli.specs.muscle import parse_muscle_text

SKELETON = REPO_ROOT / "poses" / "skeletons" / "human_r.yaml"


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    """The demo muscles and the biceps' twin: (folder of muscle files, plan, rest world, contact model)."""
    d = tmp_path_factory.mktemp("pack_in")
    for p in (REPO_ROOT / "muscles" / "demo").glob("*.yaml"):
        (d / p.name).write_text(p.read_text())
    (d / "biceps_twin.yaml").write_text(TWIN)
    plan = plan_run(load_job(DEMO_JOB), muscle_args=[str(d)], policy=RefPolicy(allow_outside=True),
                    stages={"contact": False, "penetration": False})
    skel = plan.pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    cm = contact.build(plan.muscles, plan.models, rest, plan.bone_meshes)
    return d, plan, rest, cm


@pytest.fixture(scope="module")
def packed(demo):
    d, plan, rest, cm = demo
    from axdf_cli import runtime

    return pack.pack(plan.muscles, plan.models, plan.pose.skeleton, rest, cm, iterations=12,
                     threads=runtime.use_threads())


def _gwn_shares(plan, models, rest, cm):
    meshes = [(m.rest_vertices.astype(np.float64), m.faces) for m in models]
    bones = [(v.astype(np.float64) @ rest[b, :3, :3].T + rest[b, :3, 3], f) for b, (v, f, _) in sorted(plan.bone_meshes.items())]
    return inside_shares(meshes, bones, cm.allow)


def test_the_fit_is_exact_on_the_rest_mesh(demo):
    """Rest identity: fitted to its own rest mesh in its own sections, a muscle's control points
    are its own (the rest surface is linear in them), and so is its mesh."""
    d, plan, rest, cm = demo
    for m in plan.models:
        t = np.array([s.t for s in m.spec.sections])
        fr = pack._frames(m, rest, t)
        grid = contact.vertices_to_grid(m.rest_vertices.astype(np.float64), m.U, m.A).reshape(m.U, m.A, 3)
        coords, fitted = pack.Fit(m, fr, None, 0.0)(grid)
        own = m.rest_control_points - fr.c
        assert np.abs(coords - np.stack([(own * fr.r).sum(1), (own * fr.s).sum(1)], axis=1)).max() < 1e-6
        assert np.abs(fitted - grid[1:-1]).max() < 1e-6
        spec = pack.with_outlines(m.spec, t, pack.to_file_outlines(coords, fr))
        again = MuscleModel(spec, plan.pose.skeleton.bone_index, rest, plan.pose.skeleton)
        assert np.abs(again.rest_vertices - m.rest_vertices).max() < 1e-6
        assert abs(again.v0 / m.v0 - 1.0) < 1e-6


def test_territories_never_overlap(demo):
    """Every point lies in at most one muscle's territory, however the envelopes are grown."""
    d, plan, rest, cm = demo
    mesh = pack._grids(plan.models)
    grid, box = mesh.grid, mesh.box
    f = cm.fields
    inv = np.linalg.inv(rest)
    M = len(plan.models)
    rng = np.random.default_rng(7)
    pts = grid[rng.integers(0, len(grid), 6000)] + rng.normal(0.0, 0.01, (6000, 3))  # around the muscles
    for s in (np.ones(M), 1.0 + rng.random(M)):
        reach = (s - 1.0) * 0.05 + 1e-3
        nbr_off, nbr = contact.query.neighbours(box + np.concatenate([-reach[:, None] * np.ones((1, 3)),
                                                                      reach[:, None] * np.ones((1, 3))], axis=1),
                                                cm.allow, 0.0)
        lists = contact.Lists(nbr_off, nbr, *contact.query.field_lists(box, f, inv, 0.05))
        owners = np.zeros(len(pts), int)
        enveloped = np.zeros(len(pts), int)
        held_any = 0
        q = np.empty(contact.QUERY_SIZE)
        for i in range(M):
            enveloped += [pack._frac(x, i, mesh, reach[i], q) < s[i] for x in pts]
            ok = np.zeros(len(pts), np.bool_)
            pack._owned_all(pts, np.full(len(pts), i), s, mesh, reach, lists, f.posed(inv), 0.0, ok)
            owners += ok
            held_any += ok.sum()
        assert owners.max() <= 1
        assert (enveloped >= 2).sum() > 100  # (the test means something: the envelopes overlap)
        assert held_any > 1000


def test_packing_clears_the_overlap_and_keeps_the_volume(demo, packed):
    d, plan, rest, cm = demo
    names = [s.name for s in plan.muscles]
    before = _gwn_shares(plan, plan.models, rest, cm)
    after = _gwn_shares(plan, packed.models, rest, cm)
    i, j = names.index("biceps_brachii"), names.index("biceps_twin")
    assert before[i, 0] > 0.3 and before[j, 0] > 0.3  # the twins overlap in bulk
    assert after[:, 0].max() < 0.02, after[:, 0]
    assert after[:, 1].mean() <= before[:, 1].mean() + 1e-9
    ratio = packed.volume / packed.volume0
    assert np.all(np.abs(ratio - 1.0) < 0.1), dict(zip(names, ratio.round(3)))
    # the product's own measure agrees
    assert packed.after[:, 0].max() < 0.02
    # and a muscle nothing touches keeps its shape (the brachioradialis lies clear of the others)
    k = names.index("brachioradialis")
    assert packed.before[k, 0] == 0.0
    assert np.abs(packed.models[k].rest_vertices - plan.models[k].rest_vertices).max() < 2e-3


def test_pack_command_writes_valid_files_and_the_same_bytes(demo, tmp_path):
    d, plan, rest, cm = demo
    outs = []
    for k in range(2):
        out = tmp_path / f"packed{k}"
        assert run_cli(REPO_ROOT, "pack", str(d), "--skeleton", str(SKELETON), "--out", str(out), "--rounds", "4",
                       "--allow-outside", "-q") == 0
        outs.append(out)
    names = sorted(p.name for p in outs[0].iterdir())
    assert names == sorted([p.name for p in d.glob("*.yaml")] + ["pack_report.json", "PACK.md", "manifest.json"])
    for p in outs[0].iterdir():
        if p.name != "manifest.json":
            assert p.read_bytes() == (outs[1] / p.name).read_bytes(), p.name
    man = json.loads((outs[0] / "manifest.json").read_text())
    assert man["command"] == "pack"
    rep = json.loads((outs[0] / "pack_report.json").read_text())
    assert rep["after"]["inside_muscle"] < rep["before"]["inside_muscle"]
    originals = {s.name: s for p in d.glob("*.yaml") for s in load_muscle_file(p)}
    reshaped = set()
    for p in outs[0].glob("*.yaml"):
        for spec in load_muscle_file(p):
            if spec.sections == originals[spec.name].sections:
                continue  # nothing touched it: kept as it was
            assert all(s.outline is not None for s in spec.sections)
            assert len(spec.sections) == max(tol.PACK_SECTIONS, len(originals[spec.name].sections))
            reshaped.add(spec.name)
    assert {"biceps_brachii", "biceps_twin"} <= reshaped and "brachioradialis" not in reshaped
    # a run on the packed muscles works
    assert run_cli(REPO_ROOT, "run", str(DEMO_JOB), "--muscles", str(outs[0]), "--frames", "0", "--out",
                   str(tmp_path / "run"), "--allow-outside", "--format", "npz", "--no-render", "-q") == 0


def test_pack_command_follows_the_output_rule(demo, tmp_path, capsys):
    d, plan, rest, cm = demo
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    common = ("--skeleton", str(SKELETON), "--rounds", "1", "--allow-outside", "-q")
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(mine), *common) == 2  # not its folder
    assert sorted(p.name for p in mine.iterdir()) == ["notes.txt"]
    before = {p.name: p.read_bytes() for p in d.iterdir()}
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(d), *common) == 2  # its input is never its output
    assert {p.name: p.read_bytes() for p in d.iterdir()} == before
    capsys.readouterr()
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(tmp_path / "x"), "--skeleton", str(SKELETON),
                   "--rounds", "0") == 2
    assert "--rounds" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_a_muscle_document_keeps_its_contact_keys(tmp_path):
    """transfer and pack write muscles through one document writer: `contact:` survives it."""
    from axdf_cli.importers import emit
    from axdf_cli.tools.muscle_files import file_doc

    src = (REPO_ROOT / "muscles" / "demo" / "biceps_brachii.yaml").read_text()
    p = tmp_path / "b.yaml"
    p.write_text(src + "contact: {group: arm, ignore: [brachioradialis], yield: 1.5}\n")
    spec, = load_muscle_file(p)
    q = tmp_path / "c.yaml"
    q.write_text(emit.dump_yaml(emit.rounded(file_doc([spec]))))
    again, = load_muscle_file(q)
    assert again.contact == spec.contact and spec.contact.ignore == ("brachioradialis",)


def _posed_overlap(plan, specs, frames: str) -> np.ndarray:
    """(F, M) the share of every muscle's vertices inside another at ``frames`` of the demo pose
    (no contact: the shapes as packed), by the product's measure."""
    from dataclasses import replace

    from axdf_cli.pipeline.evaluate import evaluate_plan

    skel = plan.pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    models = [MuscleModel(s, skel.bone_index, rest, skel) for s in specs]
    p = plan_run(load_job(DEMO_JOB), frames_arg=frames, stages={"contact": False, "penetration": True})
    p = replace(p, muscles=list(specs), models=models)
    share: dict = {}
    for _, results in evaluate_plan(p):
        for j, r in results:
            share.setdefault(j, []).append(r.contact[:, 0])
    return np.stack([np.concatenate(share[j]) for j in range(len(specs))], axis=1)


def test_polishing_over_a_pose_shares_space_at_its_frames(demo):
    """``pose``: the polish also resolves contact at the pose's frames and fits the mean of its
    displacements carried back to rest, so the packed shapes overlap less at those frames and
    between them (no contact stage: the shapes alone), and still little at rest."""
    from axdf_cli.tools.pack import build_pack

    d, plan, rest, cm = demo
    files = sorted(d.glob("*.yaml"))
    pol = RefPolicy(allow_outside=True)
    outs = {}
    for key, pose in (("rest", None), ("pose", REPO_ROOT / "poses" / "demo.yaml")):
        res = build_pack(files, SKELETON, pol, rounds=6, pose_path=pose, frames=None if pose is None else "40:120:20")
        specs = [s for p in files for s in parse_muscle_text(res.files[p.name].decode(), d / p.name)]
        outs[key] = (res, specs)
    at = {k: _posed_overlap(plan, specs, "40:120:5").mean() for k, (_, specs) in outs.items()}
    assert at["pose"] < 0.8 * at["rest"], at
    rep = outs["pose"][0].report
    assert rep["pose"] == {"file": "demo.yaml", "frames": [40, 60, 80, 100, 120]}
    assert rep["after"]["inside_muscle"] < 0.02 and "pose" not in outs["rest"][0].report


def test_pack_pose_errors_write_nothing(demo, tmp_path, capsys):
    d, plan, rest, cm = demo
    common = ("--skeleton", str(SKELETON), "--rounds", "1", "--allow-outside")
    out = tmp_path / "x"
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(out), "--frames", "0:10", *common) == 2
    assert "--frames needs --pose" in capsys.readouterr().err
    other = REPO_ROOT / "poses" / "gait2392_walk.yaml"  # a pose of another skeleton
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(out), "--pose", str(other), *common) == 2
    err = capsys.readouterr().err
    assert "gait2392_walk.yaml" in err and "is not human_r.yaml" in err and "Traceback" not in err
    assert run_cli(REPO_ROOT, "pack", str(d), "--out", str(out), "--pose", str(tmp_path / "none.yaml"), *common) == 2
    assert "not found" in capsys.readouterr().err
    assert not out.exists()


def _star_shaped(coords: np.ndarray) -> bool:
    """Every section's control polygon (8N, 2) turns one way around the mean of its points."""
    for pts in coords.reshape(-1, 8, 2):
        d = pts - pts.mean(axis=0)
        ang = np.arctan2(d[:, 1], d[:, 0])
        step = np.angle(np.exp(1j * np.diff(np.concatenate([ang, ang[:1]]))))
        if not (np.all(step > 0) or np.all(step < 0)):
            return False
    return True


def test_packed_sections_stay_star_shaped(demo, packed):
    """A territory split by a neighbour asks for a section with two lobes. Fitted freely, 8
    control points fold into a bow tie (the packed gait2392 had 10.6% of its rings cutting
    themselves); kept to their rays from the section's centre, they make a waist. Rest identity
    holds (the rays' own shape is fitted exactly), and no packed ring cuts itself."""
    d, plan, rest, cm = demo
    m = plan.models[[s.name for s in plan.muscles].index("biceps_brachii")]
    fr = pack._frames(m, rest, np.array([s.t for s in m.spec.sections]))  # its own sections
    grid = contact.vertices_to_grid(m.rest_vertices.astype(np.float64), m.U, m.A).reshape(m.U, m.A, 3)
    x0, _ = pack.Fit(m, fr, None, 0.0)(grid)
    coords, fitted = pack.Fit(m, fr, None, 0.0, rays=x0)(grid)
    assert np.abs(coords - x0).max() < 1e-9 and np.abs(fitted - grid[1:-1]).max() < 1e-6
    # two lobes: every ring pinched to a waist 0.05 of its width (a territory split by a neighbour)
    c = grid.mean(axis=1, keepdims=True)
    off = grid - c
    side = off[:, :1] / np.maximum(np.linalg.norm(off[:, :1], axis=2, keepdims=True), 1e-12)
    cosang = (off * side).sum(axis=2) / np.maximum(np.linalg.norm(off, axis=2), 1e-12)
    target = c + off * (0.05 + cosang ** 2)[..., None]
    free, _ = pack.Fit(m, fr, None, 0.0)(target)
    kept, _ = pack.Fit(m, fr, None, 0.0, rays=x0)(target)
    assert not _star_shaped(free)  # (the test means something)
    assert _star_shaped(kept)
    for model in packed.models:
        g = contact.vertices_to_grid(model.rest_vertices.astype(np.float64), model.U, model.A).reshape(model.U, model.A, 3)
        for ring in g[1:-1]:
            dd = ring - ring.mean(axis=0)
            vt = np.linalg.svd(dd)[2]
            ang = np.arctan2(dd @ vt[1], dd @ vt[0])
            step = np.angle(np.exp(1j * np.diff(np.concatenate([ang, ang[:1]]))))
            assert np.all(step > 0) or np.all(step < 0), model.spec.name


def test_a_forked_process_packs_on_its_thread_to_the_same_result(demo, packed, tmp_path):
    """Packing in a process forked from one that used numba's threads (the `packed` fixture
    packed on them) runs pack's kernels' twins on its own thread (GNU OpenMP, numba's
    threading layer here, stops a forked child that starts its threads:
    runtime.use_threads); the same packed shapes and measures, bit for bit."""
    import os
    import pickle

    d, plan, rest, cm = demo
    out = tmp_path / "child.pkl"
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            from axdf_cli import runtime

            assert not runtime.use_threads()
            res = pack.pack(plan.muscles, plan.models, plan.pose.skeleton, rest, cm, iterations=12,
                            threads=runtime.use_threads())
            out.write_bytes(pickle.dumps(([m.rest_vertices for m in res.models], res.before, res.after, res.volume)))
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    verts, before, after, volume = pickle.loads(out.read_bytes())
    assert all(np.array_equal(a, m.rest_vertices) for a, m in zip(verts, packed.models))
    assert np.array_equal(before, packed.before) and np.array_equal(after, packed.after)
    assert np.array_equal(volume, packed.volume)
