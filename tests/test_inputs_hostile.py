"""Hostile input files: every input is read through
``yamlio.read_input`` (YAML, .sto, XML, bone meshes), which reads regular files only, after a
``stat``, and at most ``limit + 1`` bytes; symlink loops, FIFOs and devices are exit 2 naming
the path, never a hang or a traceback. YAML 1.2 floats (``1e-5``) are numbers in every
number field, through the real loaders.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

from axdf_cli import tolerances as tol
from axdf_cli.errors import InputError
from axdf_cli.fileio.yamlio import FileRefused, parse_yaml, read_input, read_regular
from conftest import main_or_hang

ROOT = Path(__file__).resolve().parents[1]
OSIM = ROOT.parent / "shared" / "data" / "opensim"


@pytest.fixture
def project(tmp_path, monkeypatch):
    """A copy of the shipped demo library in tmp_path, as the current folder."""
    for d in ("muscles/demo", "poses/skeletons/human_r.yaml", "poses/skeletons/human_r_meshes",
              "poses/demo.yaml", "poses/jobs/demo.yaml"):
        src, dst = ROOT / d, tmp_path / d
        dst.parent.mkdir(parents=True, exist_ok=True)
        (shutil.copytree if src.is_dir() else shutil.copy)(src, dst)
    monkeypatch.chdir(tmp_path)
    return tmp_path


# ----------------------------------------------------------------------------- C: the reader


def test_read_regular_refuses_fifo_device_folder_and_oversize(tmp_path):
    os.mkfifo(tmp_path / "fifo")
    with pytest.raises(FileRefused, match="FIFO"):
        read_regular(tmp_path / "fifo", 100)  # returns at once: nothing is opened for reading
    with pytest.raises(FileRefused, match="character device"):
        read_regular("/dev/zero", 100)
    with pytest.raises(FileRefused, match="folder"):
        read_regular(tmp_path, 100)
    (tmp_path / "big").write_bytes(b"x" * 101)
    with pytest.raises(FileRefused, match="101 bytes.*at most 100"):
        read_regular(tmp_path / "big", 100)
    assert read_regular(tmp_path / "big", 101) == b"x" * 101
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(OSError):
        read_regular(tmp_path / "loop", 100)


def test_read_input_reads_at_most_limit_plus_one_byte(monkeypatch, tmp_path):
    """A file that reports size 0 (as /proc files do) but holds more than the limit is
    refused after limit + 1 bytes, not read whole."""
    p = tmp_path / "f.yaml"
    p.write_bytes(b"a" * 5000)
    real_fstat = os.fstat

    class _Zero:
        def __init__(self, st):
            self._st = st

        def __getattr__(self, k):
            return 0 if k == "st_size" else getattr(self._st, k)

    reads: list[int] = []
    real_fdopen = os.fdopen

    def fdopen(fd, *a, **k):
        f = real_fdopen(fd, *a, **k)
        orig = f.read

        class _F:
            def __enter__(self):
                return self

            def __exit__(self, *exc):
                f.close()

            def read(self, n):
                reads.append(n)
                return orig(n)
        return _F()

    monkeypatch.setattr(os, "fstat", lambda fd: _Zero(real_fstat(fd)))
    monkeypatch.setattr(os, "fdopen", fdopen)
    with pytest.raises(InputError, match="more than 1000 bytes"):
        read_input(p, limit=1000)
    assert sum(reads) <= 1001


@pytest.mark.parametrize("target", ["fifo", "loop", "/dev/zero", "folder"])
def test_validate_refuses_non_regular_inputs_with_exit_2(project, capsys, target):
    p = project / "bad.yaml"
    if target == "fifo":
        os.mkfifo(p)
    elif target == "loop":
        p.symlink_to(p)
    elif target == "folder":
        p.mkdir()
    else:
        p.symlink_to(target)
    assert main_or_hang(["validate", "bad.yaml"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bad.yaml:") and "Traceback" not in err and "internal error" not in err, err


@pytest.mark.parametrize("target", ["fifo", "loop", "/dev/zero"])
def test_skeleton_reference_to_a_non_regular_file_is_exit_2_naming_it(project, capsys, target):
    skel = project / "poses" / "skeletons" / "bad.yaml"
    if target == "fifo":
        os.mkfifo(skel)
    elif target == "loop":
        skel.symlink_to(skel)
    else:
        skel.symlink_to(target)
    pose = project / "poses" / "demo.yaml"
    pose.write_text(pose.read_text().replace("skeleton: skeletons/human_r.yaml", "skeleton: skeletons/bad.yaml"))
    for args in (["validate", "poses/demo.yaml"],
                 ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "out"]):
        assert main_or_hang(args) == 2
        err = capsys.readouterr().err
        assert "bad.yaml" in err and "Traceback" not in err and "internal error" not in err, err
    assert not (project / "out").exists()


def test_job_file_that_is_a_symlink_loop_is_exit_2(project, capsys):
    (project / "job.yaml").symlink_to(project / "job.yaml")
    assert main_or_hang(["run", "job.yaml", "--no-render"]) == 2
    err = capsys.readouterr().err
    assert "job.yaml" in err and "internal error" not in err, err


def test_oversize_yaml_is_refused_before_parsing(project, capsys, monkeypatch):
    monkeypatch.setattr(tol, "YAML_MAX_BYTES", 1000)
    (project / "big.yaml").write_text("a: 1\n" * 300)
    assert main_or_hang(["validate", "big.yaml"]) == 2
    assert "at most 1000 bytes" in capsys.readouterr().err


@pytest.mark.skipif(not (OSIM / "arm26").is_dir(), reason="OpenSim data not present")
@pytest.mark.parametrize("which", ["--motion", "model"])
def test_import_refuses_fifo_motion_and_model(tmp_path, capsys, which):
    model = next((OSIM / "arm26").glob("*.osim"))
    fifo = tmp_path / ("m.mot" if which == "--motion" else "m.osim")
    os.mkfifo(fifo)
    args = ["import", "osim", str(fifo if which == "model" else model), "--out", str(tmp_path / "out")]
    if which == "--motion":
        args += ["--motion", str(fifo)]
    assert main_or_hang(args) == 2
    err = capsys.readouterr().err
    assert str(fifo) in err and "FIFO" in err, err
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- D: YAML 1.2 floats


@pytest.mark.parametrize("text, value", [
    ("1e-5", 1e-5), ("1.0e9", 1e9), ("2E3", 2000.0), ("-1e-5", -1e-5), ("+1e5", 1e5), (".5e3", 500.0),
    ("1.5e-3", 1.5e-3), ("1.", 1.0), ("7", 7), ("0x1F", 31),
])
def test_yaml_12_exponent_floats_are_numbers(text, value):
    v = parse_yaml(f"a: {text}\n", "t.yaml")["a"]
    assert v == value and type(v) is type(value)


@pytest.mark.parametrize("text", ["1e", "e5", "1e5x", "1e-", "'1e-5'", '"1.0e9"', "1e5.0", "._e3"])
def test_non_numbers_and_quoted_exponents_stay_strings(text):
    assert isinstance(parse_yaml(f"a: {text}\n", "t.yaml")["a"], str)


def test_pyyaml_itself_is_unchanged():
    """The resolver is registered on axdf's loader class only."""
    assert yaml.safe_load("a: 1e-5") == {"a": "1e-5"}
    assert yaml.load("a: 1e-5", Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) == {"a": "1e-5"}


def test_exponent_numbers_through_the_real_loaders_give_the_same_meshes(project, capsys):
    """A muscle, skeleton and pose written with exponents run to the same bytes as the
    decimal originals (muscle radii, a skeleton offset, the pose's fps, a key value)."""
    args = ["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--overwrite"]
    assert main_or_hang(args + ["--out", "out/a"]) == 0
    m = project / "muscles" / "demo" / "biceps_brachii.yaml"
    m.write_text(m.read_text().replace("radii: [0.02, 0.015]", "radii: [2e-2, 15E-3]")
                 .replace("tendons: [0.15, 0.12]", "tendons: [1.5e-1, 12e-2]"))
    p = project / "poses" / "demo.yaml"
    text = p.read_text()
    assert "fps: 24" in text and "16:  {knee_flexion_r: 60," in text
    p.write_text(text.replace("fps: 24", "fps: 2.4e1").replace("16:  {knee_flexion_r: 60,", "16:  {knee_flexion_r: 6e1,"))
    assert main_or_hang(["validate", str(m), str(p)]) == 0
    assert main_or_hang(args + ["--out", "out/b"]) == 0
    a, b = project / "out" / "a" / "meshes", project / "out" / "b" / "meshes"
    files = sorted(x.relative_to(a) for x in a.rglob("*.ply"))
    assert files and files == sorted(x.relative_to(b) for x in b.rglob("*.ply"))
    assert all((a / f).read_bytes() == (b / f).read_bytes() for f in files)


def test_exponent_tolerances_load(tmp_path):
    from axdf_cli.compare.thresholds import load_tolerances

    (tmp_path / "t.yaml").write_text("mesh: {max_distance: 1e-5, rms_distance: 2E-6}\n"
                                     "table: {atol: 1e-9, rtol: 1.0e-6}\n")
    t = load_tolerances(tmp_path / "t.yaml")
    assert t.base.mesh.max_distance == 1e-5 and t.base.mesh.rms_distance == 2e-6
    assert t.base.table.atol == 1e-9 and t.base.table.rtol == 1e-6


def test_a_name_that_looks_like_an_exponent_is_a_clear_error_and_works_quoted(project, capsys):
    m = project / "muscles" / "demo" / "biceps_brachii.yaml"
    text = m.read_text()
    m.write_text(text.replace("muscle: biceps_brachii", "muscle: 1e-5"))
    assert main_or_hang(["validate", str(m)]) == 2
    err = capsys.readouterr().err
    assert f"{m}:4:9: muscle is the number 1e-05" in err and "quote" in err, err
    m.write_text(text.replace("muscle: biceps_brachii", 'muscle: "1e-5"'))
    assert main_or_hang(["validate", str(m)]) == 0
    assert "1e-5" in capsys.readouterr().out


# ----------------------------------------------------------------------------- E: motion time and values
ARM = OSIM / "arm26" / "arm26.osim"
needs_arm = pytest.mark.skipif(not ARM.is_file(), reason="OpenSim data not present")


def _mot(path: Path, times, values=None, in_degrees: str = "yes") -> Path:
    """A .mot for arm26 (r_shoulder_elev, r_elbow_flex): one row per time."""
    values = values if values is not None else [(10.0 * (i % 7), 20.0 + i % 5) for i in range(len(times))]
    lines = ["arm motion", "version=1", f"nRows={len(times)}", "nColumns=3", f"inDegrees={in_degrees}", "endheader",
             "time\tr_shoulder_elev\tr_elbow_flex"]
    lines += [f"{t!r}\t{a!r}\t{b!r}" if not isinstance(a, str) else f"{t!r}\t{a}\t{b!r}"
              for t, (a, b) in zip(times, values)]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture
def import_arm(tmp_path, monkeypatch):
    """``import_arm(mot, *flags)``: `axdf import osim arm26.osim --motion MOT` into tmp/out ->
    exit code (the path policy is an argument: no global state for a test to set)."""

    def run(mot: Path, *extra) -> int:
        return main_or_hang(["import", "osim", ARM, "--motion", mot, "--out", tmp_path / "out", "-q", *extra],
                            timeout=60)
    return run


FIRST_ROW = 8  # the line of the first data row in _mot's files


@needs_arm
@pytest.mark.parametrize("last", [2000.0, 20000.0])
def test_a_time_gap_is_refused_at_its_row(tmp_path, capsys, last, import_arm):
    times = [round(0.01 * i, 2) for i in range(200)] + [last]
    mot = _mot(tmp_path / "m.mot", times)
    assert import_arm(mot) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{mot}:{FIRST_ROW + 200}:1: time jumps from 1.99 to {last:g} s"), err
    assert "gap" in err and not (tmp_path / "out").exists()


@needs_arm
def test_a_motion_making_too_many_frames_is_refused(tmp_path, capsys, import_arm):
    mot = _mot(tmp_path / "m.mot", [0.0, 10.0, 20000.0])  # no gap (two steps), but 20000 s
    assert import_arm(mot, "--fps", "100") == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{mot}:{FIRST_ROW + 2}:1: the motion makes 2000001 frames"), err
    assert "at most 100000 frames" in err and not (tmp_path / "out").exists()


@needs_arm
def test_a_time_column_that_does_not_advance_names_the_file_and_row(tmp_path, capsys, import_arm):
    mot = _mot(tmp_path / "m.mot", [0.5] * 5)
    assert import_arm(mot) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{mot}:{FIRST_ROW + 1}:1: time does not advance: 4 of 4 steps are 0"), err


@needs_arm
@pytest.mark.parametrize("value, col", [("1e308", 6), ("-2e9", 6)])
def test_a_huge_value_is_refused_at_import_with_its_position(tmp_path, capsys, value, col, import_arm):
    values = [(10.0, 20.0)] * 3
    values[1] = (value, 20.0)
    mot = _mot(tmp_path / "m.mot", [0.0, 0.01, 0.02], values)
    assert import_arm(mot) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{mot}:{FIRST_ROW + 1}:{col}: {value!r} is too large"), err


@needs_arm
def test_variable_steps_below_the_gap_factor_import_and_validate(tmp_path, monkeypatch, import_arm):
    """Steps up to GAP_FACTOR times the median are not gaps (CMC's variable steps reach 3.5)."""
    times = np.cumsum([0.0] + [0.01] * 50 + [0.15] + [0.01] * 20)
    mot = _mot(tmp_path / "m.mot", [round(float(t), 4) for t in times])
    monkeypatch.chdir(tmp_path)
    assert import_arm(mot) == 0
    (pose,) = (tmp_path / "out").glob("*.yaml")
    assert main_or_hang(["validate", str(pose), "--allow-outside"]) == 0


@needs_arm
def test_a_pose_larger_than_axdf_reads_is_refused_at_import(tmp_path, capsys, monkeypatch, import_arm):
    monkeypatch.setattr(tol, "YAML_MAX_BYTES", 20_000)
    mot = _mot(tmp_path / "m.mot", [round(0.01 * i, 2) for i in range(400)])
    assert import_arm(mot) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"{mot}:{FIRST_ROW + 399}:1: the pose would be ") and "up to 20000 bytes" in err, err
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- H: XML entities
def _osim_with_doctype(tmp_path: Path, doctype: str, where: str, text: str) -> Path:
    """arm26.osim with a DOCTYPE and ``text`` replacing the content of element ``where``."""
    src = ARM.read_text()
    head, rest = src.split("\n", 1)
    assert head.startswith("<?xml")
    m_open, m_close = f"<{where}>", f"</{where}>"
    i = rest.index(m_open) + len(m_open)
    j = rest.index(m_close, i)
    out = tmp_path / "arm26.osim"
    out.write_text(f"{head}\n{doctype}\n{rest[:i]}{text}{rest[j:]}")
    shutil.copytree(ARM.parent / "Geometry", tmp_path / "Geometry")
    return out


@needs_arm
def test_external_entities_are_not_expanded(tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOPSECRET")
    model = _osim_with_doctype(tmp_path, f'<!DOCTYPE OpenSimDocument [<!ENTITY xxe SYSTEM "file://{secret}">]>',
                               "credits", "&xxe;")
    rc = main_or_hang(["import", "osim", str(model), "--out", str(tmp_path / "out"), "-q"], timeout=60)
    err = capsys.readouterr().err
    assert rc in (0, 2) and "TOPSECRET" not in err and "Traceback" not in err, err
    written = b"".join(p.read_bytes() for p in (tmp_path / "out").rglob("*") if p.is_file())
    assert b"TOPSECRET" not in written


@needs_arm
def test_entity_expansion_bomb_is_refused(tmp_path, capsys):
    ents = ['<!ENTITY l0 "lollollollollollollollollollol">'] + [
        f'<!ENTITY l{i} "{("&l" + str(i - 1) + ";") * 10}">' for i in range(1, 10)]
    model = _osim_with_doctype(tmp_path, "<!DOCTYPE OpenSimDocument [" + "".join(ents) + "]>", "credits", "&l9;")
    rc = main_or_hang(["import", "osim", str(model), "--out", str(tmp_path / "out"), "-q"], timeout=60)
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith(f"{model}:") and "malformed XML" in err, err
    assert not (tmp_path / "out").exists()


# ----------------------------------------------------------------------------- H: YAML tags, aliases, nesting
@pytest.mark.parametrize("text, where", [
    ("a: !!python/object/apply:os.system ['true']\n", "1:4"),
    ("a: !!python/name:os.system ''\n", "1:4"),
    ("a: !!python/object/new:dict {x: 1}\n", "1:4"),
    ("a: !local x\n", "1:4"),
    ("a: !!binary aGVsbG8=\n", "1:4"),
    ("a: !!set {x, y}\n", "1:4"),
    ("a: !!omap [{x: 1}]\n", "1:4"),
    ("a: 2001-12-14\n", "1:4"),  # an implicit timestamp: not a plain string, number or boolean
])
def test_non_standard_tags_are_refused_with_position(text, where):
    with pytest.raises(InputError) as e:
        parse_yaml(text, "t.yaml")
    assert str(e.value).startswith(f"t.yaml:{where}: tag ") and "is not allowed" in str(e.value)


def test_alias_bomb_and_deep_nesting_are_refused_by_the_reader():
    bomb = 'a: &a ["x","x","x","x","x","x","x","x","x"]\n' + "".join(
        f"{c}: &{c} [*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p},*{p}]\n" for p, c in zip("abcdefgh", "bcdefghi"))
    with pytest.raises(InputError, match="alias bomb"):
        parse_yaml(bomb, "t.yaml")
    # 100,000 levels: libyaml's composer recursed in C and crashed the interpreter (SIGSEGV)
    for deep in ("a: " + "[" * 100_000 + "]" * 100_000 + "\n", "- " * 100_000 + "x\n",
                 "a: " + "{a: " * 100_000 + "1" + "}" * 100_000 + "\n"):
        with pytest.raises(InputError, match=r"t\.yaml:1:\d+: document nested too deeply"):
            parse_yaml(deep, "t.yaml")
    with pytest.raises(InputError, match="nested too deeply"):
        parse_yaml("".join("  " * i + f"k{i}:\n" for i in range(200)) + "  " * 200 + "v: 1\n", "t.yaml")


def test_the_value_cap_is_for_aliases_a_plain_document_is_bounded_by_its_size(monkeypatch):
    """YAML_MAX_NODES bounds what aliases expand to; a document without one is as many values
    as it has nodes, bounded by YAML_MAX_BYTES (a 14.7 MiB pose under the 16 MiB limit was
    refused as "an alias bomb")."""
    monkeypatch.setattr(tol, "YAML_MAX_NODES", 1000)
    plain = "keys:\n" + "".join(f"  {i}: {{a: {i}.5, b: x{i}}}\n" for i in range(2000))
    doc = parse_yaml(plain, "t.yaml")
    assert len(doc["keys"]) == 2000 and doc["keys"][1999] == {"a": 1999.5, "b": "x1999"}
    assert str(doc["keys"][1999].value_marks["b"]) == "t.yaml:2001:24"
    aliased = "x: &x [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]\n" + "".join(f"k{i}: *x\n" for i in range(200))
    with pytest.raises(InputError, match="more than 1000 values"):
        parse_yaml(aliased, "t.yaml")
