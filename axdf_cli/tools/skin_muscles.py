"""The muscles under a fitted skin at rest: how many of their vertices lie outside it, and the
rest skin pushed outward until they lie inside (``axdf skin --muscles DIR [--push]``).

Inside is the skin's winding number (libigl's fast winding number: the skin is one closed
surface) over one half. The push moves skin vertices outward along their normals, over the
muscle vertices outside, by how far out each one is plus tol.SKIN_PUSH_CLEARANCE, each push
spread over the skin around it so that the skin bulges instead of spiking.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.skeleton import Skeleton, forward_kinematics
from axdf_cli.specs import RefPolicy, expand_muscle_paths
from axdf_cli.specs.muscle import load_muscle_file


def rest_muscle_vertices(folder: Path, skel: Skeleton, policy: RefPolicy | None = None) -> tuple[np.ndarray, int, list]:
    """Every vertex of every muscle in ``folder`` at the skeleton's rest pose, evaluated by axdf
    (zero tension): (N, 3), the number of muscles, the files read."""
    files = expand_muscle_paths([(Path(folder), Mark(str(folder)))], policy)
    specs = [s for f in files for s in load_muscle_file(f)]
    if not specs:
        raise InputError(Mark(str(folder)), "no muscles found", "a folder of muscle YAML files on the skeleton")
    world = forward_kinematics(skel, skel.rest_coordinates()[None])
    q = skel.rest_coordinates()[None]
    pts = []
    for spec in specs:
        for b in spec_bones(spec):
            if b not in skel.bone_index:
                raise InputError(Mark(str(folder)), f"muscle {spec.name!r} is on bone {b!r}, which skeleton "
                                 f"{skel.name!r} lacks", "muscles of the skeleton given as --skeleton")
        model = MuscleModel(spec, skel.bone_index, world[0], skel)
        pts.append(model.evaluate(world, np.zeros(1), coords=q).vertices[0])
    return np.concatenate(pts), len(specs), files


def spec_bones(spec) -> set:
    from axdf_cli.model.pose import muscle_bones

    return muscle_bones(spec)


def rest_bones(skel: Skeleton, skeleton_file: str, worn) -> tuple[list, list]:
    """The meshes of the bones the skin wears (``worn``: bone names) at the skeleton's rest
    pose, their holes capped (:func:`capped`): [((V, 3) float64, (T, 3) int64)], and the mesh
    files read."""
    from axdf_cli.pipeline.plan import rest_bone_meshes

    meshes = rest_bone_meshes(skel, skeleton_file, lambda b: b.name in worn).values()
    return [capped(v, f) for v, f, _ in meshes], [path for _, _, path in meshes]


def capped(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The mesh with every boundary loop closed by a fan to the loop's centroid, so that its
    winding number says inside or outside everywhere (gait2392's torso is open at the neck, its
    skull at the orbits and the foramen)."""
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


def bone_points(meshes: list) -> np.ndarray:
    """Points for the push over bones: every vertex and every triangle's centroid (a coarse
    skull's triangles stick out between its vertices)."""
    return np.concatenate([np.zeros((0, 3))] + [p for v, f in meshes for p in (v, v[f].mean(axis=1))])


def clear_bones(vertices: np.ndarray, faces: np.ndarray, meshes: list) -> tuple[np.ndarray, int]:
    """The skin with no vertex inside a bone mesh (winding number): MakeHuman's eye sockets and
    lips dip into a skull that has none. Each vertex inside is moved out onto the bone's
    surface (:func:`_snap_out`), then the skin around the moved ones is smoothed (its normals
    must point out again for the skin stage's push) and the snap repeated,
    ``tol.SKIN_PUSH_ROUNDS`` rounds at most; → (vertices, how many were inside at first)."""
    from axdf_cli.tools.skin import neighbour_mean

    avg = neighbour_mean(faces, len(vertices))
    v, inside = _snap_out(np.array(vertices, dtype=np.float64), meshes)
    first = int(inside.sum())
    for _ in range(tol.SKIN_PUSH_ROUNDS):
        if not inside.any():
            break
        near = inside.astype(np.float64)
        for _ in range(tol.SKIN_PUSH_SMOOTHING):
            near = np.maximum(near, avg @ near)
        around = near > 0
        v[around] = (avg @ v)[around]
        v, inside = _snap_out(v, meshes)
    return v, first


def _snap_out(v: np.ndarray, meshes: list) -> tuple[np.ndarray, np.ndarray]:
    """Every vertex of ``v`` inside a bone mesh put ``tol.SKIN_PUSH_CLEARANCE`` outside its
    surface, past the nearest surface point along the way there (in place) → (v, which were
    inside)."""
    import igl

    moved = np.zeros(len(v), bool)
    for bv, bf in meshes:
        lo, hi = bv.min(axis=0), bv.max(axis=0)
        near = np.flatnonzero(np.all((v > lo) & (v < hi), axis=1))
        if not len(near):
            continue
        w = igl.winding_number(bv, bf, v[near])
        inside = near[np.abs(w) > 0.5]
        if not len(inside):
            continue
        _, tri, closest = igl.point_mesh_squared_distance(v[inside], bv, bf)
        a, b, c = bv[bf[tri, 0]], bv[bf[tri, 1]], bv[bf[tri, 2]]
        n = np.cross(b - a, c - a) * np.sign(np.mean(w))  # (a mesh wound inward)
        out = closest - v[inside]  # from inside to the nearest surface point: the way out
        on = np.linalg.norm(out, axis=1) < 1e-9  # (on the surface: the triangle's normal)
        out[on] = n[on]
        out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
        v[inside] = closest + out * tol.SKIN_PUSH_CLEARANCE
        moved[inside] = True
    return v, moved


def outside(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(N,) bool: the points that lie outside the closed surface (vertices, faces)."""
    import igl

    w = igl.fast_winding_number(np.ascontiguousarray(vertices, dtype=np.float64),
                                np.ascontiguousarray(faces, dtype=np.int64),
                                np.ascontiguousarray(points, dtype=np.float64))
    return w < 0.5


def push_out(vertices: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """The skin moved outward (tol.SKIN_PUSH_ROUNDS rounds at most) so that ``points`` lie inside it."""
    import igl
    import trimesh

    from axdf_cli.tools.skin import neighbour_mean

    v = np.array(vertices, dtype=np.float64)
    f64 = np.ascontiguousarray(faces, dtype=np.int64)
    avg = neighbour_mean(faces, len(v))
    for _ in range(tol.SKIN_PUSH_ROUNDS):
        out = outside(v, faces, points)
        if not out.any():
            break
        p = points[out]
        d2, tri, _ = igl.point_mesh_squared_distance(p, v, f64)
        need = np.zeros(len(v))
        corners = faces[tri]  # (M, 3): every corner of the nearest triangle is pushed
        depth = np.sqrt(d2) + tol.SKIN_PUSH_CLEARANCE
        np.maximum.at(need, corners.ravel(), np.repeat(depth, 3))
        spread = need.copy()
        for _ in range(tol.SKIN_PUSH_SMOOTHING):  # the push spread over the skin around it, no less where needed
            spread = np.maximum(need, avg @ spread)
        normals = trimesh.Trimesh(v, faces, process=False).vertex_normals
        v = v + normals * spread[:, None]
    return v
