"""Tile rendered run frames into a contact sheet: one row per run folder, one column per frame.

    python scripts/contact_sheet.py OUT.png "before=/tmp/sheet_before" "after=out/sheet_after"

Each row takes every ``frames/*.png`` of its run folder in frame order (all rows must have
the same frames and size) and is labelled on its left; the frame numbers head the columns.
docs/gait2392_bellies.png was made this way (README, "OpenSim models").
"""
from __future__ import annotations

import sys
from pathlib import Path

from PIL import Image, ImageDraw, ImageFont

LABEL_W = 64  # pixels left of each row for its label
HEAD_H = 16  # pixels above the first row for the frame numbers


def contact_sheet(rows: list[tuple[str, Path]]) -> Image.Image:
    frames = [sorted((folder / "frames").glob("*.png")) for _, folder in rows]
    if not frames or not frames[0] or any([p.name for p in f] != [p.name for p in frames[0]] for f in frames):
        raise SystemExit("every run folder needs the same frames/*.png (and at least one)")
    w, h = Image.open(frames[0][0]).size
    sheet = Image.new("RGB", (LABEL_W + w * len(frames[0]), HEAD_H + h * len(rows)), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for c, p in enumerate(frames[0]):
        draw.text((LABEL_W + c * w + 4, 2), f"frame {int(p.stem)}", fill=(0, 0, 0), font=font)
    for r, ((label, _), paths) in enumerate(zip(rows, frames)):
        draw.text((4, HEAD_H + r * h + h // 2 - 6), label, fill=(0, 0, 0), font=font)
        for c, p in enumerate(paths):
            img = Image.open(p).convert("RGBA")
            bg = Image.new("RGBA", img.size, (255, 255, 255, 255))
            sheet.paste(Image.alpha_composite(bg, img).convert("RGB"), (LABEL_W + c * w, HEAD_H + r * h))
    return sheet


def main(argv: list[str]) -> int:
    if len(argv) < 2 or any("=" not in a for a in argv[1:]):
        print(__doc__, file=sys.stderr)
        return 2
    rows = [(a.split("=", 1)[0], Path(a.split("=", 1)[1])) for a in argv[1:]]
    contact_sheet(rows).save(argv[0], optimize=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
