"""Read a finished run folder back into a :class:`Scene` and its frames (for ``axdf render``).

Kept in one place because the manifest format is not final. What is read:

- ``manifest.json``: ``muscles: [{name, color, ...}]`` (colour as linear ``[r, g, b]`` in
  0..1, or sRGB ``"#rrggbb"``), ``frames: [...]``, optional ``bones: [{name, mesh}]``
  (``mesh`` relative to the run folder, a PLY in bone-local coordinates) and optional render
  settings under ``settings.render`` or ``render``.
- ``meshes/<muscle>/<muscle>_<frame:04d>.ply`` (binary little-endian, float32 x y z nx ny
  nz, int32 triangle lists) or ``.obj`` (``v``, ``vn``, ``f a//a``).
- ``bones.csv``: ``frame,bone,x,y,z,qw,qx,qy,qz`` world pose of each bone per frame.
"""
from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path
from typing import Iterator

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.render.settings import RenderSettings, parse_render_settings
from axdf_cli.runfolder import MANIFEST, mesh_relpath
from axdf_cli.scene import FrameChunk, Scene, SceneBone, SceneMuscle

def read_mesh_file(path: Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """A PLY or OBJ triangle mesh -> (V, 3) float32 positions, (V, 3) float32 normals or
    None, (T, 3) int32 triangles; unreadable files are input errors."""
    from axdf_cli.formats.read import MeshReadError, read_mesh, triangles

    path = Path(path)
    try:
        mesh = read_mesh(path.read_bytes(), path.suffix)
        faces = triangles(mesh)
    except OSError as e:
        raise InputError(Mark(str(path)), f"cannot read mesh ({e.strerror})", "an existing PLY or OBJ file") from None
    except MeshReadError as e:
        raise InputError(Mark(str(path)), f"not a readable mesh ({e})", "a PLY or OBJ triangle mesh") from None
    nrm = None if mesh.normals is None else mesh.normals.astype(np.float32)
    return mesh.vertices.astype(np.float32), nrm, faces


_READERS = {".ply": read_mesh_file, ".obj": read_mesh_file}


def _color(c, where: Mark) -> tuple[float, float, float]:
    if isinstance(c, str) and len(c) == 7 and c.startswith("#"):
        srgb = np.array([int(c[i:i + 2], 16) for i in (1, 3, 5)]) / 255.0
        lin = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
        return tuple(float(x) for x in lin)
    if isinstance(c, list) and len(c) == 3 and all(isinstance(x, (int, float)) for x in c):
        return tuple(float(min(max(x, 0.0), 1.0)) for x in c)
    raise InputError(where, f"muscle colour {c!r}", "colour is [r, g, b] in 0..1 or '#rrggbb'")


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    """(N, 4) unit quaternions (w, x, y, z) -> (N, 3, 3) rotation matrices."""
    w, x, y, z = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)


def _mesh_path(run_dir: Path, name: str, frame: int) -> Path:
    for ext in _READERS:
        p = run_dir / mesh_relpath(name, frame, ext[1:])
        if p.exists():
            return p
    raise InputError(Mark(str(run_dir / mesh_relpath(name, frame, "ply"))),
                     "mesh file missing", "the run folder must hold every muscle's mesh for every frame")


def load_run_scene(run_dir: Path) -> tuple[Scene, Iterator[FrameChunk], RenderSettings]:
    """Scene, an iterator of one-frame chunks, and the run's render settings (enabled)."""
    run_dir = Path(run_dir)
    mpath = run_dir / MANIFEST
    where = Mark(str(mpath))
    try:
        manifest = json.loads(mpath.read_text())
    except FileNotFoundError:
        raise InputError(where, "no manifest.json in the run folder", "give a folder written by axdf run") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(where, f"manifest.json is not JSON ({e})", "give a folder written by axdf run") from None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("muscles"), list) \
            or not isinstance(manifest.get("frames"), list) or not manifest["frames"]:
        raise InputError(where, "manifest.json lacks 'muscles' or 'frames'", "give a folder written by axdf run")
    frames = tuple(int(f) for f in manifest["frames"])
    names = [str(m["name"]) for m in manifest["muscles"]]
    colors = [_color(m.get("color", [0.7, 0.3, 0.3]), where) for m in manifest["muscles"]]

    # pass 1: topology from the first frame, bounds over every frame
    muscles, lo, hi = [], np.full(3, np.inf), np.full(3, -np.inf)
    for name, color in zip(names, colors):
        for k, f in enumerate(frames):
            p = _mesh_path(run_dir, name, f)
            pos, _, faces = _READERS[p.suffix](p)
            if k == 0:
                muscles.append(SceneMuscle(name, color, faces))
                nv = len(pos)
            elif len(pos) != nv:
                raise InputError(Mark(str(p)), f"{len(pos)} vertices, frame {frames[0]} has {nv}",
                                 "every frame has the same vertex count")
            lo, hi = np.minimum(lo, pos.min(0)), np.maximum(hi, pos.max(0))
    bounds = np.stack([lo, hi]) if muscles else np.zeros((2, 3))

    bones = []
    for b in manifest.get("bones") or []:
        if b.get("mesh"):
            v, _, faces = read_mesh_file(run_dir / b["mesh"])
            bones.append(SceneBone(str(b["name"]), v, faces))
    bone_world = _read_bones_csv(run_dir / "bones.csv", frames, [b.name for b in bones])

    raw = (manifest.get("settings") or {}).get("render") if isinstance(manifest.get("settings"), dict) \
        else None
    raw = raw if raw is not None else manifest.get("render")
    settings = replace(parse_render_settings(raw, where) if isinstance(raw, dict) else RenderSettings(),
                       enabled=True)
    scene = Scene(tuple(muscles), tuple(bones), bounds.astype(np.float64), frames)

    def chunks() -> Iterator[FrameChunk]:
        for k, f in enumerate(frames):
            ps, ns = [], []
            for m in muscles:
                p = _mesh_path(run_dir, m.name, f)
                pos, nrm, faces = _READERS[p.suffix](p)
                if nrm is None:
                    from axdf_cli.render.renderer import vertex_normals
                    nrm = vertex_normals(pos, faces)
                ps.append(pos[None])
                ns.append(nrm[None])
            yield FrameChunk(np.array([f]), tuple(ps), tuple(ns), bone_world[k:k + 1])

    return scene, chunks(), settings


def _read_bones_csv(path: Path, frames: tuple[int, ...], names: list[str]) -> np.ndarray:
    """(F, n_bones, 4, 4) float64 world transforms of the named bones (identity if absent)."""
    out = np.tile(np.eye(4), (len(frames), len(names), 1, 1))
    if not names:
        return out
    if not path.exists():
        raise InputError(Mark(str(path)), "bones.csv missing", "bone meshes need bones.csv")
    fi = {f: i for i, f in enumerate(frames)}
    bi = {n: j for j, n in enumerate(names)}
    with open(path, newline="") as fh:
        for row in csv.DictReader(fh):
            f, b = int(row["frame"]), row["bone"]
            if f in fi and b in bi:
                q = np.array([[float(row[k]) for k in ("qw", "qx", "qy", "qz")]])
                M = out[fi[f], bi[b]]
                M[:3, :3] = _quat_matrix(q)[0]
                M[:3, 3] = [float(row[k]) for k in ("x", "y", "z")]
    return out
