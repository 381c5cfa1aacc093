"""A skeleton's bone meshes: one read per mesh file (checked, with the bytes a run stores), and
the meshes placed in the world at the skeleton's rest pose."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.geometry.mesh import capped


def load_bone_mesh(path: str, skeleton_file: str) -> tuple[np.ndarray, np.ndarray, bytes]:
    """Read a bone's mesh (PLY or OBJ triangles, one read) → (vertices (V, 3) float32, faces
    (T, 3) as read, PLY bytes for the run's ``bones/<bone>.ply``: the file itself when it is a
    PLY, else the triangles written as one); bad files are input errors (``skeleton_file``:
    where a missing mesh is named)."""
    from axdf_cli.formats import PlyWriter, load_triangles_and_bytes

    if not Path(path).is_file():
        raise InputError(Mark(skeleton_file), f"bone mesh {path} not found", "a PLY file relative to the skeleton file")
    (v, _, f), data = load_triangles_and_bytes(path)
    if len(f) == 0:
        raise InputError(Mark(str(path)), "bone mesh has no triangles", "a PLY or OBJ mesh with at least one triangle")
    if not np.isfinite(v).all():
        raise InputError(Mark(str(path)), "non-finite vertex coordinates", "finite numbers only")
    if Path(path).suffix.lower() != "." + PlyWriter.extension:
        data = PlyWriter(f).encode(v)
    return np.ascontiguousarray(v, dtype=np.float32), f, data


def rest_bone_meshes(skel, skeleton_file: str, keep=None, cap: bool = False) -> dict:
    """The meshes of the skeleton's bones for which ``keep(bone)`` holds (None: every bone with
    a mesh), placed in the world at the rest pose: bone name -> ((V, 3) float64, (T, 3) int64,
    the mesh file's Path). ``cap``: each mesh's holes closed (:func:`~axdf_cli.geometry.mesh.capped`),
    so that its winding number says inside or outside everywhere."""
    from axdf_cli.model.skeleton import forward_kinematics

    world = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    out = {}
    for i, b in enumerate(skel.bones):
        if b.mesh and (keep is None or keep(b)):
            v, f, _ = load_bone_mesh(b.mesh, skeleton_file)
            v, f = v.astype(np.float64) @ world[i, :3, :3].T + world[i, :3, 3], np.asarray(f, np.int64)
            out[b.name] = (*(capped(v, f) if cap else (v, f)), Path(b.mesh))
    return out
