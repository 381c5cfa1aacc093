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
