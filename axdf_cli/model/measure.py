"""Shape measures of muscle meshes.

**Belly slenderness**: how much a mesh looks like a muscle belly rather than a bulb.
Along the mesh's principal axis (its axis of least inertia, the closed mesh taken as a solid
of uniform density) the mesh is cut by PLANES evenly spaced planes; each cut's width is the
diameter of the circle of the same area (the cut's area by Green's theorem over the cut
segments of the outward-wound triangles, so several loops add up). The slenderness is the
length over which the width is at least half the widest, divided by the widest width:

    slenderness = |{s : width(s) >= width_max / 2}| / width_max

A sphere gives 0.87 (sqrt(3)/2), a cylinder of length L and diameter D about L / D, a fusiform
belly between thin tendons about its belly length over its diameter. The area, not the largest
extent of a cut, is what counts: a plane that grazes a tendon lying across it (a tendon
turning under the foot) cuts a long thin sliver, wide but of small area.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Cutting planes along the principal axis: the length is resolved to 1/PLANES of the extent.
PLANES = 400


@dataclass(frozen=True)
class Slenderness:
    ratio: float  # length at >= half the widest width / widest width
    width: float  # the widest cut's diameter (m)
    length: float  # length along the principal axis where the width is >= width / 2 (m)


def principal_axis(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Unit axis of least inertia of the closed mesh (a solid of uniform density)."""
    import trimesh

    mesh = trimesh.Trimesh(np.asarray(vertices, dtype=np.float64), faces, process=False)
    comps, vecs = mesh.principal_inertia_components, mesh.principal_inertia_vectors
    return np.asarray(vecs[int(np.argmin(comps))], dtype=np.float64)


def cut_widths(vertices: np.ndarray, faces: np.ndarray, axis: np.ndarray, planes: int = PLANES):
    """Plane positions s (K,) along ``axis`` and the equivalent diameter 2 sqrt(A / pi) of the
    mesh's cut at each (K,); the mesh is closed and wound outwards."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    v = v - v.mean(axis=0)  # small numbers in the area sums
    s = v @ axis
    lo, hi = float(s.min()), float(s.max())
    step = (hi - lo) / planes
    pos = lo + step * (np.arange(planes) + 0.5)
    sf = s[f]  # (T, 3)
    # (face, plane) pairs: a face is cut by the planes between its lowest and highest vertex
    k0 = np.ceil((sf.min(axis=1) - lo) / step - 0.5).astype(np.int64)
    k1 = np.floor((sf.max(axis=1) - lo) / step - 0.5).astype(np.int64)
    span = np.maximum(k1 - k0 + 1, 0)
    face = np.repeat(np.arange(len(f)), span)
    plane = np.repeat(k0, span) + np.arange(span.sum()) - np.repeat(np.cumsum(span) - span, span)
    d = sf[face] - pos[plane][:, None]  # (P, 3) signed heights of the three vertices
    d = np.where(d == 0.0, 1e-300, d)  # a vertex on the plane counts as above it
    ia, ib = np.array([0, 1, 2]), np.array([1, 2, 0])
    cross = d[:, ia] * d[:, ib] < 0  # (P, 3) edges that cross the plane
    keep = cross.sum(axis=1) == 2
    face, plane, d, cross = face[keep], plane[keep], d[keep], cross[keep]
    w = d[:, ia] / np.where(cross, d[:, ia] - d[:, ib], 1.0)  # (P, 3); used where the edge crosses
    va, vb = v[f[face][:, ia]], v[f[face][:, ib]]  # (P, 3, 3)
    pts = va + w[..., None] * (vb - va)
    first = np.argmax(cross, axis=1)
    second = 2 - np.argmax(cross[:, ::-1], axis=1)
    rows = np.arange(len(face))
    p, q = pts[rows, first], pts[rows, second]
    # orient each segment along axis x face normal: the cut loops then run one way round
    tri = v[f[face]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("pc,pc->p", q - p, np.cross(axis, normal)) < 0
    p, q = np.where(flip[:, None], q, p), np.where(flip[:, None], p, q)
    area2 = np.einsum("pc,c->p", np.cross(p, q), axis)  # twice the signed area per segment
    area = np.abs(np.bincount(plane, weights=area2, minlength=planes)) / 2.0
    return pos, 2.0 * np.sqrt(area / np.pi)


def belly_slenderness(vertices: np.ndarray, faces: np.ndarray, planes: int = PLANES) -> Slenderness:
    """The belly slenderness of one closed mesh (module doc)."""
    axis = principal_axis(vertices, faces)
    pos, widths = cut_widths(vertices, faces, axis, planes)
    wmax = float(widths.max())
    step = float(pos[1] - pos[0]) if len(pos) > 1 else 0.0
    length = step * int(np.count_nonzero(widths >= 0.5 * wmax))
    return Slenderness(length / wmax if wmax > 0 else 0.0, wmax, length)
