"""Plot a muscle's centroid over time with and without jiggle (docs/jiggle_hop.png).

    python scripts/jiggle_plot.py OUT.png [JOB] [--muscles med_gas_r vas_lat_r]

Runs JOB (default poses/jobs/gait2392_hop.yaml) twice into a temporary folder, with jiggle
and with ``--no-jiggle``, reads every frame's PLY back and plots, per muscle, the centroid
in its insertion bone's frame (so the bones' own motion drops out and what remains is
how the belly moves on its bones) and the jiggle's offset (with minus without), in mm.
Needs matplotlib (the ``bench`` extra: ``pip install -e '.[bench]'``); not a dependency of axdf.
"""
from __future__ import annotations

import argparse
import csv
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from axdf_cli.cli.main import main as axdf
from axdf_cli.formats import FORMATS


def centroids(run: Path, muscle: str) -> tuple[np.ndarray, np.ndarray]:
    read = FORMATS["ply"].reader
    files = sorted((run / "meshes" / muscle).glob("*.ply"))
    frames = np.array([int(f.stem.rsplit("_", 1)[1]) for f in files])
    return frames, np.array([read(f.read_bytes()).vertices.astype(np.float64).mean(axis=0) for f in files])


def bone_frames(run: Path, bone: str) -> tuple[np.ndarray, np.ndarray]:
    """A bone's world rotation (F, 3, 3) and origin (F, 3) from bones.csv."""
    rows = [r for r in csv.DictReader((run / "bones.csv").open()) if r["bone"] == bone]
    q = np.array([[float(r[k]) for k in ("qw", "qx", "qy", "qz")] for r in rows])
    return Rotation.from_quat(q, scalar_first=True).as_matrix(), np.array([[float(r[k]) for k in "xyz"] for r in rows])


def main() -> None:
    try:
        import matplotlib
    except ImportError:
        raise SystemExit("jiggle_plot.py needs matplotlib, the bench extra: .venv/bin/python -m pip install "
                         "-c constraints.txt -e '.[bench]' (make bench installs it)") from None

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ap = argparse.ArgumentParser()
    ap.add_argument("png")
    ap.add_argument("job", nargs="?", default="poses/jobs/gait2392_hop.yaml")
    ap.add_argument("--muscles", nargs="+", default=["med_gas_r", "vas_lat_r"])
    ap.add_argument("--bones", nargs="+", default=["tibia_r", "femur_r"], help="each muscle's frame")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        runs = {}
        for label, extra in (("jiggle", []), ("no jiggle", ["--no-jiggle"])):
            out = Path(tmp) / label.replace(" ", "_")
            assert axdf(["run", args.job, "--out", str(out), "--no-render", "-q", *extra]) == 0
            runs[label] = out
        fps = float(__import__("json").loads((runs["jiggle"] / "manifest.json").read_text())["settings"]["fps"])
        fig, axes = plt.subplots(2, len(args.muscles), figsize=(5.2 * len(args.muscles), 5.6), sharex=True,
                                 squeeze=False)
        for k, (muscle, bone) in enumerate(zip(args.muscles, args.bones)):
            local = {}
            for label, out in runs.items():
                frames, c = centroids(out, muscle)
                rot, org = bone_frames(out, bone)
                # c_local[f,i] = sum_j R[f,j,i] (c[f,j] - o[f,j]): the centroid in the bone's frame
                local[label] = np.einsum("fji,fj->fi", rot, c - org)
            t = frames / fps
            ref = local["no jiggle"][0]
            top, bottom = axes[0, k], axes[1, k]
            for label, style in (("no jiggle", "--"), ("jiggle", "-")):
                d = (local[label] - ref) * 1000.0
                top.plot(t, np.linalg.norm(d, axis=1), style, label=label)
            off = (local["jiggle"] - local["no jiggle"]) * 1000.0
            for i, axis in enumerate("xyz"):
                bottom.plot(t, off[:, i], label=f"{axis} ({bone})")
            top.set_title(f"{muscle}: centroid in {bone}'s frame")
            top.set_ylabel("distance from its first frame (mm)")
            bottom.set_ylabel("jiggle offset (mm)")
            bottom.set_xlabel("time (s)")
            top.legend(loc="upper left", fontsize=8)
            bottom.legend(loc="upper left", fontsize=8)
            for ax in (top, bottom):
                ax.grid(alpha=0.3)
        fig.suptitle(f"{Path(args.job).name}: with and without jiggle", fontsize=10)
        fig.tight_layout()
        fig.savefig(args.png, dpi=90, metadata={"Software": None})


if __name__ == "__main__":
    main()
