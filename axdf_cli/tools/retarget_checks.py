"""Whether a retarget fit holds: its error and the coordinates it held at a range's end
against the documented bounds (``tools.constants.RETARGET_*``), each problem with its frames and the
fix; and the room coordinates that left the model file's range.

The error is compared with the *subject's height* (:func:`subject_height`: head top to sole,
:func:`axdf_cli.model.stature.stature`, in the subject's metres), so a bound means the same
for a child and an adult, and for a model in any unit. ``res`` is a
:class:`axdf_cli.tools.retarget.Retargeted`.
"""
from __future__ import annotations

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.model.ik import pose_points
from axdf_cli.model.pose import frame_spans  # (the run reports its ranges' frames the same way)



def subject_height(res) -> tuple[float, str]:
    """The subject's height, head top to sole, in the subject's metres, and where it comes from:
    :func:`axdf_cli.model.stature.stature` (the one height every command states) of the motion's
    own skeleton at rest (a BVH's: ``"motion"``), else of the model's times the fitted scale
    (``"model"``), else, for a skeleton of no family, the vertical extent of the map's weighted
    points in the model's rest pose times the scale (``"points"``)."""
    from axdf_cli.tools.skin import skeleton_stature

    own = skeleton_stature(res.mocap.skeleton) if res.mocap.skeleton is not None else None
    if own is not None:
        return own, "motion"
    model = skeleton_stature(res.rmap.skeleton)
    if model is not None:
        return model * res.world.scale, "model"
    mp = res.points
    use = mp.weights > 0
    rest = pose_points(res.rmap.skeleton, mp.q_start[None], mp.bones[use], mp.local[use])[0]
    return float(np.ptp(rest[:, 2])) * res.world.scale, "points"


def fit_bounds(res) -> dict:
    """The documented bounds (tools.constants.RETARGET_*) in the subject's metres, with the
    subject's height they are shares of (:func:`subject_height`)."""
    size, source = subject_height(res)
    return {"body_height_m": size, "body_height_from": source, "take_rms_m": tol.RETARGET_RMS_SHARE * size,
            "frame_rms_m": tol.RETARGET_FRAME_SHARE * size, "point_m": tol.RETARGET_POINT_SHARE * size,
            "pinned_share": tol.RETARGET_PINNED_SHARE}


def fit_warnings(res) -> list[str]:
    """What is wrong with a fit, each with its frames and the fix: an error beyond the bounds of
    :func:`fit_bounds`, a root coordinate at a range's end in any frame or another at one in more
    than RETARGET_PINNED_SHARE of the frames, a fitted scale outside RETARGET_SCALE_BAND."""
    skel = res.rmap.skeleton
    b = fit_bounds(res)
    err = res.error[:, res.points.weights > 0]
    names = [p.name for p, w in zip(res.rmap.points, res.points.weights) if w > 0]
    rms, frame_rms, frame_max = float(np.sqrt(np.mean(err ** 2))), np.sqrt(np.mean(err ** 2, axis=1)), err.max(axis=1)
    out = []
    bad = np.nonzero((frame_rms > b["frame_rms_m"]) | (frame_max > b["point_m"]))[0]
    at_end = res.fit.at_bound
    if rms > b["take_rms_m"] or len(bad):
        w = int(np.argmax(frame_max))
        held = [skel.coordinates[c].name for c in res.points.free if at_end[bad, c].any()]
        out.append(f"the fit misses the motion: {rms * 1000:.0f} mm RMS over the take (bound {b['take_rms_m'] * 1000:.0f}"
                   f" mm, {tol.RETARGET_RMS_SHARE:.1%} of the subject's {b['body_height_m']:.2f} m height); "
                   f"{len(bad)} frame(s) beyond {b['frame_rms_m'] * 1000:.0f} mm RMS or {b['point_m'] * 1000:.0f} mm "
                   f"at a point: {frame_spans(bad)}; worst frame {w}, {names[int(np.argmax(err[w]))]} "
                   f"{frame_max[w] * 1000:.0f} mm"
                   + (f"; at a range's end in those frames: {', '.join(held)}" if held else "")
                   + ". Fix: check the map's points for those joints (`at:`, `from:`; retarget.csv has every "
                   "point's error per frame), give a coordinate the body allows a wider range (the map's `ranges:`)"
                   ", or the motion's unit (--units)")
    root = set(res.points.root.tolist())
    n = len(at_end)
    for c in res.points.free:
        frames = np.nonzero(at_end[:, c])[0]
        if not len(frames) or (c not in root and len(frames) <= tol.RETARGET_PINNED_SHARE * n):
            continue
        coord = skel.coordinates[c]
        lo, hi = coord.range
        why = "a coordinate of the root" if c in root else f"more than {tol.RETARGET_PINNED_SHARE:.0%} of the take"
        out.append(f"{coord.name} is held at an end of its range [{lo:g}, {hi:g}] in {len(frames)} of {n} frames "
                   f"({why}): {frame_spans(frames)}. Fix: widen it in the map, `ranges: {{{coord.name}: [LO, HI]}}`, "
                   "if the body can go there, or check the map's points that move it")
    lo, hi = tol.RETARGET_SCALE_BAND
    if res.scale_source == "fit" and not lo <= res.world.scale <= hi:
        out.append(f"the fitted scale {res.world.scale:.3g} makes the subject {res.world.scale:.3g} times the model's "
                   f"size (a {b['body_height_m']:.2f} m body; expected {lo:g} to {hi:g} times). Fix: the motion's "
                   "unit (--units, --scale), or `scale:` in the map")
    return out


def room_notes(res) -> list[str]:
    """The room coordinates that leave the model file's range (which the fit ignored)."""
    out = []
    model = res.rmap.model
    for name in res.rmap.room:
        c = model.coord_index[name]
        rng = model.coordinates[c].range
        if rng is None:
            continue
        v = res.fit.q[:, c]
        n = int(((v < rng[0]) | (v > rng[1])).sum())
        if n:
            out.append(f"{name} (the subject's place or heading in the room) is fitted free of the skeleton's range "
                       f"[{rng[0]:g}, {rng[1]:g}] and leaves it in {n} frames ({v.min():.4g} to {v.max():.4g}); "
                       "`axdf run` reports those frames, --clamp-ranges would hold it inside")
    return out
