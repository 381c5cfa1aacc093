"""A data set's skin passes side by side: python scripts/dataset_skin_sheet.py OUT SHEET.png

For the samples of OUT/index.parquet named by --samples (default the first 2): the image on
white, the muscle-under-skin pass (EXR ``under.id``: each muscle its own colour, black where
no muscle lies within the cap or off the skin) and the body-part pass (``part.id``), each
scaled by --scale (nearest neighbour, so the passes' pixels stay whole).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import OpenEXR
import pandas as pd
from PIL import Image


def _palette(n: int, seed: int) -> np.ndarray:
    pal = np.random.default_rng(seed).integers(50, 256, (n, 3)).astype(np.uint8)
    pal[0] = 0
    return pal


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="the data set's folder (built with skin: and the exr pass)")
    ap.add_argument("sheet", type=Path, help="PNG to write")
    ap.add_argument("--samples", type=int, nargs="*", default=[0, 1], help="index rows shown")
    ap.add_argument("--scale", type=int, default=2, help="pixel scale (default 2)")
    args = ap.parse_args(argv)
    idx = pd.read_parquet(args.out / "index.parquet")
    rows = []
    for k in args.samples:
        r = idx.iloc[k]
        png = Image.open(args.out / r.png).convert("RGBA")
        white = Image.new("RGBA", png.size, (255, 255, 255, 255))
        beauty = np.asarray(Image.alpha_composite(white, png).convert("RGB"))
        with OpenEXR.File(str(args.out / r.exr)) as f:
            ch = f.channels()
            under = ch["under.id"].pixels.astype(np.int64)
            parts = ch["part.id"].pixels.astype(np.int64)
        rows.append(np.concatenate([beauty, _palette(1024, 7)[under], _palette(64, 3)[parts]], axis=1))
    sheet = Image.fromarray(np.concatenate(rows, axis=0))
    sheet.resize((sheet.width * args.scale, sheet.height * args.scale), Image.NEAREST).save(args.sheet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
