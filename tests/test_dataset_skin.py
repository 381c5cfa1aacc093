"""Data sets that wear the skin (``skin:``): the shipped poses/datasets/gait2392_skin.yaml
(gait2392's packed muscles under skins/gait2392, the walk at 4 frames, 2 views) built in process.
Its images show the body; in each EXR, the muscle-under-skin pass names, for >= 95% of the skin
pixels, the muscle whose surface is nearest beneath them, checked independently: each pixel's
depth unprojected through the camera labels.npz gives, and the nearest point of a dense sampling
of the muscle surfaces the sequence wrote. The body-part pass covers exactly the skin's pixels and
agrees with the skinning weights of the nearest skin vertex; labels.npz, dataset.json and the
Parquet index name the parts and the passes. A bad ``skin:`` key is refused with its position."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from dataset_helpers import write_tiny
from render_helpers import read_exr

from axdf_cli.formats import load_triangles_and_bytes
from conftest import REPO_ROOT, run_main

SPEC = REPO_ROOT / "poses" / "datasets" / "gait2392_skin.yaml"
CAP = 0.06  # tolerances.SKIN_UNDER_MAX_DEPTH: no muscle is named deeper than this


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    from axdf_cli.cli.main import main

    out = tmp_path_factory.mktemp("dsskin") / "out"
    assert main(["dataset", "build", str(SPEC), "--out", str(out), "--quiet"]) == 0
    return out


def _surface_samples(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Points on every triangle: its corners, edge midpoints and 6 interior points (a sampling
    ~2 mm apart on these meshes, far finer than a 128 x 256 pixel)."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    bary = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (.5, .5, 0), (0, .5, .5), (.5, 0, .5), (1 / 3, 1 / 3, 1 / 3),
            (.6, .2, .2), (.2, .6, .2), (.2, .2, .6), (.4, .4, .2), (.2, .4, .4)]
    return np.concatenate([x * a + y * b + z * c for x, y, z in bary])


def test_the_images_show_the_body_and_the_under_pass_names_the_nearest_muscle(built):
    from scipy.spatial import cKDTree

    meta = json.loads((built / "dataset.json").read_text())
    skin_id = next(int(k) for k, v in meta["ids"].items() if v["kind"] == "skin")
    muscle_ids = {int(k): v["name"] for k, v in meta["ids"].items() if v["kind"] == "muscle"}
    seq = built / "seq_00000"
    lab = np.load(seq / "labels.npz")
    agree = total = 0
    for fi, frame in enumerate(lab["frames"]):
        pts, owner = [], []
        for i, name in sorted(muscle_ids.items()):
            (v, _, f), _ = load_triangles_and_bytes(seq / f"meshes/{name}/{name}_{frame:04d}.ply")
            s = _surface_samples(v.astype(np.float64), np.asarray(f, np.int64))
            pts.append(s)
            owner.append(np.full(len(s), i))
        tree, owner = cKDTree(np.concatenate(pts)), np.concatenate(owner)
        for vi, view in enumerate(lab["view_names"]):
            ch = read_exr(seq / f"views/{view}/{frame:04d}.exr")
            skin = ch["id"] == skin_id
            assert skin.mean() > 0.05, f"frame {frame} {view}: the body covers {skin.mean():.1%} of the image"
            assert set(np.unique(ch["under.id"][skin])) <= set(muscle_ids) | {0}
            # independently: unproject each skin pixel's depth through labels.npz's camera
            K, w2c = lab["K"][vi], lab["world_to_camera"][fi, vi]
            r, c = np.nonzero(skin)
            z = ch["Z"][r, c].astype(np.float64)
            cam = np.stack([c + 0.5, r + 0.5, np.ones_like(z)], 1) @ np.linalg.inv(K).T * z[:, None]
            c2w = np.linalg.inv(w2c)
            world = cam @ c2w[:3, :3].T + c2w[:3, 3]
            d, j = tree.query(world)
            named = d < CAP - 0.003  # (a margin for the sampling next to the cap)
            mine = ch["under.id"][r, c]
            agree += int((mine[named] == owner[j[named]]).sum())
            total += int(named.sum())
            assert (mine[d > CAP + 0.003] == 0).all()  # nothing named beyond the cap
    assert total > 5000
    print(f"under.id agreement {agree / total:.4f} of {total}")
    assert agree / total >= 0.95, f"under.id names the nearest muscle for {agree / total:.2%} of {total} skin pixels"


def test_the_body_part_pass_covers_the_skin_and_follows_its_weights(built):
    from scipy.spatial import cKDTree

    from axdf_cli.specs.skin import load_skin

    meta = json.loads((built / "dataset.json").read_text())
    skin_id = next(int(k) for k, v in meta["ids"].items() if v["kind"] == "skin")
    parts = meta["skin"]["parts"]
    rest = load_skin(REPO_ROOT / "skins" / "gait2392" / "skin.yaml")
    assert parts == list(rest.bones)
    seq = built / "seq_00000"
    lab = np.load(seq / "labels.npz")
    assert list(lab["skin_part_names"]) == parts
    vertex_part = np.argmax(rest.weights, axis=1)
    agree = total = 0
    seen = set()
    for fi, frame in enumerate(lab["frames"]):
        (sv, _, _), _ = load_triangles_and_bytes(seq / f"meshes/skin/skin_{frame:04d}.ply")
        tree = cKDTree(sv.astype(np.float64))
        for vi, view in enumerate(lab["view_names"]):
            ch = read_exr(seq / f"views/{view}/{frame:04d}.exr")
            skin = ch["id"] == skin_id
            assert ((ch["part.id"] > 0) == skin).all()  # every skin pixel has a part, nothing else does
            assert ch["part.id"].max() <= len(parts)
            r, c = np.nonzero(skin)
            z = ch["Z"][r, c].astype(np.float64)
            K, w2c = lab["K"][vi], lab["world_to_camera"][fi, vi]
            cam = np.stack([c + 0.5, r + 0.5, np.ones_like(z)], 1) @ np.linalg.inv(K).T * z[:, None]
            c2w = np.linalg.inv(w2c)
            _, j = tree.query(cam @ c2w[:3, :3].T + c2w[:3, 3])
            got = ch["part.id"][r, c].astype(int) - 1
            agree += int((got == vertex_part[j]).sum())
            total += len(j)
            seen |= set(got.tolist())
    print(f"part.id agreement {agree / total:.4f} of {total}")
    assert agree / total >= 0.9, f"part.id agrees with the nearest vertex's weights for {agree / total:.1%}"
    assert {parts.index(p) for p in ("torso", "femur_r", "femur_l", "tibia_r", "tibia_l")} <= seen


def test_the_index_and_dataset_json_name_the_skin(built):
    import pyarrow.parquet as pq

    meta = json.loads((built / "dataset.json").read_text())
    assert meta["skin"]["drawn"] == "opaque" and set(meta["skin"]["passes"]) == {"under.id", "under.Z", "part.id"}
    assert any(k.endswith("skin.yaml") for k in meta["inputs"])
    index = pq.read_table(built / "index.parquet").to_pydict()
    assert all(p == "under.id,under.Z,part.id" for p in index["skin_passes"])
    for s, f in zip(index["skin"], index["frame"]):
        assert s == f"seq_00000/meshes/skin/skin_{f:04d}.ply" and (built / s).is_file()


def test_a_bad_skin_key_is_refused_with_its_position(tmp_path, capsys):
    spec = write_tiny(tmp_path)
    spec.write_text(spec.read_text() + "skin: missing.yaml\n")
    rc, _, err = run_main(["dataset", "build", spec, "--out", tmp_path / "out"], capsys)
    assert rc == 2 and "Traceback" not in err
    line = spec.read_text().splitlines().index("skin: missing.yaml") + 1
    assert f"tiny.yaml:{line}:7:" in err and "skin file 'missing.yaml' not found" in err
    assert not (tmp_path / "out").exists()


def test_every_view_shows_the_whole_body_hands_included(built, tmp_path, capsys):
    """Every skin vertex the sequence wrote (the hands hang beyond gait2392's last bones)
    projects inside every view's image, through the cameras labels.npz records: the sphere's
    drawn distance backs off where it is too near (``whole``, default true), and ``auto``
    centres the body with the skin on. With ``whole: false`` the same file's drawn 3.5 to 3.7 m
    cut the hands off a view."""
    from axdf_cli.dataset.labels import project

    def outside(root) -> float:
        seq = root / "seq_00000"
        lab = np.load(seq / "labels.npz")
        W, H = json.loads((root / "dataset.json").read_text())["render"]["size"]
        pts = np.stack([load_triangles_and_bytes(seq / f"meshes/skin/skin_{f:04d}.ply")[0][0]
                        for f in lab["frames"]]).astype(np.float64)
        uv, z = project(lab["K"], lab["world_to_camera"], pts)
        assert (z > 0).all()
        return float(((uv[..., 0] < 0) | (uv[..., 0] > W) | (uv[..., 1] < 0) | (uv[..., 1] > H)).mean())

    assert outside(built) == 0.0
    cropped = tmp_path / "cropped.yaml"
    text = SPEC.read_text().replace("per: sequence}", "per: sequence, whole: false}")
    assert "whole: false" in text
    cropped.write_text(re.sub(r"(?<=[ {])((?:\.\./)+)", lambda m: f"{SPEC.parent}/{m.group(1)}", text))
    rc, _, err = run_main(["dataset", "build", cropped, "--out", tmp_path / "out", "--quiet"], capsys)
    assert rc == 0, err
    assert outside(tmp_path / "out") > 0.001


def test_the_whole_body_data_set_labels_all_416_muscles(tmp_path, capsys):
    """poses/datasets/myobody_skin.yaml (myobody_atlas under skins/myobody), built here at its
    first frame from one view: dataset.json names all 416 muscles (and the 12 shape muscles of
    the shoulder girdle the atlas adds), the skin and its parts; the
    opaque body fills the image whole (every skin vertex inside it, hands included); the
    muscle-under-skin pass names only those muscles, and many of them (a body, not a few
    tubes)."""
    from axdf_cli.dataset.labels import project

    spec = REPO_ROOT / "poses" / "datasets" / "myobody_skin.yaml"
    text = spec.read_text().replace('frames: "0:248:62"', 'frames: "0:1"').replace("views: 2", "views: 1")
    assert 'frames: "0:1"' in text and "views: 1" in text
    one = tmp_path / "one.yaml"
    one.write_text(re.sub(r"(?<=[ {])((?:\.\./)+)", lambda m: f"{spec.parent}/{m.group(1)}", text))
    rc, _, err = run_main(["dataset", "build", one, "--out", tmp_path / "out", "--quiet"], capsys)
    assert rc == 0, err
    root = tmp_path / "out"
    meta = json.loads((root / "dataset.json").read_text())
    muscles = {int(k): v["name"] for k, v in meta["ids"].items() if v["kind"] == "muscle"}
    assert len(muscles) == 416 + 12 and {"DELT1_l", "LAT1", "addmagMid_l", "TRAP2_l"} <= set(muscles.values())
    skin_id = next(int(k) for k, v in meta["ids"].items() if v["kind"] == "skin")
    seq = root / "seq_00000"
    lab = np.load(seq / "labels.npz")
    ch = read_exr(seq / "views" / str(lab["view_names"][0]) / "0000.exr")
    skin = ch["id"] == skin_id
    assert skin.mean() > 0.05
    under = set(np.unique(ch["under.id"][skin]).tolist()) - {0}
    assert under <= set(muscles) and len(under) >= 60, len(under)
    W, H = meta["render"]["size"]
    pts = load_triangles_and_bytes(seq / "meshes/skin/skin_0000.ply")[0][0][None].astype(np.float64)
    uv, z = project(lab["K"], lab["world_to_camera"], pts)
    assert (z > 0).all() and ((uv[..., 0] >= 0) & (uv[..., 0] <= W) & (uv[..., 1] >= 0) & (uv[..., 1] <= H)).all()
