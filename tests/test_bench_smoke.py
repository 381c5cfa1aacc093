"""The benchmark's helpers run on a tiny case (1 muscle, 5 frames): keeps benchmarks.bench from
rotting. No speed assertions: a timing is checked to be a figure in its unit (µs per
muscle-frame: finite, positive, under a second), and what it counts is checked exactly."""
from __future__ import annotations

import numpy as np
import pytest

from benchmarks import bench, common, page
from benchmarks import case as casemod
from benchmarks.sections import compiled, contact, evaluation, jiggle, packed, retarget, skin, writers


def microseconds(x: float) -> bool:
    """A per-item time in µs as the bench reports it: finite, positive, under a second."""
    return bool(np.isfinite(x)) and 0 < x < 1e6


@pytest.fixture(scope="module")
def case():
    return casemod.load_case(n_frames=5, n_muscles=1)


@pytest.fixture(scope="module")
def synthetic():
    return casemod.load_case(n_frames=5, n_muscles=7, prefer_gait=False)


def test_case_shapes(case, synthetic):
    for c in (case, synthetic):
        assert c.world.shape[0] == 5 and c.world.shape[2:] == (4, 4)
        assert c.tension.shape == (5, len(c.specs))
    assert len(synthetic.specs) == 7 and len({s.name for s in synthetic.specs}) == 7  # perturbed copies renamed


def test_evaluation_limit_and_peer(case):
    models = case.models(1, (8, 6))
    assert microseconds(evaluation.time_evaluation(models, case.world, case.tension, repeats=1, chunk=2))
    assert microseconds(evaluation.time_limit(5, models[0].n_vertices, repeats=1))
    pytest.importorskip("geomdl")
    us, err = evaluation.time_geomdl(models[0], case.rest, n_frames=1)
    assert microseconds(us)
    assert err < 1e-6  # geomdl tessellates the same surface (rest vertices are float32)


def test_writers(case, tmp_path):
    model = case.models(1, (8, 6))[0]
    out = writers.time_writers(model, case.world, case.tension, tmp_path, n_files=5, repeats=1)
    # binary PLY: at least 3 float32 per vertex, a count byte and 3 int32 per face
    assert out["ply"]["bytes"] > model.n_vertices * 12 + len(model.faces) * 13
    assert out["obj"]["bytes"] > out["ply"]["bytes"]  # the same mesh as text
    for ext in ("ply", "obj"):
        assert all(microseconds(out[ext][k]) for k in ("encode", "write", "write_bytes", "tofile"))


def test_long_pose_stretch_and_table():
    from axdf_cli.specs import load_pose

    pose = load_pose(common.DEMO_POSE)
    long = casemod.stretched_pose(pose, 1000)
    assert (long.first, long.last) == (0, 999)
    key = next(iter(pose.keys))
    assert long.keys[key][1] == pose.keys[key][1]
    t = common.Table()
    t.section("s")
    t.add("a", "1 µs", "x", "2x", "✓")
    assert "a" in t.text() and "[s]" in t.text()
    skipped = common.Table()
    skipped.section("retargeting: skipped")  # a section whose rows were skipped: printed, not a crash
    assert skipped.text().splitlines()[-1] == "[retargeting: skipped]"
    assert skipped.markdown() == "### retargeting: skipped\n"  # a heading, no empty table
    assert np.isfinite(common.median_time(lambda: None, 3))


def test_wrapping_rows():
    wc, nc = casemod.load_wrap_case(8, True), casemod.load_wrap_case(8, False)
    if wc is None:
        pytest.skip("arm26 library not shipped")
    assert any(s.path.wraps for s in wc.specs) and not any(s.path.wraps for s in nc.specs)
    for c in (wc, nc):
        assert microseconds(evaluation.time_evaluation(c.models(2, (8, 6)), c.world, c.tension, repeats=1, chunk=4,
                                                  coords=c.coords))


def test_packed_writers(case, tmp_path):
    """The packed formats' writer rows on 3 muscles x 5 frames; every file of every format is
    written (and removed) and every figure positive."""
    pytest.importorskip("pxr")
    models = case.models(1, (8, 6))
    out = packed.time_sequence_writers(models, case.world, case.tension, tmp_path / "w", n_muscles=3, repeats=1)
    assert set(out) == set(packed.PACKED_FORMATS)
    for fmt, d in out.items():
        assert d["bytes"] > 0 and d["tofile_bytes"] > 0
        assert all(d[k] > 0 for k in ("write", "sha256", "tofile")), fmt
    assert not any((tmp_path / "w").rglob("*.*"))  # all removed again


def test_jiggle_rows_helpers(repo_root):
    import dataclasses

    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(common.DEMO_JOB), frames_arg="0:5")
    plan = dataclasses.replace(plan, models=plan.models[-2:], muscles=plan.muscles[-2:])  # the gastrocnemius heads (jiggle)
    assert jiggle.time_chunks(plan, repeats=1) > 0
    seconds, n = jiggle.time_jiggle_stage(plan, repeats=1)
    assert seconds > 0 and n == 2


def test_retarget_jacobian_timing():
    from axdf_cli.tools.retarget import load_map

    a, b, diff = retarget.jacobian_times(load_map(retarget.CMU_MAP), repeats=1)
    assert a > 0 and b > 0
    assert diff < 1e-6  # the analytic Jacobian is the finite differences' limit


def test_compiled_pass_rows(tmp_path):
    """The compiled pass's helpers: a whole run in a subprocess (the demo job, 3 frames, 8x6),
    tofile of its bytes, step 1b into fresh memory and in steady state."""
    r = compiled.whole_run(common.DEMO_JOB, 3, "npz", tmp_path / "run", resolution="8x6")
    assert r["muscle_frames"] == 3 * 7 and r["bytes"] > 0 and r["seconds"] > 0 and r["startup"] > 0
    assert not (tmp_path / "run").exists()
    assert compiled.tofile_seconds(r["bytes"], tmp_path) > 0
    cold, warm, nf = compiled.first_touch(common.DEMO_JOB, repeats=1)
    assert cold > 0 and warm > 0 and nf >= 1


def test_contact_pass(repo_root):
    """The contact rows' helper on a few demo frames: measures, steps and volumes per frame and
    muscle; contact keeps every volume and pops nowhere (each muscle's largest step is its
    attachment's here, which contact does not move)."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job

    job = load_job(repo_root / "poses" / "jobs" / "demo.yaml")
    t0, m0, s0, v0 = contact.contact_pass(plan_run(job, frames_arg="68:71", stages={"contact": False, "penetration": False}))
    t1, m1, s1, v1 = contact.contact_pass(plan_run(job, frames_arg="68:71", stages={"contact": True}))
    assert t0 > 0 and t1 > 0
    nf, nm = v1.shape
    assert nf >= 3 and m1.shape == (nf, nm, 3) and s1.shape == (nf, nm)
    assert not m0.any() and (m1[..., 1] > 0).any()  # no stage measured, then contact's measures
    assert (s0[0] == 0).all() and (s0[1:] > 0).all()
    np.testing.assert_allclose(v1, v0, rtol=1e-9)
    assert (s1[1:] <= contact.POP_RATIO * s0[1:]).all()


def test_bones_by_libigl_counts_what_winding_numbers_count(repo_root):
    """The bench's bone check (libigl's signed distance to the bone meshes) on a few demo frames
    measured without contact (vertices in the bones): its share inside a bone is the one our
    own generalized winding numbers give (tests/winding.py), its field share the product's
    stats weighted by vertices, and its deepest point lies inside."""
    from winding import inside_shares

    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.specs import load_job

    plan = plan_run(load_job(repo_root / "poses" / "jobs" / "demo.yaml"), frames_arg="60:76:5",
                    stages={"contact": False, "penetration": True})
    exact, field, deep, nf = contact.bones_by_libigl(plan)
    assert nf == len(plan.frames) == 4
    inside = n = 0.0
    measured = 0.0
    for chunk, results in evaluate_plan(plan):
        results = list(results)
        for fi in range(len(chunk.frames)):
            w = chunk.world[fi]
            bones = [(v.astype(np.float64) @ w[b, :3, :3].T + w[b, :3, 3], f) for b, (v, f, _) in plan.bone_meshes.items()]
            meshes = [(r.vertices[fi].astype(np.float64), plan.models[j].faces) for j, r in results]
            nv = np.array([len(v) for v, _ in meshes], dtype=np.float64)
            ref = inside_shares(meshes, bones, np.zeros((len(meshes), len(meshes)), bool))
            inside += float((ref[:, 1] * nv).sum())
            measured += float(sum(n_ * r.contact[fi, 1] for n_, (_, r) in zip(nv, results)))
            n += nv.sum()
    assert inside / n > 0.01  # the demo's muscles reach into their bones without contact
    assert abs(exact - inside / n) <= 0.002, (exact, inside / n)
    assert field == pytest.approx(measured / n, abs=1e-12)
    assert deep > 0.0


def test_markdown_file_is_written(tmp_path):
    """``--markdown PATH`` (make bench: docs/BENCH.md) writes the sections as a generated page: a
    header naming `make bench`, then each section between its markers, saying the command, the
    commit, the machine and its time, with one Markdown table per sub-section."""
    t = common.Table()
    t.section("evaluation")
    t.add("evaluate 48x24", "1.0 µs/mf", "fill 0.5 µs/mf", "2.0x", "<= 3x ✓")
    t.add("a | b", "2")
    path = tmp_path / "BENCH.md"
    page.write(path, {"evaluation": page.block("evaluation", t.markdown(), "python -m benchmarks.bench --quick",
                                               common.machine_line(), 10.0, 12.0)})
    text = path.read_text(encoding="utf-8")
    assert text.startswith("# Benchmark tables\n")
    assert "Generated by `make bench`" in text
    assert "<!-- section: evaluation -->\n## evaluation" in text and text.endswith("<!-- /section: evaluation -->\n")
    assert "Measured by `python -m benchmarks.bench --quick` on: commit " in text and "logical CPUs" in text
    assert "Section time 10 s (the whole run: 12 s)" in text
    assert "### evaluation\n\n| measure | figure | reference (same run) | ratio | target |\n|---|---|---|---|---|\n" in text
    assert "| evaluate 48x24 | 1.0 µs/mf | fill 0.5 µs/mf | 2.0x | <= 3x ✓ |" in text
    assert "| a \\| b | 2 |  |  |  |" in text


def test_markdown_option_on_a_table(tmp_path, monkeypatch):
    """main(--markdown) writes the file for a rows subset too (retarget rows stubbed)."""
    def rows(table, run):
        table.section("retargeting")
        table.add("fit", "10 fps")
        return []

    monkeypatch.setattr(retarget, "rows", rows)
    path = tmp_path / "out" / "BENCH.md"
    path.parent.mkdir()
    assert bench.main(["--only", "retarget", "--quick", "--markdown", str(path)]) == 0
    text = path.read_text(encoding="utf-8")
    assert "`python -m benchmarks.bench --only retarget --quick`" in text
    assert "| fit | 10 fps |  |  |  |" in text


def test_skin_pass(repo_root, tmp_path, capsys):
    """The skin rows' helper on two walk frames of a few packed muscles: a plan with a skin
    gives each frame's skin measures (volume, its ratio to rest near 1, the share outside),
    one without gives zeros."""
    from axdf_cli.pipeline.plan import plan_run
    from axdf_cli.pipeline.skin_stage import SKIN_COLUMNS
    from conftest import run_main

    assert run_main(["skin", "--skeleton", str(repo_root / "poses" / "skeletons" / "gait2392.yaml"), "--out",
                     str(tmp_path / "skin"), "-q"], capsys)[0] == 0
    muscles = [str(repo_root / "muscles" / "gait2392_packed" / f"{m}.yaml") for m in ("vas_lat_r", "med_gas_r")]
    pose = str(repo_root / "poses" / "gait2392_walk.yaml")
    plain = plan_run(None, muscle_args=muscles, pose_arg=pose, out_arg=str(tmp_path / "o"), frames_arg="30:31")
    skinned = plan_run(None, muscle_args=muscles, pose_arg=pose, out_arg=str(tmp_path / "o"), frames_arg="30:31",
                       skin_arg=str(tmp_path / "skin" / "skin.yaml"))
    t0, m0 = skin.skin_pass(plain)
    t1, m1 = skin.skin_pass(skinned)
    assert t0 > 0 and t1 > 0 and m1.shape == (2, len(SKIN_COLUMNS)) and not m0.any()
    ratio = m1[:, SKIN_COLUMNS.index("volume_ratio")]
    assert np.all(np.abs(ratio - 1) < 0.2) and np.all(m1[:, SKIN_COLUMNS.index("volume")] > 0.03)


def test_skin_pops_tells_a_jump_from_a_fast_smooth_change(monkeypatch):
    """skin_pops samples finer where the skin steps most: a smooth change, however fast, has
    each finer step take about 1/POP_SUBSTEPS of the coarse step; a jump has one take it all."""
    def offsets(jump):
        def fake(plan, frames):
            t = np.asarray(frames, np.float64)
            smooth = 0.05 * t  # 50 mm a frame, continuous
            step = np.where(t >= 3.3, 0.03, 0.0) if jump else np.zeros_like(t)
            off = np.zeros((len(t), 2, 3))
            off[:, 0, 0] = smooth
            off[:, 1, 1] = step
            return t, off
        return fake

    monkeypatch.setattr(skin, "skin_offsets", offsets(False))
    smooth = skin.skin_pops(None, 0, 6)
    assert smooth["substep"] == pytest.approx(0.05 / skin.POP_SUBSTEPS)
    assert smooth["share"] == pytest.approx(1 / skin.POP_SUBSTEPS)
    monkeypatch.setattr(skin, "skin_offsets", offsets(True))
    jump = skin.skin_pops(None, 0, 6)
    assert jump["substep"] == pytest.approx(0.03) and jump["share"] == pytest.approx(1.0)
