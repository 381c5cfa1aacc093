"""Mesh comparison (any format of :data:`axdf_cli.formats.FORMATS`, PLY and OBJ): exact
topology, then per-vertex distances, in the files' own vertex order. A file holding every
muscle of a frame (``--mesh-files frame``) is one mesh whose named parts
(:attr:`~axdf_cli.formats.Mesh.groups`) must match too; its worst vertex is named by its part."""
from __future__ import annotations

import numpy as np

from axdf_cli.compare.result import Outcome, read_side
from axdf_cli.compare.thresholds import MeshTol
from axdf_cli.formats import Mesh, read_mesh


# ----------------------------------------------------------------------------- comparison
def hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Hausdorff distance between two vertex sets ``(Va, 3)``, ``(Vb, 3)``
    (nearest vertex both ways with scipy's cKDTree); inf when either set holds a non-finite
    vertex (no distance to it is finite)."""
    if len(a) == 0 or len(b) == 0:
        return float("inf") if len(a) != len(b) else 0.0
    if not (np.isfinite(a).all() and np.isfinite(b).all()):
        return float("inf")
    from scipy.spatial import cKDTree

    d_ab = cKDTree(b).query(a)[0]
    d_ba = cKDTree(a).query(b)[0]
    return float(max(d_ab.max(), d_ba.max()))


def compare_meshes(a: Mesh, g: Mesh, tol: MeshTol) -> Outcome:
    """Topology must match exactly (vertex count, face sizes and indices); then the maximum
    and RMS vertex distance and the maximum normal difference are held against ``tol``."""
    metrics: dict = {"vertices": len(g.vertices), "faces": len(g.face_sizes)}
    reasons: list[str] = []
    if a.groups and g.groups and a.groups != g.groups:  # (a per-muscle OBJ names its one part, a PLY none)
        return Outcome(False, (f"named parts differ: {_parts_text(a.groups, g.groups)}",), metrics)
    same_faces = (np.array_equal(a.face_sizes, g.face_sizes) and np.array_equal(a.face_indices, g.face_indices))
    if len(a.vertices) != len(g.vertices) or not same_faces:
        h = hausdorff(a.vertices, g.vertices)
        metrics.update(actual_vertices=len(a.vertices), actual_faces=len(a.face_sizes), hausdorff=h)
        if len(a.vertices) != len(g.vertices) or len(a.face_sizes) != len(g.face_sizes):
            what = (f"{len(a.vertices)} vertices, {len(a.face_sizes)} faces vs golden "
                    f"{len(g.vertices)} vertices, {len(g.face_sizes)} faces")
        else:
            what = f"same counts but {_first_face_difference(a, g)}"
        reasons = [f"topology differs: {what}; Hausdorff distance {h:.3g} m"]
        reasons += _non_finite(a, "actual") + _non_finite(g, "golden")
        return Outcome(False, tuple(reasons), metrics)
    d = np.linalg.norm(a.vertices - g.vertices, axis=1)  # (V,)
    if len(d) == 0:
        return Outcome(True, (), metrics | {"max_distance": 0.0, "rms_distance": 0.0})
    reasons += _non_finite(a, "actual") + _non_finite(g, "golden")
    worst = int(np.nanargmax(d)) if np.any(np.isfinite(d)) else 0
    dmax = float(np.max(d))
    rms = float(np.sqrt(np.mean(d * d)))
    metrics.update(max_distance=dmax, rms_distance=rms, worst_vertex=worst,
                   vertices_over=int(np.sum(~(d <= tol.max_distance))))
    if len(g.groups) > 1:
        metrics["worst_part"] = _part_of(g.groups, worst)
    if not dmax <= tol.max_distance:
        reasons.append(f"max vertex distance {dmax:.3g} m (vertex {worst}{_in_part(g.groups, worst)}) > "
                       f"{tol.max_distance:g} m; "
                       f"{metrics['vertices_over']} of {len(d)} vertices over")
    if not rms <= tol.rms_distance:
        reasons.append(f"RMS vertex distance {rms:.3g} m > {tol.rms_distance:g} m")
    if (a.normals is None) != (g.normals is None):
        reasons.append("per-vertex normals in " + ("golden only" if a.normals is None else "actual only"))
    elif a.normals is not None:
        dn = np.linalg.norm(a.normals - g.normals, axis=1)
        nmax = float(np.max(dn))
        metrics["normal_max"] = nmax
        if not nmax <= tol.normal_max:
            reasons.append(f"normal difference {nmax:.3g} (vertex {int(np.nanargmax(dn)) if np.any(np.isfinite(dn)) else 0})"
                           f" > {tol.normal_max:g}")
    return Outcome(not reasons, tuple(reasons), metrics)


def _part_of(groups: tuple, vertex: int) -> str:
    """The name of the part (``Mesh.groups``) holding ``vertex``."""
    starts = [s for _, s in groups]
    return groups[max(0, int(np.searchsorted(starts, vertex, side="right")) - 1)][0]


def _in_part(groups: tuple, vertex: int) -> str:
    if len(groups) < 2:
        return ""
    name = _part_of(groups, vertex)
    start = next(s for n, s in groups if n == name)
    return f", vertex {vertex - start} of {name}"


def _parts_text(a: tuple, g: tuple) -> str:
    """The first difference between two files' named parts, in words."""
    an, gn = [n for n, _ in a], [n for n, _ in g]
    if an != gn:
        missing, extra = [n for n in gn if n not in an], [n for n in an if n not in gn]
        if missing or extra:
            return (f"{', '.join(missing[:5]) or 'none'} in golden only, {', '.join(extra[:5]) or 'none'} "
                    "in actual only")
        return f"order {', '.join(an[:5])} ... vs golden {', '.join(gn[:5])} ..."
    k = next(i for i, (x, y) in enumerate(zip(a, g)) if x != y)
    return f"part {gn[k]} starts at vertex {a[k][1]} vs golden {g[k][1]}"


def _non_finite(m: Mesh, side: str) -> list[str]:
    n = int(np.sum(~np.isfinite(m.vertices).all(axis=1)))
    return [f"{n} {side} vertices are not finite"] if n else []


def _first_face_difference(a: Mesh, g: Mesh) -> str:
    if not np.array_equal(a.face_sizes, g.face_sizes):
        i = int(np.flatnonzero(a.face_sizes != g.face_sizes)[0])
        return f"face {i} has {a.face_sizes[i]} corners vs golden {g.face_sizes[i]}"
    starts = np.concatenate([[0], np.cumsum(g.face_sizes)[:-1]])
    k = int(np.flatnonzero(a.face_indices != g.face_indices)[0])
    i = int(np.searchsorted(starts, k, side="right") - 1)
    s, n = starts[i], g.face_sizes[i]
    return (f"face {i} is {a.face_indices[s:s + n].tolist()} vs golden {g.face_indices[s:s + n].tolist()}")


def compare_mesh_files(a_bytes: bytes, g_bytes: bytes, a_suffix: str, g_suffix: str, tol: MeshTol) -> Outcome:
    a = read_side("actual", read_mesh, a_bytes, a_suffix)
    g = read_side("golden", read_mesh, g_bytes, g_suffix)
    return compare_meshes(a, g, tol)
