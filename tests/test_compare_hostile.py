"""`axdf compare` against hostile files.

One bad file never aborts a folder comparison: it is an ERROR verdict (distinct from FAIL)
in the summary, the JSON report and the JUnit XML (``<error>``), the exit code is 1, and no
file makes it hang, exit 70 or read outside the compared folders. ``--update`` never writes
through a symbolic link out of GOLDEN and refuses folders nested in each other (exit 2,
nothing written).
"""
from __future__ import annotations

import json
import os
import re
import shutil
import struct
import xml.etree.ElementTree as ET
import zlib
from pathlib import Path

import numpy as np
import pytest

from conftest import main_or_hang
from compare_helpers import make_run, tree_bytes, tube, write_obj, write_ply

MESH = "meshes/m0/m0_0000.ply"


@pytest.fixture
def runs(tmp_path):
    """Two identical small run folders (1 muscle, 2 frames)."""
    return (make_run(tmp_path / "actual", muscles=1, frames=2),
            make_run(tmp_path / "golden", muscles=1, frames=2))


@pytest.fixture
def compare(tmp_path, capsys):
    """``compare(actual, golden, *flags)``: `axdf compare` with --report and --junit ->
    (exit code, report, JUnit root, stdout)."""
    def run(actual, golden, *extra) -> tuple[int, dict, ET.Element, str]:
        rpt, xml = tmp_path / "out" / "r.json", tmp_path / "out" / "r.xml"
        capsys.readouterr()
        rc = main_or_hang(["compare", actual, golden, "--report", rpt, "--junit", xml, *extra])
        doc = json.loads(rpt.read_bytes().decode("utf-8"))
        return rc, doc, ET.fromstring(xml.read_bytes()), capsys.readouterr().out
    return run


# ----------------------------------------------------------------------------- hostile files
def _ply_header_patch(good: bytes, old: bytes, new: bytes) -> bytes:
    assert old in good
    return good.replace(old, new, 1)


def _ply_with_list_count(good: bytes, count_type: str, first_count: bytes) -> bytes:
    """The tube with its face list count of type ``count_type`` ('uint' or 'float'), the
    first face's count replaced by ``first_count`` (4 bytes)."""
    v, n, f = tube(0, 0, 10, 12)
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(f)}\nproperty list {count_type} int vertex_indices\nend_header\n").encode()
    rec = np.zeros(len(f), np.dtype([("n", "<u4"), ("i", "<i4", (3,))]))
    rec["n"] = 3
    rec["i"] = f
    body = bytearray(rec.tobytes())
    body[:4] = first_count
    return head + v.astype("<f4").tobytes() + bytes(body)


def _png(w: int, h: int) -> bytes:
    """A PNG whose header says w x h RGBA but whose data holds a few rows: only a reader
    that decodes notices; a header-only check sees the size."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 6, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(b"\0" * 4096)) + chunk(b"IEND", b""))


def _exr_data_window(good: bytes, x1: int, y1: int) -> bytes:
    data = bytearray(good)
    i = data.find(b"dataWindow\0box2i\0")
    assert i > 0
    off = i + len(b"dataWindow\0box2i\0") + 4
    data[off:off + 16] = struct.pack("<4i", 0, 0, x1, y1)
    return bytes(data)


def _hostile(case: str, actual: Path, tmp_path: Path) -> str:
    """Make one hostile file in ``actual``; return its relative path."""
    good = (actual / MESH).read_bytes()
    ply = {
        "ply negative element count": lambda: _ply_header_patch(good, b"element vertex 122", b"element vertex -5"),
        "ply duplicate property": lambda: _ply_header_patch(good, b"property float y\n", b"property float x\n"),
        "ply NaN list count": lambda: _ply_with_list_count(good, "float", np.float32(np.nan).tobytes()),
        "ply 0xFFFFFFFF list count": lambda: _ply_with_list_count(good, "uint", b"\xff\xff\xff\xff"),
        "ply ascii index beyond int64": lambda: (
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
            b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
            b"3 0 1 99999999999999999999999\n"),
        "ply negative list length": lambda: _ply_with_list_count(good, "int", struct.pack("<i", -7)),
    }
    if case in ply:
        (actual / MESH).write_bytes(ply[case]())
        return MESH
    if case == "obj face line without corners":
        write_obj(actual.parent / "golden" / "meshes/m0/x.obj", *tube(0, 0))
        (actual / "meshes/m0/x.obj").write_bytes(b"v 0 0 0\nf \n")
        return "meshes/m0/x.obj"
    if case == "png bomb 30000x30000":
        (actual / "frames/0000.png").write_bytes(_png(30000, 30000))
        return "frames/0000.png"
    if case == "png 9000x9000 over the pixel limit":
        (actual / "frames/0000.png").write_bytes(_png(9000, 9000))
        (actual.parent / "golden" / "frames/0000.png").write_bytes(_png(9000, 9001))
        return "frames/0000.png"
    if case == "png 9000x9000 on both sides":
        (actual / "frames/0000.png").write_bytes(_png(9000, 9000))
        (actual.parent / "golden" / "frames/0000.png").write_bytes(_png(9000, 9000) + b"\0")
        return "frames/0000.png"
    if case == "exr patched dataWindow":
        p = actual / "frames/0000.exr"
        p.write_bytes(_exr_data_window(p.read_bytes(), 200000, 200000))
        return "frames/0000.exr"
    if case == "exr dataWindow bigger than the data":  # on both sides: the sizes agree, decoding fails
        p = actual / "frames/0000.exr"
        p.write_bytes(_exr_data_window(p.read_bytes(), 63, 200) + b"\0")
        g = actual.parent / "golden" / "frames/0000.exr"
        g.write_bytes(_exr_data_window(g.read_bytes(), 63, 200))
        return "frames/0000.exr"
    if case == "json 100k deep":
        (actual / "camera.json").write_text("[" * 100_000 + "]" * 100_000)
        return "camera.json"
    if case == "json 5000-digit integer":
        (actual / "camera.json").write_text('{"K": ' + "7" * 5000 + "}")
        return "camera.json"
    if case == "manifest 100k deep":
        (actual / "manifest.json").write_text('{"inputs": ' + "[" * 100_000 + "]" * 100_000 + "}")
        return "manifest.json"
    if case == "csv huge field":
        (actual / "stats.csv").write_text("frame,muscle\n0," + "x" * 200_000 + "\n")
        return "stats.csv"
    rel = "odd/entry.bin"
    (actual / "odd").mkdir()
    (actual.parent / "golden" / "odd").mkdir(exist_ok=True)
    (actual.parent / "golden" / rel).write_bytes(b"golden")
    p = actual / rel
    if case == "fifo":
        os.mkfifo(p)
    elif case == "symlink loop":
        p.symlink_to(p)
    elif case == "symlink to /dev/zero":
        p.symlink_to("/dev/zero")
    elif case == "symlink to a file outside":
        (tmp_path / "secret.bin").write_bytes(b"golden")  # same bytes: it must still not be read
        p.symlink_to(tmp_path / "secret.bin")
    elif case == "symlink to a folder":
        p.symlink_to(actual / "meshes")
    else:
        raise AssertionError(case)
    return rel


ERROR_CASES = ["ply negative element count", "ply duplicate property", "ply NaN list count",
               "ply 0xFFFFFFFF list count", "ply ascii index beyond int64", "ply negative list length",
               "obj face line without corners",
               "png bomb 30000x30000", "png 9000x9000 over the pixel limit", "png 9000x9000 on both sides",
               "exr patched dataWindow",
               "exr dataWindow bigger than the data", "json 100k deep", "json 5000-digit integer",
               "manifest 100k deep", "csv huge field", "fifo", "symlink loop", "symlink to /dev/zero",
               "symlink to a file outside", "symlink to a folder"]


@pytest.mark.parametrize("case", ERROR_CASES)
def test_one_hostile_file_is_an_error_verdict_and_the_rest_is_compared(runs, tmp_path, case, compare):
    actual, golden = runs
    rel = _hostile(case, actual, tmp_path)
    rc, doc, junit, out = compare(actual, golden)
    assert rc == 1, out
    verdicts = {f["path"]: f for f in doc["files"]}
    assert verdicts[rel]["verdict"] == "error", verdicts[rel]
    assert verdicts[rel]["reasons"] and "please report" not in verdicts[rel]["reasons"][0], verdicts[rel]
    others = [f for p, f in verdicts.items() if p != rel]
    assert len(others) >= 9 and all(f["verdict"] == "pass" for f in others), others
    assert doc["counts"]["error"] == 1 and doc["counts"]["fail"] == 0 and doc["verdict"] == "different"
    cases = {c.get("name"): c for c in junit.iter("testcase")}
    assert cases[rel].find("error") is not None and cases[rel].find("failure") is None
    assert junit.get("errors") == "1" and junit.get("failures") == "0"
    assert f"  ERROR   {rel}" in out
    assert out.splitlines()[-3].startswith("DIFFERENT: 1 of") and "1 error" in out.splitlines()[-3]


def test_symlink_inside_the_folder_is_followed(runs, tmp_path, compare):
    actual, golden = runs
    (golden / "link.csv").write_bytes((golden / "stats.csv").read_bytes())
    (actual / "link.csv").symlink_to(actual / "stats.csv")
    rc, doc, _, _ = compare(actual, golden)
    assert rc == 0, doc


def test_obj_with_nan_and_inf_against_another_topology_fails_with_reasons(tmp_path, compare):
    v, n, f = tube(0, 0)
    write_obj(tmp_path / "g.obj", v, n, f)
    bad = np.vstack([v, [[np.nan, np.inf, 0.0]]])
    write_obj(tmp_path / "a.obj", bad, np.vstack([n, [[0, 0, 1]]]), f)
    rc, doc, _, out = compare(tmp_path / "a.obj", tmp_path / "g.obj")
    assert rc == 1
    (r,) = doc["files"]
    assert r["verdict"] == "fail" and "topology differs" in r["reasons"][0]
    assert "1 actual vertices are not finite" in r["reasons"] and r["metrics"]["hausdorff"] is None


def test_png_sizes_are_compared_from_the_headers_before_decoding(runs, tmp_path, compare):
    """A 4000x4000 header over data that would not decode: a size mismatch (FAIL), which
    only a header-only check can report; nothing of the large image is decoded."""
    actual, golden = runs
    (actual / "frames/0000.png").write_bytes(_png(4000, 4000))
    rc, doc, _, _ = compare(actual, golden)
    (r,) = [f for f in doc["files"] if f["path"] == "frames/0000.png"]
    assert rc == 1 and r["verdict"] == "fail", r
    assert r["reasons"] == ["image is 4000x4000 with 4 channels vs golden 64x64 with 4 channels"]


def test_exr_sizes_are_compared_from_the_headers(runs, tmp_path, compare):
    actual, golden = runs
    p = actual / "frames/0000.exr"
    p.write_bytes(_exr_data_window(p.read_bytes(), 99, 99))
    rc, doc, _, _ = compare(actual, golden)
    (r,) = [f for f in doc["files"] if f["path"] == "frames/0000.exr"]
    assert rc == 1 and r["verdict"] == "fail" and r["reasons"] == ["image is 100x100 vs golden 64x64"], r


def test_json_integers_beyond_float_are_compared_not_crashed(tmp_path, compare):
    (tmp_path / "a.json").write_text('{"n": ' + "1" * 400 + ', "m": ' + "3" * 400 + "}")
    (tmp_path / "g.json").write_text('{"n": ' + "1" * 399 + '2, "m": ' + "4" * 400 + "}")
    rc, doc, _, _ = compare(tmp_path / "a.json", tmp_path / "g.json")
    (r,) = doc["files"]
    assert rc == 1 and r["verdict"] == "fail", r
    # n differs by 1 in 400 digits: within rtol; m differs by a 400-digit number: beyond
    assert [x.split(":")[0] for x in r["reasons"][1:]] == ["$.m"], r


def test_fifo_named_on_the_command_line_is_bad_usage(tmp_path, capsys):
    os.mkfifo(tmp_path / "a.ply")
    write_ply(tmp_path / "g.ply", *tube(0, 0))
    assert main_or_hang(["compare", str(tmp_path / "a.ply"), str(tmp_path / "g.ply")]) == 2
    assert "is not a folder or a regular file" in capsys.readouterr().err


@pytest.mark.skipif(os.geteuid() == 0, reason="root lists any folder")
def test_unlistable_folder_is_an_error(runs, tmp_path, compare):
    actual, golden = runs
    (actual / "locked").mkdir()
    (actual / "locked").chmod(0)
    try:
        rc, doc, _, _ = compare(actual, golden)
    finally:
        (actual / "locked").chmod(0o755)
    assert rc == 1 and {f["path"]: f["verdict"] for f in doc["files"]}["locked/"] == "error"


# ----------------------------------------------------------------------------- any file name
ODD_NAMES = ["ctl\x01\x1b[31mred.csv", "x]]>&<y\".txt", "tab\tname.txt", "new\nline.txt", "fffe\ufffe.txt",
             "ünïcödé ✓.txt"]


def test_reports_are_valid_for_any_file_name(runs, tmp_path, compare):
    actual, golden = runs
    for name in ODD_NAMES:
        (actual / name).write_bytes(b"a")
        (golden / name).write_bytes(b"g")
    raw = os.fsencode(str(actual)) + b"/bad\xff\xfe.txt"  # not UTF-8: a surrogate in os.fsdecode
    with open(raw, "wb") as fh:
        fh.write(b"only in actual")
    rc, doc, junit, out = compare(actual, golden)  # ET.fromstring: well-formed XML
    assert rc == 1
    names = {c.get("name") for c in junit.iter("testcase")}
    assert "bad\\xff\\xfe.txt" in names and "ctl\\x01\\x1b[31mred.csv" in names and 'x]]>&<y".txt' in names
    assert "ünïcödé ✓.txt" in names and "fffe\\ufffe.txt" in names and "new\\nline.txt" in names
    assert {f["path"] for f in doc["files"]} >= {"bad\\xff\\xfe.txt", "tab\\tname.txt"}
    out.encode("utf-8")  # printable on a strict UTF-8 terminal
    assert all(line.isprintable() for line in out.splitlines()), out


# ----------------------------------------------------------------------------- -q
def test_quiet_prints_a_subset_of_the_default_ending_with_the_verdict(runs, tmp_path, capsys):
    actual, golden = runs
    for rel in ("stats.csv", MESH):
        p = actual / rel
        p.write_bytes(p.read_bytes()[:-30] + b"garbage")
    (actual / "extra.txt").write_text("x")
    assert main_or_hang(["compare", str(actual), str(golden)]) == 1
    default = capsys.readouterr().out.splitlines()
    assert main_or_hang(["compare", "-q", str(actual), str(golden)]) == 1
    quiet = capsys.readouterr().out.splitlines()
    assert len(quiet) < len(default) and set(quiet[:-1]) <= set(default)
    assert quiet[-1].startswith("DIFFERENT: 3 of 11 files")
    assert quiet[-1].split(" in ")[0] == default[-1].split(" in ")[0]
    assert [q.split() for q in quiet[:-1]] == [["EXTRA", "extra.txt"], ["ERROR", MESH], ["FAIL", "stats.csv"]]


# ----------------------------------------------------------------------------- --update
def _changed(actual: Path) -> None:
    v, n, f = tube(0, 0)
    write_ply(actual / MESH, v + np.float32(1e-3), n, f)
    (actual / "stats.csv").write_text("frame\n1\n")


def test_update_refuses_a_symlinked_folder_in_golden(runs, tmp_path, capsys):
    actual, golden = runs
    elsewhere = tmp_path / "elsewhere"
    shutil.move(golden / "meshes", elsewhere)
    (golden / "meshes").symlink_to(elsewhere)
    _changed(actual)
    before, before_g = tree_bytes(elsewhere), tree_bytes(golden)
    rc = main_or_hang(["compare", str(actual), str(golden), "--update", "--report", str(tmp_path / "r.json")])
    err = capsys.readouterr().err
    assert rc == 2 and "GOLDEN/meshes" in err and "symbolic link" in err, err
    assert tree_bytes(elsewhere) == before and tree_bytes(golden) == before_g
    assert not (tmp_path / "r.json").exists()


def test_update_refuses_a_file_symlink_out_of_golden(runs, tmp_path, capsys):
    actual, golden = runs
    outside = tmp_path / "outside.csv"
    outside.write_bytes((golden / "stats.csv").read_bytes())
    (golden / "stats.csv").unlink()
    (golden / "stats.csv").symlink_to(outside)
    _changed(actual)
    before = outside.read_bytes()
    assert main_or_hang(["compare", str(actual), str(golden), "--update"]) == 2
    assert "GOLDEN/stats.csv" in capsys.readouterr().err
    assert outside.read_bytes() == before


@pytest.mark.parametrize("what", ["fifo", "link out"])
def test_update_refuses_what_it_cannot_copy_from_actual(runs, tmp_path, capsys, what):
    actual, golden = runs
    _changed(actual)
    if what == "fifo":
        os.mkfifo(actual / "pipe")
    else:
        (tmp_path / "secret").write_text("s")
        (actual / "secret").symlink_to(tmp_path / "secret")
    before = tree_bytes(golden)
    assert main_or_hang(["compare", str(actual), str(golden), "--update"]) == 2
    assert "ACTUAL/" in capsys.readouterr().err
    assert tree_bytes(golden) == before


@pytest.mark.parametrize("layout", ["golden inside actual (new)", "golden inside actual (existing)",
                                    "actual inside golden", "same folder"])
def test_update_refuses_nested_folders(tmp_path, capsys, layout):
    outer = make_run(tmp_path / "A", muscles=1, frames=1)
    if layout == "golden inside actual (new)":
        actual, golden = outer, outer / "golden"
    elif layout == "golden inside actual (existing)":
        shutil.copytree(outer, tmp_path / "copy")
        shutil.move(tmp_path / "copy", outer / "golden")
        actual, golden = outer, outer / "golden"
    elif layout == "actual inside golden":
        shutil.copytree(outer, tmp_path / "copy")
        shutil.move(tmp_path / "copy", outer / "run")
        actual, golden = outer / "run", outer
    else:
        actual, golden = outer, tmp_path / "A" / "." / ""
    before = tree_bytes(outer)
    for _ in range(2):
        assert main_or_hang(["compare", str(actual), str(golden), "--update"]) == 2
        assert "inside" in capsys.readouterr().err
    assert tree_bytes(outer) == before


def test_compare_leaves_a_nested_golden_out_of_the_outer_listing(tmp_path, compare):
    outer = make_run(tmp_path / "A", muscles=1, frames=1)
    shutil.copytree(outer, tmp_path / "copy")
    shutil.move(tmp_path / "copy", outer / "golden")
    rc, doc, _, _ = compare(outer, outer / "golden")
    assert rc == 0 and not any(f["path"].startswith("golden/") for f in doc["files"])


def test_update_still_blesses_a_plain_golden(runs, tmp_path, capsys):
    actual, golden = runs
    _changed(actual)
    (golden / "old.txt").write_text("gone")
    (actual / "sub").mkdir()
    (actual / "sub" / "new.txt").write_text("new")
    assert main_or_hang(["compare", str(actual), str(golden), "--update"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"updated golden .*: 1 added, 2 replaced, 1 removed", out), out
    assert tree_bytes(actual) == tree_bytes(golden)


# ----------------------------------------------------------------------------- readers, fuzzed
def test_mesh_readers_raise_only_mesh_read_errors_on_mutated_files():
    """Seeded mutations of a binary PLY, an ascii PLY and an OBJ (bytes flipped, hostile
    tokens inserted, spans cut, truncation): every reader either returns a Mesh or raises
    MeshReadError (an ERROR verdict), never another exception."""
    import random

    from axdf_cli.formats import FORMATS, MeshReadError, read_mesh

    v, n, f = tube(0, 0, 4, 5)
    ascii_ply = (b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                 b"element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n"
                 b"3 0 1 2\n4 0 1 2 0\n")
    seeds = [(FORMATS["ply"].writer(f).encode(v, n), ".ply"), (ascii_ply, ".ply"),
             (FORMATS["obj"].writer(f).encode(v, n), ".obj")]
    tokens = [b"-1", b"4294967295", b"nan", b"1e999", b"99999999999999999999", b"0", b"list", b"float",
              b"\n", b" ", b"//", b"/", b"-", b"f ", b"v ", b"vn ", b"element ", b"property ", b"\nf \n", b"\nv 1\n"]
    rng = random.Random(10)
    for _ in range(3000):
        seed, suffix = rng.choice(seeds)
        data = bytearray(seed)
        for _ in range(rng.randint(1, 4)):
            if not data:
                break
            op, i = rng.random(), rng.randrange(len(data))
            if op < 0.3:
                data[i] = rng.randrange(256)
            elif op < 0.6:
                data[i:i + rng.randint(0, 3)] = rng.choice(tokens)
            elif op < 0.8:
                del data[i:i + rng.randint(1, 20)]
            else:
                del data[i:]
        try:
            read_mesh(bytes(data), suffix)
        except MeshReadError:
            pass


def test_what_axdf_leaves_while_writing_is_not_compared(tmp_path, compare):
    """The lock, a killed writer's temporary and a staging folder are axdf's own working
    entries, not part of the run: they neither fail nor error a comparison."""
    actual = make_run(tmp_path / "actual", muscles=1, frames=1)
    golden = make_run(tmp_path / "golden", muscles=1, frames=1)
    (actual / ".axdf-lock").write_bytes(b"")
    (actual / "meshes" / "m0" / ".axdf-tmp-999999-m0_0000.ply").write_bytes(b"half")
    (golden / ".axdf-new-999999" / "meshes").mkdir(parents=True)
    (golden / ".axdf-new-999999" / "stats.csv").write_text("x\n")
    rc, doc, _, _ = compare(actual, golden)
    assert rc == 0, doc
    assert not any(".axdf-" in f["path"] for f in doc["files"])
