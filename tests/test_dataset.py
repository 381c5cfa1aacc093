"""`axdf dataset`: the same seed gives the same bytes however the work is split; bad files
are refused with their position; a dead worker is reported and --resume finishes the work."""
from __future__ import annotations

import json
import os
import shutil

import numpy as np
import pytest
from conftest import all_files, run_main
from dataset_helpers import DATASET_YAML, build_in, write_tiny


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The tiny data set's files, and a reference build with one worker."""
    d = tmp_path_factory.mktemp("tiny")
    write_tiny(d)
    build_in(d, "ref")
    return d


def test_reference_build_is_complete(tiny):
    files = all_files(tiny / "ref")
    d = json.loads(files["dataset.json"])
    assert [s["name"] for s in d["sequences"]] == [f"seq_{i:05d}" for i in range(6)]
    assert [s["frames"] for s in d["sequences"]] == [1, 1, 1, 3, 3, 3]
    for s in d["sequences"]:
        rec = json.loads(files[f"{s['name']}/sequence.json"])
        for rel in rec["files"]:
            assert f"{s['name']}/{rel}" in files
        for f in rec["frames"]:
            for v in d["views"]:
                assert f"{s['name']}/views/{v}/{f:04d}.png" in files
                assert f"{s['name']}/views/{v}/{f:04d}.exr" in files
        assert f"{s['name']}/meshes/chainm/chainm_{rec['frames'][0]:04d}.ply" in files
    assert "bones/b0.ply" in files and "index.parquet" in files
    # no absolute paths inside any output file
    for rel, data in files.items():
        assert str(tiny).encode() not in data, rel


def test_same_bytes_with_two_workers(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "jobs2", "--jobs", "2", "-q"], capsys)
    assert rc == 0, err
    assert all_files(tiny / "jobs2") == all_files(tiny / "ref")


def test_same_bytes_from_two_shards_merged(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    rc, out, err = run_main(["dataset", "build", "tiny.yaml", "--out", "shards", "--shard", "1/2"], capsys)
    assert rc == 0, err
    assert not (tiny / "shards" / "index.parquet").exists()  # shard 0 still to do
    assert "axdf dataset merge" in out
    rc, _, err = run_main(["dataset", "merge", "shards"], capsys)
    assert rc == 2 and "seq_00000" in err  # not complete: nothing merged
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "shards", "--shard", "0/2", "-q"], capsys)
    assert rc == 0, err
    (tiny / "shards" / "index.parquet").unlink()  # the last shard wrote it; merge writes it again
    rc, _, err = run_main(["dataset", "merge", "shards", "-q"], capsys)
    assert rc == 0, err
    assert all_files(tiny / "shards") == all_files(tiny / "ref")


def test_same_bytes_on_a_local_ray_cluster(tiny, monkeypatch, capsys):
    import ray

    monkeypatch.chdir(tiny)
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "ray", "--engine", "ray", "--jobs", "2", "-q"],
                          capsys)
    assert rc == 0, err
    assert not ray.is_initialized()  # the local cluster we started is shut down
    assert all_files(tiny / "ray") == all_files(tiny / "ref")


def test_another_seed_gives_other_poses_and_cameras(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "seed12", "--seed", "12", "-q"], capsys)
    assert rc == 0, err
    a = np.load(tiny / "ref" / "seq_00000" / "labels.npz")
    b = np.load(tiny / "seed12" / "seq_00000" / "labels.npz")
    assert not np.allclose(a["coords"], b["coords"])
    assert not np.allclose(a["world_to_camera"], b["world_to_camera"])
    # the motion as it is does not depend on the seed; its cameras do
    a, b = (np.load(tiny / o / "seq_00005" / "labels.npz") for o in ("ref", "seed12"))
    np.testing.assert_array_equal(a["coords"], b["coords"])


def test_index_opens_in_one_line(tiny):
    import pandas as pd

    idx = pd.read_parquet(tiny / "ref" / "index.parquet")
    assert len(idx) == (3 * 1 + 3 * 3) * 2
    assert list(idx["sample"]) == list(range(len(idx)))
    assert list(idx.columns[:8]) == ["sample", "sequence", "sequence_index", "source", "frame", "frame_index",
                                     "view", "view_index"]
    assert set(idx["source"]) == {"uniform", "perturb:walk", "motion:walk"}
    assert (idx["seed"] == 11).all() and (idx["shard"] == 0).all()
    for _, r in idx.iterrows():
        assert (tiny / "ref" / r.png).is_file() and (tiny / "ref" / r.exr).is_file()
        lab = np.load(tiny / "ref" / r.labels)
        assert lab["frames"][r.frame_index] == r.frame and lab["view_names"][r.view_index] == r.view
    # index rows for a sequence of 3 frames and 2 views, in order
    s3 = idx[idx.sequence == "seq_00003"]
    assert list(zip(s3.frame, s3.view)) == [(f, v) for f in (0, 1, 2) for v in ("view00", "view01")]


def test_bad_dataset_file_exit_2_with_position_nothing_written(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    bad = DATASET_YAML.replace("format_placeholder", "") + "colour: red\n"
    (tiny / "bad.yaml").write_text(bad)
    rc, _, err = run_main(["dataset", "build", "bad.yaml", "--out", "bad_out"], capsys)
    n = bad.count("\n")
    assert rc == 2 and f"bad.yaml:{n}:1: unknown key 'colour'" in err, err
    assert "Traceback" not in err and not (tiny / "bad_out").exists()
    # a coordinate with no range anywhere cannot be sampled uniformly: the entry is named
    bad = DATASET_YAML.replace("  roll: {range: [-80, 80]}\n", "")
    (tiny / "bad2.yaml").write_text(bad)
    rc, _, err = run_main(["dataset", "build", "bad2.yaml", "--out", "bad_out"], capsys)
    line = bad.splitlines().index("  - {sample: uniform, count: 3, frames: 1}") + 1
    assert rc == 2 and f"bad2.yaml:{line}:14: coordinate 'roll' has no range" in err, err
    assert not (tiny / "bad_out").exists()
    # a range outside the skeleton's own, a bad shard, a folder holding something else
    (tiny / "bad3.yaml").write_text(DATASET_YAML.replace("sequences:", "shards: 0\nsequences:"))
    rc, _, err = run_main(["dataset", "build", "bad3.yaml", "--out", "bad_out"], capsys)
    assert rc == 2 and "bad3.yaml:" in err and "shards" in err
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "bad_out", "--shard", "2/2"], capsys)
    assert rc == 2 and "--shard" in err and not (tiny / "bad_out").exists()
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "bad_out", "--seed", "-1"], capsys)
    assert rc == 2 and "--seed" in err and not (tiny / "bad_out").exists()
    (tiny / "other").mkdir(exist_ok=True)
    (tiny / "other" / "keep.txt").write_text("x")
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "other"], capsys)
    assert rc == 2 and "--overwrite" in err and sorted(os.listdir(tiny / "other")) == ["keep.txt"]


def test_existing_sequences_need_resume_or_overwrite(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    shutil.copytree(tiny / "ref", tiny / "again")
    rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "again"], capsys)
    assert rc == 2 and "--resume" in err
    rc, out, err = run_main(["dataset", "build", "tiny.yaml", "--out", "again", "--resume"], capsys)
    assert rc == 0 and "0 made, 6 already complete" in out, err
    rc, out, err = run_main(["dataset", "build", "tiny.yaml", "--out", "again", "--overwrite", "--shard", "0/3"], capsys)
    assert rc == 0 and "2 made" in out, err
    assert all_files(tiny / "again") == all_files(tiny / "ref")


KILLER = """\
# loaded by every Python process of the test (PYTHONPATH): the worker that makes seq_00003
# dies right after writing its meshes, as a worker killed by the OOM killer would
import os
from axdf_cli.dataset import door

_real = door.run_sequence


def _dies(plan, resume):
    out = _real(plan, resume)
    if plan.out.name == "seq_00003" and os.getpid() != int(os.environ["AXDF_TEST_PARENT"]):
        os._exit(1)
    return out


door.run_sequence = _dies
"""


def test_dead_worker_is_reported_and_resume_finishes(tiny, tmp_path):
    import subprocess
    import sys

    (tmp_path / "sitecustomize.py").write_text(KILLER)
    cmd = [sys.executable, "-c", "import os, sys; os.environ['AXDF_TEST_PARENT'] = str(os.getpid()); "
           "from axdf_cli.cli.main import main; sys.exit(main(sys.argv[1:]))",
           "dataset", "build", "tiny.yaml", "--out", "dies", "--jobs", "2"]
    # (before the PYTHONPATH already set: both builds run the same axdf)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")])))
    p = subprocess.run(cmd, cwd=tiny, env=env, capture_output=True, text=True, timeout=300)
    assert p.returncode == 3 and "died" in p.stderr and "seq_00003" in p.stderr and "--resume" in p.stderr, p.stderr
    assert "Traceback" not in p.stderr
    assert (tiny / "dies" / "seq_00003" / "manifest.json").is_file()
    assert not (tiny / "dies" / "seq_00003" / "sequence.json").exists()
    assert not (tiny / "dies" / "index.parquet").exists()
    p = subprocess.run(cmd[:3] + cmd[3:] + ["--resume"], cwd=tiny, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    assert "already complete" in p.stdout
    assert all_files(tiny / "dies") == all_files(tiny / "ref")


def test_dry_run_writes_nothing(tiny, monkeypatch, capsys):
    monkeypatch.chdir(tiny)
    rc, out, _ = run_main(["dataset", "build", "tiny.yaml", "--out", "dry", "--dry-run"], capsys)
    assert rc == 0 and "6 of 6 sequences (12 frames x 2 view(s) = 24 samples)" in out, out
    assert not (tiny / "dry").exists()


def test_npz_bytes_are_deterministic_and_load():
    from axdf_cli.dataset.labels import npz_bytes

    arrays = {"a": np.arange(6.0).reshape(2, 3), "names": np.array(["x", "yz"])}
    assert npz_bytes(arrays) == npz_bytes(dict(arrays))
    import io

    z = np.load(io.BytesIO(npz_bytes(arrays)))
    np.testing.assert_array_equal(z["a"], arrays["a"])
    assert list(z["names"]) == ["x", "yz"]


def test_readme_loading_snippet_runs(tiny):
    from conftest import REPO_ROOT

    text = (REPO_ROOT / "README.md").read_text()
    block = text[text.index("### ML researcher"):].split("```python\n", 1)[1].split("```", 1)[0]
    assert len(block.strip().splitlines()) <= 10
    scope: dict = {}
    exec(block.replace('"out/my_data"', repr(str(tiny / "ref"))), scope)
    # the chain's keypoints: its 4 articulated joints (b0, a root without DOFs, has none)
    assert scope["image"].shape == (48, 40, 4) and scope["uv"].shape == (4, 2) and scope["visible"].dtype == bool



@pytest.mark.parametrize("bad", ["..", "."])
def test_overwrite_of_a_hand_edited_dataset_json_is_refused_and_removes_nothing(tiny, monkeypatch, capsys, bad):
    """A dataset.json whose sequence names are not names ('..', '.': a hand-edited file) is
    exit 2 at its line and column; nothing is deleted (it once removed OUT's parent)."""
    from test_safety import snapshot

    monkeypatch.chdir(tiny)
    holder = tiny / f"holder{len(bad)}"
    (holder / "ds" / "seq_x").mkdir(parents=True)
    (holder / "keep.txt").write_text("beside OUT")
    (holder / "ds" / "mine.txt").write_text("in OUT, not the data set's")
    (holder / "ds" / "dataset.json").write_text(json.dumps(
        {"tool": "axdf", "dataset": "old", "seed": 1, "shards": 1, "image": {"passes": ["png"]},
         "sequences": [{"name": bad}, {"name": "seq_x"}]}, indent=1))
    before = snapshot(holder)
    rc, out, err = run_main(["dataset", "build", "tiny.yaml", "--out", str(holder / "ds"), "--overwrite"], capsys)
    assert rc == 2 and "dataset.json:" in err and "not a sequence name" in err, err
    assert snapshot(holder) == before
