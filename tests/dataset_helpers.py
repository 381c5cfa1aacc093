"""A tiny data set on disk for the dataset tests: the conftest's chain skeleton with a ball
mesh (radius BALL_R) at every bone's origin, its muscle, a pose file and an OpenSim motion."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from conftest import CHAIN_MUSCLE_YAML, CHAIN_SKELETON_YAML

BALL_R = 0.04  # larger than the muscle's radius (0.025), so a joint's pixel shows its ball

DATASET_YAML = """\
dataset: tiny
seed: 11
skeleton: chain.yaml
muscles: [chainm.yaml]
coordinates:
  stretch: {range: [0.0, 0.4]}
  bend: {range: [-50, 50]}
  roll: {range: [-80, 80]}
motions:
  walk: {pose: walk.yaml, frames: "0:8:4"}
sequences:
  - {sample: uniform, count: 3, frames: 1}
  - {sample: uniform, count: 1, frames: 3, keys: 2}
  - {sample: perturb, around: walk, count: 1, spread: {default: 5, stretch: 0.05}}
  - {motion: walk}
activation: {sample: uniform, range: [0.2, 0.9]}
cameras:
  sphere: {views: 2, distance: [1.2, 1.5], elevation: [-10, 30], fov: 40}
render: {size: [40, 48], supersample: 1}
"""

WALK_YAML = """\
pose: walk
skeleton: chain.yaml
fps: 24
frames: [0, 8]
keys:
  0: {bend: 0, roll: 0, stretch: 0.1}
  8: {bend: 40, roll: 60, stretch: 0.3}
"""


def ball_ply() -> bytes:
    from axdf_cli.formats import PlyWriter

    m = trimesh.creation.icosphere(subdivisions=3, radius=BALL_R)
    return PlyWriter(m.faces).encode(np.asarray(m.vertices, np.float32), np.asarray(m.vertex_normals, np.float32))


def write_tiny(folder: Path, dataset_yaml: str = DATASET_YAML) -> Path:
    """The tiny data set's files in ``folder``; returns the dataset file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    skel = CHAIN_SKELETON_YAML
    for b in range(5):
        skel = skel.replace(f"  - name: b{b}\n", f"  - name: b{b}\n    mesh: ball.ply\n")
    (folder / "chain.yaml").write_text(skel)
    (folder / "ball.ply").write_bytes(ball_ply())
    (folder / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    (folder / "walk.yaml").write_text(WALK_YAML)
    (folder / "tiny.yaml").write_text(dataset_yaml)
    return folder / "tiny.yaml"


def build_in(folder: Path, out: str) -> Path:
    """``axdf dataset build tiny.yaml --out OUT`` in ``folder`` (in process, for module fixtures,
    which cannot use monkeypatch.chdir); returns folder / out."""
    import os

    from axdf_cli.cli.main import main

    cwd = os.getcwd()
    os.chdir(folder)
    try:
        assert main(["dataset", "build", "tiny.yaml", "--out", out, "-q"]) == 0
    finally:
        os.chdir(cwd)
    return Path(folder) / out
