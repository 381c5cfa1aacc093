"""The walk with its skin, three ways: python scripts/walk_skin_sheet.py SHEET.png [--frame N]

Runs poses/jobs/gait2392_walk_skin.yaml at one frame into a temporary folder and renders it
twice: the skin see-through over the muscles, and opaque. The third panel is the opaque
render's muscle-under-skin pass (EXR ``under.id``: each muscle its own colour over the grey
body, grey where no muscle lies within reach under the skin). docs/gait2392_walk_skin.png
(README, "A body over the muscles") is made this way.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR
from PIL import Image

from axdf_cli.cli.main import main as axdf

ROOT = Path(__file__).resolve().parents[1]


def _on_white(png: Path) -> np.ndarray:
    img = Image.open(png).convert("RGBA")
    return np.asarray(Image.alpha_composite(Image.new("RGBA", img.size, (255, 255, 255, 255)), img).convert("RGB"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sheet", type=Path, help="PNG to write")
    ap.add_argument("--frame", type=int, default=62, help="the walk's frame (default 62)")
    ap.add_argument("--size", default="400x480", help="each panel's size (default 400x480)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        run, opaque = Path(tmp) / "run", Path(tmp) / "opaque"
        job = ROOT / "poses" / "jobs" / "gait2392_walk_skin.yaml"
        if axdf(["run", str(job), "--frames", str(args.frame), "--render", "--size", args.size, "--out", str(run), "-q"]):
            return 1
        if axdf(["render", str(run), "--skin-view", "opaque", "--size", args.size, "--out", str(opaque), "-q"]):
            return 1
        name = f"{args.frame:04d}"
        see, body = _on_white(run / "frames" / f"{name}.png"), _on_white(opaque / "frames" / f"{name}.png")
        with OpenEXR.File(str(opaque / "frames" / f"{name}.exr")) as f:
            under = f.channels()["under.id"].pixels.astype(np.int64)
            alpha = f.channels()["id"].pixels > 0  # (with the skin opaque, the id pass is the body)
        pal = np.random.default_rng(7).integers(50, 256, (int(under.max(initial=0)) + 1, 3)).astype(np.uint8)
        passes = np.full(body.shape, 230, np.uint8)
        passes[alpha] = 200
        passes[under > 0] = pal[under[under > 0]]
        Image.fromarray(np.concatenate([see, body, passes], axis=1)).save(args.sheet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
