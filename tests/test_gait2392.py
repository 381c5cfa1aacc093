"""The shipped gait2392 library: all 92 muscles over the whole walking trial."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
import trimesh

from axdf_cli import specs as loaders
from axdf_cli import pipeline
from axdf_cli import tolerances as tol
from axdf_cli.cli.main import main

#: the model alone (these tests are about the muscle model; contact has tests/test_contact.py)
MODEL_ONLY = {"contact": False, "penetration": False}

ROOT = Path(__file__).resolve().parents[1]
JOB = ROOT / "poses" / "jobs" / "gait2392_walk.yaml"


@pytest.fixture(scope="module")
def whole_trial():
    job = loaders.load_job(JOB, loaders.RefPolicy((ROOT,)))
    plan = pipeline.plan_run(job, frames_arg="0:210", stages=MODEL_ONLY)
    ratios, twists, finite = [], [], True
    for _, _, results in pipeline.evaluate_chunks(plan):
        rs = [r for _, r in results]
        finite &= all(np.isfinite(r.vertices).all() and np.isfinite(r.normals).all() for r in rs)
        ratios.append(np.stack([r.volume / m.v0 for r, m in zip(rs, plan.models)], axis=1))
        twists.append(np.stack([r.twist for r in rs], axis=1))
    return plan, np.concatenate(ratios), np.concatenate(twists), finite


def test_all_92_muscles_over_the_whole_trial(whole_trial):
    plan, ratios, twists, finite = whole_trial
    assert len(plan.models) == 92
    assert len(plan.frames) == 211
    assert finite
    # `exact` keeps every frame's volume within 0.5% of rest (measured: ~1e-12)
    assert np.abs(ratios - 1.0).max() < tol.VOLUME_EXACT_PROMISE
    # no twist flip: the insertion roll changes smoothly from frame to frame
    assert np.abs(np.diff(twists, axis=0)).max() < 30.0


def test_every_gait_mesh_is_closed_and_outward(whole_trial):
    plan = whole_trial[0]
    rest = None
    for _, _, results in pipeline.evaluate_chunks(plan, chunk=1):
        rest = [r for _, r in results]
        break
    for r, m in zip(rest, plan.models):
        mesh = trimesh.Trimesh(r.vertices[0], m.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent, m.spec.name
        assert mesh.volume > 0, m.spec.name


def test_gait_job_stats_csv_shows_it(tmp_path, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = tmp_path / "gait"
    assert main(["run", str(JOB.relative_to(ROOT)), "--no-render", "--frames", "0:210:30", "--out", str(out), "-q"]) == 0
    rows = list(csv.DictReader((out / "stats.csv").open()))
    assert len(rows) == 92 * 8
    assert max(abs(float(r["volume_ratio"]) - 1) for r in rows) < tol.VOLUME_EXACT_PROMISE
    assert all(r["warning"] == "" for r in rows)
