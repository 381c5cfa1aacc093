"""The fast PLY/OBJ writers give exactly the bytes of the original (simple) writers."""
from __future__ import annotations

import numpy as np
import pytest

from axdf_cli.formats import ObjWriter, PlyWriter
from axdf_cli.formats import read_triangles
from axdf_cli.model.muscle import grid_faces


# ---- the original implementations (reference for byte identity) ----------------------------

def old_ply_encode(faces, name, positions, normals) -> bytes:
    faces = np.asarray(faces, dtype=np.int32)
    rec = np.empty(len(faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rec["n"] = 3
    rec["i"] = faces
    lines = ["ply", "format binary_little_endian 1.0"]
    if name:
        lines.append(f"comment axdf muscle {name}")
    lines += [f"element vertex {len(positions)}",
              "property float x", "property float y", "property float z",
              "property float nx", "property float ny", "property float nz",
              f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header", ""]
    v = np.empty((len(positions), 6), dtype="<f4")
    v[:, :3] = positions
    v[:, 3:] = normals
    return b"".join(["\n".join(lines).encode("ascii"), v.tobytes(), rec.tobytes()])


def old_obj_encode(faces, name, positions, normals) -> bytes:
    f = np.asarray(faces, dtype=np.int64) + 1
    fb = (("f %d//%d %d//%d %d//%d\n" * len(f)) % tuple(np.repeat(f, 2, axis=1).ravel())).encode("ascii")
    head = (f"o {name}\n" if name else "").encode("ascii")
    n = len(positions)
    p = np.round(np.asarray(positions, dtype=np.float64), 6) + 0.0
    nn = np.round(np.asarray(normals, dtype=np.float64), 6) + 0.0
    v = ("v %.6f %.6f %.6f\n" * n) % tuple(p.ravel())
    vn = ("vn %.6f %.6f %.6f\n" * n) % tuple(nn.ravel())
    return b"".join([head, v.encode("ascii"), vn.encode("ascii"), fb])


def stress_arrays(seed: int, n: int):
    """Positions (float32 and float64) and normals with precision-stressing values."""
    rng = np.random.default_rng(seed)
    p = rng.normal(scale=0.3, size=(n, 3))
    special = np.array([0.0, -0.0, 1e-7, -1e-7, 4e-7, -4e-7, 5e-7, -5e-7, 5.5e-7, -5.5e-7, 1.5e-6, 2.5e-6,
                        0.9999995, -0.9999995, 0.1234565, 999.9999994, -999.9999994, 123.456789, 1e-300])
    p.ravel()[:len(special)] = special
    # halfway cases of the 7th decimal
    k = min(50, p.size - len(special))
    p.ravel()[len(special):len(special) + k] = (rng.integers(-10**6, 10**6, k) + 0.5) * 1e-6
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return p, nrm


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("name", ["vastus_lat_r", ""])
def test_ply_and_obj_bytes_match_the_original_writers(seed, dtype, name):
    faces = grid_faces(12, 8)
    n = 2 + 10 * 8
    p, nrm = stress_arrays(seed, n)
    p, nrm = p.astype(dtype), nrm.astype(dtype)
    for new, old in ((PlyWriter(faces, name), old_ply_encode), (ObjWriter(faces, name), old_obj_encode)):
        ref = old(faces, name, p, nrm)
        assert new.encode(p, nrm) == ref
        assert new.encode(p * 2, nrm) == old(faces, name, p * 2, nrm)  # buffer reuse across frames
        assert new.encode(p, nrm) == ref


def test_obj_fallback_for_large_and_non_finite_coordinates():
    faces = grid_faces(8, 3)
    p, nrm = stress_arrays(5, 2 + 6 * 3)
    for bad in (1234.5, -1e7, np.nan, np.inf):
        q = p.copy()
        q[3, 1] = bad
        assert ObjWriter(faces, "m").encode(q, nrm) == old_obj_encode(faces, "m", q, nrm)


def test_write_is_atomic_and_equals_encode(tmp_path):
    import hashlib

    faces = grid_faces(6, 5)
    p, nrm = stress_arrays(3, 2 + 4 * 5)
    for w in (PlyWriter(faces, "m"), ObjWriter(faces, "m")):
        path = tmp_path / w.extension / f"m_0000.{w.extension}"
        assert w.write(path, p, nrm) is None
        data = path.read_bytes()
        assert data == w.encode(p, nrm)
        assert w.write(path, p, nrm, sha256=True) == hashlib.sha256(data).hexdigest()
        assert sorted(x.name for x in path.parent.iterdir()) == [path.name]  # no temporaries left


def test_ply_round_trip_and_vertex_count_change():
    faces = grid_faces(6, 5)
    w = PlyWriter(faces, "m")
    p, nrm = stress_arrays(4, 2 + 4 * 5)
    rp, rn, rf = read_triangles(w.encode(p, nrm), ".ply")
    np.testing.assert_array_equal(rp, p.astype(np.float32))
    np.testing.assert_array_equal(rn, nrm.astype(np.float32))
    np.testing.assert_array_equal(rf, faces)
    q, m = p[:7], nrm[:7]  # another vertex count re-lays the buffer out
    assert w.encode(q, m) == old_ply_encode(faces, "m", q, m)
    with pytest.raises(ValueError):
        w.encode(p, nrm[:-1])
