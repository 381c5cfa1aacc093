"""One mesh file per frame with every muscle (``--mesh-files frame``, a job's ``mesh_files:``)
and a data set's PNG masks and depth (``render: {passes: [..., mask, depth]}``): round trips
through axdf's readers, trimesh and Pillow; the default layout is unchanged."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest
from conftest import REPO_ROOT, all_files, run_main

GOLDEN_JOB = REPO_ROOT / "tests" / "golden_job.yaml"
NAMES = ["biceps_brachii", "brachioradialis"]
FRAMES = [104, 120, 168]


def _parts(rng: np.random.Generator, n: int):
    """``n`` small closed meshes (icospheres of several sizes) with random positions and unit
    normals: [(name, faces, vertex count)], [positions], [normals]."""
    import trimesh

    parts, pos, nrm = [], [], []
    for k in range(n):
        m = trimesh.creation.icosphere(subdivisions=1 + k % 2, radius=0.1 + 0.05 * k)
        v = np.asarray(m.vertices, np.float32) + rng.normal(size=3).astype(np.float32)
        nn = rng.normal(size=v.shape).astype(np.float32)
        nrm.append(nn / np.linalg.norm(nn, axis=1, keepdims=True))
        parts.append((f"m{k}.part_{k}", np.asarray(m.faces, np.int32), len(v)))
        pos.append(v)
    return parts, pos, nrm


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_frame_writer_round_trips_each_muscle_through_axdf_and_trimesh(fmt, tmp_path):
    import trimesh

    from axdf_cli.formats import FORMATS, read_mesh

    rng = np.random.default_rng(37)
    parts, pos, nrm = _parts(rng, 3)
    f = FORMATS[fmt]
    data = f.frame_writer(parts).encode(pos, nrm)
    mesh = read_mesh(data, f.suffix)
    assert [g[0] for g in mesh.groups] == [p[0] for p in parts]
    slices = mesh.group_slices()
    tri = mesh.triangles()
    for (name, faces, n), p, nn in zip(parts, pos, nrm):
        sl = slices[name]
        assert sl.stop - sl.start == n
        # each part is exactly the per-muscle writer's file, indices shifted
        alone = read_mesh(f.writer(faces, name).encode(p, nn), f.suffix)
        np.testing.assert_array_equal(mesh.vertices[sl], alone.vertices)
        np.testing.assert_array_equal(mesh.normals[sl], alone.normals)
        mine = tri[(tri[:, 0] >= sl.start) & (tri[:, 0] < sl.stop)] - sl.start
        np.testing.assert_array_equal(mine, faces)
    path = tmp_path / f"frame{f.suffix}"
    path.write_bytes(data)
    if fmt == "obj":  # trimesh (and Blender's importer) make one object per 'o' line
        scene = trimesh.load_scene(path, split_objects=True, group_material=False, process=False)
        got = {k: (len(g.vertices), len(g.faces)) for k, g in scene.geometry.items()}
        assert got == {name: (n, len(faces)) for name, faces, n in parts}
    else:  # one mesh; the ushort 'muscle' vertex property tells the muscles apart
        m = trimesh.load(path, process=False)
        assert len(m.vertices) == sum(n for _, _, n in parts)
        assert len(m.faces) == sum(len(fc) for _, fc, _ in parts)
        index = m.metadata["_ply_raw"]["vertex"]["data"]["muscle"]
        np.testing.assert_array_equal(index, np.repeat(np.arange(len(parts)), [n for _, _, n in parts]))
        head = data[:data.index(b"end_header")].decode()
        assert [f"comment axdf muscle {k} {name}" in head for k, (name, _, _) in enumerate(parts)] == [True] * 3


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The golden job without rendering, in ply and obj: one file per muscle per frame (the
    default), and one file per frame (the flag; and with --jobs 2)."""
    from axdf_cli.cli.main import main

    d = tmp_path_factory.mktemp("per_frame")
    common = ["run", str(GOLDEN_JOB), "--no-render", "--format", "ply,obj", "-q"]
    assert main(common + ["--out", str(d / "default")]) == 0
    assert main(common + ["--out", str(d / "frame"), "--mesh-files", "frame"]) == 0
    assert main(common + ["--out", str(d / "jobs2"), "--mesh-files", "frame", "--jobs", "2"]) == 0
    return d


def test_default_layout_is_one_file_per_muscle_per_frame(runs):
    files = all_files(runs / "default")
    meshes = sorted(r for r in files if r.startswith("meshes/"))
    assert meshes == sorted(f"meshes/{m}/{m}_{f:04d}.{e}" for m in NAMES for f in FRAMES for e in ("ply", "obj"))
    manifest = json.loads(files["manifest.json"])
    assert "mesh_files" not in manifest["settings"]  # the default is left unsaid (golden manifests unchanged)


def test_per_frame_files_hold_every_muscle_as_written_alone(runs):
    from axdf_cli.formats import read_mesh

    files = all_files(runs / "frame")
    meshes = sorted(r for r in files if r.startswith("meshes/"))
    assert meshes == sorted(f"meshes/{f:04d}.{e}" for f in FRAMES for e in ("ply", "obj"))
    manifest = json.loads(files["manifest.json"])
    assert manifest["settings"]["mesh_files"] == "frame"
    for rel in meshes:  # the manifest lists each with its sha256
        import hashlib
        assert manifest["files"][rel] == hashlib.sha256(files[rel]).hexdigest()
    counts = {m["name"]: (m["vertices"], m["faces"]) for m in manifest["muscles"]}
    default = all_files(runs / "default")
    for f in FRAMES:
        for ext in ("ply", "obj"):
            whole = read_mesh(files[f"meshes/{f:04d}.{ext}"], "." + ext)
            assert [g[0] for g in whole.groups] == NAMES
            tri = whole.triangles()
            for name, sl in whole.group_slices().items():
                alone = read_mesh(default[f"meshes/{name}/{name}_{f:04d}.{ext}"], "." + ext)
                assert sl.stop - sl.start == counts[name][0]
                np.testing.assert_array_equal(whole.vertices[sl], alone.vertices)
                np.testing.assert_array_equal(whole.normals[sl], alone.normals)
                mine = tri[(tri[:, 0] >= sl.start) & (tri[:, 0] < sl.stop)] - sl.start
                assert len(mine) == counts[name][1]
                np.testing.assert_array_equal(mine, alone.triangles())
    # the other files are the default run's, byte for byte
    for rel in ("stats.csv", "bones.csv"):
        assert files[rel] == default[rel]


def test_per_frame_files_are_the_same_bytes_with_two_jobs(runs):
    one, two = all_files(runs / "frame"), all_files(runs / "jobs2")
    assert one == two


def test_compare_reads_per_frame_files_and_names_the_muscle(runs, tmp_path, capsys):
    import shutil

    rc, out, _ = run_main(["compare", runs / "frame", runs / "jobs2"], capsys)
    assert rc == 0, out
    moved = tmp_path / "moved"
    shutil.copytree(runs / "frame", moved)
    path = moved / "meshes" / f"{FRAMES[1]:04d}.obj"
    lines = path.read_text().split("\n")
    at = lines.index("o brachioradialis") + 1 + 4  # its 5th vertex
    v = lines[at].split()
    lines[at] = " ".join([v[0], f"{float(v[1]) + 0.002:.6f}", v[2], v[3]])
    path.write_text("\n".join(lines))
    rc, out, _ = run_main(["compare", moved, runs / "frame"], capsys)
    assert rc == 1
    assert "vertex 4 of brachioradialis" in out, out


def test_render_reads_a_per_frame_run_as_the_default_one(runs, tmp_path, capsys):
    for name in ("default", "frame"):
        rc, _, err = run_main(["render", runs / name, "--out", tmp_path / name, "--size", "48x40", "-q"], capsys)
        assert rc == 0, err
    a, b = all_files(tmp_path / "default" / "frames"), all_files(tmp_path / "frame" / "frames")
    assert a and a == b


def test_mesh_files_job_key_and_its_refusals(tmp_path, capsys):
    job = GOLDEN_JOB.read_text().replace("format: ply", "format: obj\nmesh_files: frame")
    job = job.replace("../muscles/", str(REPO_ROOT / "muscles") + "/").replace("../poses/", str(REPO_ROOT / "poses")
                                                                               + "/")
    (tmp_path / "job.yaml").write_text(job)
    rc, out, err = run_main(["run", tmp_path / "job.yaml", "--out", tmp_path / "o", "--dry-run",
                             "--allow-outside"], capsys)
    assert rc == 0 and "3 mesh files per format, each with every muscle" in out, out + err
    bad = job.replace("mesh_files: frame", "mesh_files: frames")
    (tmp_path / "bad.yaml").write_text(bad)
    rc, _, err = run_main(["run", tmp_path / "bad.yaml", "--out", tmp_path / "o", "--allow-outside"], capsys)
    line = bad.split("\n").index("mesh_files: frames") + 1
    assert rc == 2 and f"bad.yaml:{line}:13: mesh_files is 'frames'" in err and "Traceback" not in err, err
    rc, _, err = run_main(["run", tmp_path / "job.yaml", "--out", tmp_path / "o", "--format", "npz",
                           "--allow-outside"], capsys)
    assert rc == 2 and "mesh_files" in err and "add ply or obj" in err, err
    assert not (tmp_path / "o").exists()


# ----------------------------------------------------------------------------- data sets
def test_label_png_takes_8_or_16_bits_as_the_labels_need():
    from PIL import Image

    from axdf_cli.render.png import encode_label_png, label_png_bits

    assert [label_png_bits(n) for n in (2, 256, 257, 65536)] == [8, 8, 16, 16]
    rng = np.random.default_rng(3)
    for labels in (7, 300):
        ids = rng.integers(0, labels, size=(9, 11)).astype(np.uint32)
        img = Image.open(io.BytesIO(encode_label_png(ids, label_png_bits(labels))))
        assert img.mode == ("L" if labels <= 256 else "I;16")
        np.testing.assert_array_equal(np.asarray(img), ids)


@pytest.fixture(scope="module")
def png_sets(tmp_path_factory):
    """The tiny data set with PNG masks and depth beside the EXR, built twice, and with them
    instead of the EXR."""
    from dataset_helpers import DATASET_YAML, build_in, write_tiny

    d = tmp_path_factory.mktemp("png_sets")
    base = "render: {size: [40, 48], supersample: 1}"
    assert base in DATASET_YAML
    write_tiny(d, DATASET_YAML.replace(base, base[:-1] + ", passes: [png, exr, mask, depth]}"))
    build_in(d, "both")
    build_in(d, "again")
    write_tiny(d, DATASET_YAML.replace(base, base[:-1] + ", passes: [png, mask, depth]}"))
    build_in(d, "png_only")
    return d


def _exr(data: bytes):
    import OpenEXR

    import tempfile
    with tempfile.NamedTemporaryFile(suffix=".exr") as t:
        t.write(data)
        t.flush()
        with OpenEXR.File(t.name) as f:
            ch = f.channels()
            return np.array(ch["id"].pixels), np.array(ch["Z"].pixels)


def test_dataset_png_masks_equal_the_exr_ids_and_depth_is_millimetres(png_sets):
    import pandas as pd
    from PIL import Image

    files = all_files(png_sets / "both")
    index = pd.read_parquet(png_sets / "both" / "index.parquet")
    assert len(index) > 0
    seen = set()
    for row in index.itertuples():
        ids, z = _exr(files[row.exr])
        mask = Image.open(io.BytesIO(files[row.mask]))
        depth = Image.open(io.BytesIO(files[row.depth]))
        assert mask.mode == "L" and depth.mode == "I;16"  # 1 muscle + 5 bones: 8 bits
        m, dp = np.asarray(mask), np.asarray(depth).astype(np.float64)
        np.testing.assert_array_equal(m, ids)
        assert np.all((dp == 0) == (z == 0))
        assert np.abs(dp / 1000.0 - z)[z > 0].max() <= 0.0005 + 1e-6
        seen |= set(np.unique(m).tolist())
        rec = json.loads(files[f"{row.sequence}/sequence.json"])
        assert row.mask.split("/", 1)[1] in rec["files"] and row.depth.split("/", 1)[1] in rec["files"]
    assert 1 in seen and 0 in seen  # the muscle and the background are in view
    d = json.loads(files["dataset.json"])
    assert d["image"]["passes"] == ["png", "exr", "mask", "depth"]
    assert "millimetres" in d["depth"] and "8-bit" in d["mask"]


def test_dataset_png_passes_give_the_same_bytes_and_can_replace_the_exr(png_sets):
    import pandas as pd

    assert all_files(png_sets / "both") == all_files(png_sets / "again")
    files = all_files(png_sets / "png_only")
    assert not any(r.endswith(".exr") for r in files)
    both = all_files(png_sets / "both")
    pngs = [r for r in files if r.endswith((".mask.png", ".depth.png"))]
    assert pngs and all(files[r] == both[r] for r in pngs)
    index = pd.read_parquet(png_sets / "png_only" / "index.parquet")
    assert index["exr"].isna().all() and index["mask"].notna().all() and index["depth"].notna().all()


def test_dataset_default_passes_write_no_png_mask_or_depth(tmp_path):
    import pandas as pd
    from dataset_helpers import build_in, write_tiny

    write_tiny(tmp_path)
    build_in(tmp_path, "plain")
    files = all_files(tmp_path / "plain")
    assert not any(r.endswith((".mask.png", ".depth.png")) for r in files)
    index = pd.read_parquet(tmp_path / "plain" / "index.parquet")
    assert index["mask"].isna().all() and index["depth"].isna().all() and index["exr"].notna().all()
