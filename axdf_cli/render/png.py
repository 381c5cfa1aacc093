"""PNG preview frames: 8-bit RGBA, sRGB-encoded, straight alpha, no metadata (deterministic)."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 transfer function on linear values in [0, 1] (float32 in, float32 out)."""
    x = np.clip(x, 0.0, 1.0).astype(np.float32)
    return np.where(x <= 0.0031308, 12.92 * x,
                    1.055 * np.power(x, np.float32(1 / 2.4)) - 0.055).astype(np.float32)


def to_rgba8(rgba: np.ndarray) -> np.ndarray:
    """(H, W, 4) float32 linear premultiplied -> (H, W, 4) uint8 sRGB straight alpha."""
    a = np.clip(rgba[..., 3:4], 0.0, 1.0)
    rgb = np.where(a > 0, rgba[..., :3] / np.where(a > 0, a, 1.0), 0.0)
    out = np.empty(rgba.shape, dtype=np.uint8)
    out[..., :3] = np.rint(linear_to_srgb(rgb) * 255.0).astype(np.uint8)
    out[..., 3] = np.rint(a[..., 0] * 255.0).astype(np.uint8)
    return out


def encode_png(rgba8: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgba8), mode="RGBA").save(buf, format="PNG", compress_level=6)
    return buf.getvalue()


def write_png(path: Path, rgba: np.ndarray) -> str:
    """Write a (H, W, 4) float32 linear premultiplied image as PNG; return its sha256."""
    return atomic.write_bytes(path, encode_png(to_rgba8(rgba)))
