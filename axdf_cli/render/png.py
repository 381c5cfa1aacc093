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


#: Depth PNG: 16-bit unsigned, value = camera depth in millimetres (z * DEPTH_PNG_PER_METRE,
#: rounded to the nearest integer: at most 0.5 mm off), 0 = background; depth beyond
#: 65.535 m is stored as 65535, depth under 1 mm as 1 (never as background).
DEPTH_PNG_PER_METRE = 1000.0


def label_png_bits(labels: int) -> int:
    """The bit depth of a label PNG holding ids ``0 .. labels - 1``: 8 up to 256 labels,
    else 16 (a label PNG holds at most 65536)."""
    if labels > 1 << 16:
        raise ValueError(f"{labels} labels; a 16-bit PNG holds at most 65536")
    return 8 if labels <= 1 << 8 else 16


def encode_label_png(ids: np.ndarray, bits: int) -> bytes:
    """(H, W) integer labels -> a greyscale PNG of ``bits`` (8 or 16) bits, the label as the
    pixel's value; no metadata (the same labels give the same bytes)."""
    from PIL import Image

    ids = np.asarray(ids)
    top = (1 << bits) - 1
    if ids.size and (int(ids.max()) > top or int(ids.min()) < 0):
        raise ValueError(f"labels {int(ids.min())}..{int(ids.max())} do not fit {bits} bits")
    return _grey_png(Image, ids, bits)


def encode_depth_png(depth: np.ndarray) -> bytes:
    """(H, W) float camera depth in metres, 0 = background -> a 16-bit greyscale PNG in
    millimetres (:data:`DEPTH_PNG_PER_METRE`); no metadata."""
    from PIL import Image

    z = np.asarray(depth, np.float64)
    mm = np.clip(np.rint(z * DEPTH_PNG_PER_METRE), 1, 65535)
    return _grey_png(Image, np.where(z > 0, mm, 0), 16)


def _grey_png(Image, values: np.ndarray, bits: int) -> bytes:
    """(H, W) values in 0 .. 2**bits - 1 -> PNG bytes (mode L, or I;16: 16-bit grey)."""
    buf = io.BytesIO()
    if bits == 8:
        img = Image.fromarray(np.ascontiguousarray(values, dtype=np.uint8), mode="L")
    else:
        a = np.ascontiguousarray(values, dtype="<u2")
        img = Image.frombytes("I;16", (a.shape[1], a.shape[0]), a.tobytes())
    img.save(buf, format="PNG", compress_level=6)
    return buf.getvalue()
