"""Mesh comparison (PLY and OBJ): exact topology, then per-vertex distances.

Small numpy readers keep the file's vertex order exactly (trimesh's OBJ loader may merge or
split vertices by normals). Faces are kept as polygon sizes plus a flat index array, so
triangles and any other polygons compare alike.
"""
from __future__ import annotations

import re
import warnings
from dataclasses import dataclass

import numpy as np

from axdf_cli.compare.result import Outcome, Unreadable, read_side
from axdf_cli.compare.tolerances import MeshTol


@dataclass(frozen=True)
class Mesh:
    vertices: np.ndarray  # (V, 3) float64
    normals: np.ndarray | None  # (V, 3) float64 per-vertex normals, or None
    face_sizes: np.ndarray  # (M,) int64 vertices per face
    face_indices: np.ndarray  # (sum(face_sizes),) int64 zero-based vertex indices

    def __post_init__(self):
        v = self.vertices
        if v.ndim != 2 or v.shape[1] != 3:
            raise Unreadable(f"vertices have shape {v.shape}, expected (V, 3)")
        if self.normals is not None and self.normals.shape != v.shape:
            raise Unreadable(f"{len(self.normals)} normals for {len(v)} vertices")
        if int(self.face_sizes.sum()) != len(self.face_indices):
            raise Unreadable("face sizes and indices disagree")
        if len(self.face_indices) and (self.face_indices.min() < 0 or self.face_indices.max() >= len(v)):
            raise Unreadable(f"a face index is outside 0..{len(v) - 1}")


# ----------------------------------------------------------------------------- PLY
_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_ply(data: bytes) -> Mesh:
    """Read a PLY (binary little/big endian or ascii) with a ``vertex`` element (x y z,
    optional nx ny nz) and an optional ``face`` element (``list <count> <index>``)."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise Unreadable("not a PLY file (no 'ply' magic or no end_header)")
    nl = data.find(b"\n", end)
    if nl < 0:
        raise Unreadable("PLY header is not terminated")
    body = memoryview(data)[nl + 1:]
    fmt = None
    elements: list[tuple[str, int, list]] = []  # (name, count, [(prop, type) | (prop, (count_t, item_t))])
    for line in data[:end].decode("ascii", "replace").splitlines():
        tok = line.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        try:
            if tok[0] == "format":
                fmt = tok[1]
            elif tok[0] == "element":
                elements.append((tok[1], int(tok[2]), []))
            elif tok[0] == "property" and tok[1] == "list":
                elements[-1][2].append((tok[4], (_PLY_TYPES[tok[2]], _PLY_TYPES[tok[3]])))
            elif tok[0] == "property":
                elements[-1][2].append((tok[2], _PLY_TYPES[tok[1]]))
        except (IndexError, KeyError, ValueError):
            raise Unreadable(f"bad PLY header line {line!r}") from None
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise Unreadable(f"PLY format {fmt!r} is not binary_little_endian, binary_big_endian or ascii")
    if fmt == "ascii":
        return _ply_ascii(bytes(body).decode("ascii", "replace"), elements)
    order = "<" if fmt == "binary_little_endian" else ">"
    arrays: dict[str, dict] = {}
    pos = 0
    for name, count, props in elements:
        if all(not isinstance(t, tuple) for _, t in props):
            dt = np.dtype([(p, order + t) for p, t in props])
            need = dt.itemsize * count
            if pos + need > len(body):
                raise Unreadable(f"PLY file ends inside element {name!r}")
            rec = np.frombuffer(body, dt, count, pos)
            pos += need
            arrays[name] = {p: rec[p] for p, _ in props}
            continue
        if len(props) != 1:
            raise Unreadable(f"PLY element {name!r} mixes a list with other properties")
        pname, (ct, it) = props[0]
        sizes, flat, pos = _read_list(body, pos, count, order + ct, order + it, name)
        arrays[name] = {pname: (sizes, flat)}
    v = arrays.get("vertex")
    if v is None or not all(k in v for k in "xyz"):
        raise Unreadable("PLY has no vertex element with x, y, z")
    verts = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64)
    normals = None
    if all(k in v for k in ("nx", "ny", "nz")):
        normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1).astype(np.float64)
    sizes, flat = _faces_of(arrays)
    return Mesh(verts, normals, sizes, flat)


def _read_list(body, pos, count, ct, it, name):
    """Read ``count`` lists; fast path when every list has the first list's length."""
    ct, it = np.dtype(ct), np.dtype(it)
    if count == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), pos
    if pos + ct.itemsize > len(body):
        raise Unreadable(f"PLY file ends inside element {name!r}")
    k = int(np.frombuffer(body, ct, 1, pos)[0])
    dt = np.dtype([("n", ct), ("i", it, (k,))])
    if pos + dt.itemsize * count <= len(body):
        rec = np.frombuffer(body, dt, count, pos)
        if np.all(rec["n"] == k):
            return (np.full(count, k, np.int64), rec["i"].reshape(-1).astype(np.int64),
                    pos + dt.itemsize * count)
    sizes, chunks = [], []  # mixed polygon sizes: one list at a time
    for _ in range(count):
        if pos + ct.itemsize > len(body):
            raise Unreadable(f"PLY file ends inside element {name!r}")
        n = int(np.frombuffer(body, ct, 1, pos)[0])
        pos += ct.itemsize
        if pos + n * it.itemsize > len(body):
            raise Unreadable(f"PLY file ends inside element {name!r}")
        chunks.append(np.frombuffer(body, it, n, pos))
        pos += n * it.itemsize
        sizes.append(n)
    flat = np.concatenate(chunks).astype(np.int64) if chunks else np.zeros(0, np.int64)
    return np.asarray(sizes, np.int64), flat, pos


def _faces_of(arrays) -> tuple[np.ndarray, np.ndarray]:
    f = arrays.get("face")
    if not f:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    value = next(iter(f.values()))
    if not isinstance(value, tuple):
        raise Unreadable("PLY face element has no vertex index list")
    return value


def _ply_ascii(text: str, elements) -> Mesh:
    lines = iter(text.splitlines())
    arrays: dict[str, dict] = {}
    try:
        for name, count, props in elements:
            rows = [next(lines).split() for _ in range(count)]
            if props and isinstance(props[0][1], tuple):
                sizes = np.array([int(r[0]) for r in rows], np.int64)
                flat = np.array([int(x) for r in rows for x in r[1:1 + int(r[0])]], np.int64)
                arrays[name] = {props[0][0]: (sizes, flat)}
            else:
                a = np.array(rows, np.float64).reshape(count, len(props))
                arrays[name] = {p: a[:, j] for j, (p, _) in enumerate(props)}
    except (StopIteration, ValueError):
        raise Unreadable("ascii PLY body is short or not numeric") from None
    v = arrays.get("vertex", {})
    if not all(k in v for k in "xyz"):
        raise Unreadable("PLY has no vertex element with x, y, z")
    verts = np.stack([v["x"], v["y"], v["z"]], axis=1)
    normals = np.stack([v["nx"], v["ny"], v["nz"]], axis=1) if all(k in v for k in ("nx", "ny", "nz")) else None
    sizes, flat = _faces_of(arrays)
    return Mesh(verts, normals, sizes, flat)


# ----------------------------------------------------------------------------- OBJ
_OBJ_V = re.compile(rb"^v[ \t]+([^\n]*)", re.M)
_OBJ_VN = re.compile(rb"^vn[ \t]+([^\n]*)", re.M)
_OBJ_F = re.compile(rb"^f[ \t]+([^\n]*)", re.M)


def _parse_numbers(text: bytes, dtype, what: str) -> np.ndarray:
    """Whitespace-separated numbers -> ``(n,)`` array at C speed; any other text is Unreadable."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy warns (not raises) when it stops at bad text
        try:
            return np.fromstring(text, dtype=dtype, sep=" ")
        except (ValueError, DeprecationWarning):
            raise Unreadable(f"an OBJ {what} line is not numeric") from None


def _obj_numbers(lines: list[bytes], what: str, dtype) -> np.ndarray:
    """The numbers of OBJ lines (without their keyword) as ``(len(lines), k)``; every line
    must have the same count k."""
    if not lines:
        return np.zeros((0, 3), dtype)
    out = _parse_numbers(b" ".join(lines), dtype, what)
    if out.size % len(lines):
        raise Unreadable(f"OBJ {what} lines have different numbers of values")
    return out.reshape(len(lines), -1)


def read_obj(data: bytes) -> Mesh:
    """Read ``v``/``vn``/``f`` lines of an OBJ in file order. Per-vertex normals are taken
    when every face corner names the normal with its vertex's own index (``f a//a``)."""
    v = _obj_numbers(_OBJ_V.findall(data), "v", np.float64)
    if v.shape[1] < 3:
        raise Unreadable("OBJ 'v' lines have fewer than 3 values")
    verts = v[:, :3]  # x y z (a w or a colour may follow)
    vn = _obj_numbers(_OBJ_VN.findall(data), "vn", np.float64)
    face_lines = _OBJ_F.findall(data)
    if not face_lines:
        return Mesh(verts, vn if len(vn) == len(verts) and len(vn) else None,
                    np.zeros(0, np.int64), np.zeros(0, np.int64))
    sizes = np.array([len(line.split()) for line in face_lines], np.int64)
    joined = b" ".join(face_lines)
    first = joined.split(None, 1)[0]
    # every corner written alike: a | a/t | a//n | a/t/n -> (vertex, texture, normal) columns
    if b"//" in first:
        text, cols = joined.replace(b"//", b" "), ("v", "n")
    else:
        cols = ("v", "t", "n")[: first.count(b"/") + 1]
        text = joined.replace(b"/", b" ")
    n_corners = int(sizes.sum())
    idx = _parse_numbers(text, np.int64, "f")
    if idx.size != n_corners * len(cols):
        raise Unreadable("OBJ face corners are not all written alike (a, a/t, a//n or a/t/n)")
    idx = idx.reshape(n_corners, len(cols))
    flat = idx[:, 0]
    flat = np.where(flat < 0, flat + len(verts), flat - 1)  # 1-based; negative is relative
    normals = None
    if "n" in cols and len(vn) == len(verts):
        ni = idx[:, cols.index("n")]
        ni = np.where(ni < 0, ni + len(vn), ni - 1)
        if np.array_equal(ni, flat):
            normals = vn[:, :3]
    return Mesh(verts, normals, sizes, flat)


READERS = {".ply": read_ply, ".obj": read_obj}


# ----------------------------------------------------------------------------- comparison
def hausdorff(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Hausdorff distance between two vertex sets ``(Va, 3)``, ``(Vb, 3)``
    (nearest vertex both ways with scipy's cKDTree)."""
    if len(a) == 0 or len(b) == 0:
        return float("inf") if len(a) != len(b) else 0.0
    from scipy.spatial import cKDTree

    d_ab = cKDTree(b).query(a)[0]
    d_ba = cKDTree(a).query(b)[0]
    return float(max(d_ab.max(), d_ba.max()))


def compare_meshes(a: Mesh, g: Mesh, tol: MeshTol) -> Outcome:
    """Topology must match exactly (vertex count, face sizes and indices); then the maximum
    and RMS vertex distance and the maximum normal difference are held against ``tol``."""
    metrics: dict = {"vertices": len(g.vertices), "faces": len(g.face_sizes)}
    reasons: list[str] = []
    same_faces = (np.array_equal(a.face_sizes, g.face_sizes) and np.array_equal(a.face_indices, g.face_indices))
    if len(a.vertices) != len(g.vertices) or not same_faces:
        h = hausdorff(a.vertices, g.vertices)
        metrics.update(actual_vertices=len(a.vertices), actual_faces=len(a.face_sizes), hausdorff=h)
        if len(a.vertices) != len(g.vertices) or len(a.face_sizes) != len(g.face_sizes):
            what = (f"{len(a.vertices)} vertices, {len(a.face_sizes)} faces vs golden "
                    f"{len(g.vertices)} vertices, {len(g.face_sizes)} faces")
        else:
            what = f"same counts but {_first_face_difference(a, g)}"
        return Outcome(False, (f"topology differs: {what}; Hausdorff distance {h:.3g} m",), metrics)
    d = np.linalg.norm(a.vertices - g.vertices, axis=1)  # (V,)
    if len(d) == 0:
        return Outcome(True, (), metrics | {"max_distance": 0.0, "rms_distance": 0.0})
    if not np.all(np.isfinite(a.vertices)):
        reasons.append(f"{int(np.sum(~np.isfinite(a.vertices).all(axis=1)))} vertices are not finite")
    worst = int(np.nanargmax(d)) if np.any(np.isfinite(d)) else 0
    dmax = float(np.max(d))
    rms = float(np.sqrt(np.mean(d * d)))
    metrics.update(max_distance=dmax, rms_distance=rms, worst_vertex=worst,
                   vertices_over=int(np.sum(~(d <= tol.max_distance))))
    if not dmax <= tol.max_distance:
        reasons.append(f"max vertex distance {dmax:.3g} m (vertex {worst}) > {tol.max_distance:g} m; "
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
    a = read_side("actual", READERS[a_suffix], a_bytes)
    g = read_side("golden", READERS[g_suffix], g_bytes)
    return compare_meshes(a, g, tol)
