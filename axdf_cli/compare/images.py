"""Image comparison (PNG and OpenEXR) with a three-part tolerance, as idiff and Playwright:
a per-pixel threshold, an allowed fraction of failing pixels, and a hard maximum.

A pixel fails when any of its channels differs beyond the per-pixel tolerance; the image
fails when more than ``fail_fraction`` of its pixels fail, or when any value differs by more
than ``hard_max``. PSNR and mean NVIDIA FLIP (Andersson et al. 2020, "FLIP: A Difference
Evaluator for Alternating Images", package ``flip-evaluator``) are reported, not judged.
FLIP costs ~0.1 s per 256x256 image and ~0.5 s at 512x512, so it is computed only for
images that fail (``flip_mean`` is null otherwise; 0 for identical pixels): a run whose
every frame differs a little, within tolerance, compares in seconds, not minutes.
For a failing image the comparator returns a picture: actual | golden | heat map, where the
heat map shows each pixel's error over its tolerance (black 0, orange at the tolerance,
white at twice the tolerance or more).
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from axdf_cli.compare.result import Outcome, Unreadable, read_side
from axdf_cli.compare.thresholds import ChannelTol, ExrTol, PngTol
from axdf_cli.errors import EnvironmentProblem

# the heat map reaches white at this many times the per-pixel tolerance
HEAT_FULL_SCALE = 2.0
# background shade under transparent pixels in the pictures
PICTURE_BACKGROUND = 0.25
PICTURE_GAP = 4  # pixels between the three panels


# ----------------------------------------------------------------------------- reading
# Images are decoded only up to this many pixels (8192 x 8192): a decoded image is held as
# float32 per channel on both sides, with differences, so 2^26 pixels already take several
# GB. Sizes are read from the headers first: a small file whose header claims a huge image
# (a decompression bomb) is refused without decoding it, and two images of different sizes
# fail without decoding either.
MAX_IMAGE_PIXELS = 1 << 26


def _check_pixels(w: int, h: int, what: str) -> None:
    if w < 0 or h < 0 or w * h > MAX_IMAGE_PIXELS:
        raise Unreadable(f"{what} header says {w}x{h} pixels; at most {MAX_IMAGE_PIXELS} pixels are decoded")


def _open_png(data: bytes):
    """The PIL image (header read, pixels not decoded) and its size and channel count."""
    import warnings

    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)  # our own limit applies
            img = Image.open(io.BytesIO(data))
    except Image.DecompressionBombError as e:
        raise Unreadable(f"PNG header claims a huge image ({e})") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as e:
        raise Unreadable(f"not a readable PNG ({e})") from None
    w, h = img.size
    channels = 4 if img.mode == "P" else 1 if img.mode == "1" else len(img.getbands())
    return img, w, h, channels


def _decode_png(img) -> np.ndarray:
    """A PIL image -> ``(H, W, C) float32`` in [0, 1] (C = 1 grey, 2 grey+alpha, 3 RGB, 4 RGBA)."""
    w, h = img.size
    _check_pixels(w, h, "PNG")
    try:
        img.load()
    except (OSError, SyntaxError, ValueError) as e:
        raise Unreadable(f"not a readable PNG ({e})") from None
    if img.mode == "P":
        img = img.convert("RGBA")
    elif img.mode == "1":
        img = img.convert("L")
    arr = np.asarray(img)
    if arr.dtype == np.uint8:
        out = arr.astype(np.float32) / 255.0
    elif arr.dtype.kind in "ui":  # 16-bit grey ("I;16", "I")
        out = arr.astype(np.float32) / 65535.0
    else:
        raise Unreadable(f"PNG mode {img.mode!r} is not supported")
    return out[:, :, None] if out.ndim == 2 else out


def read_png(data: bytes) -> np.ndarray:
    """PNG bytes -> ``(H, W, C) float32`` in [0, 1] (C = 1 grey, 2 grey+alpha, 3 RGB, 4 RGBA)."""
    return _decode_png(_open_png(data)[0])


def _exr_file(data: bytes, header_only: bool):
    try:
        import OpenEXR
    except ImportError:
        raise EnvironmentProblem("the OpenEXR Python bindings are missing",
                                 "pip install 'OpenEXR>=3.2'") from None
    return OpenEXR.File(io.BytesIO(data), separate_channels=True, header_only=header_only)


def exr_size(data: bytes) -> tuple[int, int]:
    """(width, height) from an OpenEXR header's dataWindow, without reading pixels."""
    try:
        with _exr_file(data, header_only=True) as f:
            lo, hi = (np.asarray(x, np.int64) for x in f.header()["dataWindow"])
    except (RuntimeError, ValueError, KeyError, TypeError) as e:
        raise Unreadable(f"not a readable OpenEXR file ({e})") from None
    return int(hi[0] - lo[0] + 1), int(hi[1] - lo[1] + 1)


def read_exr(data: bytes | str | Path) -> dict[str, np.ndarray]:
    """OpenEXR bytes (or a file) -> {channel name: (H, W) array} in the file's pixel types
    (half, float32, uint32), one entry per channel (R G B A not grouped). The header's size is
    checked first (a patched dataWindow is refused, not allocated)."""
    if not isinstance(data, bytes):
        data = Path(data).read_bytes()
    _check_pixels(*exr_size(data), "OpenEXR")
    try:
        with _exr_file(data, header_only=False) as f:
            out = {name: np.asarray(ch.pixels) for name, ch in f.channels().items()}
    except (RuntimeError, ValueError, MemoryError) as e:  # the bindings' errors for unreadable files
        raise Unreadable(f"not a readable OpenEXR file ({type(e).__name__}: {e})") from None
    if not out:
        raise Unreadable("not a readable OpenEXR file (no channels)")
    return out


# ----------------------------------------------------------------------------- metrics
def psnr(a: np.ndarray, g: np.ndarray, peak: float = 1.0) -> float | None:
    """Peak signal-to-noise ratio in dB over all values (None when identical: infinite)."""
    d = a.astype(np.float64) - g.astype(np.float64)
    d = d[np.isfinite(d)]
    mse = float(np.mean(d * d)) if d.size else 0.0
    return None if mse == 0.0 else float(10.0 * np.log10(peak * peak / mse))


def flip_mean(a_rgb: np.ndarray, g_rgb: np.ndarray, srgb: bool) -> float:
    """Mean LDR FLIP error of ``(H, W, 3)`` images in [0, 1] (0 identical, 1 most different)."""
    try:
        import flip_evaluator
    except ImportError:
        raise EnvironmentProblem("the FLIP image metric is missing", "pip install flip-evaluator") from None
    ref = np.ascontiguousarray(np.clip(np.nan_to_num(g_rgb), 0.0, 1.0), np.float32)
    test = np.ascontiguousarray(np.clip(np.nan_to_num(a_rgb), 0.0, 1.0), np.float32)
    _, mean, _ = flip_evaluator.evaluate(ref, test, "LDR", inputsRGB=srgb, applyMagma=False)
    return float(mean)


def _rgb(img: np.ndarray) -> np.ndarray:
    """``(H, W, C)`` -> ``(H, W, 3)``: grey replicated, alpha dropped."""
    c = img.shape[2]
    return np.repeat(img[:, :, :1], 3, axis=2) if c < 3 else img[:, :, :3]


# ----------------------------------------------------------------------------- pictures
def heat_map(ratio: np.ndarray) -> np.ndarray:
    """``(H, W)`` error / tolerance -> ``(H, W, 3) uint8``, black-red-yellow-white ("hot")."""
    t = np.clip(np.nan_to_num(ratio, nan=HEAT_FULL_SCALE, posinf=HEAT_FULL_SCALE) / HEAT_FULL_SCALE, 0.0, 1.0)
    rgb = np.stack([np.clip(3 * t, 0, 1), np.clip(3 * t - 1, 0, 1), np.clip(3 * t - 2, 0, 1)], axis=2)
    return (rgb * 255 + 0.5).astype(np.uint8)


def _display(img: np.ndarray, linear: bool) -> np.ndarray:
    """``(H, W, C)`` float -> ``(H, W, 3) uint8`` over a grey background."""
    rgb = np.clip(np.nan_to_num(_rgb(img).astype(np.float32)), 0.0, 1.0)
    if linear:
        rgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    if img.shape[2] in (2, 4):
        alpha = np.clip(np.nan_to_num(img[:, :, -1:].astype(np.float32)), 0.0, 1.0)
        rgb = rgb * alpha + PICTURE_BACKGROUND * (1.0 - alpha)
    return (rgb * 255 + 0.5).astype(np.uint8)


def side_by_side(actual: np.ndarray, golden: np.ndarray, heat: np.ndarray) -> np.ndarray:
    """Three ``(H, W, 3) uint8`` panels -> ``(H, 3W + 2*gap, 3) uint8``."""
    gap = np.full((actual.shape[0], PICTURE_GAP, 3), 255, np.uint8)
    return np.concatenate([actual, gap, golden, gap, heat], axis=1)


# ----------------------------------------------------------------------------- PNG
def compare_png(a_bytes: bytes, g_bytes: bytes, tol: PngTol) -> Outcome:
    ai, aw, ah, ac = read_side("actual", _open_png, a_bytes)
    gi, w, h, gc = read_side("golden", _open_png, g_bytes)
    read_side("actual", _check_pixels, aw, ah, "PNG")
    read_side("golden", _check_pixels, w, h, "PNG")
    metrics: dict = {"width": w, "height": h, "channels": gc}
    if (aw, ah, ac) != (w, h, gc):  # from the headers: nothing decoded
        return Outcome(False, (f"image is {aw}x{ah} with {ac} channels vs golden {w}x{h} with {gc} channels",),
                       metrics)
    a = read_side("actual", _decode_png, ai)
    g = read_side("golden", _decode_png, gi)
    diff = np.abs(a - g).max(axis=2)  # (H, W) worst channel per pixel
    failing = diff > tol.threshold
    n_fail = int(failing.sum())
    dmax = float(diff.max())
    metrics.update(max_difference=dmax, failing_pixels=n_fail, failing_fraction=n_fail / diff.size,
                   psnr_db=psnr(a, g), flip_mean=0.0 if dmax == 0 else None)
    y, x = np.unravel_index(int(np.argmax(diff)), diff.shape)
    reasons = _judge(failing, tol.fail_fraction, f"threshold {tol.threshold:.4g}",
                     f"largest difference {dmax:.4g} at x={x} y={y}")
    if tol.hard_max is not None and dmax > tol.hard_max:
        reasons.append(f"a pixel differs by {dmax:.4g} > hard maximum {tol.hard_max:g}")
    picture = None
    if reasons:
        metrics["flip_mean"] = flip_mean(_rgb(a), _rgb(g), srgb=True)  # the perceptual metric, for failures
        ratio = diff / tol.threshold if tol.threshold > 0 else np.where(diff > 0, np.inf, 0.0)
        picture = side_by_side(_display(a, False), _display(g, False), heat_map(ratio))
    return Outcome(not reasons, tuple(reasons), metrics, picture=picture, mask=failing if reasons else None)


def _judge(failing: np.ndarray, fail_fraction: float, tol_text: str, detail: str) -> list[str]:
    n_fail = int(failing.sum())
    frac = n_fail / failing.size
    if frac <= fail_fraction:
        return []
    return [f"{n_fail} pixels ({100 * frac:.3g}%) differ beyond {tol_text}; allowed {100 * fail_fraction:.3g}%;"
            f" {detail}"]


# ----------------------------------------------------------------------------- EXR
def channel_class(name: str) -> str:
    """color (R G B A), depth (Z), normal (N.*), id (exact), or other."""
    low = name.lower()
    last = name.rsplit(".", 1)[-1]
    if low == "id" or low.endswith(".id"):
        return "id"
    if name.startswith("N.") or name == "N":
        return "normal"
    if last in ("R", "G", "B", "A"):
        return "color"
    if last == "Z":
        return "depth"
    return "other"


def _channel_error(a: np.ndarray, g: np.ndarray, t: ChannelTol) -> tuple[np.ndarray, np.ndarray]:
    """Per-pixel ``|a - g|`` and its ratio to ``atol + rtol*|g|``, both ``(H, W) float64``.
    Equal values pass (matching inf or NaN included); other non-finite differences are inf."""
    a64, g64 = a.astype(np.float64), g.astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        same = (a64 == g64) | (np.isnan(a64) & np.isnan(g64))
        d = np.where(same, 0.0, np.abs(a64 - g64))
        d = np.where(np.isnan(d), np.inf, d)
        allowed = t.atol + t.rtol * np.abs(np.where(np.isfinite(g64), g64, 0.0))
        ratio = np.where(d == 0, 0.0, d / np.where(allowed > 0, allowed, 1.0))
        ratio = np.where((allowed == 0) & (d > 0), np.inf, ratio)
    return d, ratio


def compare_exr(a_bytes: bytes, g_bytes: bytes, tol: ExrTol) -> Outcome:
    (aw, ah), (w, h) = read_side("actual", exr_size, a_bytes), read_side("golden", exr_size, g_bytes)
    read_side("actual", _check_pixels, aw, ah, "OpenEXR")
    read_side("golden", _check_pixels, w, h, "OpenEXR")
    if (aw, ah) != (w, h):  # from the headers: nothing decoded
        return Outcome(False, (f"image is {aw}x{ah} vs golden {w}x{h}",), {"width": w, "height": h})
    a = read_side("actual", read_exr, a_bytes)
    g = read_side("golden", read_exr, g_bytes)
    reasons: list[str] = []
    notes: list[str] = []
    only_a, only_g = sorted(set(a) - set(g)), sorted(set(g) - set(a))
    if only_a or only_g:
        reasons.append(f"channels differ: actual only {only_a or '-'}, golden only {only_g or '-'}")
    names = [n for n in g if n in a]
    if not names:
        return Outcome(False, tuple(reasons) or ("no channels",), {})
    h, w = g[names[0]].shape
    metrics: dict = {"width": w, "height": h, "channels": {}}
    if any(a[n].shape != g[n].shape for n in names):
        ah, aw = a[names[0]].shape
        return Outcome(False, tuple(reasons) + (f"image is {aw}x{ah} vs golden {w}x{h}",), metrics)
    failing = np.zeros((h, w), bool)
    ratio_max = np.zeros((h, w))
    for n in names:
        cls = channel_class(n)
        ca, cg = a[n], g[n]
        if ca.dtype != cg.dtype:  # values are compared all the same (id may be UINT or FLOAT)
            notes.append(f"channel {n} is {ca.dtype} vs golden {cg.dtype}")
        if np.array_equal(ca, cg):  # most channels of a near-identical frame: skip the arithmetic
            metrics["channels"][n] = {"class": cls, "max_difference": 0.0, "failing_pixels": 0}
            continue
        if cls == "id":
            bad = ca.astype(np.float64) != cg.astype(np.float64)
            d = bad.astype(np.float64)
            ratio = np.where(bad, np.inf, 0.0)
            t = None
        else:
            t = getattr(tol, cls)
            d, ratio = _channel_error(ca, cg, t)
            bad = ratio > 1.0
        failing |= bad
        ratio_max = np.maximum(ratio_max, ratio)
        dmax = float(d.max())
        metrics["channels"][n] = {"class": cls, "max_difference": dmax, "failing_pixels": int(bad.sum())}
        if t is not None and t.hard_max is not None and dmax > t.hard_max:
            reasons.append(f"channel {n} differs by {dmax:.4g} > hard maximum {t.hard_max:g}")
    n_fail = int(failing.sum())
    metrics.update(failing_pixels=n_fail, failing_fraction=n_fail / failing.size)
    colour = [c for c in ("R", "G", "B") if c in names]
    if colour:
        ac = np.stack([a[c] for c in colour], axis=2).astype(np.float32)
        gc = np.stack([g[c] for c in colour], axis=2).astype(np.float32)
        metrics["psnr_db"] = psnr(ac, gc)
        metrics["flip_mean"] = 0.0 if np.array_equal(ac, gc) else None
    worst = sorted(((m["failing_pixels"], n) for n, m in metrics["channels"].items() if m["failing_pixels"]),
                   reverse=True)[:4]
    reasons += _judge(failing, tol.fail_fraction, "their channels' tolerances",
                      "failing pixels per channel: " + ", ".join(f"{n} {k}" for k, n in worst))
    if reasons and colour and metrics["flip_mean"] is None:  # the perceptual metric, for failures only
        metrics["flip_mean"] = flip_mean(_rgb(ac), _rgb(gc), srgb=False)
    picture = None
    if reasons:
        picture = side_by_side(_exr_display(a, names), _exr_display(g, names), heat_map(ratio_max))
    return Outcome(not reasons, tuple(reasons), metrics, tuple(notes), picture, failing if reasons else None)


def _exr_display(ch: dict, names: list[str]) -> np.ndarray:
    """RGB(A) tone-mapped when present; otherwise the first channel, normalized to [0, 1]."""
    rgba = [c for c in ("R", "G", "B", "A") if c in names]
    if len(rgba) >= 3:
        return _display(np.stack([ch[c] for c in rgba], axis=2).astype(np.float32), linear=True)
    x = ch[names[0]].astype(np.float64)
    fin = x[np.isfinite(x)]
    lo, hi = (float(fin.min()), float(fin.max())) if fin.size else (0.0, 1.0)
    x = (np.nan_to_num(x, nan=lo, posinf=hi, neginf=lo) - lo) / (hi - lo if hi > lo else 1.0)
    return _display(x[:, :, None].astype(np.float32), linear=False)
