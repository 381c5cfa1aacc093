"""Measures of a body from its skeleton's joints: its height (stature), head top to sole.

One definition for every command that states a person's height (``axdf skin``'s stature,
``axdf retarget``'s subject): :func:`stature`. A skeleton has joints, not a head top or a sole,
so the height is its joints' lengths at rest plus documented allowances: the segment fractions
of body height H of Drillis & Contini (1966), as Winter tabulates them (*Biomechanics and Motor
Control of Human Movement*, 4th ed., 2009, Fig. 4.1):

- **with shoulders**: H = (thigh + shank + hip centre to shoulder centre) / (1 - 0.039 - 0.182):
  below the ankles, sole to ankle, 0.039 H (:data:`SOLE_FRACTION`); above the shoulder joints,
  the head allowance, shoulder to head top, 0.182 H (:data:`HEAD_FRACTION`);
- **legs only**: H = (thigh + shank) / 0.491 (:data:`LEG_FRACTION`: thigh 0.245 H, shank 0.246 H).

Lengths are measured joint to joint (the mean of the two sides), so a rest pose that is not
upright (legs spread, a stoop) measures the same person.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

#: Thigh + shank, hip joint to ankle joint, as a share of stature (0.245 + 0.246).
LEG_FRACTION = 0.491
#: Sole to ankle joint, as a share of stature.
SOLE_FRACTION = 0.039
#: The head allowance: shoulder joint to head top, as a share of stature (1 - 0.818).
HEAD_FRACTION = 0.182

#: The joints :func:`stature` reads: each side's hip, knee and ankle; the shoulders if any.
LEG_JOINTS = ("hip", "knee", "ankle")


def _mean_length(joints: Mapping[str, np.ndarray], a: str, b: str) -> float:
    return float(np.mean([np.linalg.norm(np.asarray(joints[f"{b}_{s}"]) - np.asarray(joints[f"{a}_{s}"]))
                          for s in "lr"]))


def stature(joints: Mapping[str, np.ndarray]) -> float:
    """The body's height, head top to sole (metres), from its joint centres at rest (module
    doc): ``joints`` maps ``hip_l``, ``hip_r``, ``knee_l``, ``knee_r``, ``ankle_l``,
    ``ankle_r`` and, when the skeleton has them, ``shoulder_l``, ``shoulder_r`` to (3,)
    positions."""
    leg = _mean_length(joints, "hip", "knee") + _mean_length(joints, "knee", "ankle")
    if "shoulder_l" not in joints or "shoulder_r" not in joints:
        return leg / LEG_FRACTION
    hips = (np.asarray(joints["hip_l"]) + np.asarray(joints["hip_r"])) / 2
    shoulders = (np.asarray(joints["shoulder_l"]) + np.asarray(joints["shoulder_r"])) / 2
    trunk = float(np.linalg.norm(shoulders - hips))
    return (leg + trunk) / (1.0 - SOLE_FRACTION - HEAD_FRACTION)
