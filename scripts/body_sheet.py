"""The whole body from the front and from behind: docs/myobody_atlas_walk.png.

    python scripts/body_sheet.py SHEET.png [--run DIR] [--frames 0,120] [--size 320x480]

Renders a finished run of poses/jobs/myobody_atlas_walk.yaml (``axdf run
poses/jobs/myobody_atlas_walk.yaml --frames 0:248:24``; ``--run`` names its folder) with
``axdf render``: a row per frame (the walk's first frame, standing, and mid-stride), and in
each row the muscles alone from the front and from behind, then the same under the see-through
skin. The camera is aimed at the pelvis from 3.8 m in front of (-y) and behind (+y) it, z up.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from PIL import Image, ImageDraw

ROOT = Path(__file__).resolve().parent.parent
VIEWS = (("off", "front", "0,-3.8,0"), ("off", "behind", "0,3.8,0"),
         ("see-through", "front", "0,-3.8,0"), ("see-through", "behind", "0,3.8,0"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sheet", type=Path)
    ap.add_argument("--run", type=Path, default=ROOT / "out" / "myobody_atlas_walk")
    ap.add_argument("--frames", default="0,120")
    ap.add_argument("--size", default="320x480")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    frames = [int(f) for f in a.frames.split(",")]
    sheet = Image.new("RGB", (w * len(VIEWS), h * len(frames)), (255, 255, 255))
    with tempfile.TemporaryDirectory() as tmp:
        for col, (skin, label, offset) in enumerate(VIEWS):
            out = Path(tmp) / f"{col}"
            subprocess.run([sys.executable, "-m", "axdf_cli", "render", str(a.run), "--out", str(out), "-q",
                            "--skin-view", skin, "--size", a.size, "--frames", a.frames,
                            "--camera-target", "bone:pelvis", f"--camera-offset={offset}",
                            "--camera-up", "0,0,1"], check=True)
            for row, f in enumerate(frames):
                cell = Image.open(out / "frames" / f"{f:04d}.png").convert("RGB")
                ImageDraw.Draw(cell).text((6, 6), f"frame {f}, {label}, skin {skin}", fill=(0, 0, 0))
                sheet.paste(cell, (col * w, row * h))
    a.sheet.parent.mkdir(parents=True, exist_ok=True)
    sheet.save(a.sheet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
