"""Hostile round 6: fresh cases of the four kinds earlier rounds found defects in, each refused
with exit 2 and ``FILE:LINE:COL: what; allowed`` (or ``FILE: ...`` for a binary file), no
traceback, nothing written (the --out folder not created or left as it was), or, where it is no
error, holding: no NaN written, memory bounded, results independent of the working folder.

1. ``axdf atlas`` on a small synthetic atlas (six real Visible Human files copied to tmp_path,
   a map of one muscle): malformed maps (format specs in files:, an atlas file linking out of
   the folder, muscles named twice, bone pairs the skeleton lacks, landmarks on one line,
   lists past their bounds, no split:), corrupt PLYs (lying counts, NaN, a face out of range,
   no faces, a point, 1e30), --sides and --sections, --out onto the inputs and --overwrite
   emptying an input folder;
2. ``axdf fit``: slivers, two pieces, open, non-manifold, NaN, huge and negative indices, a
   PLY claiming 10^12 vertices, odd names, several bad files named at once;
3. skin files: NPZ members of the wrong kind, object arrays, names that are no names, region
   names twice, fat out of range, rest meshes degenerate or linked into the output;
4. ``axdf run`` of an axis-and-path muscle, resumed from another working folder.

Seeded where random. Needs ../shared/data for part 1 (skipped without it).
"""
from __future__ import annotations

import io
import json
import os
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from cli_in_folder import run_cli
from conftest import REPO_ROOT, all_files
from osim_common import DATA
from test_fit_hostile import SKELETON as FIT_LEG

VHF = DATA / "atlas" / "visible_human_female"
SKELETON = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"
SOLEUS = REPO_ROOT / "muscles" / "gait2392" / "soleus_r.yaml"
needs_atlas = pytest.mark.skipif(not (VHF / "Right").is_dir(), reason=f"the Visible Human atlas not found at {VHF}")

ATLAS_FILES = ("Right/VHF_Right_Cartilage_FemurHead_smooth.ply", "Left/VHF_Left_Cartilage_FemurHead_smooth.ply",
               "Right/VHF_Right_Cartilage_FemurDistal_smooth.ply", "Right/VHF_Right_Cartilage_Talus_smooth.ply",
               "Right/VHF_Right_Bone_Talus_smooth.ply", "Right/VHF_Right_Muscle_Soleus_smooth.ply")
MAP = """\
files: "{folder}/VHF_{folder}_{kind}_{name}_smooth.ply"
sides: {r: Right, l: Left}
landmarks:
  hip: {cartilage: FemurHead, leg: same, bone: femur}
  hip_other: {cartilage: FemurHead, leg: other, bone: femur}
  knee: {cartilage: FemurDistal, leg: same, bone: tibia}
  ankle: {cartilage: Talus, leg: same, bone: talus}
bones:
  - {atlas: [Talus], bone: talus, both: true}
muscles:
  soleus: [Soleus]
"""


def _no_trace(rc: int, err: str) -> None:
    assert rc == 2, (rc, err[-3000:])
    assert "Traceback" not in err and "internal error" not in err, err


def _line(text: str, start: str) -> int:
    return next(i for i, t in enumerate(text.splitlines(), 1) if t.lstrip().startswith(start))


# ============================================================================ 1. axdf atlas


@pytest.fixture(scope="module")
def small_atlas(tmp_path_factory) -> Path:
    """Six real files of the right leg (and the left femoral head): a map of one muscle."""
    if not (VHF / "Right").is_dir():
        pytest.skip(f"the Visible Human atlas not found at {VHF}")
    root = tmp_path_factory.mktemp("atlas6")
    for rel in ATLAS_FILES:
        (root / "atlas" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(VHF / rel, root / "atlas" / rel)
    (root / "lib").mkdir()
    shutil.copy(SOLEUS, root / "lib" / "soleus_r.yaml")
    return root


@pytest.fixture()
def at(small_atlas, tmp_path) -> Path:
    """A fresh copy of the small atlas, its library and map in tmp_path."""
    shutil.copytree(small_atlas / "atlas", tmp_path / "atlas")
    shutil.copytree(small_atlas / "lib", tmp_path / "lib")
    (tmp_path / "map.yaml").write_text(MAP)
    return tmp_path


def _atlas(d: Path, capsys, *argv, out="out", map_="map.yaml", muscles="lib", atlas="atlas") -> tuple[int, str]:
    capsys.readouterr()
    rc = run_cli(d, "atlas", str(atlas), "--onto", str(SKELETON), "--map", str(map_), "--muscles", str(muscles),
                 "--out", str(out), "--sides", "r", "--quiet", *argv)
    return rc, capsys.readouterr().err


def _atlas_refused(d: Path, capsys, *argv, **kw) -> str:
    before = all_files(d)
    rc, err = _atlas(d, capsys, "--register-only", *argv, **kw)
    _no_trace(rc, err)
    assert not (d / "out").exists() and all_files(d) == before
    return err


def _map(d: Path, text: str) -> str:
    (d / "map.yaml").write_text(text)
    return "map.yaml"


@needs_atlas
def test_the_small_atlas_registers(at, capsys):
    """The baseline every atlas case departs from: it registers, finite numbers only."""
    rc, err = _atlas(at, capsys, "--register-only")
    assert rc == 0, err
    report = json.loads((at / "out" / "atlas_report.json").read_text(),
                        parse_constant=lambda c: pytest.fail(f"{c} in the report"))
    assert report["sides"]["r"]["bones_after"]["talus_r"]["mean_mm"] < 2.0
    assert (at / "out" / "registered" / "soleus_r.ply").is_file()


@needs_atlas
@pytest.mark.parametrize("spec", ["{name:>99999999}", "{name!r}", "{name:x}"])
def test_a_files_placeholder_with_a_format_spec_is_refused(at, capsys, spec):
    """{name:>99999999} padded every path to 100 MB before any check (memory), {name!r} quoted it."""
    _map(at, MAP.replace("{name}_smooth", f"{spec}_smooth"))
    err = _atlas_refused(at, capsys)
    assert err.startswith(f"map.yaml:1:8: files: ") and "a placeholder takes no format or conversion" in err


@needs_atlas
def test_a_files_pattern_climbing_out_is_refused(at, capsys):
    _map(at, MAP.replace('files: "{folder}/', 'files: "{folder}/../../'))
    assert "is not an atlas file pattern" in _atlas_refused(at, capsys)


@needs_atlas
def test_an_atlas_file_linking_out_of_the_folder_is_refused_at_the_map(at, tmp_path_factory, capsys):
    """A cartilage that is a link to a file elsewhere (read before: the atlas is a folder tree)."""
    elsewhere = tmp_path_factory.mktemp("elsewhere") / "talus.ply"
    target = at / "atlas" / "Right" / "VHF_Right_Cartilage_Talus_smooth.ply"
    shutil.move(target, elsewhere)
    target.symlink_to(elsewhere)
    err = _atlas_refused(at, capsys)
    assert err.startswith(f"map.yaml:{_line(MAP, 'ankle:')}:10: atlas file ") and "leaves the atlas folder" in err
    # a link inside the tree is fine
    shutil.copy(elsewhere, at / "atlas" / "talus_copy.ply")
    target.unlink()
    target.symlink_to(at / "atlas" / "talus_copy.ply")
    rc, err = _atlas(at, capsys, "--register-only")
    assert rc == 0, err


@needs_atlas
@pytest.mark.parametrize("extra, start, words", [
    ("kept: [soleus]\n", "kept:", "kept muscle soleus is named twice (first at line 11)"),
    ("split:\n  sol: {atlas: [Soleus], parts: [soleus, soleus2]}\n", "sol:", "split sol's part soleus is named twice"),
    ("kept: [per_brev, per_brev]\n", "kept:", "kept muscle per_brev is named twice"),
])
def test_a_model_muscle_named_twice_is_refused(at, capsys, extra, start, words):
    """(the later entry's files silently replaced the earlier's)"""
    _map(at, MAP + extra)
    err = _atlas_refused(at, capsys)
    assert err.startswith(f"map.yaml:{_line(MAP + extra, start)}:") and words in err, err


@needs_atlas
def test_a_map_without_split_kept_or_unused_is_read(at, capsys):
    """An atlas sharing no muscle between model parts: split: was required and could not be empty."""
    rc, err = _atlas(at, capsys, "--register-only", map_=_map(at, MAP + "split: {}\nkept: []\n"))
    assert rc == 0, err


@needs_atlas
def test_a_bone_pair_the_skeleton_lacks_is_refused_at_its_line(at, capsys):
    """(it was skipped silently: the warp pulled nothing)"""
    _map(at, MAP.replace("bone: talus, both", "bone: talusx, both"))
    err = _atlas_refused(at, capsys)
    assert err.startswith(f"map.yaml:{_line(MAP, '- {atlas: [Talus]')}:5: bone talusx: skeleton gait2392's "
                          "bone talusx_r does not exist; did you mean 'talus_r'?"), err


@needs_atlas
def test_landmarks_on_one_point_are_refused(at, capsys):
    """Every landmark the same cartilage and bone: the similarity's scale was 0/0 (NaN)."""
    text = MAP.replace("FemurDistal, leg: same, bone: tibia", "Talus, leg: same, bone: talus") \
        .replace("cartilage: FemurHead, leg: same, bone: femur", "cartilage: Talus, leg: same, bone: talus") \
        .replace("cartilage: FemurHead, leg: other, bone: femur", "cartilage: Talus, leg: same, bone: talus")
    err = _atlas_refused(at, capsys, map_=_map(at, text))
    assert err.startswith(f"map.yaml:4:") and "on one line or point" in err, err


@needs_atlas
@pytest.mark.parametrize("case", ["landmarks", "names", "muscles"])
def test_the_maps_lists_are_bounded(at, capsys, case):
    """A small map cannot make the command fit thousands of spheres or look up thousands of files."""
    from axdf_cli.tools import constants as tol

    if case == "landmarks":
        many = "".join(f"  l{i}: {{cartilage: Talus, leg: same, bone: talus}}\n" for i in range(tol.ATLAS_MAX_LANDMARKS + 1))
        text = MAP.replace("landmarks:\n", "landmarks:\n" + many)
        words = f"landmarks has {tol.ATLAS_MAX_LANDMARKS + 5} entries; landmarks: at most {tol.ATLAS_MAX_LANDMARKS}"
    elif case == "names":
        text = MAP.replace("soleus: [Soleus]", "soleus: [" + ", ".join(f"S{i}" for i in range(10000)) + "]")
        words = f"lists 10000 names; muscle soleus's atlas names: at most {tol.ATLAS_MAX_NAMES}"
    else:
        text = MAP + "".join(f"  m{i}: [Soleus]\n" for i in range(tol.ATLAS_MAX_MUSCLES))
        words = f"muscles has {tol.ATLAS_MAX_MUSCLES + 1} entries"
    assert words in _atlas_refused(at, capsys, map_=_map(at, text))


@needs_atlas
@pytest.mark.parametrize("text, start, words", [
    (MAP.replace("soleus: [Soleus]", "soleus: Soleus"), "soleus:", "is not a list of names"),
    (MAP.replace("soleus: [Soleus]", "soleus: [Soleus]\n  soleus: [Soleus]"), 12, "duplicate key 'soleus' (first at line 11)"),
    (MAP.replace("both: true", "both: yes please"), "- {atlas", "both is"),
    (MAP.replace("sides: {r: Right, l: Left}", "sides: {r: Right, l: Left, x: Up}"), "sides:", "unknown side 'x'"),
    (MAP.replace("leg: other", "leg: .nan"), "hip_other:", "'.nan' is not finite"),
    (MAP.replace("sides: {r: Right, l: Left}", "sides: {r: ../Right, l: Left}"), "sides:", "side r's folder is"),
    (MAP + "unused: [1.5]\n", "unused:", "unused is the number 1.5"),
])
def test_malformed_map_entries_are_refused_at_their_line(at, capsys, text, start, words):
    err = _atlas_refused(at, capsys, map_=_map(at, text))
    line = start if isinstance(start, int) else _line(text, start)
    assert err.startswith(f"map.yaml:{line}:") and words in err, err


def _ply(v: np.ndarray, f: np.ndarray, count_v: int | None = None, count_f: int | None = None) -> bytes:
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v) if count_v is None else count_v}\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {len(f) if count_f is None else count_f}\nproperty list uchar int vertex_indices\n"
            "end_header\n").encode()
    rec = np.zeros(len(f), np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    rec["n"], rec["i"] = 3, f
    return head + np.asarray(v, "<f4").tobytes() + rec.tobytes()


def _read(path: Path):
    from axdf_cli.formats import load_triangles

    v, _, f = load_triangles(path)
    return np.asarray(v, np.float64), np.asarray(f, np.int64)


@needs_atlas
@pytest.mark.parametrize("case, words", [
    ("nan", "has 1 non-finite vertices"),
    ("face out of range", "names vertex 1000000000, but the file has 12316 vertices"),
    ("no faces", "has 0 triangles, no closed surface"),
    ("lying vertex count", "PLY file ends inside element"),
    ("huge claimed count", "PLY file ends inside element 'vertex'"),
    ("point", "is 0 mm across"),
    ("far", "mm from the origin at most"),
    ("open", "is open: 3 edges border one triangle only"),
    ("not a ply", "not a readable mesh"),
])
def test_a_corrupt_atlas_mesh_is_refused_by_name(at, capsys, case, words):
    """A cartilage (its sphere's centre a landmark) or the muscle made corrupt: NaN went into the
    landmarks' similarity and out as NaN, a face out of range was an IndexError (exit 70)."""
    name = "Right/VHF_Right_Muscle_Soleus_smooth.ply" if case in ("open", "no faces") else \
        "Right/VHF_Right_Cartilage_FemurDistal_smooth.ply"
    path = at / "atlas" / name
    v, f = _read(path)
    rng = np.random.default_rng(61)
    k = int(rng.integers(len(v)))
    data = {
        "nan": lambda: _ply(np.where(np.arange(len(v))[:, None] == k, np.nan, v), f),
        "face out of range": lambda: _ply(v, np.where(np.arange(len(f))[:, None] == k % len(f), 10 ** 9, f)),
        "no faces": lambda: _ply(v, f[:0]),
        "lying vertex count": lambda: _ply(v, f, count_v=len(v) * 3),
        "huge claimed count": lambda: _ply(v, f, count_v=10 ** 12, count_f=10 ** 12),
        "point": lambda: _ply(np.zeros_like(v) + 5.0, f),
        "far": lambda: _ply(v + 1e30, f),
        "open": lambda: _ply(v, f[1:]),
        "not a ply": lambda: rng.bytes(5000),
    }[case]()
    path.write_bytes(data)
    tracemalloc.start()
    try:
        err = _atlas_refused(at, capsys)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 200e6, peak
    assert err.startswith(f"atlas/{name}: ") and words in err, err


@needs_atlas
@pytest.mark.parametrize("argv, words", [
    (("--sides", ""), "--sides ''"), (("--sides", "r,"), "--sides 'r,'"), (("--sides", "R"), "--sides 'R'"),
    (("--sections", "3"), "--sections 3"), (("--sections", "65"), "--sections 65"),
    (("--sections", "-4"), "--sections -4"),
])
def test_sides_and_sections_out_of_range(at, capsys, argv, words):
    capsys.readouterr()
    rc = run_cli(at, "atlas", "atlas", "--onto", str(SKELETON), "--map", "map.yaml", "--muscles", "lib",
                 "--out", "out", "--quiet", *argv)
    err = capsys.readouterr().err
    _no_trace(rc, err)
    assert words in err and not (at / "out").exists()


@needs_atlas
@pytest.mark.parametrize("out", ["atlas", "atlas/Right/new", "lib", "lib/new"])
def test_out_onto_an_input_folder_is_refused(at, capsys, out):
    before = all_files(at)
    rc, err = _atlas(at, capsys, "--register-only", "--overwrite", out=out)
    _no_trace(rc, err)
    assert "lies in this input folder" in err and all_files(at) == before


@needs_atlas
def test_overwrite_never_empties_an_input_folder(at, capsys):
    """--muscles OUT/muscles with --out OUT --overwrite --register-only: the old output's muscles/,
    the folder the command read, was deleted as 'listed in the old manifest'."""
    rc, err = _atlas(at, capsys, "--sections", "4")
    assert rc == 0, err
    assert (at / "out" / "muscles" / "soleus_r.yaml").is_file()
    before = all_files(at / "out")
    rc, err = _atlas(at, capsys, "--register-only", "--overwrite", muscles="out/muscles")
    _no_trace(rc, err)
    assert "out/muscles: this input folder's files would be deleted: muscles/" in err, err
    assert all_files(at / "out") == before
    # the map inside the output folder, --overwrite: read, never deleted (not listed) and kept
    shutil.copy(at / "map.yaml", at / "out" / "map.yaml")
    rc, err = _atlas(at, capsys, "--register-only", "--overwrite", map_="out/map.yaml")
    assert rc == 0, err
    assert (at / "out" / "map.yaml").read_text() == MAP


# ============================================================================ 2. axdf fit

LEG = FIT_LEG  # the two-bone leg of test_fit_hostile


def _ellipsoid(shift=(0.03, 0.0, 0.7), scale=(0.02, 0.02, 0.12), subdiv: int = 3):
    import trimesh

    m = trimesh.creation.icosphere(subdiv, 1.0)
    m.apply_scale(scale)
    m.apply_translation(shift)
    return np.asarray(m.vertices), np.asarray(m.faces, np.int64)


@pytest.fixture()
def leg(tmp_path) -> Path:
    (tmp_path / "leg.yaml").write_text(LEG)
    return tmp_path


def _fit(d: Path, capsys, *argv) -> tuple[int, str]:
    capsys.readouterr()
    rc = run_cli(d, "fit", *argv, "--skeleton", "leg.yaml", "--out", "fitted", "--quiet", "--sections", "4")
    return rc, capsys.readouterr().err


def _fit_refused(d: Path, capsys, *argv) -> str:
    rc, err = _fit(d, capsys, *argv)
    _no_trace(rc, err)
    assert not (d / "fitted").exists()
    return err


def test_a_sliver_is_dropped_and_a_second_body_refused(leg, capsys):
    v, f = _ellipsoid()
    sv, sf = _ellipsoid(shift=(0.1, 0, 0.7), scale=(0.001, 0.001, 0.001), subdiv=1)
    (leg / "sliver.ply").write_bytes(_ply(np.concatenate([v, sv]), np.concatenate([f, sf + len(v)])))
    rc, err = _fit(leg, capsys, "sliver.ply")
    assert rc == 0, err
    (rep,) = json.loads((leg / "fitted" / "fit_report.json").read_text())["muscles"]
    assert rep["muscle"] == "sliver"
    shutil.rmtree(leg / "fitted")
    bv, bf = _ellipsoid(shift=(-0.03, 0, 0.7))
    (leg / "two.ply").write_bytes(_ply(np.concatenate([v, bv]), np.concatenate([f, bf + len(v)])))
    assert "two.ply: mesh is 2 separate closed pieces, 2 of them" in _fit_refused(leg, capsys, "two.ply")


@pytest.mark.parametrize("case, words", [
    ("open", "mesh is not closed"),
    ("twice", "mesh is not closed"),
    ("nan", "has non-finite vertex coordinates"),
    ("inf", "has non-finite vertex coordinates"),
    ("huge index", "names vertex"),
    ("negative index", "names vertex -1"),
    ("claims 10^12", "PLY"),
    ("empty", "holds no triangles"),
])
def test_broken_meshes_are_refused_by_name(leg, capsys, case, words):
    v, f = _ellipsoid()
    rng = np.random.default_rng(62)
    k = int(rng.integers(len(f)))
    data = {
        "open": lambda: _ply(v, np.delete(f, k, axis=0)),
        "twice": lambda: _ply(v, np.concatenate([f, f[k:k + 1]])),
        "nan": lambda: _ply(np.where(np.arange(len(v))[:, None] == k % len(v), np.nan, v), f),
        "inf": lambda: _ply(np.where(np.arange(len(v))[:, None] == k % len(v), np.inf, v), f),
        "huge index": lambda: _ply(v, np.where(np.arange(len(f))[:, None] == k, 2 ** 31 - 1, f)),
        "negative index": lambda: _ply(v, np.where(np.arange(len(f))[:, None] == k, -1, f)),
        "claims 10^12": lambda: _ply(v, f, count_v=10 ** 12, count_f=10 ** 12),
        "empty": lambda: b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
                         b"property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n",
    }[case]()
    (leg / "bad.ply").write_bytes(data)
    tracemalloc.start()
    try:
        err = _fit_refused(leg, capsys, "bad.ply")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 200e6, peak
    assert err.startswith("bad.ply: ") and words in err, err


def test_an_obj_naming_a_missing_vertex_is_refused(leg, capsys):
    v, f = _ellipsoid()
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in v)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f[:-1]) + f"f 1 2 {10 ** 6}\n"
    (leg / "bad.obj").write_text(text)
    err = _fit_refused(leg, capsys, "bad.obj")
    assert err.startswith("bad.obj: face 1279 (of 1280, counted from 0) names vertex 999999, but the file has 642 "
                          "vertices"), err
    assert "IndexError" not in err


@pytest.mark.parametrize("stem, words", [
    ("a b", "cannot name a muscle"), ("sóleus", "cannot name a muscle"), ("tab\t", "cannot name a muscle"),
    ("x" * 250, "cannot name a muscle"),
])
def test_odd_stems_name_no_muscle(leg, capsys, stem, words):
    v, f = _ellipsoid()
    (leg / f"{stem}.ply").write_bytes(_ply(v, f))
    assert words in _fit_refused(leg, capsys, f"{stem}.ply")


def test_two_meshes_of_one_stem_are_refused(leg, capsys):
    v, f = _ellipsoid()
    for sub in ("a", "b"):
        (leg / sub).mkdir()
        (leg / sub / "m.ply").write_bytes(_ply(v, f))
    err = _fit_refused(leg, capsys, "a/m.ply", "b/m.ply")
    assert "m" in err
    err = _fit_refused(leg, capsys, "a/m.ply", "a/m.ply")


def test_several_bad_meshes_are_named_at_once(leg, capsys):
    """Three bad files among two good ones: one refusal names all three, nothing written."""
    v, f = _ellipsoid()
    (leg / "good1.ply").write_bytes(_ply(v, f))
    (leg / "good2.ply").write_bytes(_ply(v + [0.005, 0, 0], f))
    (leg / "nan.ply").write_bytes(_ply(np.where(np.arange(len(v))[:, None] == 3, np.nan, v), f))
    (leg / "open.ply").write_bytes(_ply(v, f[1:]))
    (leg / "cut.ply").write_bytes(_ply(v, f)[:-100])
    err = _fit_refused(leg, capsys, "good1.ply", "nan.ply", "good2.ply", "open.ply", "cut.ply", "missing.ply")
    for name in ("nan.ply: ", "open.ply: ", "cut.ply: ", "missing.ply: "):
        assert name in err, (name, err)
    assert "good1.ply:" not in err and "good2.ply:" not in err


def test_a_mesh_that_is_a_link_to_a_device_or_fifo_is_refused(leg, capsys):
    (leg / "zero.stl").symlink_to("/dev/zero")
    os.mkfifo(leg / "fifo.ply")
    err = _fit_refused(leg, capsys, "zero.stl", "fifo.ply")
    assert "zero.stl: " in err and "fifo.ply: " in err


@pytest.mark.parametrize("paths, words", [
    ("nowhere", "nowhere"), ("leg.yaml", "leg.yaml"),
])
def test_paths_that_are_no_muscle_folder_are_refused(leg, capsys, paths, words):
    v, f = _ellipsoid()
    (leg / "m.ply").write_bytes(_ply(v, f))
    assert words in _fit_refused(leg, capsys, "m.ply", "--paths", paths)


def test_paths_outside_the_tree_by_dotdot_resolve_from_the_working_folder(leg, tmp_path_factory, capsys):
    """--paths ../lib given from a sub-folder: the same fit as the absolute path (the working folder
    decides what a relative path names, nothing else)."""
    v, f = _ellipsoid()
    (leg / "m.ply").write_bytes(_ply(v, f))
    (leg / "lib").mkdir()
    (leg / "lib" / "m.yaml").write_text("muscle: m\npath:\n  - {bone: pelvis, at: [0.03, 0, -0.2]}\n"
                                        "  - {bone: femur, at: [0.03, 0, -0.35]}\n"
                                        "sections:\n  - {t: 0.3, radii: [0.02, 0.02], angle: 0}\n"
                                        "  - {t: 0.7, radii: [0.02, 0.02], angle: 0}\n")
    (leg / "sub").mkdir()
    capsys.readouterr()
    assert run_cli(leg / "sub", "fit", "../m.ply", "--skeleton", "../leg.yaml", "--paths", "../lib", "--out", "../a",
                   "--quiet", "--sections", "4") == 0, capsys.readouterr().err
    assert run_cli(Path("/"), "fit", str(leg / "m.ply"), "--skeleton", str(leg / "leg.yaml"), "--paths",
                   str(leg / "lib"), "--out", str(leg / "b"), "--quiet", "--sections", "4",
                   "--allow-outside") == 0, capsys.readouterr().err
    a, b = all_files(leg / "a"), all_files(leg / "b")
    assert a["muscles/m.yaml"] == b["muscles/m.yaml"]


# ============================================================================ 3. skin files

SKIN = REPO_ROOT / "skins" / "gait2392"
POSE = REPO_ROOT / "poses" / "gait2392_walk.yaml"
REST = REPO_ROOT / "poses" / "gait2392_rest.yaml"
VAS = REPO_ROOT / "muscles" / "gait2392_packed" / "vas_lat_l.yaml"


def _skin(tmp_path: Path) -> Path:
    shutil.copytree(SKIN, tmp_path / "s")
    return tmp_path / "s" / "skin.yaml"


def _npz(path: Path, allow_pickle: bool = False, **arrays) -> None:
    buf = io.BytesIO()
    np.savez(buf, **arrays) if allow_pickle else np.savez_compressed(buf, **arrays)
    path.write_bytes(buf.getvalue())


def _main(argv, capsys) -> tuple[int, str, str]:
    from axdf_cli.cli.main import main

    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def _skin_refused(capsys, argv, *words) -> str:
    rc, _, err = _main(argv, capsys)
    _no_trace(rc, err)
    for w in words:
        assert w in err, (w, err)
    return err


def _skin_run(out: Path, skin: Path, *extra, pose: Path = POSE, frames: str = "0:1") -> list:
    return ["run", "--pose", pose, "--muscles", VAS, "--skin", skin, "--frames", frames, "--out", out, "--quiet",
            "--allow-outside", *extra]


def _skin_line(path: Path, key: str) -> int:
    return _line(path.read_text(), f"{key}:")


@pytest.mark.parametrize("which, change, words", [
    ("fat", lambda a: {**a, "regions": np.array(["head", "head"] + [str(r) for r in a["regions"][2:]])},
     "names region head more than once"),
    ("fat", lambda a: {**a, "regions": np.array(["he ad"] + [str(r) for r in a["regions"][1:]])},
     "lists the region name 'he ad'"),
    ("fat", lambda a: {**a, "fat": np.where(np.arange(len(a["fat"])) == 7, 0.5, a["fat"]).astype("<f4")},
     "thicknesses out of range (one is 0.5 m)"),
    ("fat", lambda a: {**a, "fat": np.where(np.arange(len(a["fat"])) == 7, 1e30, a["fat"]).astype("<f4")},
     "thicknesses out of range (one is 1e+30 m)"),
    ("fat", lambda a: {**a, "fat": a["fat"].astype(np.complex64)}, "array fat is <c8"),
    ("fat", lambda a: {**a, "region": a["region"].astype(bool)}, "array region is |b1"),
    ("weights", lambda a: {**a, "bones": np.array([""] + [str(b) for b in a["bones"][1:]])},
     "lists the bone name ''"),
    ("weights", lambda a: {**a, "bones": np.array(["a/b"] + [str(b) for b in a["bones"][1:]])},
     "lists the bone name 'a/b'"),
    ("weights", lambda a: {**a, "bones": np.array(["pel\nvis"] + [str(b) for b in a["bones"][1:]])},
     "lists the bone name 'pel\\nvis'"),
    ("weights", lambda a: {**a, "vertex_count": np.array(13380.0)}, "array vertex_count is <f8 of shape ()"),
    ("weights", lambda a: {**a, "weight": np.array(1.0, "<f4")}, "array weight is <f4 of shape ()"),
    ("weights", lambda a: {**a, "bones": a["bones"].reshape(-1, 1)}, "array bones is <U"),
    ("weights", lambda a: {**a, "bones": a["bones"].astype("S")}, "array bones is |S"),
])
def test_npz_members_of_the_wrong_kind_are_refused(tmp_path, capsys, which, change, words):
    path = _skin(tmp_path)
    target = path.parent / f"skin_{which}.npz"
    _npz(target, **change(dict(np.load(target))))
    _skin_refused(capsys, ["validate", path], f"{path}:{_skin_line(path, which)}:", target.name, words)


def test_an_object_array_is_refused_unread(tmp_path, capsys, monkeypatch):
    """An NPZ member pickled (dtype object) is refused from its header; nothing unpickles it."""
    path = _skin(tmp_path)
    target = path.parent / "skin_weights.npz"
    arrays = dict(np.load(target))
    arrays["bones"] = np.array(list(arrays["bones"]), dtype=object)
    _npz(target, allow_pickle=True, **arrays)
    import pickle

    def no_pickle(*a, **k):
        raise AssertionError("an NPZ member was unpickled")

    monkeypatch.setattr(pickle, "load", no_pickle)
    monkeypatch.setattr(pickle, "loads", no_pickle)
    _skin_refused(capsys, ["validate", path], "skin_weights.npz: array bones is |O")


def test_a_rest_mesh_linked_into_the_output_is_refused(tmp_path, capsys):
    """The skin's mesh a link (outside OUT) to the run's own skin_0000.ply: the real path decides."""
    out = tmp_path / "out"
    rc, _, err = _main(_skin_run(out, SKIN / "skin.yaml", pose=REST, frames="0"), capsys)
    assert rc == 0, err
    path = _skin(tmp_path)
    (path.parent / "skin_rest.ply").unlink()
    (path.parent / "skin_rest.ply").symlink_to(out / "meshes" / "skin" / "skin_0000.ply")
    before = all_files(out)
    _skin_refused(capsys, _skin_run(out, path, "--overwrite", pose=REST, frames="0"),
                  "this input lies in the output folder")
    assert all_files(out) == before


def test_a_rest_mesh_with_zero_area_triangles_gives_finite_meshes_or_a_refusal(tmp_path, capsys):
    """Two vertices of one triangle moved onto the third (no index repeated: closed, finite, outward):
    the run writes no NaN (normals of triangles with no area) or refuses the mesh by name."""
    from axdf_cli.formats import PlyWriter, load_triangles

    path = _skin(tmp_path)
    v, _, f = load_triangles(SKIN / "skin_rest.ply")
    v = np.array(v, np.float32)
    a, b, c = f[int(np.random.default_rng(63).integers(len(f)))]
    v[b] = v[a]
    v[c] = v[a]
    (path.parent / "skin_rest.ply").write_bytes(PlyWriter(f).encode(v))
    out = tmp_path / "out"
    rc, _, err = _main(_skin_run(out, path), capsys)
    if rc == 2:
        assert "skin_rest.ply" in err and "Traceback" not in err, err
        assert not out.exists()
        return
    assert rc == 0, err
    for k in (0, 1):
        w, n, _ = load_triangles(out / "meshes" / "skin" / f"skin_{k:04d}.ply")
        assert np.isfinite(w).all() and (n is None or np.isfinite(n).all())


def test_axdf_skin_refuses_a_zero_length_left_shank(tmp_path, capsys):
    text = (REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml").read_text()
    k = text.index("name: talus_l")
    i = text.index("offset:", k)
    j = text.index("\n", i)
    zero = text[:i] + "offset: [0, 0, 0]" + text[j:]
    skel = tmp_path / "skel.yaml"
    skel.write_text(zero.replace("mesh: meshes/", f"mesh: {SKELETON.parent / 'meshes'}/"))
    out = tmp_path / "o"
    _skin_refused(capsys, ["skin", "--skeleton", skel, "--out", out, "--allow-outside"], f"{skel}:",
                  "segment shank_l", "talus_l")
    assert not out.exists()


@pytest.mark.parametrize("fps", [0.001, 1e5])
def test_a_skin_jiggle_at_extreme_frame_rates_writes_finite_meshes(tmp_path, capsys, fps):
    path = _skin(tmp_path)
    path.write_text(path.read_text() + "jiggle: {frequency: 100, damping_ratio: 0.05}\n")
    text = POSE.read_text().replace("skeleton: skeletons/gait2392.yaml", f"skeleton: {SKELETON}")
    pose = tmp_path / "pose.yaml"
    pose.write_text("\n".join(f"fps: {fps:g}" if t.startswith("fps:") else t for t in text.splitlines()) + "\n")
    out = tmp_path / "out"
    rc, _, err = _main(_skin_run(out, path, pose=pose, frames="5:6"), capsys)
    assert rc == 0, err
    from axdf_cli.formats import load_triangles

    for k in (5, 6):
        w, n, _ = load_triangles(out / "meshes" / "skin" / f"skin_{k:04d}.ply")
        assert np.isfinite(w).all() and (n is None or np.isfinite(n).all())


# ============================================================================ 4. run --resume elsewhere

AXIS_PATH = REPO_ROOT / "muscles" / "gait2392_atlas" / "soleus_r.yaml"


def _mesh_files(out: Path) -> dict:
    return {k: v for k, v in all_files(out).items() if k.startswith("meshes/") or k in ("stats.csv", "bones.csv")}


@pytest.fixture()
def project(tmp_path) -> Path:
    """A project folder: an axis-and-path muscle and a pose on gait2392 by relative paths."""
    (tmp_path / "m").mkdir()
    shutil.copy(AXIS_PATH, tmp_path / "m" / "soleus_r.yaml")
    text = POSE.read_text().replace("skeleton: skeletons/gait2392.yaml", f"skeleton: {SKELETON}")
    (tmp_path / "walk.yaml").write_text(text)
    return tmp_path


def _run_in(cwd: Path, capsys, *argv) -> tuple[int, str]:
    old = os.getcwd()
    os.chdir(cwd)
    try:
        rc, _, err = _main(["run", *argv, "--no-render", "--quiet"], capsys)
    finally:
        os.chdir(old)
    return rc, err


def test_resume_from_another_working_folder_gives_the_uninterrupted_run(project, capsys, tmp_path_factory):
    """An axis-and-path muscle run from the project by relative paths, its last frames lost, resumed
    from elsewhere by absolute paths (and from a sub-folder by ../ ones): the same files as one
    uninterrupted run."""
    rc, err = _run_in(project, capsys, "--muscles", "m", "--pose", "walk.yaml", "--frames", "0:5", "--out", "out")
    assert rc == 0, err
    (project / "out" / "meshes" / "soleus_r" / "soleus_r_0005.ply").unlink()
    elsewhere = tmp_path_factory.mktemp("elsewhere")
    rc, err = _run_in(elsewhere, capsys, "--muscles", str(project / "m"), "--pose", str(project / "walk.yaml"),
                      "--frames", "0:5", "--out", str(project / "out"), "--resume", "--allow-outside")
    assert rc == 0, err
    (project / "out" / "meshes" / "soleus_r" / "soleus_r_0004.ply").unlink()
    (project / "sub").mkdir()
    rc, err = _run_in(project / "sub", capsys, "--muscles", "../m", "--pose", "../walk.yaml", "--frames", "0:5",
                      "--out", "../out", "--resume")
    assert rc == 0, err
    rc, err = _run_in(project, capsys, "--muscles", "m", "--pose", "walk.yaml", "--frames", "0:5", "--out", "whole")
    assert rc == 0, err
    got, want = _mesh_files(project / "out"), _mesh_files(project / "whole")
    assert set(got) == set(want) and "meshes/soleus_r/soleus_r_0005.ply" in got
    assert got == want


def test_resume_elsewhere_with_another_muscle_of_the_same_name_is_refused(project, capsys, tmp_path_factory):
    """From another folder, the relative --muscles m names another file: resuming would mix two runs."""
    rc, err = _run_in(project, capsys, "--muscles", "m", "--pose", "walk.yaml", "--frames", "0:1", "--out", "out")
    assert rc == 0, err
    other = tmp_path_factory.mktemp("other")
    (other / "m").mkdir()
    text = AXIS_PATH.read_text().replace("volume: exact", "volume: paper")
    (other / "m" / "soleus_r.yaml").write_text(text)
    shutil.copy(project / "walk.yaml", other / "walk.yaml")
    before = all_files(project / "out")
    rc, err = _run_in(other, capsys, "--muscles", "m", "--pose", "walk.yaml", "--frames", "0:3",
                      "--out", str(project / "out"), "--resume", "--allow-outside")
    _no_trace(rc, err)
    assert "--resume" in err and all_files(project / "out") == before


def test_an_axis_off_the_paths_bones_is_refused_before_the_run_writes(project, capsys):
    text = AXIS_PATH.read_text().replace("{bone: tibia_r, at: [-0.0213981", "{bone: femur_l, at: [-0.0213981")
    (project / "m" / "soleus_r.yaml").write_text(text)
    rc, err = _run_in(project, capsys, "--muscles", "m", "--pose", "walk.yaml", "--frames", "0:1", "--out", "out")
    _no_trace(rc, err)
    assert err.startswith("m/soleus_r.yaml:10:") and "which its path does not span" in err, err
    assert not (project / "out").exists()
