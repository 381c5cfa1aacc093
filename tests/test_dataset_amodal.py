"""The amodal pass: each muscle's full extent per view and frame, occluders
ignored, as COCO RLE annotations: it equals the muscle's silhouette rendered with nothing in
front of it, holds every pixel the id pass shows of it, and is larger where bones hide it."""
from __future__ import annotations

import json

import numpy as np
import pytest
from dataset_helpers import build_in, write_tiny
from render_helpers import read_exr

AMODAL_YAML = """\
dataset: rig
seed: 3
skeleton: chain.yaml
muscles: [chainm.yaml]
coordinates:
  stretch: {range: [0.0, 0.3]}
  bend: {range: [-50, 50]}
  roll: {range: [-80, 80]}
sequences:
  - {sample: uniform, count: 2, frames: 2}
activation: none
cameras:
  rig:
    - {name: front, position: [0, -1.2, -0.25], target: [0, 0, -0.25], fov: 40}
    - {name: below, position: [0, 0, -2.0], target: [0, 0, 0], up: [0, 1, 0], fov: 30}
render: {size: [64, 80], supersample: 1, passes: [png, exr, amodal], bones: BONES}
"""


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = {}
    for bones in ("true", "false"):
        d = tmp_path_factory.mktemp(f"amodal_{bones}")
        write_tiny(d, AMODAL_YAML.replace("BONES", bones))
        out[bones] = build_in(d, "out")
    return out


def test_rle_is_cocos_column_major_runs():
    from axdf_cli.dataset.amodal import rle_counts, rle_decode

    assert rle_counts(np.array([[0, 1], [1, 1]], bool)) == [1, 3]  # columns (0,1), (1,1)
    assert rle_counts(np.array([[1, 0], [1, 0]], bool)) == [0, 2, 2]  # starts set: a first run of 0 zeros
    rng = np.random.default_rng(5)
    for _ in range(20):
        m = rng.random((int(rng.integers(1, 9)), int(rng.integers(1, 9)))) < 0.4
        c = rle_counts(m)
        assert sum(c) == m.size and np.array_equal(rle_decode(c, m.shape), m)


def _masks(root, seq="seq_00000"):
    from axdf_cli.dataset.amodal import rle_decode

    coco = json.loads((root / seq / "amodal.json").read_text())
    images = {im["id"]: im for im in coco["images"]}
    out = {}
    for a in coco["annotations"]:
        im = images[a["image_id"]]
        out[(im["view"], im["frame"], a["category_id"])] = (rle_decode(a["segmentation"]["counts"],
                                                                       a["segmentation"]["size"]), a)
    return coco, out


def test_amodal_masks_are_the_whole_muscle_whatever_hides_it(built):
    coco, with_bones = _masks(built["true"])
    _, alone = _masks(built["false"])
    assert [c["name"] for c in coco["categories"]] == ["chainm"]
    assert len(coco["images"]) == 4 and {im["file_name"] for im in coco["images"]} == {
        f"views/{v}/{f:04d}.png" for v in ("front", "below") for f in (0, 1)}
    assert with_bones.keys() == alone.keys() and len(with_bones) == 4
    hidden = 0
    for (view, frame, cat), (mask, ann) in with_bones.items():
        # the same mask whether or not the balls are drawn: occluders are ignored
        assert np.array_equal(mask, alone[(view, frame, cat)][0])
        ids = read_exr(built["true"] / "seq_00000" / "views" / view / f"{frame:04d}.exr")["id"]
        shown = ids == cat
        assert not (shown & ~mask).any()  # every visible pixel of the muscle is in its mask
        assert ann["visible_area"] == int(shown.sum()) and ann["area"] == int(mask.sum())
        x, y, w, h = ann["bbox"]
        rows, cols = np.nonzero(mask)
        assert (x, y, x + w - 1, y + h - 1) == (cols.min(), rows.min(), cols.max(), rows.max())
        hidden += ann["visible_area"] < ann["area"]
        # without bones the id pass shows the muscle whole: its silhouette is the amodal mask
        ids_alone = read_exr(built["false"] / "seq_00000" / "views" / view / f"{frame:04d}.exr")["id"]
        assert np.array_equal(ids_alone == cat, mask)
    assert hidden >= 2  # looking up the chain the balls hide most of the muscle


def test_the_amodal_pass_is_listed_and_checked(built, tmp_path):
    ds = json.loads((built["true"] / "dataset.json").read_text())
    assert ds["image"]["passes"] == ["png", "exr", "amodal"] and "amodal.json" in ds["amodal"]
    rec = json.loads((built["true"] / "seq_00000" / "sequence.json").read_text())
    assert "amodal.json" in rec["files"]
    from axdf_cli.cli.main import main

    write_tiny(tmp_path, AMODAL_YAML.replace("BONES", "true").replace("amodal]", "modal]"))
    import os

    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        assert main(["dataset", "build", "tiny.yaml", "--out", "o"]) == 2
    finally:
        os.chdir(cwd)
    assert not (tmp_path / "o").exists()


def test_index_names_each_samples_amodal_file(built, tmp_path):
    """index.parquet's `amodal` column: the sequence's amodal.json with the pass (the file is
    there), null without it."""
    import pandas as pd

    root = built["true"]
    idx = pd.read_parquet(root / "index.parquet")
    assert list(idx["amodal"]) == [f"{s}/amodal.json" for s in idx["sequence"]]
    assert all((root / p).is_file() for p in set(idx["amodal"]))
    write_tiny(tmp_path, AMODAL_YAML.replace("BONES", "false").replace("passes: [png, exr, amodal]", "passes: [png]"))
    plain = pd.read_parquet(build_in(tmp_path, "plain") / "index.parquet")
    assert plain["amodal"].isna().all() and not plain["png"].isna().any()
