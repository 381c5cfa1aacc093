"""Hostile round 5: skin files checked as strictly as muscle files. Each case is
refused with exit 2 and ``FILE:LINE:COL: what; allowed`` (no traceback, nothing written) or,
where it is no error, holds: a run that would replace its own input, ``axdf skin`` on a
zero-length segment, a rest mesh that is no body, malformed or oversized NPZ arrays, a jiggle
filter that grew with the pose's fps, duplicate bone names, ``--no-jiggle`` and a skin worn on a
skeleton of other proportions. Seeded where random."""
from __future__ import annotations

import io
import json
import shutil
import tracemalloc
import zipfile
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.formats import PlyWriter, load_triangles_and_bytes
from conftest import REPO_ROOT, all_files, run_main

SKIN = REPO_ROOT / "skins" / "gait2392"
SKELETON = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"
POSE = REPO_ROOT / "poses" / "gait2392_walk.yaml"
MUSCLE = REPO_ROOT / "muscles" / "gait2392_packed" / "vas_lat_l.yaml"
REST = REPO_ROOT / "poses" / "gait2392_rest.yaml"  # (its skin_0000.ply is the rest skin, worn)


def _copy(tmp_path: Path, name: str = "s") -> Path:
    shutil.copytree(SKIN, tmp_path / name)
    return tmp_path / name / "skin.yaml"


def _line(path: Path, key: str) -> int:
    return 1 + next(i for i, t in enumerate(path.read_text().splitlines()) if t.startswith(f"{key}:"))


def _refused(capsys, argv, *words) -> str:
    rc, _, err = run_main(argv, capsys)
    assert rc == 2 and "Traceback" not in err, (rc, err[-2000:])
    for w in words:
        assert w in err, (w, err)
    return err


def _npz(path: Path, **arrays) -> None:
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    path.write_bytes(buf.getvalue())


def _skeleton_copy(tmp_path: Path, text: str) -> Path:
    """gait2392 edited, its bone meshes still found (absolute paths)."""
    p = tmp_path / "skel.yaml"
    p.write_text(text.replace("mesh: meshes/", f"mesh: {SKELETON.parent / 'meshes'}/"))
    return p


def _pose_on(tmp_path: Path, skeleton: Path, fps: float | None = None) -> Path:
    text = POSE.read_text().replace("skeleton: skeletons/gait2392.yaml", f"skeleton: {skeleton}")
    if fps is not None:
        text = "\n".join(f"fps: {fps:g}" if t.startswith("fps:") else t for t in text.splitlines()) + "\n"
    p = tmp_path / "pose.yaml"
    p.write_text(text)
    return p


def _run(out: Path, skin: Path, *extra, pose: Path = POSE, frames: str = "0:1") -> list:
    return ["run", "--pose", pose, "--muscles", MUSCLE, "--skin", skin, "--frames", frames, "--out", out,
            "--quiet", "--allow-outside", *extra]


# ----------------------------------------------------------------------------- 1. input inside output


def test_a_run_refuses_to_replace_its_own_inputs(tmp_path, capsys):
    """A skin (and its mesh, the run's own skin_0000.ply) or a muscle inside OUT where the run
    writes is refused before anything is written: OUT stays byte for byte."""
    out = tmp_path / "out"
    rc, _, err = run_main(_run(out, SKIN / "skin.yaml", pose=REST, frames="0"), capsys)
    assert rc == 0, err
    here = out / "meshes" / "skin"
    for name in ("skin.yaml", "skin_weights.npz", "skin_fat.npz"):
        shutil.copy(SKIN / name, here / name)
    (here / "skin.yaml").write_text((SKIN / "skin.yaml").read_text().replace("mesh: skin_rest.ply",
                                                                             "mesh: skin_0000.ply"))
    before = all_files(out)
    _refused(capsys, _run(out, here / "skin.yaml", "--overwrite", pose=REST, frames="0"), "skin.yaml: this input lies in the output folder")
    assert all_files(out) == before
    # the skin outside, its mesh inside: the mesh is named
    outside = _copy(tmp_path)
    outside.write_text(outside.read_text().replace("mesh: skin_rest.ply", f"mesh: {here / 'skin_0000.ply'}"))
    _refused(capsys, _run(out, outside, "--overwrite", pose=REST, frames="0"), "skin_0000.ply: this input lies in the output folder",
             "meshes/skin/skin_0000.ply")
    # a muscle the earlier run lists (--resume writes there too)
    shutil.copy(MUSCLE, out / "bones" / "vas.yaml")
    argv = [str(a) for a in _run(out, SKIN / "skin.yaml", "--resume", pose=REST, frames="0")]
    argv[argv.index(str(MUSCLE))] = str(out / "bones" / "vas.yaml")
    _refused(capsys, argv, "vas.yaml: this input lies in the output folder")
    assert {k: v for k, v in all_files(out).items() if k != "bones/vas.yaml"} == before


# ----------------------------------------------------------------------------- 2. zero-length segment


def test_axdf_skin_refuses_a_zero_length_segment_and_writes_no_nan(tmp_path, capsys):
    text = SKELETON.read_text()
    k = text.index("name: talus_r")
    zero = text[:k] + text[k:].replace("offset: [0.0, -0.43, 0.0]", "offset: [0, 0, 0]", 1)
    skel = _skeleton_copy(tmp_path, zero)
    line = 1 + next(i for i, t in enumerate(zero.splitlines()) if "offset: [0, 0, 0]" in t and i > zero[:k].count("\n"))
    out = tmp_path / "o"
    _refused(capsys, ["skin", "--skeleton", skel, "--out", out, "--allow-outside"],
             f"{skel}:{line}:13: skeleton 'gait2392''s segment shank_r", "talus_r")
    assert not out.exists()
    # a sound skeleton: a report of finite numbers only (strict JSON), and the segments recorded
    rc, _, err = run_main(["skin", "--skeleton", SKELETON, "--out", tmp_path / "good", "-q"], capsys)
    assert rc == 0, err

    def no_constant(c):
        raise AssertionError(f"{c} in skin_report.json")

    json.loads((tmp_path / "good" / "skin_report.json").read_text(), parse_constant=no_constant)
    from axdf_cli.specs.skin import load_skin

    skin = load_skin(tmp_path / "good" / "skin.yaml")
    assert skin.segments["shank_r"] == ("tibia_r", "talus_r", 0.43) and len(skin.segments) == 7


# ----------------------------------------------------------------------------- 3. the rest mesh


def _mesh_cases(v: np.ndarray, f: np.ndarray) -> dict:
    rng = np.random.default_rng(49)
    nan = v.copy()
    nan[int(rng.integers(len(v)))] = np.nan
    far = v.copy()
    far[int(rng.integers(len(v)))] = 1e30
    twice = np.concatenate([f, f[:1]])  # one triangle twice: an edge of three triangles
    return {
        "nan": (nan, f, "non-finite vertices"),
        "one triangle": (v[:3], np.array([[0, 1, 2]]), "has 1 triangle, no closed surface"),
        "open": (v, f[1:], "is open: 3 edges border one triangle only"),
        "point": (np.zeros_like(v), f, "is 0 m across"),
        "far": (far, f, "1e+30 m across"),
        "inside out": (v, f[:, ::-1], "is inside out"),
        "flat": (v * [1.0, 1.0, 0.0], f, "a flat or folded surface"),
        "twice": (v, twice, "not manifold or not wound consistently"),
        "loose vertex": (np.concatenate([v, v[:1]]), f, "1 vertices on no triangle"),
    }


def test_the_rest_mesh_must_be_a_body(tmp_path, capsys):
    """validate (and run) refuse a rest mesh that is no body, at the skin file's mesh: key."""
    (v, _, f), _ = load_triangles_and_bytes(SKIN / "skin_rest.ply")
    path = _copy(tmp_path)
    line = _line(path, "mesh")
    for name, (vv, ff, words) in _mesh_cases(np.asarray(v, np.float32), np.asarray(f)).items():
        (path.parent / "skin_rest.ply").write_bytes(PlyWriter(ff).encode(np.asarray(vv, np.float32)))
        _refused(capsys, ["validate", path], f"{path}:{line}:7: skin_rest.ply", words)
    out = tmp_path / "out"
    _refused(capsys, _run(out, path), f"{path}:{line}:7:")  # (the last case, through run)
    assert not out.exists()


# ----------------------------------------------------------------------------- 4, 5, 7. the NPZs


def _weights() -> dict:
    return dict(np.load(SKIN / "skin_weights.npz"))


def _fat() -> dict:
    return dict(np.load(SKIN / "skin_fat.npz"))


def test_malformed_npz_arrays_are_refused(tmp_path, capsys):
    path = _copy(tmp_path)
    wl, fl = _line(path, "weights"), _line(path, "fat")
    w, fat = _weights(), _fat()
    n = int(w["vertex_count"])
    cases = [
        ("weights", {**w, "vertex_count": np.array([n, n])}, "array vertex_count is <i8 of shape (2,)"),
        ("weights", {**w, "vertex_count": np.array(str(n))}, "array vertex_count is <U5"),
        ("weights", {**w, "bones": np.array("pelvis")}, "array bones is <U6 of shape ()"),
        ("weights", {**w, "weight": w["weight"].astype(str)}, "array weight is <U"),
        ("weights", {**w, "bone": w["bone"][:-1]}, "entries; as many of each"),
        ("weights", {**w, "bones": np.array(["p" * 300] + list(w["bones"][1:]))}, "names of up to 300 characters"),
        ("weights", {**w, "bones": np.array([str(b) if b != "femur_r" else "pelvis" for b in w["bones"]])},
         "names bone pelvis more than once"),
        ("fat", {**fat, "regions": np.array("head")}, "array regions is <U4 of shape ()"),
        ("fat", {**fat, "fat": fat["fat"].astype(str)}, "array fat is <U"),
        ("fat", {**fat, "fat": np.stack([fat["fat"], fat["fat"]], axis=1)}, "array fat is <f4 of shape (13380, 2)"),
        ("fat", {**fat, "region": fat["region"][:-1]}, "has the region of 13379 vertices"),
    ]
    for key, arrays, words in cases:
        target = path.parent / ("skin_weights.npz" if key == "weights" else "skin_fat.npz")
        _npz(target, **arrays)
        _refused(capsys, ["validate", path], f"{path}:{wl if key == 'weights' else fl}:", target.name, words)
        shutil.copy(SKIN / target.name, target)
    data = (SKIN / "skin_weights.npz").read_bytes()
    for cut in (len(data) // 2, len(data) - 10):  # truncated
        (path.parent / "skin_weights.npz").write_bytes(data[:cut])
        _refused(capsys, ["validate", path], f"{path}:{wl}:", "skin_weights.npz is not a readable NPZ")
    (path.parent / "skin_weights.npz").write_bytes(np.random.default_rng(5).bytes(4096))
    _refused(capsys, ["validate", path], "skin_weights.npz is not a readable NPZ")
    shutil.copy(SKIN / "skin_weights.npz", path.parent / "skin_weights.npz")
    out = tmp_path / "out"
    _npz(path.parent / "skin_fat.npz", **{**fat, "fat": np.stack([fat["fat"], fat["fat"]], axis=1)})
    _refused(capsys, _run(out, path), f"{path}:{fl}:", "shape (13380, 2)")
    assert not out.exists()


def _huge_member(zf: zipfile.ZipFile, name: str, dtype: str, count: int) -> None:
    """An honest, compressed npy member of ``count`` zeros (streamed: never in memory whole)."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": dtype, "fortran_order": False, "shape": (count,)})
    with zf.open(name + ".npy", "w", force_zip64=True) as fp:
        fp.write(header.getvalue())  # (the magic and the header)
        chunk = bytes(1 << 22)
        left = count * np.dtype(dtype).itemsize
        while left:
            fp.write(chunk[:min(left, len(chunk))])
            left -= min(left, len(chunk))


def test_npz_claims_are_checked_before_memory_follows_them(tmp_path, capsys):
    """A small NPZ claiming 30 million weights (360 MB unpacked), or 2 million bones (dense
    weights of 200 GB), is refused from its headers: the refusal takes a few MB."""
    path = _copy(tmp_path)
    w = _weights()
    target = path.parent / "skin_weights.npz"
    with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zf:
        for k in ("vertex_count", "bones"):
            buf = io.BytesIO()
            np.save(buf, w[k])
            zf.writestr(k + ".npy", buf.getvalue())
        for k, dt in (("vertex", "<i4"), ("bone", "<i2"), ("weight", "<f4")):
            _huge_member(zf, k, dt, 30_000_000)
    assert target.stat().st_size < 2_000_000
    tracemalloc.start()
    try:
        _refused(capsys, ["validate", path], "claims 30000000 weights", "(133800)")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, peak
    many = np.char.add("b", np.arange(2_000_000).astype("U7"))
    _npz(target, **{**w, "bones": many})
    tracemalloc.start()
    try:
        _refused(capsys, ["validate", path], "names 2000000 bones", "at most 1024")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, peak
    # worn on a skeleton: at most its bones
    _npz(target, **{**w, "bones": np.array(list(w["bones"]) + [f"x{i}" for i in range(30)])})
    _refused(capsys, _run(tmp_path / "out", path), "names 40 bones", "at most 13")


# ----------------------------------------------------------------------------- 6, 8. jiggle


def test_the_skin_jiggle_filter_is_bounded_and_close_to_the_full_one(monkeypatch):
    """At any fps the filter has at most SKIN_JIGGLE_TAPS + 1 taps; sampled coarser than the
    frames it gives the full filter's lag to within 1% (the tolerance's claim), at the
    lightest damping and the highest frequency allowed among the cases."""
    from axdf_cli import tolerances as tol
    from axdf_cli.pipeline import skin_stage as ss
    from axdf_cli.specs.skin import SkinJiggle

    def lag(spring, fps):
        c, step = ss.jiggle_coefficients(spring, fps), ss.jiggle_span(spring, fps)[1]
        frames = np.arange(0, int(fps), max(1, int(fps / 200)))
        s = lambda t: np.clip(t / 0.2, 0.0, 1.0)  # noqa: E731
        x = lambda t: 0.05 * s(t) ** 2 * (3 - 2 * s(t))  # noqa: E731
        return np.array([c @ x((f - np.arange(len(c)) * step) / fps) for f in frames]), len(c)

    for spring, fps in ((SkinJiggle(100.0, 0.05, 1.0), 100000.0), (SkinJiggle(2.0, 0.05, 1.0), 3000.0),
                        (SkinJiggle(0.01, 0.3, 1.0), 100000.0)):
        cap, n = lag(spring, fps)
        assert n <= tol.SKIN_JIGGLE_TAPS + 1
        monkeypatch.setattr(tol, "SKIN_JIGGLE_TAPS", 10 ** 9)
        full, n_full = lag(spring, fps)
        monkeypatch.undo()
        assert n_full > 10 * n
        assert np.abs(cap - full).max() < 0.01 * np.abs(full).max()
    # a pose of few frames per second: every frame, as before
    assert ss.jiggle_span(SkinJiggle(5.0, 0.3, 1.0), 120.0)[1] == 1.0


def test_a_fast_pose_jiggles_in_bounded_memory_and_no_jiggle_stills_it(tmp_path, capsys):
    """100,000 fps and a 0.01 Hz skin jiggle: two frames took 29 s and 1.4 GB (the filter had
    200,000 taps); now the run's peak is a few hundred MB at most. --no-jiggle stills the skin (its
    meshes those of the skin without a jiggle, both runs with the muscles' jiggle off) and the
    manifest says so."""
    path = _copy(tmp_path)
    plain = path.read_text()
    path.write_text(plain + "jiggle: {frequency: 0.01, damping_ratio: 0.3}\n")
    pose = _pose_on(tmp_path, SKELETON, fps=100000)
    tracemalloc.start()
    try:
        rc, _, err = run_main(_run(tmp_path / "fast", path, pose=pose, frames="10:11"), capsys)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert rc == 0, err
    assert peak < 400e6, peak
    path.write_text(plain + "jiggle: {frequency: 5, damping_ratio: 0.3}\n")
    for name, skin, extra in (("on", path, ()), ("off", path, ("--no-jiggle",)), ("none", SKIN / "skin.yaml", ("--no-jiggle",))):
        rc, _, err = run_main(_run(tmp_path / name, skin, *extra, frames="30:31"), capsys)
        assert rc == 0, err
    on, off, none = (all_files(tmp_path / n) for n in ("on", "off", "none"))
    rel = "meshes/skin/skin_0031.ply"
    assert off[rel] == none[rel] and on[rel] != off[rel]
    stage = [s for s in json.loads(off["manifest.json"])["settings"]["stages"] if s["name"] == "skin"][0]
    assert stage["jiggle"] is False
    stage = [s for s in json.loads(on["manifest.json"])["settings"]["stages"] if s["name"] == "skin"][0]
    assert stage["jiggle"]["frequency"] == 5.0
    # resuming the jiggling run with --no-jiggle would mix two runs
    _refused(capsys, _run(tmp_path / "on", path, "--resume", "--no-jiggle", frames="30:31"), "--resume would mix")


# ----------------------------------------------------------------------------- 9. other proportions


def test_a_skin_on_a_skeleton_of_other_proportions_is_refused(tmp_path, capsys):
    """gait2392 with 1.6 times longer shanks: a skin without segments: (an older skin file)
    puts the feet's joints outside it; a skin that records its segments (the shipped one, a
    fresh fit) names the shanks and their lengths. Both say how to refit it. Within the
    tolerance (2% longer) it is worn."""
    long_ = _skeleton_copy(tmp_path, SKELETON.read_text().replace("offset: [0.0, -0.43, 0.0]",
                                                                  "offset: [0.0, -0.688, 0.0]"))
    pose = _pose_on(tmp_path, long_)
    out = tmp_path / "out"
    old = tmp_path / "old_skin"
    shutil.copytree(SKIN, old)
    text = (old / "skin.yaml").read_text()
    start = text.index("segments:\n")
    end = text.index("\n", text.index("\n", start) + 1)
    while text[end + 1:end + 3] == "  ":  # the indented entries under segments:
        end = text.index("\n", end + 1)
    (old / "skin.yaml").write_text(text[:start] + text[end + 1:])
    assert "segments:" not in (old / "skin.yaml").read_text()
    skin_line = _line(old / "skin.yaml", "skeleton")
    _refused(capsys, _run(out, old / "skin.yaml", pose=pose), f"skin.yaml:{skin_line}:11:",
             "lie outside its rest mesh (calcn_r", f"axdf skin --skeleton {long_}")
    _refused(capsys, _run(out, SKIN / "skin.yaml", pose=pose), "shank_l (tibia_l to talus_l) 0.430 m, here 0.688 m",
             f"axdf skin --skeleton {long_}")
    rc, _, err = run_main(["skin", "--skeleton", SKELETON, "--out", tmp_path / "fresh", "-q"], capsys)
    assert rc == 0, err
    fresh = tmp_path / "fresh" / "skin.yaml"
    _refused(capsys, _run(out, fresh, pose=pose), "shank_l (tibia_l to talus_l) 0.430 m, here 0.688 m (+60%)",
             "within 5% of the fit's", f"axdf skin --skeleton {long_}")
    assert not out.exists()
    near = _skeleton_copy(tmp_path, SKELETON.read_text().replace("offset: [0.0, -0.43, 0.0]",
                                                                 "offset: [0.0, -0.4386, 0.0]"))
    rc, _, err = run_main(_run(out, fresh, pose=_pose_on(tmp_path, near)), capsys)
    assert rc == 0, err


def test_segments_naming_other_bones_or_no_number_are_refused(tmp_path, capsys):
    rc, _, err = run_main(["skin", "--skeleton", SKELETON, "--out", tmp_path / "fresh", "-q"], capsys)
    assert rc == 0, err
    path = tmp_path / "fresh" / "skin.yaml"
    good = path.read_text()
    line = 1 + next(i for i, t in enumerate(good.splitlines()) if t.startswith("  shank_r:"))
    path.write_text(good.replace("{from: tibia_r, to: talus_r, length: 0.43}", "{from: tibia_r, to: talus_x, "
                                                                                "length: 0.43}"))
    _refused(capsys, _run(tmp_path / "o", path), f"{path}:{line}:12: segment shank_r runs from tibia_r to talus_x")
    path.write_text(good.replace("{from: tibia_r, to: talus_r, length: 0.43}", "{from: tibia_r, to: talus_r, "
                                                                                "length: .nan}"))
    _refused(capsys, ["validate", path], f"{path}:{line}:", "'.nan' is not finite")
    path.write_text(good.replace("{from: tibia_r, to: talus_r, length: 0.43}", "{from: tibia_r, to: talus_r}"))
    _refused(capsys, ["validate", path], f"{path}:{line}:", "has no 'length'")
