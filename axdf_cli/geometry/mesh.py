"""Closing a mesh's holes so that its winding number says inside or outside everywhere."""
from __future__ import annotations

import numpy as np


def capped(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh (vertices (V, 3), faces (T, 3)) with every boundary loop closed by a fan to the
    loop's centroid, wound as the loop's triangles are, so that its winding number says inside
    or outside everywhere (gait2392's torso is open at the neck, its skull at the orbits and
    the foramen) → (vertices (V + L, 3) float64, faces (T + sum of the L loops' lengths, 3)
    int64); a mesh with no boundary comes back as it is (in those dtypes)."""
    v, f = np.asarray(vertices, np.float64), np.asarray(faces, np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    _, inv, cnt = np.unique(np.sort(e, axis=1), axis=0, return_inverse=True, return_counts=True)
    nxt = {int(a): int(b) for a, b in e[cnt[inv.ravel()] == 1]}  # each boundary edge, as wound
    seen, centres, fans = set(), [], []
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, c = [start], nxt[start]
        seen.add(start)
        while c != start and c in nxt and c not in seen:
            loop.append(c)
            seen.add(c)
            c = nxt[c]
        centre = len(v) + len(centres)
        centres.append(v[loop].mean(axis=0))
        fans += [(loop[(k + 1) % len(loop)], loop[k], centre) for k in range(len(loop))]
    if not centres:
        return v, f
    return np.concatenate([v, np.array(centres)]), np.concatenate([f, np.array(fans, np.int64)])


def surface_problem(faces: np.ndarray, n: int) -> str | None:
    """What keeps triangles (T, 3) over ``n`` vertices from being one closed, manifold,
    consistently wound surface (every vertex on a triangle, no repeated corner, every directed
    edge once and its reverse once), as words after the mesh's name; None when nothing does."""
    faces = np.asarray(faces, np.int64)
    nf = len(faces)
    if nf < 4:
        return f"has {nf} triangle{'s' if nf != 1 else ''}, no closed surface"
    if ((faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])).any():
        return "has triangles with a repeated corner"
    loose = np.flatnonzero(np.bincount(faces.ravel(), minlength=n) == 0)
    if len(loose):
        return f"has {len(loose)} vertices on no triangle (the first, vertex {int(loose[0])})"
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()  # the directed edges a -> b of every triangle
    key = a * n + b
    uniq, count = np.unique(key, return_counts=True)
    if (count > 1).any():
        k = int(uniq[np.argmax(count > 1)])
        return (f"is not manifold or not wound consistently: the edge {k // n}-{k % n} runs the same way in "
                f"{int(count.max())} triangles")
    open_ = ~np.isin(b * n + a, uniq)
    if open_.any():
        return f"is open: {int(open_.sum())} edges border one triangle only"
    return None
