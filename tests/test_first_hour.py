"""What a new user meets in the first hour: the compare header, the hint for a
motion file given as a pose, range warnings for path muscles, a data set's frame ranges
checked before the work, the compile notice and pack's progress."""
from __future__ import annotations

import re
import shlex
import shutil

import pytest

from compare_helpers import make_run
from conftest import REPO_ROOT, run_main


def test_the_compare_header_names_each_folder_once(tmp_path, capsys):
    golden = make_run(tmp_path / "golden")
    actual = tmp_path / "actual"
    shutil.copytree(golden, actual)
    rc, out, _ = run_main(["compare", actual, golden], capsys)
    header = out.splitlines()[0]
    assert rc == 0, out
    assert "golden golden" not in header
    assert header == f"axdf compare: {actual} (actual) against {golden} (golden)"


# ----------------------------------------------------------------------------- ranges of path muscles
PACKED = REPO_ROOT / "muscles" / "gait2392_packed"
GAIT_SKELETON = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"


def _knee_pose(folder, knee: float):
    p = folder / "bent.yaml"
    p.write_text(f"pose: bent\nskeleton: {GAIT_SKELETON}\nfps: 30\nframes: [0, 1]\n"
                 f"keys:\n  0: {{knee_angle_r: 0}}\n  1: {{knee_angle_r: {knee}}}\n")
    return p


def test_a_path_muscle_posed_outside_a_range_is_warned_and_refused_with_strict(tmp_path, capsys):
    from axdf_cli.model.pose import muscle_bones
    from axdf_cli.specs import load_muscle_file

    muscle = PACKED / "vas_lat_r.yaml"
    spec = load_muscle_file(muscle)[0]
    assert spec.path is not None and not spec.axis and {"femur_r", "tibia_r"} <= muscle_bones(spec)
    pose = _knee_pose(tmp_path, -500)
    argv = ["run", "--muscles", muscle, "--pose", pose, "--out", tmp_path / "o", "--no-render", "--allow-outside"]
    rc, _, err = run_main([*argv, "--dry-run"], capsys)
    assert rc == 0 and "knee_angle_r is outside its range [-120, 10] in 1 of 2 frames: 1 (keyed -500" in err, err
    rc, _, err = run_main([*argv, "--strict"], capsys)
    assert rc == 2 and "--strict" in err and "vas_lat_r frame 1: knee_angle_r = -500" in err, err
    assert not (tmp_path / "o").exists()
    # a muscle the coordinate does not move (the left leg's) is not warned (the coordinate is)
    rc, _, err = run_main([*argv[:2], PACKED / "vas_lat_l.yaml", *argv[3:], "--strict", "--dry-run"], capsys)
    assert rc == 0 and "vas_lat_l" not in err and "knee_angle_r is outside its range" in err, err


def test_the_roots_place_and_heading_are_no_muscles_range(tmp_path, capsys):
    """A retargeted take turns around: pelvis_rotation passes gait2392's +-90 (a range that
    exists because the model file needs one). It carries every bone of a muscle rigidly, so
    no muscle is warned of it (the run reports the coordinate itself); the knee past its range
    [-120, 10] still is."""
    pose = tmp_path / "turn.yaml"
    pose.write_text(f"pose: turn\nskeleton: {GAIT_SKELETON}\nfps: 30\nframes: [0, 1]\n"
                    "keys:\n  0: {pelvis_rotation: 0, knee_angle_r: 0}\n"
                    "  1: {pelvis_rotation: 170, pelvis_tx: 40, knee_angle_r: 40}\n")
    argv = ["run", "--muscles", PACKED / "vas_lat_r.yaml", "--pose", pose, "--out", tmp_path / "o", "--no-render",
            "--allow-outside", "--dry-run", "--strict"]
    rc, _, err = run_main(argv, capsys)
    assert rc == 2 and "knee_angle_r = 40 outside" in err and "pelvis_rotation =" not in err, err
    assert "pelvis_rotation is outside its range [-90, 90] in 1 of 2 frames: 1 (keyed 170" in err, err
    pose.write_text(pose.read_text().replace("knee_angle_r: 40", "knee_angle_r: -20"))
    rc, _, err = run_main(argv, capsys)
    assert rc == 0 and "vas_lat_r frame" not in err and "knee_angle_r is outside" not in err, err


def test_a_data_set_motion_outside_a_range_is_warned(tmp_path, capsys, monkeypatch):
    mot = ("bent\nversion=1\nnRows=2\nnColumns=2\ninDegrees=yes\nendheader\n"
           "time\tknee_angle_r\n0.0\t0\n0.1\t-500\n")
    (tmp_path / "bent.mot").write_text(mot)
    (tmp_path / "d.yaml").write_text(
        f"dataset: d\nseed: 1\nskeleton: {GAIT_SKELETON}\nmuscles: [{PACKED / 'vas_lat_r.yaml'}]\n"
        "motions:\n  bent: {motion: bent.mot, fps: 10}\nsequences:\n  - {motion: bent}\n"
        "cameras:\n  sphere: {views: 1, distance: [3, 3], elevation: [0, 0], fov: 40}\n"
        "render: {size: [32, 32], supersample: 1}\n")
    monkeypatch.chdir(tmp_path)
    rc, out, err = run_main(["dataset", "build", "d.yaml", "--out", "o", "--dry-run", "--allow-outside"], capsys)
    assert rc == 0, err
    assert "warning: motion bent" in err and "knee_angle_r = -500 outside its range" in err and "vas_lat_r" in err


# ----------------------------------------------------------------------------- the hint for a BVH given as a pose
CMU = REPO_ROOT.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"


def _hint(tmp_path, capsys, bvh: str = "walk.bvh") -> str:
    rc, _, err = run_main(["run", "--muscles", PACKED / "vas_lat_r.yaml", "--pose", bvh, "--out", "o", "--dry-run"],
                          capsys)
    assert rc == 2 and "is not an axdf pose" in err, err
    return err


def test_the_hint_for_a_bvh_pose_names_retarget_and_a_shipped_map(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "walk.bvh").write_text("HIERARCHY\n")  # refused by its suffix, before it is read
    err = _hint(tmp_path, capsys)
    assert "axdf import bvh" not in err
    assert f"axdf retarget walk.bvh --map {REPO_ROOT / 'poses/maps/cmu_to_gait2392.yaml'}" in err
    assert "--pose out/walk_gait2392/walk_gait2392.yaml" in err and "cmu_to_myobody.yaml" in err


@pytest.mark.skipif(not CMU.is_file(), reason=f"CMU BVH not found at {CMU}")
def test_following_the_hint_gives_a_pose_for_gait2392s_muscles(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    lines = CMU.read_text().splitlines()
    m = lines.index("MOTION")  # the take's first 6 frames
    (tmp_path / "walk.bvh").write_text("\n".join(lines[:m + 1] + ["Frames: 6", lines[m + 2]] + lines[m + 3:m + 9]) + "\n")
    err = _hint(tmp_path, capsys)
    found = re.search(r"(axdf retarget .*?), then --pose (\S+)", err)
    assert found, err
    rc, _, err = run_main([*shlex.split(found.group(1))[1:], "-q"], capsys)
    assert rc == 0, err
    rc, out, err = run_main(["run", "--muscles", PACKED / "vas_lat_r.yaml", "--pose", found.group(2), "--out", "o",
                             "--dry-run"], capsys)
    assert rc == 0 and "unknown bone" not in err and "would write 6 meshes" in out, err


# ----------------------------------------------------------------------------- a data set's frames, before the work
def test_a_data_sets_frame_ranges_are_checked_before_any_take_is_fitted(tmp_path, capsys, monkeypatch):
    import numpy as np

    import axdf_cli.tools.retarget as retarget_tool
    from dataset_helpers import DATASET_YAML, write_tiny

    def no_fit(*a, **k):
        raise AssertionError("a take was fitted before the frame ranges were checked")

    monkeypatch.setattr(retarget_tool, "retarget", no_fit)
    rng = np.random.default_rng(37)
    np.savez(tmp_path / "take.npz", joints=rng.normal(size=(5, 2, 3)), names=np.array(["a", "b"]), fps=30.0)
    (tmp_path / "map.yaml").write_text("points: {}\n")  # (never read: the frames are refused first)
    mot = ("walk\nversion=1\nnRows=3\nnColumns=2\ninDegrees=no\nendheader\n"
           "time\tbend\n0.0\t0.0\n0.5\t0.5\n1.0\t1.0\n")
    (tmp_path / "walk.mot").write_text(mot)
    monkeypatch.chdir(tmp_path)
    for take_frames, mot_frames, bad in (('"0:50"', '"0:2"', "take.npz"), ('"0:4"', '"0:99"', "walk.mot")):
        yaml = DATASET_YAML.replace(
            '  walk: {pose: walk.yaml, frames: "0:8:4"}',
            f"  take: {{retarget: take.npz, map: map.yaml, frames: {take_frames}}}\n"
            f"  walk: {{motion: walk.mot, fps: 2, frames: {mot_frames}}}")
        yaml = yaml.replace("  - {motion: walk}\n", "  - {motion: take}\n  - {motion: walk}\n")
        write_tiny(tmp_path, yaml)
        rc, _, err = run_main(["dataset", "build", "tiny.yaml", "--out", "o", "-q"], capsys)
        assert rc == 2 and "tiny.yaml:" in err and "outside" in err and "fitted" not in err, (bad, err)
        assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- the compile notice
def test_the_compile_notice_counts_the_kernels_missing_from_the_cache(tmp_path, monkeypatch):
    import sys

    from axdf_cli import runtime

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    line = runtime.compile_notice("run")
    total = len(runtime.cached_kernels(lambda m: m not in runtime.PACK_ONLY))
    assert line.startswith(f"axdf: compiling {total} of {total} numba kernels once (about ")
    assert line.endswith(f"min of CPU); later runs load them from {tmp_path}")
    assert len(runtime.cached_kernels()) > total  # pack's own kernels: only `axdf pack` compiles them
    assert f"of {len(runtime.cached_kernels())} numba" in runtime.compile_notice("pack")
    for k in runtime.cached_kernels()[:5]:
        (tmp_path / k).touch()  # an entry of another checkout's (its own subfolder) does not count
        (tmp_path / runtime.cache_entry(k)).parent.mkdir(exist_ok=True)
        (tmp_path / runtime.cache_entry(k)).touch()
    assert f"compiling {total - 5} of {total}" in runtime.compile_notice("run")
    assert runtime.cache_entry(runtime.cached_kernels()[0]).endswith(f".py{sys.version_info[0]}{sys.version_info[1]}.nbi")
    runtime.mark_warm("run")  # the command finished once: its kernels are compiled
    assert runtime.compile_notice("run") is None and runtime.compile_notice("pack") is not None


def test_the_cli_says_so_before_a_cold_compile_once_and_not_for_validate(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    monkeypatch.chdir(REPO_ROOT)
    run = ["run", "poses/jobs/demo.yaml", "--frames", "0", "--out", tmp_path / "o", "--dry-run"]
    rc, _, err = run_main(["validate", "poses/jobs/demo.yaml"], capsys)
    assert rc == 0 and "compiling" not in err, err
    rc, _, err = run_main(run, capsys)
    assert rc == 0 and err.count("axdf: compiling ") == 1 and f"later runs load them from {tmp_path}" in err, err
    rc, _, err = run_main(run, capsys)  # the kernels are compiled now
    assert rc == 0 and "compiling" not in err, err
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "cold"))
    (tmp_path / "cold").mkdir()
    rc, _, err = run_main([*run, "-q"], capsys)
    assert rc == 0 and "compiling" not in err, err


def test_the_notice_comes_for_fit_and_for_skin_only_with_muscles(tmp_path, capsys, monkeypatch):
    """`axdf skin` evaluates muscles (numba's kernels) only with --muscles: without, a cold
    cache gets no notice of minutes of compiling that will not happen; `axdf fit` always does."""
    from types import SimpleNamespace

    from axdf_cli.cli.main import _notice

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert _notice(SimpleNamespace(command="skin", muscles=None, quiet=False)) is None
    assert "compiling" not in capsys.readouterr().err
    assert _notice(SimpleNamespace(command="skin", muscles="muscles/gait2392", quiet=False)) == "skin"
    assert capsys.readouterr().err.startswith("axdf: compiling ")
    assert _notice(SimpleNamespace(command="fit", quiet=False)) == "fit"
    assert capsys.readouterr().err.startswith("axdf: compiling ")


def test_a_cold_compile_reports_its_progress_as_kernels_finish(monkeypatch):
    """A first run that compiles for minutes is not silent: numba's compile events (sent on a
    cache miss only) are counted, a kernel another calls with it, and reported."""
    import io

    from numba import njit

    from axdf_cli import runtime

    @njit
    def inner(x):
        return x + 1.0

    @njit
    def outer(x):
        return inner(x) * 2.0

    monkeypatch.setattr(runtime, "PROGRESS_EVERY_S", 0.0)
    out = io.StringIO()
    with runtime.compile_progress(lambda text: print(text, file=out)):
        assert outer(1.0) == 4.0
        assert outer(2.0) == 6.0  # compiled already: no event
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("axdf: 2 kernels compiled ("), lines
    assert lines[0].endswith("last: test_a_cold_compile_reports_its_progress_as_kernels_finish.<locals>.outer)")


def test_a_log_gets_progress_lines_only_when_it_asks(monkeypatch, capsys):
    """stderr not a terminal (a log): no bar, and no progress unless AXDF_LOG_PROGRESS asks for
    a line at most every so many seconds (make demo's jobs are never silent for long)."""
    from axdf_cli.cli import progress

    monkeypatch.delenv(progress.LOG_PROGRESS_VAR, raising=False)
    assert progress.bar(False, "mesh", total=4) is None
    monkeypatch.setenv(progress.LOG_PROGRESS_VAR, "20")
    assert progress.bar(True, "mesh", total=4) is None  # -q: nothing
    b = progress.bar(False, "mesh", total=4, desc="meshes")
    b.update(1)
    assert capsys.readouterr().err == ""  # not yet 20 s
    b.last -= 20.0
    b.update(2)
    assert capsys.readouterr().err.startswith("axdf: meshes: 3 of 4 meshes (")


def test_make_demo_compiles_every_command_that_compiles_first(tmp_path):
    """make demo warms the kernel cache before its jobs, by running every command that compiles
    kernels (but pack, import and atlas, which make demo never runs) on tiny inputs."""
    import importlib.util
    import subprocess

    from axdf_cli.cli.main import KERNEL_COMMANDS

    spec = importlib.util.spec_from_file_location("warm_kernels", REPO_ROOT / "scripts" / "warm_kernels.py")
    warm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(warm)
    commands = {argv[0] for _, argv in warm.steps(tmp_path)}
    assert commands == set(KERNEL_COMMANDS) - {"pack", "import", "atlas"}, commands
    again = tmp_path / "again"
    again.mkdir()
    for _, argv in warm.steps(again):
        for a in argv:  # every input named exists (the outputs go under tmp_path)
            if a.startswith(str(REPO_ROOT)):
                assert (REPO_ROOT / a[len(str(REPO_ROOT)) + 1:]).exists(), a
    if shutil.which("make") is None:
        pytest.skip("no make here")
    plan = subprocess.run(["make", "-n", "demo"], cwd=REPO_ROOT, capture_output=True, text=True, check=True).stdout
    assert plan.index("scripts/warm_kernels.py") < plan.index("axdf run"), plan


# ----------------------------------------------------------------------------- make demo installs no test tools
def test_make_demo_installs_no_test_tools_and_make_test_adds_them(tmp_path):
    import subprocess

    if shutil.which("make") is None:
        pytest.skip("no make here")
    for name in ("Makefile", "pyproject.toml", "constraints.txt", "constraints-blender.txt"):
        shutil.copy(REPO_ROOT / name, tmp_path / name)  # a fresh clone's: no .venv yet

    def planned(target: str) -> list[str]:
        out = subprocess.run(["make", "-n", target], cwd=tmp_path, capture_output=True, text=True, check=True).stdout
        return [ln for ln in out.splitlines() if "pip install" in ln and "--upgrade pip" not in ln]

    demo, test = planned("demo"), planned("test")
    assert demo and not any("[test]" in ln or "pytest" in ln for ln in demo), demo
    assert any(".[test]" in ln for ln in test), test


# ----------------------------------------------------------------------------- axdf pack's progress
def test_pack_reports_each_phase_and_round_in_a_log_and_nothing_with_quiet(tmp_path, capsys):
    from axdf_cli import tolerances as tol

    d = tmp_path / "in"
    d.mkdir()
    for name in ("biceps_brachii", "brachioradialis"):
        shutil.copy(REPO_ROOT / "muscles" / "demo" / f"{name}.yaml", d)
    common = ["pack", d, "--skeleton", REPO_ROOT / "poses" / "skeletons" / "human_r.yaml", "--rounds", "1",
              "--allow-outside"]
    rc, _, err = run_main([*common, "--out", tmp_path / "o"], capsys)  # (stderr is not a terminal: a log)
    assert rc == 0, err
    lines = [ln for ln in err.splitlines() if ln.startswith("axdf pack: ")]
    total = 1 + tol.PACK_POLISH_ROUNDS
    assert lines[0] == "axdf pack: the models of 2 muscles"
    assert any("distance fields" in ln for ln in lines)
    rounds = [ln.split(" done")[0] for ln in lines if " done: " in ln]  # (the polish ends early once done)
    assert 1 <= len(rounds) <= total and rounds == [
        f"axdf pack: round {k} of at most {total}" for k in range(1, len(rounds) + 1)], lines
    rc, _, err = run_main([*common, "--out", tmp_path / "q", "-q"], capsys)
    assert rc == 0 and err == "", err


def test_the_compile_notice_covers_imports_that_compile(tmp_path, monkeypatch, capsys):
    """`axdf import osim|mjcf` compile the surface and path kernels (a cold import of arm26
    compiles 41): the notice counts those; `import bvh` compiles none and says nothing."""
    from argparse import Namespace

    from axdf_cli import runtime
    from axdf_cli.cli.main import _notice

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    n = len(runtime.cached_kernels(runtime.COMMAND_MODULES["import"].__contains__))
    assert 0 < n < len(runtime.cached_kernels(lambda m: m not in runtime.PACK_ONLY))
    assert _notice(Namespace(command="import", source="osim", quiet=False)) == "import"
    assert f"compiling {n} of {n} numba kernels" in capsys.readouterr().err
    assert _notice(Namespace(command="import", source="bvh", quiet=False)) is None
    assert capsys.readouterr().err == ""
