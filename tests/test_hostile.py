"""A hostile round: new variations of its cases (output rule, links, signals,
damaged inputs and packed files), each a regression test of a defect the round found.

Where a command must leave things alone, the test snapshots the tree (test_safety.snapshot).
"""
from __future__ import annotations

import json
import os
import stat

import pytest

from conftest import run_main
from test_outputs import Importer, imp, proj  # noqa: F401  (fixtures)
from test_safety import own_leftovers, snapshot


def test_overwrite_checks_the_way_to_every_file_it_deletes_before_the_first_byte(imp, proj, capsys, tmp_path):
    """A manifest edited to list a file below a link (OUT/evil -> elsewhere): --overwrite,
    which deletes the old output's listed files, once found the link in the middle of the
    swap, with exit 2 after it had rewritten the manifest as incomplete."""
    assert run_main(imp.args("--out", "imp", "-q"), capsys)[0] == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "x.yaml").write_text("mine\n")
    (proj / "imp" / "evil").symlink_to(elsewhere)
    m = json.loads((proj / "imp" / "manifest.json").read_text())
    m["files"]["evil/x.yaml"] = "0" * 64
    (proj / "imp" / "manifest.json").write_text(json.dumps(m, indent=1))
    before = snapshot(tmp_path)
    rc, _, err = run_main(imp.args("--out", "imp", "--overwrite"), capsys)
    assert rc == 2 and "imp/evil is a symbolic link" in err, err
    assert snapshot(tmp_path) == before and own_leftovers(proj / "imp") == []


# ----------------------------------------------------------------------------- data sets


@pytest.fixture
def ds(tmp_path, monkeypatch):
    from dataset_helpers import write_tiny

    root = tmp_path / "ds"
    write_tiny(root)
    monkeypatch.chdir(root)
    return root


def test_dataset_out_a_dangling_link_is_refused_and_nothing_made_at_its_end(ds, capsys, tmp_path):
    """`--out` a link to nothing was exit 3 ("cannot write (File exists)")."""
    (ds / "d").symlink_to(tmp_path / "nowhere")
    before = snapshot(tmp_path)
    for extra in ([], ["--dry-run"], ["--overwrite"]):
        rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q", *extra], capsys)
        assert rc == 2 and "d " in err and "Traceback" not in err, (extra, err)
    assert snapshot(tmp_path) == before and not (tmp_path / "nowhere").exists()


@pytest.mark.parametrize("key, value", [("shards", 0), ("shards", -1), ("seed", -5), ("seed", 10 ** 12)])
def test_merge_refuses_a_dataset_json_with_impossible_counts_at_its_key(tmp_path, capsys, key, value):
    """`shards: 0` with no sequences once wrote an index (exit 0); `shards: -1` was blamed on a
    sequence "not complete"."""
    d = tmp_path / "d"
    d.mkdir()
    dj = {"tool": "axdf", "dataset": "x", "seed": 1, "shards": 1, "image": {"passes": ["rgb"]}, "sequences": []}
    dj[key] = value
    (d / "dataset.json").write_text(json.dumps(dj, indent=1))
    before = snapshot(tmp_path)
    rc, _, err = run_main(["dataset", "merge", str(d)], capsys)
    line = json.dumps(dj, indent=1).splitlines().index(f' "{key}": {value},') + 1
    assert rc == 2 and f"dataset.json:{line}:" in err and key in err, err
    assert snapshot(tmp_path) == before


# ----------------------------------------------------------------------------- compare


def test_compare_an_npz_with_a_member_axdf_does_not_write_is_an_error(proj, capsys):
    """An NPZ with one more member (its CRC-32 right, numpy reads it) was PASS."""
    import shutil
    import zipfile

    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:2", "--format", "npz",
                           "--out", "g", "-q"], capsys)
    assert rc == 0, err
    shutil.copytree(proj / "g", proj / "a")
    with zipfile.ZipFile(proj / "a" / "npz" / "biceps_brachii.npz", "a") as z:
        z.writestr("extra.npy", b"x")
    rc, _, _ = run_main(["compare", "a", "g", "--report", "rep.json", "-q"], capsys)
    verdicts = {f["path"]: (f["verdict"], f.get("detail", "")) for f in json.loads((proj / "rep.json").read_text())["files"]}
    assert rc == 1 and verdicts["npz/biceps_brachii.npz"][0] == "error", verdicts


# ----------------------------------------------------------------------------- transfer


TRANSFER = ["transfer", "muscles/demo", "--from", "poses/skeletons/human_r.yaml", "--to",
            "poses/skeletons/human_r.yaml", "--map", "map.yaml"]


@pytest.mark.parametrize("out", ["muscles/demo/moved", "muscles/demo/a/../moved", "link_to_demo/moved"])
def test_transfer_out_inside_its_input_folder_is_refused(proj, capsys, out):
    """`transfer muscles/demo --out muscles/demo/moved` once wrote its muscles below the folder
    it reads whole: the same command again then failed on "two muscle files named ..."."""
    from axdf_cli.specs import load_skeleton

    bones = [b.name for b in load_skeleton(proj / "poses" / "skeletons" / "human_r.yaml").bones]
    (proj / "map.yaml").write_text("transfer: same\nbones:\n" + "".join(f"  {b}: {b}\n" for b in bones))
    (proj / "link_to_demo").symlink_to(proj / "muscles" / "demo")
    before = snapshot(proj)
    rc, _, err = run_main([*TRANSFER, "--out", out], capsys)
    assert rc == 2 and err.startswith("muscles/demo: ") and "read whole" in err, err
    assert snapshot(proj) == before
    assert run_main([*TRANSFER, "--out", "moved", "-q"], capsys)[0] == 0  # beside it: fine, and again
    assert run_main([*TRANSFER, "--out", "moved", "--overwrite", "-q"], capsys)[0] == 0


# ----------------------------------------------------------------------------- a full disk


@pytest.mark.parametrize("command", ["import", "run"])
def test_a_full_disk_at_the_lock_is_exit_3_and_leaves_nothing(imp, proj, capsys, monkeypatch, command):
    """A disk full to the last block still takes the lock file's inode but not its pid: that
    write was an OSError (exit 70) and left OUT/.axdf-lock. Found on a filled tmpfs."""
    import errno

    def no_space(fd, length):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "ftruncate", no_space)
    before = snapshot(proj)
    args = imp.args("--out", "new") if command == "import" else \
        ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "new"]
    rc, _, err = run_main(args, capsys)
    assert rc == 3 and "no space left on device" in err and "internal error" not in err, err
    assert snapshot(proj) == before and not (proj / "new").exists()  # no lock, and no folder it made


def test_a_folder_where_the_lock_goes_is_exit_2(proj, capsys):
    """OUT/.axdf-lock a folder (not axdf's): exit 2 naming it, nothing written (was exit 3)."""
    (proj / "held" / ".axdf-lock").mkdir(parents=True)
    before = snapshot(proj)
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "held"], capsys)
    assert rc == 2 and ".axdf-lock is a folder" in err and "Traceback" not in err, err
    assert snapshot(proj) == before


@pytest.mark.parametrize("shard", ["1/99999999999999999999", "0/1000001"])
def test_a_shard_count_beyond_the_limit_is_exit_2(capsys, shard):
    rc, _, err = run_main(["dataset", "build", "nothing.yaml", "--out", "x", "--shard", shard], capsys)
    assert rc == 2 and "--shard" in err and "1000000" in err, err


# ----------------------------------------------------------------------------- hostile inputs


def test_a_yaml_integer_of_5000_digits_is_exit_2_at_its_position(proj, capsys):
    """Python refuses to convert integers of more than 4300 digits: that ValueError was exit 70."""
    from axdf_cli.specs import load_skeleton

    bones = [b.name for b in load_skeleton(proj / "poses" / "skeletons" / "human_r.yaml").bones]
    (proj / "map.yaml").write_text("transfer: same\nbones:\n" + "".join(f"  {b}: {b}\n" for b in bones[1:]) +
                                   f"  {bones[0]}: {{to: {bones[0]}, scale: {'9' * 5000}}}\n")
    before = snapshot(proj)
    rc, _, err = run_main([*TRANSFER, "--out", "moved"], capsys)
    assert rc == 2 and err.startswith(f"map.yaml:{len(bones) + 2}:") and "5000 characters" in err, err
    assert snapshot(proj) == before


@pytest.mark.parametrize("kind, root", [("mjcf", "mujoco"), ("osim", "OpenSimDocument")])
def test_xml_nested_deeper_than_a_model_is_exit_2_at_the_element(tmp_path, capsys, monkeypatch, kind, root):
    """3000 nested <body> elements were a RecursionError (exit 70) in the MJCF reader."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / f"deep.{kind}").write_text(f"<{root}>" + "<body>" * 3000 + "</body>" * 3000 + f"</{root}>\n")
    rc, _, err = run_main(["import", kind, f"deep.{kind}", "--out", "imp"], capsys)
    assert rc == 2 and err.startswith(f"deep.{kind}:1:") and "nested too deeply" in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"deep.{kind}"]


@pytest.fixture
def two_copies(proj, capsys):
    import shutil

    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "g", "-q"], capsys)
    assert rc == 0, err
    shutil.copytree(proj / "g", proj / "a")
    return proj


@pytest.mark.parametrize("flag, path", [("--report", "g/stats.csv"), ("--report", "a/manifest.json"),
                                        ("--junit", "poses/demo.yaml"), ("--report", "link.json"),
                                        ("--junit", "fifo"), ("--report", "dangling.json")])
def test_compare_never_writes_its_report_over_a_file_it_did_not_write(two_copies, capsys, flag, path):
    """`compare a g --report g/stats.csv` replaced the golden file with the report (exit 1),
    `--report a/manifest.json` the run's manifest, `--junit poses/demo.yaml` any file; a link
    was swapped for a plain file, a FIFO replaced."""
    (two_copies / "link.json").symlink_to(two_copies / "g" / "stats.csv")
    (two_copies / "dangling.json").symlink_to(two_copies / "nowhere.json")
    os.mkfifo(two_copies / "fifo")
    fifo = two_copies / "fifo"  # (a snapshot would block reading it)
    before = snapshot(two_copies, skip=fifo)
    rc, _, err = run_main(["compare", "a", "g", flag, path], capsys)
    assert rc == 2 and path in err and "Traceback" not in err, err
    assert snapshot(two_copies, skip=fifo) == before and not (two_copies / "nowhere.json").exists()
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_compare_replaces_its_own_reports_and_refuses_one_path_for_both(two_copies, capsys):
    for _ in range(2):  # a new report, then the same path again: ours, replaced
        rc, _, err = run_main(["compare", "a", "g", "--report", "r.json", "--junit", "r.xml", "-q"], capsys)
        assert rc == 0, err
    assert json.loads((two_copies / "r.json").read_text())["tool"] == "axdf compare"
    before = snapshot(two_copies)
    rc, _, err = run_main(["compare", "a", "g", "--report", "r.json", "--junit", "./r.json"], capsys)
    assert rc == 2 and "the same file" in err, err
    rc, _, err = run_main(["compare", "a", "g", "--junit", "r.json"], capsys)  # a JSON report is not a JUnit file
    assert rc == 2 and "was not written by axdf" in err, err
    assert snapshot(two_copies) == before


def test_a_killed_overwrite_of_another_data_set_leaves_no_staging_after_the_next_build(ds, capsys):
    """SIGKILL during `--overwrite --seed 5` leaves OUT/.axdf-new-<pid>; a later build of the
    data set there (same seed, so not staged itself) kept that folder for good."""
    import subprocess
    import sys

    assert run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q"], capsys)[0] == 0
    ref = snapshot(ds / "d")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()  # a process id that is gone
    stale = ds / "d" / f".axdf-new-{dead.pid}"
    (stale / "seq_00000").mkdir(parents=True)
    (stale / "seq_00000" / "labels.npz").write_bytes(b"half")
    for extra in (["--resume"], ["--overwrite"]):
        rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q", *extra], capsys)
        assert rc == 0, err
        assert not stale.exists() and snapshot(ds / "d") == ref
        stale.mkdir()


# ----------------------------------------------------------------------------- Ctrl-C and workers


def _sigint_blocked(shared, item) -> bool:
    """In a worker: whether SIGINT is blocked in it (bit SIGINT-1 of SigBlk)."""
    import signal

    with open("/proc/self/status") as f:
        mask = next(int(line.split()[1], 16) for line in f if line.startswith("SigBlk:"))
    return bool(mask >> (signal.SIGINT - 1) & 1)


@pytest.mark.parametrize("fresh", [False, True])
def test_workers_and_the_fork_server_start_with_sigint_blocked(fresh):
    """Ctrl-C at a random moment of a data-set build (the shell sends SIGINT to the whole
    process group) printed a KeyboardInterrupt traceback from the fork server, which was
    still importing its preload, or from a worker not yet started; the build itself said
    "interrupted" (exit 130). Now every pool process is born with SIGINT blocked and the
    parent gets the signal once its pool has started."""
    import signal

    from axdf_cli.workers import process_map

    if not os.path.exists("/proc/self/status"):
        pytest.skip("needs /proc")
    assert process_map(_sigint_blocked, [0, 1], None, jobs=2, fresh=fresh) == [True, True]
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])  # the parent's is restored
    if fresh:
        from multiprocessing import forkserver

        pid = forkserver._forkserver._forkserver_pid
        with open(f"/proc/{pid}/status") as f:
            mask = next(int(line.split()[1], 16) for line in f if line.startswith("SigBlk:"))
        assert mask >> (signal.SIGINT - 1) & 1


def test_ctrl_c_while_the_subcommands_import_is_interrupted_not_a_traceback(monkeypatch, capsys):
    """A Ctrl-C 0.1 s after start landed in build_parser (it imports every subcommand), before
    main() caught signals: a KeyboardInterrupt traceback and death by SIGINT. The handler is
    now installed first; the signal arrives as the real handler raises it."""
    import signal

    from axdf_cli.cli import main as cli_main

    def importing():
        signal.raise_signal(signal.SIGINT)  # what the terminal sends, into main's own handler
        raise AssertionError("the signal did not interrupt")

    monkeypatch.setattr(cli_main, "build_parser", importing)
    rc, _, err = run_main(["run", "x.yaml"], capsys)
    assert rc == 130 and err.strip() == "axdf: interrupted", err


def test_a_read_only_place_for_a_file_outside_out_is_exit_3_before_out_is_written(imp, proj, capsys, monkeypatch):
    """`--pose-out` on a read-only mount: the import wrote OUT's interim manifest (complete:
    false, listing files that never came) and then failed at the pose (exit 3). Found with a
    tmpfs remounted read-only; here os.access reports the folder as such."""
    (proj / "ro").mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **k: False if os.path.abspath(p) == str(proj / "ro")
                        and mode & os.W_OK else real(p, mode, **k))
    before = snapshot(proj)
    for flag, path in (("--pose-out", "ro/p.yaml"), ("--skeleton-out", "ro/sub/s.yaml"), ("--out", "ro/imp")):
        args = imp.args("--out", "imp", flag, path) if flag != "--out" else imp.args("--out", path)
        rc, _, err = run_main(args, capsys)
        assert rc == 3 and "cannot write in" in err and "ro/" in err, err
        assert snapshot(proj) == before and not (proj / "imp").exists()


# ----------------------------------------------------------------------------- limits


def test_an_import_shows_its_progress_on_a_terminal(proj):
    """`import bvh` of a 100k-joint file ran 813 s with no progress. On a terminal
    (stderr a tty) an import now shows a bar through its steps, ending at the write."""
    import pty
    import subprocess
    import sys

    import fcntl
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal 100 wide
    p = subprocess.Popen([sys.executable, "-m", "axdf_cli", "import", "bvh", "walk.bvh", "--scale", "0.01", "--out",
                          "imp"], cwd=proj, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=slave)
    os.close(slave)
    seen = b""
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:  # the child closed the terminal
            break
        if not chunk:
            break
        seen += chunk
    os.close(master)
    assert p.wait(timeout=60) == 0, seen
    text = seen.decode("utf-8", "replace")
    assert "import walk.bvh" in text and "write" in text and "step" in text, text


@pytest.fixture
def failing_png(tmp_path):
    """Two runs (compare_helpers.make_run) whose frame 3 PNG differs: compare draws a picture."""
    import numpy as np
    from PIL import Image

    from compare_helpers import make_run

    golden, actual = make_run(tmp_path / "golden"), make_run(tmp_path / "actual")
    g = np.asarray(Image.open(golden / "frames/0003.png"))
    Image.fromarray(np.roll(g, 2, axis=1)).save(actual / "frames/0003.png")
    return actual, golden


def test_compare_removes_only_its_own_old_pictures(failing_png, tmp_path, capsys):
    """`--diff-dir` removed every *.diff.png below it, a file of yours of that name too."""
    actual, golden = failing_png
    pics = tmp_path / "pics"
    (pics / "holiday").mkdir(parents=True)
    (pics / "holiday" / "beach.diff.png").write_bytes(b"\x89PNG mine")
    args = ["compare", str(actual), str(golden), "--diff-dir", str(pics), "-q"]
    assert run_main(args, capsys)[0] == 1
    ours = pics / "frames" / "0003.png.diff.png"
    assert ours.is_file() and (pics / "holiday" / "beach.diff.png").read_bytes() == b"\x89PNG mine"
    (actual / "frames/0003.png").write_bytes((golden / "frames/0003.png").read_bytes())
    rc, _, err = run_main(args, capsys)  # now passing: its old picture would mislead, and goes
    assert not ours.exists() and (pics / "holiday" / "beach.diff.png").read_bytes() == b"\x89PNG mine", err


def test_compare_never_draws_its_pictures_through_a_link(failing_png, tmp_path, capsys):
    actual, golden = failing_png
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (tmp_path / "pics").mkdir()
    (tmp_path / "pics" / "frames").symlink_to(elsewhere)
    (tmp_path / "linked").symlink_to(elsewhere)
    for where in ("pics", "linked"):
        rc, _, err = run_main(["compare", str(actual), str(golden), "--diff-dir", str(tmp_path / where)], capsys)
        assert rc == 2 and "symbolic link" in err, err
    assert list(elsewhere.iterdir()) == []


# ----------------------------------------------------------------------------- a FIFO where axdf reads its own files


@pytest.mark.parametrize("where, args", [
    ("run/manifest.json", ["render", "run", "--size", "32x32"]),
    ("run/manifest.json", ["render", "run", "--out", "frames_elsewhere", "--size", "32x32"]),
    ("run/manifest.json", ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "run", "--resume"]),
    ("imp/manifest.json", ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "imp", "--overwrite"]),
])
def test_a_fifo_for_a_manifest_is_refused_not_a_hang(proj, capsys, where, args):
    """A FIFO at OUT/manifest.json blocked `render`, `run --resume` and `import --overwrite`
    for good (read_bytes on a FIFO waits for a writer); every manifest is read as inputs are."""
    import subprocess
    import sys

    assert run_main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "run", "-q"],
                    capsys)[0] == 0
    assert run_main(["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "imp", "-q"], capsys)[0] == 0
    (proj / where).unlink()
    os.mkfifo(proj / where)
    p = subprocess.run([sys.executable, "-m", "axdf_cli", *args], cwd=proj, capture_output=True, text=True,
                       timeout=120)  # (in a child: a hang here is a timeout, not a stuck test run)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr
    assert stat.S_ISFIFO(os.lstat(proj / where).st_mode) and not (proj / "frames_elsewhere").exists()


def test_a_fifo_for_a_sequence_record_is_refused_not_a_hang(ds, capsys):
    """`dataset merge` and `--resume` read every seq_*/sequence.json: a FIFO there hung both."""
    import subprocess
    import sys

    assert run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q"], capsys)[0] == 0
    rec = ds / "d" / "seq_00000" / "sequence.json"
    rec.unlink()
    os.mkfifo(rec)
    p = subprocess.run([sys.executable, "-m", "axdf_cli", "dataset", "merge", "d"], cwd=ds, capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 2 and "seq_00000: its sequence.json is refused (is a FIFO" in p.stderr, p.stderr
    p = subprocess.run([sys.executable, "-m", "axdf_cli", "dataset", "build", "tiny.yaml", "--out", "d", "--resume",
                        "-q"], cwd=ds, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and stat.S_ISREG(os.lstat(rec).st_mode), p.stderr  # the sequence made again


@pytest.mark.parametrize("damage", ["your file only", "a damaged run manifest"])
def test_dataset_refuses_a_damaged_sequence_folder_before_making_any(ds, capsys, damage):
    """A sequence folder holding your file and no run, or a damaged run manifest, was refused
    by that sequence's own run (exit 2) after the sequences before it had been made again."""
    import shutil

    assert run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q"], capsys)[0] == 0
    seq = ds / "d" / "seq_00002"
    if damage == "your file only":
        shutil.rmtree(seq)
        seq.mkdir()
        (seq / "mine.txt").write_text("mine\n")
    else:
        (seq / "sequence.json").unlink()
        (seq / "manifest.json").write_text('{"tool": 5')
    before = snapshot(ds)
    inodes = {p: p.stat().st_ino for p in (ds / "d").rglob("*") if p.is_file()}  # (a file made again, even
    for extra in (["--overwrite"], ["--resume"]):  # with the same bytes, is a new inode: atomic rename)
        rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "d", "-q", *extra], capsys)
        assert rc == 2 and "seq_00002" in err, (extra, err)
        assert snapshot(ds) == before
        assert {p: p.stat().st_ino for p in (ds / "d").rglob("*") if p.is_file()} == inodes


# ----------------------------------------------------------------------------- odd paths


@pytest.mark.parametrize("args", [
    ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "walk.bvh/x"],
    ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "imp", "--pose-out", "walk.bvh/p.yaml"],
    ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "loop/x"],
    ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", "loop"],
    ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "walk.bvh/x"],
    ["compare", "walk.bvh", "walk.bvh", "--report", "walk.bvh/r.json"],
])
def test_an_output_below_a_file_or_a_link_loop_is_exit_2(proj, capsys, args):
    """`--out walk.bvh/x` was exit 3 ("cannot write (Not a directory)"), `--out` a link loop
    (or below one) exit 70 (Path.resolve's RuntimeError): a path mistake is bad input."""
    (proj / "loop").symlink_to("loop2")
    (proj / "loop2").symlink_to("loop")
    before = snapshot(proj)
    rc, _, err = run_main(args, capsys)
    assert rc == 2 and ("walk.bvh is not a folder" in err or "loop" in err) and "internal error" not in err, err
    assert snapshot(proj) == before


def test_a_file_name_that_is_not_utf8_is_exit_2(proj, capsys):
    """A BVH named b'w\\xff.bvh' was exit 70 (the name, written into the YAML header, cannot be
    UTF-8): every argument must be UTF-8 text."""
    bad = os.fsdecode(b"w\xff.bvh")
    (proj / bad).write_bytes((proj / "walk.bvh").read_bytes())
    (proj / "mus").mkdir()  # found in a folder (transfer's MUSCLES): exit 70 writing TRANSFER.md
    (proj / "mus" / os.fsdecode(b"b\xff.yaml")).write_bytes((proj / "muscles/demo/biceps_brachii.yaml").read_bytes())
    before = snapshot(proj)
    for args in (["import", "bvh", bad, "--scale", "0.01", "--out", "imp"],
                 ["import", "bvh", "walk.bvh", "--scale", "0.01", "--out", os.fsdecode(b"imp\xff")],
                 [*TRANSFER[:1], "mus", *TRANSFER[2:], "--out", "moved"]):
        rc, _, err = run_main(args, capsys)
        assert rc == 2 and "is not UTF-8 text" in err, err
    assert snapshot(proj) == before


def test_overwrite_still_knows_the_files_outside_out_an_earlier_import_wrote(proj, capsys):
    """Files outside OUT are never deleted: `import mjcf --skeleton-out s.yaml --name a`, then
    `--name b --overwrite`, left meshes/a/ beside s.yaml, and `--name a --overwrite` again was
    refused on them ("not written by this command"). The manifest keeps recognising them
    (outside_earlier) while their bytes are axdf's; one you changed is still refused."""
    imp = Importer("mjcf")

    def again(name):
        return run_main(imp.args("--out", "imp", "--skeleton-out", "s.yaml", "--name", name, "--overwrite", "-q"),
                        capsys)

    assert run_main(imp.args("--out", "imp", "--skeleton-out", "s.yaml", "--name", "a", "-q"), capsys)[0] == 0
    assert (proj / "meshes" / "a" / "upper.ply").is_file()
    assert again("b")[0] == 0
    m = json.loads((proj / "imp" / "manifest.json").read_text())
    assert set(m["outside_earlier"]) == {"../meshes/a/upper.ply"} and "../meshes/b/upper.ply" in m["outside"]
    rc, _, err = again("a")
    assert rc == 0, err
    assert set(json.loads((proj / "imp" / "manifest.json").read_text())["outside_earlier"]) == {"../meshes/b/upper.ply"}
    (proj / "meshes" / "b" / "upper.ply").write_bytes(b"mine")  # yours now: no longer recognised
    assert again("c")[0] == 0
    assert set(json.loads((proj / "imp" / "manifest.json").read_text())["outside_earlier"]) == {"../meshes/a/upper.ply"}
    before = snapshot(proj)
    rc, _, err = again("b")
    assert rc == 2 and "meshes/b/upper.ply" in err, err
    assert snapshot(proj) == before
