"""Sampling poses: keyed coordinates and activation curves → arrays over frames.

``linear`` and ``cubic`` interpolate between keys; ``step`` holds each key until the next.
``cubic`` is the monotone piecewise-cubic Hermite interpolant (PCHIP, Fritsch & Carlson
1980): smooth through the keys without overshooting them, like Blender's auto-clamped
Bézier handles (a natural spline through sparse keys swings far past them). Before the first key and after the last, a
curve holds that key's value. Coordinates keyed nowhere keep their rest value.
"""
from __future__ import annotations

import numpy as np

from axdf_cli.errors import InputError, Mark


def interpolate(frames: np.ndarray, key_frames, key_values, mode: str) -> np.ndarray:
    """One curve at ``frames`` (F,) from keys → (F,) float64."""
    kf = np.asarray(key_frames, dtype=np.float64)
    kv = np.asarray(key_values, dtype=np.float64)
    x = np.asarray(frames, dtype=np.float64)
    if len(kf) == 1:
        return np.full(x.shape, kv[0])
    if mode == "step":
        i = np.clip(np.searchsorted(kf, x, side="right") - 1, 0, len(kf) - 1)
        return kv[i]
    if mode == "cubic" and len(kf) >= 3:
        from scipy.interpolate import PchipInterpolator

        xc = np.clip(x, kf[0], kf[-1])
        return PchipInterpolator(kf, kv)(xc)
    return np.interp(x, kf, kv)


def sample_coordinates(pose, frames: np.ndarray) -> np.ndarray:
    """Coordinates of the pose's skeleton at ``frames``: (F, C) float64, axdf units."""
    skel = pose.skeleton
    q = np.broadcast_to(skel.rest_coordinates(), (len(frames), len(skel.coordinates))).copy()
    for c, (kf, kv) in pose.keys.items():
        q[:, skel.coord_index[c]] = interpolate(frames, kf, kv, pose.interpolation)
    return q


def sample_activation(pose, muscle_names, frames: np.ndarray) -> np.ndarray:
    """Activation (F, M) in [0, 1]; NaN where the pose has no curve for a muscle."""
    out = np.full((len(frames), len(muscle_names)), np.nan)
    for j, name in enumerate(muscle_names):
        if name in pose.activation:
            kf, kv = pose.activation[name]
            out[:, j] = np.clip(interpolate(frames, kf, kv, pose.interpolation), 0.0, 1.0)
    return out


def effective_tension(tension: float, activation: np.ndarray) -> np.ndarray:
    """Tension over frames: the muscle's ``tension`` is its tone at zero activation and
    activation drives it towards 1: ``e = tension + (1 - tension) a`` (a = 0 without a curve)."""
    a = np.nan_to_num(activation, nan=0.0)
    return tension + (1.0 - tension) * a


def parse_frames(spec, where: Mark, first: int, last: int) -> np.ndarray:
    """``0:48``, ``0:48:2``, ``3,7,10:12`` (ends inclusive, as in Blender) or a list of ints → sorted
    unique frames, all inside the pose's [first, last]."""
    allowed = "frames are like 0:48, 0:48:2 or 3,7,10:12 (ends inclusive)"
    if isinstance(spec, (list, tuple)):
        parts = [str(x) for x in spec]
    elif isinstance(spec, int) and not isinstance(spec, bool):
        parts = [str(spec)]
    elif isinstance(spec, str):
        parts = [p.strip() for p in spec.split(",")]
    else:
        raise InputError(where, f"frames is {spec!r}", allowed)
    out: list[int] = []
    for p in parts:
        try:
            bits = [int(b) for b in p.split(":")]
        except ValueError:
            raise InputError(where, f"bad frame range {p!r}", allowed) from None
        if len(bits) == 1:
            out.append(bits[0])
        elif len(bits) in (2, 3):
            step = bits[2] if len(bits) == 3 else 1
            if step <= 0 or bits[1] < bits[0]:
                raise InputError(where, f"bad frame range {p!r}", allowed + "; start <= end, step >= 1")
            if (bits[1] - bits[0]) // step > 10_000_000:
                raise InputError(where, f"frame range {p!r} is too long", "at most 10,000,000 frames")
            out.extend(range(bits[0], bits[1] + 1, step))
        else:
            raise InputError(where, f"bad frame range {p!r}", allowed)
    frames = np.unique(np.array(out, dtype=np.int64))
    if len(frames) == 0:
        raise InputError(where, "no frames selected", allowed)
    if frames[0] < first or frames[-1] > last:
        raise InputError(where, f"frames {frames[0]}..{frames[-1]} outside the pose's [{first}, {last}]",
                         f"frames within {first}..{last}")
    return frames
