"""The image files of a rendered frame: one writer per pass, keyed by file extension
(``png``: 8-bit sRGB RGBA; ``exr``: RGBA, Z, N and id, and with an opaque skin under.id and under.Z,
and in a data set part.id). Every frame gets one file of each."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

from axdf_cli.render.exr import exr_channels, write_exr
from axdf_cli.render.png import write_png
from axdf_cli.render.renderer import FrameImages


def _write_png(path: Path, img: FrameImages) -> str:
    return write_png(path, img.rgba)


def _write_exr(path: Path, img: FrameImages) -> str:
    return write_exr(path, exr_channels(img.rgba, img.depth, img.normals, img.ids, img.under, img.parts))


#: file extension -> writer(path, FrameImages) -> sha256; every frame gets one file of each
FRAME_WRITERS: dict[str, Callable[[Path, FrameImages], str]] = {"png": _write_png, "exr": _write_exr}
