"""One output rule for every command that writes: imports, transfer, data sets
and `render --out` never lose a user's file, never write through a link, never take an input
for an output, check everything before the first byte, hold one writer's lock, and leave no
process or lock behind; `compare` calls a broken packed file an ERROR; importers write only
what `validate` accepts; messages point at the real cause.

Where a command must leave things alone, the test snapshots the tree (every file's sha256,
every link's target) before and after (test_safety.snapshot).
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO_ROOT, run_main
from dataset_helpers import DATASET_YAML, write_tiny
from test_safety import own_leftovers, snapshot, spawn, wait_for

CMU_BVH = REPO_ROOT.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"

SMALL_BVH = """\
HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.033333
0 90 0 0 0 0 0 0 0
1 90 0 10 0 0 5 0 0
2 90 0 20 0 0 10 0 0
"""


# A small MuJoCo model: an include (its mesh asset), a PLY bone mesh, a hinge, one muscle.
ARM_XML = """<mujoco model="arm">
  <compiler angle="degree" meshdir="assets"/>
  <include file="parts.xml"/>
  <worldbody>
    <body name="upper" pos="0 0 1">
      <geom type="mesh" mesh="upper_mesh"/>
      <site name="s0" pos="0.02 0 -0.05"/>
      <body name="lower" pos="0 0 -0.3">
        <joint name="elbow" axis="0 1 0" range="0 120"/>
        <site name="s1" pos="0.02 0 -0.1"/>
      </body>
    </body>
  </worldbody>
  <tendon><spatial name="t"><site site="s0"/><site site="s1"/></spatial></tendon>
  <actuator><muscle name="flexor" tendon="t" force="300" lengthrange="0.2 0.4"/></actuator>
</mujoco>
"""
PARTS_XML = '<mujocoinclude><asset><mesh name="upper_mesh" file="upper.ply"/></asset></mujocoinclude>\n'


@pytest.fixture
def proj(tmp_path, monkeypatch):
    """A project folder holding the demo library (poses/, muscles/demo), a small BVH and a
    small MuJoCo model (arm.xml, its include, its bone mesh, a qpos motion)."""
    import trimesh

    root = tmp_path / "project"
    shutil.copytree(REPO_ROOT / "poses", root / "poses")
    shutil.copytree(REPO_ROOT / "muscles" / "demo", root / "muscles" / "demo")
    (root / "walk.bvh").write_text(SMALL_BVH)
    (root / "arm.xml").write_text(ARM_XML)
    (root / "parts.xml").write_text(PARTS_XML)
    (root / "assets").mkdir()
    (root / "assets" / "upper.ply").write_bytes(trimesh.creation.box(extents=(0.04, 0.04, 0.3)).export(file_type="ply"))
    np.savez(root / "arm_q.npz", qpos=np.radians([[0.0], [30.0], [60.0]]), fps=np.float64(30))
    monkeypatch.chdir(root)
    return root


def bvh(*args):
    return ["import", "bvh", "walk.bvh", "--scale", "0.01", *args]


class Importer:
    """One import command as the output tests drive it: ``args(...)`` its command line (with a
    motion, so that it writes a pose), ``source`` its model file, ``inputs`` every file it
    reads and lists in its manifest (a MuJoCo model's mesh files are guarded, not listed),
    ``files(name)`` what it writes into --out with skeleton ``name``."""

    def __init__(self, kind: str):
        self.kind = kind
        self.source = {"bvh": "walk.bvh", "mjcf": "arm.xml"}[kind]
        self.inputs = {"bvh": ["walk.bvh"], "mjcf": ["arm.xml", "arm_q.npz", "parts.xml"]}[kind]

    def args(self, *extra, source=None):
        if self.kind == "bvh":
            return ["import", "bvh", source or self.source, "--scale", "0.01", *extra]
        return ["import", "mjcf", source or self.source, "--motion", "arm_q.npz", *extra]

    def files(self, name: str) -> set:
        if self.kind == "bvh":
            return {f"skeletons/{name}.yaml"}
        return {f"skeletons/{name}.yaml", f"skeletons/meshes/{name}/upper.ply", "muscles/flexor.yaml",
                "import_report.json", "IMPORT.md"}


@pytest.fixture(params=["bvh", "mjcf"])
def imp(request, proj):
    return Importer(request.param)


# ----------------------------------------------------------------------------- A1, B: imports (bvh, mjcf)


def test_import_refuses_a_folder_it_does_not_own(imp, proj, capsys):
    """`--out poses` once replaced the tracked poses/demo.yaml by a BVH named demo.bvh."""
    shutil.copy(proj / "walk.bvh", proj / "demo.bvh")
    before = snapshot(proj)
    for extra in ([], ["--overwrite"]):
        rc, _, err = run_main(imp.args("--out", "poses", "--pose-name", "demo", *extra), capsys)
        assert rc == 2 and "holds no axdf output" in err, err
    if imp.kind == "bvh":
        rc, _, err = run_main(["import", "bvh", "demo.bvh", "--out", "poses", "--scale", "0.01"], capsys)
        assert rc == 2 and "holds no axdf output" in err, err
    assert snapshot(proj) == before


def test_import_never_takes_its_input_for_an_output(imp, proj, capsys):
    """`--pose-out copy.bvh` once replaced its own input with YAML."""
    before = snapshot(proj)
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", imp.source, "--overwrite"), capsys)
    assert rc == 2 and f"{imp.source}: this input is also an output: --pose-out {imp.source}" in err, err
    (proj / "alias.model").symlink_to(imp.source)  # the same file by another name
    before = snapshot(proj)
    rc, _, err = run_main(imp.args("--out", "imp", "--skeleton-out", "alias.model"), capsys)
    assert rc == 2 and "this input is also an output" in err, err
    assert snapshot(proj) == before


def test_import_mjcf_never_writes_over_what_the_model_reads(proj, capsys):
    """A MuJoCo model reads more than its XML: its includes and its mesh assets (PLY among
    them), and the motion. None of them is ever an output: `--meshes-out assets` would write
    the body upper's mesh onto the asset assets/upper.ply it was made from."""
    imp = Importer("mjcf")
    before = snapshot(proj)
    for extra, words in ((["--meshes-out", "assets"], "assets/upper.ply: this input is also an output: "
                                                      "--meshes-out file assets/upper.ply"),
                         (["--pose-out", "parts.xml"], "parts.xml: this input is also an output"),
                         (["--skeleton-out", "arm_q.npz"], "arm_q.npz: this input is also an output")):
        for ow in ([], ["--overwrite"]):
            rc, _, err = run_main(imp.args("--out", "imp", *extra, *ow), capsys)
            assert rc == 2 and words in err, (extra, err)
    assert snapshot(proj) == before


def test_import_refuses_one_path_for_two_outputs(imp, proj, capsys):
    """The same path for --skeleton-out and --pose-out once wrote one file (the skeleton lost)."""
    before = snapshot(proj)
    rc, _, err = run_main(imp.args("--out", "imp", "--skeleton-out", "a.yaml", "--pose-out", "./a.yaml"), capsys)
    assert rc == 2 and "the same file" in err, err
    assert snapshot(proj) == before


def test_import_never_replaces_a_link_nor_writes_through_one(imp, proj, capsys, tmp_path):
    """A user's symlink was swapped for a plain file; OUT/skeletons -> elsewhere was followed."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "mine.yaml").write_text("mine\n")
    (proj / "pose_link.yaml").symlink_to(elsewhere / "mine.yaml")
    before = snapshot(tmp_path)
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", "pose_link.yaml", "--overwrite"), capsys)
    assert rc == 2 and "is a symbolic link" in err, err
    (proj / "imp").mkdir()
    (proj / "imp" / "skeletons").symlink_to(elsewhere)
    before = snapshot(tmp_path)
    for extra in ([], ["--overwrite"]):
        rc, _, err = run_main(imp.args("--out", "imp", *extra), capsys)
        assert rc == 2, err
    assert snapshot(tmp_path) == before


def test_import_overwrite_replaces_only_what_it_wrote(imp, proj, capsys):
    """OUT is the command's own (manifest.json, command: import bvh|mjcf); --overwrite replaces
    its files there and, outside it, only files its manifest lists with the same bytes."""
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", "walk_pose.yaml", "--name", "walk", "-q"), capsys)
    assert rc == 0, err
    manifest = json.loads((proj / "imp" / "manifest.json").read_text())
    assert manifest["tool"] == "axdf" and manifest["command"] == f"import {imp.kind}" and manifest["complete"]
    assert set(manifest["files"]) == imp.files("walk")
    assert set(manifest["outside"]) == {"../walk_pose.yaml"}
    assert [i["file"] for i in manifest["inputs"]] == imp.inputs
    for i in manifest["inputs"]:
        assert i["sha256"] == hashlib.sha256((proj / i["file"]).read_bytes()).hexdigest()
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", "walk_pose.yaml", "--name", "walk"), capsys)
    assert rc == 2 and "--overwrite" in err  # without it: refused
    (proj / "imp" / "notes.txt").write_text("mine")
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", "walk_pose.yaml", "--name", "walk", "--overwrite",
                                   "-q"), capsys)
    assert rc == 0, err
    assert (proj / "imp" / "notes.txt").read_text() == "mine"
    assert own_leftovers(proj / "imp") == []
    # a file axdf wrote and you changed since is yours: refused, kept
    (proj / "walk_pose.yaml").write_text((proj / "walk_pose.yaml").read_text() + "# my edit\n")
    before = snapshot(proj)
    rc, _, err = run_main(imp.args("--out", "imp", "--pose-out", "walk_pose.yaml", "--name", "walk", "--overwrite"),
                          capsys)
    assert rc == 2 and "was changed since axdf wrote it" in err, err
    assert snapshot(proj) == before
    # a file axdf did not write there (another --out's manifest does not count) is refused
    rc, _, err = run_main(imp.args("--out", "imp2", "--skeleton-out", "imp/skeletons/walk.yaml", "--overwrite"), capsys)
    assert rc == 2 and "was not written by this command" in err, err
    # another command's output folder is not this one's
    rc, _, err = run_main(["transfer", "muscles/demo", "--from", "poses/skeletons/human_r.yaml", "--to",
                           "poses/skeletons/human_r.yaml", "--map", "map.yaml", "--out", "imp", "--overwrite"],
                          capsys)
    assert rc == 2
    other = Importer("bvh" if imp.kind == "mjcf" else "mjcf")
    rc, _, err = run_main(other.args("--out", "imp", "--overwrite"), capsys)
    assert rc == 2 and f"holds the output of axdf import {imp.kind}" in err, err
    assert snapshot(proj) == before


def test_import_overwrite_deletes_what_the_old_output_listed_only_when_complete(imp, proj, capsys, monkeypatch):
    from axdf_cli.fileio import atomic

    assert run_main(imp.args("--out", "imp", "--name", "a", "-q"), capsys)[0] == 0
    assert (proj / "imp" / "skeletons" / "a.yaml").is_file()
    before = snapshot(proj)
    real = atomic.write_bytes
    calls = {"n": 0}

    def full_disk(path, data):
        calls["n"] += 1
        if calls["n"] == 2:
            from axdf_cli.errors import EnvironmentProblem
            raise EnvironmentProblem(f"{path}: no space left on device")
        return real(path, data)

    monkeypatch.setattr(atomic, "write_bytes", full_disk)
    rc, _, err = run_main(imp.args("--out", "imp", "--name", "b", "--overwrite"), capsys)
    assert rc == 3, err
    assert snapshot(proj) == before  # the old output as it was, no staging left
    monkeypatch.setattr(atomic, "write_bytes", real)
    assert run_main(imp.args("--out", "imp", "--name", "b", "--overwrite", "-q"), capsys)[0] == 0
    listed = set(json.loads((proj / "imp" / "manifest.json").read_text())["files"])
    assert imp.files("b") <= listed and not (imp.files("a") - imp.files("b")) & listed
    assert all((proj / "imp" / f).is_file() for f in imp.files("b"))
    assert not any((proj / "imp" / f).exists() for f in imp.files("a") - imp.files("b"))
    if imp.kind == "bvh":  # the pose is named after the skeleton
        assert not (proj / "imp" / "a.yaml").exists() and (proj / "imp" / "b.yaml").is_file()
    else:
        assert not (proj / "imp" / "skeletons" / "meshes" / "a").exists()


def test_import_checks_before_the_first_byte_and_holds_the_lock(imp, proj, capsys):
    assert run_main(imp.args("--out", "imp", "-q"), capsys)[0] == 0
    fd = os.open(proj / "imp" / ".axdf-lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        before = snapshot(proj, skip=proj / "imp" / ".axdf-lock")
        rc, _, err = run_main(imp.args("--out", "imp", "--overwrite"), capsys)
        assert rc == 3 and "another axdf process" in err, err
        assert snapshot(proj, skip=proj / "imp" / ".axdf-lock") == before
    finally:
        os.close(fd)


# ----------------------------------------------------------------------------- A2: transfer


def transfer(out: str, *extra, muscles="muscles/demo"):
    return ["transfer", muscles, "--from", "poses/skeletons/human_r.yaml", "--to", "poses/skeletons/human_r.yaml",
            "--map", "map.yaml", "--out", out, *extra]


@pytest.fixture
def tproj(proj):
    from axdf_cli.specs import load_skeleton

    bones = [b.name for b in load_skeleton(proj / "poses" / "skeletons" / "human_r.yaml").bones]
    (proj / "map.yaml").write_text("transfer: same\nbones:\n" + "".join(f"  {b}: {b}\n" for b in bones))
    return proj


def test_transfer_never_rewrites_its_input_muscles(tproj, capsys):
    before = snapshot(tproj)
    for extra in ([], ["--overwrite"]):
        rc, _, err = run_main(transfer("muscles/demo", *extra), capsys)
        assert rc == 2 and "this input is also an output" in err, err
    assert snapshot(tproj) == before
    # an earlier transfer's output read back as input is never overwritten or deleted either
    assert run_main(transfer("moved", "-q"), capsys)[0] == 0
    before = snapshot(tproj)
    rc, _, err = run_main(transfer("moved", "--overwrite", muscles="moved"), capsys)
    assert rc == 2 and "this input is also an output" in err, err
    assert snapshot(tproj) == before


def test_transfer_keeps_a_users_transfer_md(tproj, capsys):
    (tproj / "out").mkdir()
    (tproj / "out" / "TRANSFER.md").write_text("my notes\n")
    before = snapshot(tproj)
    for extra in ([], ["--overwrite"]):
        rc, _, err = run_main(transfer("out", *extra), capsys)
        assert rc == 2 and "holds no axdf output" in err, err
    assert snapshot(tproj) == before


# ----------------------------------------------------------------------------- A3, B, C: data sets


@pytest.fixture
def ds(tmp_path, monkeypatch):
    """The tiny data set's files in tmp_path/ds (current folder), built once into OUT `d`."""
    root = tmp_path / "ds"
    write_tiny(root)
    (root / "tiny7.yaml").write_text(DATASET_YAML.replace("seed: 11", "seed: 7"))
    monkeypatch.chdir(root)
    return root


def build(*extra, dataset="tiny.yaml", out="d"):
    return ["dataset", "build", dataset, "--out", out, "-q", *extra]


def test_dataset_overwrite_keeps_files_that_are_not_the_data_sets(ds, capsys):
    """--overwrite once deleted seq_00000/my_annotations.txt, views/my_labels/ and bones/custom.ply."""
    assert run_main(build(), capsys)[0] == 0
    mine = {"d/seq_00000/my_annotations.txt": "a", "d/seq_00003/views/my_labels/x.txt": "b",
            "d/bones/custom.ply": "c", "d/notes.txt": "d"}
    for rel, text in mine.items():
        (ds / rel).parent.mkdir(parents=True, exist_ok=True)
        (ds / rel).write_text(text)
    ref = snapshot(ds / "d")
    for dataset in ("tiny.yaml", "tiny7.yaml"):  # the same data set again, then another seed
        rc, _, err = run_main(build("--overwrite", dataset=dataset), capsys)
        assert rc == 0, err
        for rel, text in mine.items():
            assert (ds / rel).read_text() == text, rel
        assert own_leftovers(ds / "d") == []
    assert json.loads((ds / "d" / "dataset.json").read_text())["seed"] == 7
    rc, _, err = run_main(build("--overwrite"), capsys)  # and back: the same bytes as the first build
    assert rc == 0, err
    assert snapshot(ds / "d") == ref


def test_dataset_another_seed_replaces_the_old_only_once_complete(ds, capsys, monkeypatch):
    """A new seed with --overwrite once deleted the old data set before building it."""
    from axdf_cli.dataset import worker

    assert run_main(build(), capsys)[0] == 0
    before = snapshot(ds)
    real = worker.build_sequence
    calls = {"n": 0}

    def stop_at_the_fourth(ctx, index, out, resume):
        calls["n"] += 1
        if calls["n"] == 4:
            raise KeyboardInterrupt
        return real(ctx, index, out, resume)

    monkeypatch.setattr(worker, "build_sequence", stop_at_the_fourth)
    rc, _, err = run_main(build("--overwrite", dataset="tiny7.yaml"), capsys)
    assert rc == 130, err
    assert snapshot(ds) == before  # the old data set whole, no staging folder left


def test_dataset_another_seed_sigint_keeps_the_old_data_set(ds, capsys):
    """Real Ctrl-C during a --overwrite build of another seed: the old data set stays whole."""
    assert run_main(build(), capsys)[0] == 0
    before = snapshot(ds)
    p = spawn(["dataset", "build", "tiny7.yaml", "--out", "d", "--overwrite"], ds, start_new_session=True)
    assert wait_for(lambda: any((ds / "d").glob(".axdf-new-*/seq_0000[2-5]/sequence.json")), timeout=120)
    os.killpg(p.pid, signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130 and b"Traceback" not in err, err.decode()
    assert snapshot(ds) == before


def test_dataset_checks_everything_before_deleting_anything(ds, capsys, tmp_path):
    """An exit 2 once came after sequences and the index were deleted."""
    assert run_main(build(), capsys)[0] == 0
    (ds / "d" / "seq_00001" / "views").rename(ds / "moved_views")
    (ds / "d" / "seq_00001" / "views").symlink_to(ds / "moved_views")
    before = snapshot(ds)
    for extra, dataset in ((["--overwrite"], "tiny.yaml"), (["--overwrite"], "tiny7.yaml"), (["--resume"], "tiny.yaml"),
                           (["--overwrite", "--shard", "0/2"], "tiny7.yaml")):
        rc, _, err = run_main(build(*extra, dataset=dataset), capsys)
        assert rc == 2, (extra, dataset, err)
    assert snapshot(ds) == before


def test_dataset_resume_never_writes_through_links(ds, capsys, tmp_path):
    """--resume once wrote PNG/EXR through a link at seq_*/views or views/view00."""
    assert run_main(build(), capsys)[0] == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    seq = ds / "d" / "seq_00004"
    (seq / "sequence.json").unlink()  # incomplete: --resume makes it again
    shutil.rmtree(seq / "views" / "view00")
    (seq / "views" / "view00").symlink_to(elsewhere)
    before = snapshot(tmp_path)
    rc, _, err = run_main(build("--resume"), capsys)
    assert rc == 2 and "view00" in err and "symbolic link" in err, err
    assert snapshot(tmp_path) == before and not list(elsewhere.iterdir())


def test_dataset_a_file_where_a_sequence_goes_is_exit_2(ds, capsys):
    assert run_main(build(), capsys)[0] == 0
    shutil.rmtree(ds / "d" / "seq_00000")
    (ds / "d" / "seq_00000").write_text("a file")
    before = snapshot(ds)
    rc, _, err = run_main(build("--overwrite"), capsys)
    assert rc == 2 and "seq_00000 is not a folder" in err, err
    assert snapshot(ds) == before


def test_dataset_one_writer_holds_the_folder(ds, capsys):
    """Two --overwrite builds once both exited 70 and left a sequence --resume refused."""
    assert run_main(build(), capsys)[0] == 0
    fd = os.open(ds / "d", os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(fd, fcntl.LOCK_SH)  # a build of shards holds it shared
    try:
        before = snapshot(ds)
        rc, _, err = run_main(build("--overwrite"), capsys)
        assert rc == 3 and "another axdf process" in err, err
        rc, _, err = run_main(["dataset", "merge", "d"], capsys)
        assert rc == 3 and "another axdf process" in err, err
        assert snapshot(ds) == before
    finally:
        os.close(fd)
    # two processes at once: one makes the data set, the other is refused; --resume accepts the result
    procs = [spawn(["dataset", "build", "tiny7.yaml", "--out", "d", "--overwrite"], ds) for _ in range(2)]
    codes = sorted(p.wait(timeout=300) for p in procs)
    errs = b"".join(p.stderr.read() for p in procs)
    assert codes in ([0, 0], [0, 2], [0, 3]) and b"Traceback" not in errs, (codes, errs.decode())
    assert run_main(build("--resume", dataset="tiny7.yaml"), capsys)[0] == 0


@pytest.mark.parametrize("text", ["{}", "[]", '{"tool": "axdf", "dataset": "x", "seed": 1, "shards": 1, '
                                             '"image": {"passes": []}, "sequences": 5}', "not json"])
def test_merge_refuses_a_foreign_or_damaged_dataset_json(tmp_path, capsys, text):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "dataset.json").write_text(text)
    before = snapshot(tmp_path)
    rc, _, err = run_main(["dataset", "merge", str(tmp_path / "d")], capsys)
    assert rc == 2 and "dataset.json:" in err and "Traceback" not in err, err
    assert snapshot(tmp_path) == before


def test_merge_of_shards_made_with_another_seed_says_so(ds, capsys):
    assert run_main(build("--shard", "0/2"), capsys)[0] == 0
    assert run_main(build("--shard", "1/2", "--seed", "99", out="other"), capsys)[0] == 0
    for seq in (ds / "other").glob("seq_*"):
        shutil.copytree(seq, ds / "d" / seq.name)
    rc, _, err = run_main(["dataset", "merge", "d"], capsys)
    assert rc == 2 and "made for another data set" in err and "dataset.json:" in err, err
    assert not (ds / "d" / "index.parquet").exists()


def test_dry_run_is_bounded_for_ten_million_samples(ds):
    """--dry-run of a 10,000,000-sample uniform set took 75 s and 12 GB (the sequences listed)."""
    (ds / "huge.yaml").write_text(DATASET_YAML.replace("count: 3, frames: 1", "count: 9999990, frames: 1")
                                  .replace("views: 2", "views: 1"))
    code = ("import resource, subprocess, sys; p = subprocess.run([sys.executable, '-m', 'axdf_cli', 'dataset', "
            "'build', 'huge.yaml', '--dry-run'], capture_output=True, text=True); "
            "print(p.returncode, resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); print(p.stdout)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ds, capture_output=True, text=True, check=True).stdout
    rc, peak_kib = map(int, out.split("\n")[0].split())
    assert rc == 0 and "would make 9999993 of 9999993 sequences (9999999 frames x 1 view(s) = 9999999 samples)" in out, out
    assert peak_kib < 600 * 1024, f"peak {peak_kib / 1024:.0f} MiB"


def test_seed_limits_agree(ds, capsys):
    from axdf_cli.tolerances import MAX_SEED

    rc, _, err = run_main(build("--dry-run", "--seed", str(MAX_SEED + 1)), capsys)
    assert rc == 2 and f"0..{MAX_SEED}" in err, err
    (ds / "big_seed.yaml").write_text(DATASET_YAML.replace("seed: 11", f"seed: {MAX_SEED + 1}"))
    rc, _, err = run_main(build("--dry-run", dataset="big_seed.yaml"), capsys)
    assert rc == 2 and "big_seed.yaml:2:" in err, err
    assert run_main(build("--dry-run", "--seed", str(MAX_SEED)), capsys)[0] == 0
    (ds / "max_seed.yaml").write_text(DATASET_YAML.replace("seed: 11", f"seed: {MAX_SEED}"))
    assert run_main(build("--dry-run", dataset="max_seed.yaml"), capsys)[0] == 0


def test_a_camera_at_no_distance_is_refused_at_its_line(ds, capsys):
    """distance 1e-300 once wrote NaN matrices and joints into labels.npz with exit 0."""
    (ds / "near.yaml").write_text(DATASET_YAML.replace("distance: [1.2, 1.5]", "distance: [1.0e-300, 1.0e-300]"))
    rc, _, err = run_main(build(dataset="near.yaml", out="near"), capsys)
    assert rc == 2 and "near.yaml:18:" in err and "distance" in err, err
    assert not (ds / "near").exists()


# ----------------------------------------------------------------------------- C: Ray


@pytest.mark.parametrize("address, code, words", [("bogus", 2, "HOST:PORT"), ("ray://127.0.0.1:1", 3, "Ray"),
                                                  ("127.0.0.1:1", 3, "cannot reach"), ("auto", 3, "no running Ray"),
                                                  ("http://127.0.0.1:8265", 2, "HOST:PORT")])
def test_a_bad_ray_address_is_refused_before_anything_is_written(ds, capsys, monkeypatch, address, code, words):
    pytest.importorskip("ray")
    monkeypatch.delenv("RAY_ADDRESS", raising=False)
    import axdf_cli.dataset.raycluster as rc_mod
    monkeypatch.setattr(rc_mod, "_recorded_cluster", lambda: None)
    before = snapshot(ds)
    rc, _, err = run_main(build("--engine", "ray", "--address", address), capsys)
    assert rc == code and words in err and "Traceback" not in err, err
    assert snapshot(ds) == before


def ray_processes(session: str) -> list[int]:
    """Processes whose command line names this Ray session's folder."""
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                if session.encode() in (d / "cmdline").read_bytes():
                    out.append(int(d.name))
            except OSError:
                pass
    return out


def descendants(pid: int) -> set[int]:
    from test_safety import children

    out, todo = set(), [pid]
    while todo:
        for c in children(todo.pop()):
            out.add(c)
            todo.append(c)
    return out


@pytest.fixture
def ray_ds(ds):
    pytest.importorskip("ray")
    (ds / "long.yaml").write_text(DATASET_YAML.replace("count: 3, frames: 1", "count: 40, frames: 2"))
    return ds


@pytest.mark.parametrize("how", ["SIGTERM", "SIGINT", "SIGKILL"])
def test_a_stopped_ray_build_leaves_no_process_lock_or_temporary(ray_ds, how):
    """SIGTERM once gave exit 15 and a C++ stack dump; SIGKILL left ray::DashboardAgent and
    ray::RuntimeEnvAgent running; SIGINT left seq_*/.axdf-lock."""
    p = spawn(["dataset", "build", "long.yaml", "--out", "r", "--engine", "ray", "--jobs", "2"], ray_ds,
              start_new_session=True)
    assert wait_for(lambda: len(list((ray_ds / "r").glob("seq_*/sequence.json"))) >= 3, timeout=240)
    ray_side = descendants(p.pid)
    assert ray_side
    if how == "SIGKILL":
        p.kill()
        p.wait(timeout=30)
        p.communicate(timeout=30)
    else:
        p.send_signal(signal.SIGTERM) if how == "SIGTERM" else os.killpg(p.pid, signal.SIGINT)
        _, err = p.communicate(timeout=120)
        assert p.returncode == 130, err.decode()[-2000:]
        assert b"Traceback" not in err and b"StackTrace" not in err, err.decode()[-2000:]
    from test_safety import alive

    assert wait_for(lambda: not any(alive(q) for q in ray_side), timeout=60), \
        [Path(f"/proc/{q}/cmdline").read_bytes() for q in ray_side if alive(q)]
    if how != "SIGKILL":
        assert own_leftovers(ray_ds / "r") == []
        return
    rc = subprocess.run([sys.executable, "-m", "axdf_cli", "dataset", "build", "long.yaml", "--out", "r", "--resume",
                         "-q", "--jobs", "2"], cwd=ray_ds, capture_output=True, timeout=600)
    assert rc.returncode == 0, rc.stderr.decode()[-2000:]
    assert own_leftovers(ray_ds / "r") == []


# ----------------------------------------------------------------------------- A4, D: render


@pytest.fixture
def two_runs(proj, capsys):
    for out, frames in (("a", "0:1"), ("b", "2:3")):
        rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", frames, "--out", out, "-q"],
                              capsys)
        assert rc == 0, err
    return proj


def test_render_out_never_writes_into_another_run(two_runs, capsys):
    """`render RUN_A --out RUN_B` once wrote A's frames and camera.json into run B."""
    before = snapshot(two_runs)
    for extra in ([], ["--overwrite"], ["--resume"]):
        rc, _, err = run_main(["render", "a", "--out", "b", "--size", "32x32", *extra], capsys)
        assert rc == 2 and "holds the output of axdf run" in err, err
    assert snapshot(two_runs) == before


def test_render_out_of_another_runs_frames_is_replaced_whole(two_runs, capsys):
    """With --overwrite, B's images once showed A's muscles while B's manifest named its own."""
    assert run_main(["render", "a", "--out", "fa", "--size", "32x32", "-q"], capsys)[0] == 0
    (two_runs / "fa" / "mine.txt").write_text("mine")
    before = snapshot(two_runs)
    rc, _, err = run_main(["render", "b", "--out", "fa", "--size", "32x32"], capsys)
    assert rc == 2 and "frames rendered from another run" in err, err
    assert snapshot(two_runs) == before
    rc, _, err = run_main(["render", "b", "--out", "fa", "--size", "32x32", "--overwrite", "-q"], capsys)
    assert rc == 0, err
    m = json.loads((two_runs / "fa" / "manifest.json").read_text())
    b = json.loads((two_runs / "b" / "manifest.json").read_text())
    assert m["command"] == "render" and m["frames"] == b["frames"] == [2, 3] and m["inputs"] == b["inputs"]
    assert sorted(p.name for p in (two_runs / "fa" / "frames").iterdir()) == \
        ["0002.exr", "0002.png", "0003.exr", "0003.png"]  # A's frames 0, 1 are gone
    assert (two_runs / "fa" / "mine.txt").read_text() == "mine" and own_leftovers(two_runs / "fa") == []


def test_render_of_deleted_frames_renders_them(two_runs, capsys):
    """`render` once claimed that frames deleted by hand were "rendered already"."""
    assert run_main(["render", "a", "--size", "32x32", "-q"], capsys)[0] == 0
    for f in (two_runs / "a" / "frames").iterdir():
        f.unlink()
    rc, _, err = run_main(["render", "a", "--size", "32x32", "-q"], capsys)
    assert rc == 0, err
    assert len(list((two_runs / "a" / "frames").iterdir())) == 4


# ----------------------------------------------------------------------------- D: compare


@pytest.fixture
def packed(proj, capsys):
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:5", "--format",
                           "npz,mdd,pc2", "--out", "g", "-q"], capsys)
    assert rc == 0, err
    shutil.copytree(proj / "g", proj / "a")
    return proj


def flip(path: Path, offset: int, fmt: str | None = None, value=None) -> None:
    data = bytearray(path.read_bytes())
    if fmt is None:
        data[offset] ^= 1
    else:
        data[offset:offset + struct.calcsize(fmt)] = struct.pack(fmt, value)
    path.write_bytes(bytes(data))


def verdicts(capsys, *paths) -> dict:
    rc, out, err = run_main(["compare", *paths, "--report", "rep.json", "-q"], capsys)
    rep = json.loads(Path("rep.json").read_text())
    return rc, {f["path"]: f["verdict"] for f in rep["files"]}


def test_compare_a_flipped_npz_byte_is_an_error(packed, capsys):
    """A flipped byte inside points.npy was SAME although numpy reports a bad CRC-32."""
    p = packed / "a" / "npz" / "biceps_brachii.npz"
    with zipfile.ZipFile(p) as z:
        info = z.getinfo("points.npy")
    flip(p, info.header_offset + 30 + len(info.filename) + len(info.extra) + 500)  # a low mantissa bit
    rc, v = verdicts(capsys, "a", "g")
    assert rc == 1 and v["npz/biceps_brachii.npz"] == "error"
    rc, v = verdicts(capsys, "a/npz/biceps_brachii.npz", "a/npz/biceps_brachii.npz")  # identical, still broken
    assert rc == 1 and list(v.values()) == ["error"]


@pytest.mark.parametrize("case", ["nan", "repeated"])
def test_compare_mdd_frame_times_must_be_finite_and_increasing(packed, capsys, case):
    p = packed / "a" / "mdd" / "biceps_brachii.mdd"
    t = np.fromfile(p, ">f4", 2, offset=8)
    flip(p, 12, ">f", float("nan") if case == "nan" else float(t[0]))
    rc, v = verdicts(capsys, "a", "g")
    assert rc == 1 and v["mdd/biceps_brachii.mdd"] == "error"


def test_compare_pc2_sample_rate_must_advance(packed, capsys):
    flip(packed / "a" / "pc2" / "biceps_brachii.pc2", 24, "<f", 0.0)
    rc, v = verdicts(capsys, "a", "g")
    assert rc == 1 and v["pc2/biceps_brachii.pc2"] == "error"


# ----------------------------------------------------------------------------- D: importers write what validate accepts


@pytest.mark.parametrize("change, where, words", [
    (lambda t: t.replace("JOINT Chest", "JOINT " + "C" * 300), "walk.bvh:6:", "characters"),
    (lambda t: t.replace("Frame Time: 0.033333", "Frame Time: 1e-300"), "walk.bvh:18:", "fps"),
    (lambda t: t.replace("2 90 0 20", "2 1e8 0 20"), "walk.bvh:21:", "position"),
])
def test_import_refuses_what_validate_would_refuse(proj, capsys, change, where, words):
    (proj / "walk.bvh").write_text(change(SMALL_BVH))
    before = snapshot(proj)
    rc, _, err = run_main(["import", "bvh", "walk.bvh", "--out", "imp", "--scale", "100"], capsys)
    assert rc == 2 and err.startswith(where) and words in err, err
    assert snapshot(proj) == before


def test_import_mjcf_refuses_what_validate_would_refuse_at_its_line(proj, capsys):
    """A hinge's range of 1e8 rad passes the XML's own limits (numbers within ±1e9) but is
    5.7e9 degrees in the skeleton, beyond what any axdf file holds: refused at the joint."""
    (proj / "arm.xml").write_text(ARM_XML.replace('angle="degree"', 'angle="radian"').replace('range="0 120"',
                                                                                            'range="0 1e8"'))
    before = snapshot(proj)
    rc, _, err = run_main(["import", "mjcf", "arm.xml", "--out", "imp"], capsys)
    assert rc == 2 and err.startswith("arm.xml:9:9:") and "range" in err, err
    assert snapshot(proj) == before


def test_the_yaml_writer_never_parses_what_it_writes(monkeypatch):
    """An import of a 100k-joint BVH took 813 s: every string was parsed as a YAML document and
    every list item copied the lines so far. The writer now only matches PyYAML's resolvers."""
    import yaml

    from axdf_cli.importers import emit

    def no_parse(*a, **k):
        raise AssertionError("dump_yaml parsed YAML")

    monkeypatch.setattr(yaml, "safe_load", no_parse)
    emit._plain_string.cache_clear()
    doc = {"bones": [{"name": f"b{i}", "parent": "ground", "offset": [0.1, 0.2, 0.3],
                      "dofs": [{"coord": f"b{i}_x", "type": "rotation", "axis": [1, 0, 0]}]} for i in range(2000)],
           "keys": {0: {"yes": 1.0, "on": 2.0, "null": 3.0, "x1": 4.0}}}
    text = emit.dump_yaml(doc)
    monkeypatch.undo()
    back = yaml.safe_load(text)
    assert back["keys"][0] == {"yes": 1.0, "on": 2.0, "null": 3.0, "x1": 4.0}  # quoted where they must be
    assert back["bones"][1999]["dofs"][0]["coord"] == "b1999_x" and len(back["bones"]) == 2000


# ----------------------------------------------------------------------------- D: transfer messages


def test_transfer_map_scale_out_of_range_is_blamed_on_the_map(tproj, capsys):
    text = (tproj / "map.yaml").read_text().replace("humerus_r: humerus_r", "humerus_r: {to: humerus_r, scale: 1.0e-30}")
    (tproj / "map.yaml").write_text(text)
    line = text.splitlines().index("  humerus_r: {to: humerus_r, scale: 1.0e-30}") + 1
    rc, _, err = run_main(transfer("out"), capsys)
    assert rc == 2 and err.startswith(f"map.yaml:{line}:") and "scale" in err, err
    assert not (tproj / "out").exists()


def test_a_tiny_map_segment_is_refused_not_a_164_km_muscle(tproj, capsys):
    text = (tproj / "map.yaml").read_text().replace(
        "humerus_r: humerus_r", "humerus_r: {to: humerus_r, to_segment: [humerus_r, [0, 0, 1.0e-6]]}")
    (tproj / "map.yaml").write_text(text)
    line = next(i for i, t in enumerate(text.splitlines(), 1) if "to_segment" in t)
    rc, _, err = run_main(transfer("out"), capsys)
    assert rc == 2 and err.startswith(f"map.yaml:{line}:") and "segment" in err, err
    assert not (tproj / "out").exists()


def test_transfer_refuses_a_muscle_defined_twice(tproj, capsys):
    (tproj / "twice").mkdir()
    shutil.copy(tproj / "muscles" / "demo" / "biceps_brachii.yaml", tproj / "twice" / "a.yaml")
    shutil.copy(tproj / "muscles" / "demo" / "biceps_brachii.yaml", tproj / "twice" / "b.yaml")
    rc, _, err = run_main(transfer("out", muscles="twice"), capsys)
    assert rc == 2 and err.startswith("twice/b.yaml:") and "also defined in" in err, err
    assert not (tproj / "out").exists()


def test_overwrite_never_replaces_a_file_its_manifest_does_not_list(tproj, capsys, tmp_path):
    """Inside a folder the command owns, a file (or link) at a path the new output writes
    that the old manifest does not list is yours: refused, kept."""
    assert run_main(transfer("moved", "-q"), capsys)[0] == 0
    listed = json.loads((tproj / "moved" / "manifest.json").read_text())["files"]
    (tproj / "moved" / "TRANSFER.md").unlink()
    (tproj / "moved" / "TRANSFER.md").write_text("my notes\n")  # same path, but the manifest's sha differs: still listed
    assert "TRANSFER.md" in listed
    m = json.loads((tproj / "moved" / "manifest.json").read_text())
    del m["files"]["TRANSFER.md"]  # now it is not axdf's
    (tproj / "moved" / "manifest.json").write_text(json.dumps(m, indent=1))
    before = snapshot(tproj)
    rc, _, err = run_main(transfer("moved", "--overwrite"), capsys)
    assert rc == 2 and "does not list it" in err, err
    assert snapshot(tproj) == before
    (tproj / "moved" / "TRANSFER.md").unlink()
    (tproj / "moved" / "TRANSFER.md").symlink_to(tmp_path / "elsewhere.md")
    before = snapshot(tmp_path)
    rc, _, err = run_main(transfer("moved", "--overwrite"), capsys)
    assert rc == 2 and "symbolic link" in err, err
    assert snapshot(tmp_path) == before


def test_an_output_on_the_output_folder_itself_and_render_of_a_non_run(imp, proj, capsys):
    before = snapshot(proj)
    for out in ("imp", "imp/sub"):
        rc, _, err = run_main(imp.args("--out", out, "--pose-out", "imp"), capsys)
        assert rc == 2 and "is the output folder" in err, err
    assert snapshot(proj) == before
    assert run_main(imp.args("--out", "imp", "-q"), capsys)[0] == 0
    rc, _, err = run_main(["render", "imp", "--out", "r"], capsys)
    assert rc == 2 and f"holds the output of axdf import {imp.kind}, not a run" in err, err
    assert not (proj / "r").exists()
