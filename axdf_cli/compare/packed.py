"""Per-sequence files (``npz``, ``pc2``, ``mdd``, ``usdc`` muscle layers) compared frame by
frame, and USD layers without a muscle sequence (``scene.usda``, ``usd/bones.usdc``) value by
value.

A sequence passes when both hold the same frame numbers, vertex count and faces (when the
format has faces) and every frame passes the mesh tolerances as a PLY of that frame would:
its maximum vertex distance, its RMS distance and its largest normal difference. The report
names the worst frame and gives the maximum and RMS distance of every frame.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.compare.meshes import hausdorff
from axdf_cli.compare.result import Outcome, Unreadable
from axdf_cli.compare.thresholds import MeshTol
from axdf_cli.formats import read_sequence, verify_sequence
from axdf_cli.formats.mesh import MeshReadError
from axdf_cli.formats.packed import PointSequence

BLOCK_BYTES = 64 << 20  # frames compared per block: bounded memory on long sequences
MAX_LISTED = 10


def _side(side: str, fn, *args):
    try:
        return fn(*args)
    except MeshReadError as e:
        raise Unreadable(f"{side}: {e}") from None


def _block(x, s: int, e: int) -> np.ndarray:
    """Frames s..e-1 of an array, memory map or lazily read sequence, as float64 (e-s, V, 3)."""
    if isinstance(x, np.ndarray):
        return np.asarray(x[s:e], np.float64)
    return np.stack([np.asarray(x[k], np.float64) for k in range(s, e)])


def compare_sequences(a: PointSequence, g: PointSequence, tol: MeshTol) -> Outcome:
    F, V = g.points.shape[:2]
    metrics: dict = {"frames": F, "vertices": V}
    if a.points.shape[:2] != (F, V):
        return Outcome(False, (f"{a.points.shape[0]} frames x {a.points.shape[1]} vertices vs golden "
                               f"{F} x {V}",), metrics)
    if not np.allclose(a.frames, g.frames, rtol=0, atol=1e-6):
        k = int(np.flatnonzero(~np.isclose(a.frames, g.frames, rtol=0, atol=1e-6))[0])
        return Outcome(False, (f"frame numbers differ: index {k} is {a.frames[k]:g} vs golden {g.frames[k]:g}",),
                       metrics)
    if (a.faces is None) != (g.faces is None) or (g.faces is not None and not np.array_equal(a.faces, g.faces)):
        h = hausdorff(_block(a.points, 0, 1)[0], _block(g.points, 0, 1)[0]) if F else 0.0
        return Outcome(False, (f"faces differ; Hausdorff distance of the first frame {h:.3g} m",),
                       metrics | {"hausdorff": h})
    dmax, rms, nmax = np.zeros(F), np.zeros(F), np.zeros(F)
    worst_vertex = np.zeros(F, np.int64)
    normals = a.normals is not None and g.normals is not None
    step = max(1, BLOCK_BYTES // max(1, V * 3 * 8 * 4))
    for s in range(0, F, step):
        e = min(F, s + step)
        # d[f, v] = |a[f, v] - g[f, v]|
        d = np.linalg.norm(_block(a.points, s, e) - _block(g.points, s, e), axis=2)
        d = np.where(np.isfinite(d), d, np.inf)
        dmax[s:e] = d.max(axis=1, initial=0.0)
        worst_vertex[s:e] = d.argmax(axis=1) if V else 0
        rms[s:e] = np.sqrt(np.mean(d * d, axis=1)) if V else 0.0
        if normals:
            dn = np.linalg.norm(_block(a.normals, s, e) - _block(g.normals, s, e), axis=2)
            nmax[s:e] = np.where(np.isfinite(dn), dn, np.inf).max(axis=1, initial=0.0)
    frame = lambda k: float(g.frames[k])  # noqa: E731
    wf = int(np.argmax(dmax)) if F else 0
    metrics.update(max_distance=float(dmax.max(initial=0.0)), rms_distance=float(rms.max(initial=0.0)),
                   worst_frame=frame(wf) if F else None, worst_vertex=int(worst_vertex[wf]) if F else None,
                   frames_over=int(np.sum((dmax > tol.max_distance) | (rms > tol.rms_distance)
                                          | (nmax > tol.normal_max))),
                   per_frame_max=[float(x) for x in dmax], per_frame_rms=[float(x) for x in rms])
    reasons: list[str] = []
    over = np.flatnonzero(dmax > tol.max_distance)
    if len(over):
        reasons.append(f"max vertex distance {dmax[wf]:.3g} m at frame {frame(wf):g} (vertex {worst_vertex[wf]}) "
                       f"> {tol.max_distance:g} m; {len(over)} of {F} frames over: "
                       + _frames_list(g.frames[over]))
    over = np.flatnonzero(rms > tol.rms_distance)
    if len(over):
        k = int(np.argmax(rms))
        reasons.append(f"RMS vertex distance {rms[k]:.3g} m at frame {frame(k):g} > {tol.rms_distance:g} m; "
                       f"{len(over)} of {F} frames over")
    if (a.normals is None) != (g.normals is None):
        reasons.append("per-vertex normals in " + ("golden only" if a.normals is None else "actual only"))
    elif normals:
        k = int(np.argmax(nmax)) if F else 0
        metrics["normal_max"] = float(nmax.max(initial=0.0))
        if F and nmax[k] > tol.normal_max:
            reasons.append(f"normal difference {nmax[k]:.3g} at frame {frame(k):g} > {tol.normal_max:g}")
    return Outcome(not reasons, tuple(reasons), metrics)


def _frames_list(frames) -> str:
    f = [f"{x:g}" for x in frames[:MAX_LISTED]]
    return ", ".join(f) + (f" ... ({len(frames) - MAX_LISTED} more)" if len(frames) > MAX_LISTED else "")


def verify_files(a: Path, g: Path, identical: bool) -> None:
    """Each side's own checks (:func:`axdf_cli.formats.verify_sequence`: an NPZ's CRC-32 of
    every member, point caches' frame times, a USD layer's samples), once when the files are
    byte-identical: a broken packed file is an ERROR verdict, never SAME. A USD layer that
    is not a muscle sequence (``usd/bones.usdc``) is checked value by value instead."""
    for side, path in (("actual", a),) if identical else (("actual", a), ("golden", g)):
        if path.suffix.lower() == ".usdc" and not _is_sequence_layer(path):
            continue
        _side(side, verify_sequence, path)


def compare_sequence_files(a: Path, g: Path, tol: MeshTol) -> Outcome:
    """Two per-sequence files of the same format. A USD layer whose default prim is not a
    time-sampled mesh (``usd/bones.usdc``) is compared value by value, numbers within the
    mesh distance tolerance."""
    if g.suffix.lower() == ".usdc" and not _is_sequence_layer(g):
        return compare_usd_layers(a, g, tol.max_distance, 0.0)
    sa = _side("actual", read_sequence, a)  # (MDD frames as indices: both sides are read alike)
    sg = _side("golden", read_sequence, g)
    return compare_sequences(sa, sg, tol)


def _is_sequence_layer(path: Path) -> bool:
    from axdf_cli.formats.usd import read_usd

    try:
        read_usd(path)
    except MeshReadError:
        return False
    return True


# ----------------------------------------------------------------------------- USD layers
def layer_values(path: Path) -> dict:
    """Every field of every spec of a USD layer (not composed): ``{"<spec path> <field>":
    value}``, time samples as ``"<path> timeSamples@<time>"``; numbers as float64 arrays,
    everything else as text."""
    from axdf_cli.formats.usd import pxr

    Sdf = pxr()[0]
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Exception as e:  # pxr raises Tf.ErrorException
        raise MeshReadError(f"not a readable USD layer ({str(e).strip().splitlines()[-1]})") from None
    if layer is None:
        raise MeshReadError("not a readable USD layer")
    out: dict = {}
    paths = [Sdf.Path.absoluteRootPath]
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: paths.append(p) if p != Sdf.Path.absoluteRootPath else None)
    for p in paths:
        spec = layer.GetObjectAtPath(p)
        for key in spec.ListInfoKeys():
            value = spec.GetInfo(key)
            if key == "timeSamples":
                for t, v in sorted(value.items()):
                    out[f"{p} timeSamples@{t:g}"] = _value(v)
            else:
                out[f"{p} {key}"] = _value(value)
    return out


def _value(v):
    """A pxr value as a float64 array when it is numeric, else its text."""
    from axdf_cli.formats.usd import pxr

    Gf = pxr()[4]
    if isinstance(v, (Gf.Quatd, Gf.Quatf, Gf.Quath)):
        return np.array([v.GetReal(), *v.GetImaginary()], np.float64)
    if isinstance(v, bool):
        return str(v)
    try:
        a = np.asarray(v, np.float64)
        if a.dtype == np.float64 and a.size == np.asarray(v, object).size:
            return a
    except (TypeError, ValueError):
        pass
    return str(v)


def compare_usd_layers(a: Path, g: Path, atol: float, rtol: float) -> Outcome:
    """Two USD layers: the same specs and fields; numbers within ``atol + rtol*|golden|``,
    everything else equal."""
    va = _side("actual", layer_values, a)
    vg = _side("golden", layer_values, g)
    diffs, worst = [], 0.0
    for k in sorted(set(va) | set(vg)):
        if k not in va or k not in vg:
            diffs.append(f"{k}: {'missing' if k not in va else 'not in golden'}")
            continue
        x, y = va[k], vg[k]
        if isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.shape == y.shape:
            d = np.abs(x - y)
            d = np.where(np.isnan(x) & np.isnan(y), 0.0, d)
            worst = max(worst, float(np.nan_to_num(d, nan=np.inf).max(initial=0.0)))
            if not np.all(d <= atol + rtol * np.abs(y)):
                diffs.append(f"{k}: differs by {float(np.nan_to_num(d, nan=np.inf).max()):.3g}")
        elif isinstance(x, np.ndarray) or isinstance(y, np.ndarray) or x != y:
            diffs.append(f"{k}: {_short(x)} vs golden {_short(y)}")
    metrics = {"values": len(vg), "max_abs_difference": worst, "differences": len(diffs)}
    if not diffs:
        return Outcome(True, (), metrics)
    reasons = [f"{len(diffs)} values differ beyond atol {atol:g} + rtol {rtol:g}:"] + diffs[:MAX_LISTED]
    if len(diffs) > MAX_LISTED:
        reasons.append(f"... and {len(diffs) - MAX_LISTED} more")
    return Outcome(False, tuple(reasons), metrics)


def _short(x) -> str:
    s = np.array2string(x, threshold=6) if isinstance(x, np.ndarray) else str(x)
    return s if len(s) <= 60 else s[:57] + "..."
