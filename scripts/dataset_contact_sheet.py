"""A contact sheet of a data set's views: python scripts/dataset_contact_sheet.py OUT SHEET.png

Tiles the first samples of OUT/index.parquet (one row per sequence and frame, one column per
view, at most --rows rows), composited on white, with each keypoint's projection drawn from
labels.npz (joined to its parent keypoint by a line): green when visible, red when hidden.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd
from PIL import Image, ImageDraw


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="the data set's folder")
    ap.add_argument("sheet", type=Path, help="PNG to write")
    ap.add_argument("--rows", type=int, default=6, help="sequence-frames shown (default 6)")
    ap.add_argument("--every", type=int, default=1, help="show every k-th sequence-frame")
    ap.add_argument("--per-row", type=int, default=1, help="sequence-frames side by side in one sheet row")
    args = ap.parse_args(argv)
    idx = pd.read_parquet(args.out / "index.parquet")
    keys = idx[["sequence", "frame"]].drop_duplicates().iloc[::args.every].head(args.rows)
    views = list(dict.fromkeys(idx["view"]))
    tiles = {}
    for _, r in idx.merge(keys, on=["sequence", "frame"]).iterrows():
        im = Image.open(args.out / r.png).convert("RGBA")
        bg = Image.new("RGBA", im.size, (255, 255, 255, 255))
        bg.alpha_composite(im)
        im = bg.convert("RGB")
        lab = np.load(args.out / r.labels)
        draw = ImageDraw.Draw(im)
        uv = lab["joints2d"][r.frame_index, r.view_index]
        for j, p in enumerate(lab["joint_parents"]):
            if p >= 0:
                draw.line([tuple(uv[p]), tuple(uv[j])], fill=(60, 60, 200), width=1)
        for (u, v), ok in zip(uv, lab["visible"][r.frame_index, r.view_index]):
            draw.ellipse([u - 2, v - 2, u + 2, v + 2], fill=(30, 170, 60) if ok else (220, 40, 40))
        tiles[(r.sequence, r.frame, r.view)] = im
    w, h = next(iter(tiles.values())).size
    per = max(1, args.per_row)
    sheet = Image.new("RGB", (w * len(views) * per, h * -(-len(keys) // per)), "white")
    for i, (_, k) in enumerate(keys.iterrows()):
        for j, v in enumerate(views):
            if (k.sequence, k.frame, v) in tiles:
                sheet.paste(tiles[(k.sequence, k.frame, v)], (((i % per) * len(views) + j) * w, (i // per) * h))
    sheet.save(args.sheet, optimize=True)
    print(f"wrote {args.sheet} ({len(keys)} x {len(views)} views)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
