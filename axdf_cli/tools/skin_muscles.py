"""The muscles under a fitted skin at rest: how many of their vertices lie outside it, and the
rest skin grown outward until they lie inside (``axdf skin --muscles DIR [--push]``).

Inside is the skin's winding number (:mod:`axdf_cli.geometry.winding`: the skin is one closed
surface). The growth (:func:`~axdf_cli.geometry.grow.grow_over`) moves skin vertices outward along their normals, over
the muscle vertices outside, by how far out each one is plus tol.SKIN_PUSH_CLEARANCE, each push
spread over the skin around it so that the skin bulges instead of spiking.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.tools import constants as tol
from axdf_cli.errors import InputError, Mark
from axdf_cli.geometry.grow import neighbour_mean
from axdf_cli.geometry.winding import inside, inside_of, winding_numbers
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
        w = winding_numbers(bv, bf, v[near], exact=True)  # (skin vertices close to a bone: exact)
        into = near[inside_of(w)]
        if not len(into):
            continue
        _, tri, closest = igl.point_mesh_squared_distance(v[into], bv, bf)
        a, b, c = bv[bf[tri, 0]], bv[bf[tri, 1]], bv[bf[tri, 2]]
        n = np.cross(b - a, c - a) * np.sign(np.mean(w))  # (a mesh wound inward)
        out = closest - v[into]  # from inside to the nearest surface point: the way out
        on = np.linalg.norm(out, axis=1) < 1e-9  # (on the surface: the triangle's normal)
        out[on] = n[on]
        out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-300)
        v[into] = closest + out * tol.SKIN_PUSH_CLEARANCE
        moved[into] = True
    return v, moved
