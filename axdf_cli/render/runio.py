"""Read a finished run folder back into a :class:`Scene` and its frames (for ``axdf render``).

The layout and the manifest are :mod:`axdf_cli.fileio.runfolder`'s. What is read:

- ``manifest.json`` (an axdf run's: ``tool: axdf``): ``muscles: [{name, color, ...}]``
  (colour as linear ``[r, g, b]`` in 0..1, or sRGB ``"#rrggbb"``), ``frames: [...]``,
  ``settings.format`` (the meshes' formats, ``ply`` or ``ply,usd``: a folder with stale
  files of another format reads the right ones), ``settings.fps`` (MDD times), optional
  ``bones: [{name, mesh, stick_from}]`` (``mesh`` relative to
  the run folder, a PLY in bone-local coordinates; ``stick_from``: the bone a mesh-less bone
  is drawn joined to), optional ``framing: {first_frame, points}`` (what the automatic
  camera frames) and optional ``settings.render``. A damaged manifest is an input error at
  its line and column.
- ``meshes/<muscle>/<muscle>_<frame:04d>.ply`` (binary little-endian, float32 x y z nx ny
  nz, int32 triangle lists) or ``.obj`` (``v``, ``vn``, ``f a//a``), or with
  ``settings.mesh_files: frame`` one file per frame, ``meshes/<frame:04d>.ply|obj``, each
  muscle a named part (OBJ ``o``, PLY ``muscle`` vertex property); in a run without a
  per-frame format, each muscle's per-sequence file (``npz/<m>.npz``, ``pc2/<m>.pc2`` with
  its rest mesh ``pc2/<m>.ply``, ``mdd/<m>.mdd``, ``usd/<m>.usdc``), read a frame at a time.
- ``meshes/<part>/<part>_<frame:04d>.ply|obj``: each part the run's stages added (its
  manifest's ``parts``: the skin of a run with ``--skin``), drawn by its kind (a skin as
  ``settings.render.skin`` says).
- ``bones.csv``: ``frame,bone,x,y,z,qw,qx,qy,qz`` world pose of each bone per frame.
"""
from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path
from typing import Iterator

import numpy as np

from axdf_cli.errors import InputError, Mark
from axdf_cli.formats import FORMATS, MESH_FILES, MeshReadError, load_triangles, read_preference, read_sequence
from axdf_cli.specs.render import RenderSettings, parse_render_settings
from axdf_cli.fileio.runfolder import (BONES_CSV, Manifest, frame_mesh_relpath, mesh_relpath,
                                      read_run_manifest)
from axdf_cli.fileio.runfolder import plain_relpath as _plain
from axdf_cli.fileio.yamlio import NAME_ALLOWED, is_name
from axdf_cli.render.framing import follow_rows, recorded_follow, recorded_framing
from axdf_cli.parts import Kind
from axdf_cli.render.scene import FrameChunk, Scene, SceneLayer, SceneMuscle

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


class _FrameFiles:
    """A muscle written one file per frame (``meshes/<m>/<m>_<frame>.<fmt>``)."""

    def __init__(self, run_dir: Path, name: str, fmt: str):
        self.run_dir, self.name, self.fmt = run_dir, name, fmt

    def where(self, frame: int) -> Path:
        p = self.run_dir / mesh_relpath(self.name, frame, self.fmt)
        if not p.is_file():
            raise InputError(Mark(str(p)), "mesh file missing",
                             "the run folder must hold every muscle's mesh for every frame")
        return p

    def read(self, frame: int):
        return load_triangles(self.where(frame))


class _OneFilePerFrame:
    """A run's files holding every muscle of a frame (``meshes/<frame>.<fmt>``): the last
    frame read, split into its named parts (muscles read a frame at a time share one read)."""

    def __init__(self, run_dir: Path, fmt: str):
        self.run_dir, self.fmt = run_dir, fmt
        self.frame, self.mesh, self.tri, self.parts = None, None, None, {}

    def where(self, frame: int) -> Path:
        p = self.run_dir / frame_mesh_relpath(frame, self.fmt)
        if not p.is_file():
            raise InputError(Mark(str(p)), "mesh file missing", "the run folder must hold every frame's mesh file")
        return p

    def part(self, frame: int, name: str):
        """(V, 3) float32 positions, normals or None, (T, 3) faces of muscle ``name``."""
        if frame != self.frame:
            from axdf_cli.formats import read_mesh

            path = self.where(frame)
            try:
                mesh = read_mesh(path.read_bytes(), path.suffix)
                tri = mesh.triangles()
            except MeshReadError as e:
                raise InputError(Mark(str(path)), f"not a readable mesh ({e})", "a mesh file written by axdf run") \
                    from None
            self.frame, self.mesh, self.tri, self.parts = frame, mesh, tri, mesh.group_slices()
        sl = self.parts.get(name)
        if sl is None:
            raise InputError(Mark(str(self.where(frame))), f"holds no part named {name!r}",
                             "a file per frame with every muscle of the manifest as a named part")
        m = self.mesh
        faces = self.tri[(self.tri[:, 0] >= sl.start) & (self.tri[:, 0] < sl.stop)] - sl.start
        if len(faces) and (faces.min() < 0 or faces.max() >= sl.stop - sl.start):
            raise InputError(Mark(str(self.where(frame))), f"a face of {name!r} joins vertices of another part",
                             "a file per frame whose parts' faces stay within their own vertices")
        nrm = None if m.normals is None else m.normals[sl].astype(np.float32)
        return m.vertices[sl].astype(np.float32), nrm, faces.astype(np.int32)


class _FramePart:
    """A muscle read from :class:`_OneFilePerFrame` files."""

    def __init__(self, files: _OneFilePerFrame, name: str):
        self.files, self.name = files, name

    def where(self, frame: int) -> Path:
        return self.files.where(frame)

    def read(self, frame: int):
        return self.files.part(frame, self.name)


class _SequenceFile:
    """A muscle written in a per-sequence format (npz, pc2, mdd, usd), read a frame at a time."""

    def __init__(self, path: Path, seq, faces):
        self.file, self.seq, self.faces = path, seq, faces
        self.index = {int(round(f)): k for k, f in enumerate(seq.frames)}

    def where(self, frame: int) -> str:
        return f"{self.file} (frame {frame})"

    def read(self, frame: int):
        k = self.index[frame]
        nrm = None if self.seq.normals is None else np.asarray(self.seq.normals[k], np.float32)
        return np.asarray(self.seq.points[k], np.float32), nrm, self.faces


def muscle_frames(run_dir: Path, name: str, formats, frames: tuple[int, ...], fps=None, per_frame=None):
    """Where a muscle's frames are read from: its per-frame meshes when the run wrote a
    per-frame format (``per_frame``: the run's :class:`_OneFilePerFrame` files when it wrote one
    file per frame with every muscle), else its per-sequence file (npz, pc2, mdd, usd: the first the run
    wrote in its order of preference: ``Format.read_order``), whose frames must be the run's. ``.read(frame)`` gives (V, 3) float32 positions,
    normals or None, (T, 3) faces."""
    from axdf_cli.fileio.runfolder import rest_mesh_relpath, sequence_relpath

    for fmt in formats:
        if FORMATS[fmt].layout == "frame":
            return _FrameFiles(run_dir, name, fmt) if per_frame is None else _FramePart(per_frame, name)
    fmt = read_preference(formats)[0]
    path = run_dir / sequence_relpath(name, FORMATS[fmt].folder, FORMATS[fmt].writer.extension)
    if not path.is_file() or path.is_symlink():
        raise InputError(Mark(str(path)), "file missing (or not a regular file)",
                         f"the run folder must hold every muscle's {fmt} file")
    try:
        seq = read_sequence(path, fps)
    except MeshReadError as e:
        raise InputError(Mark(str(path)), f"not readable ({e})", f"a {fmt} file written by axdf run") from None
    if len(seq.frames) != len(frames) or not np.allclose(seq.frames, frames):
        raise InputError(Mark(str(path)), f"holds frames {_span(seq.frames)}, the manifest {_span(frames)}",
                         "the file of the same run")
    faces = seq.faces
    if faces is None:  # a point cache: the topology is its rest mesh's
        faces = load_triangles(run_dir / rest_mesh_relpath(name, FORMATS[fmt].folder))[2]
    return _SequenceFile(path, seq, faces)


def _span(frames) -> str:
    f = np.asarray(frames, np.float64)
    return f"{f[0]:g}..{f[-1]:g} ({len(f)})" if len(f) else "none"


def load_run_scene(run_dir: Path, manifest: Manifest | None = None, frames=None
                   ) -> tuple[Scene, Iterator[FrameChunk], RenderSettings]:
    """Scene, an iterator of one-frame chunks (of ``frames``, default every frame of the run)
    and the run's render settings (enabled). A manifest that is not an axdf run's, or damaged,
    is an input error at its position."""
    scene, source, settings = load_run_source(run_dir, manifest, frames)
    return scene, source.chunks(source.selected), settings


def load_run_source(run_dir: Path, manifest: Manifest | None = None, frames=None, target_bone=None
                    ) -> tuple[Scene, "RunFrames", RenderSettings]:
    """:func:`load_run_scene` with the frames as a :class:`RunFrames` (a render worker reads
    its own). ``target_bone``: (name, Mark) of the bone a camera aims at, or None: its origin
    at every frame of the run (``bones.csv``) becomes ``Scene.targets``."""
    run_dir = Path(run_dir)
    m = manifest or read_run_manifest(run_dir)
    all_frames = tuple(m.frames())
    muscles_raw = m.get(("muscles",), list, "a list of {name, color, ...}")
    allowed = "mesh formats, comma-separated: " + ", ".join(FORMATS)
    formats = m.get(("settings", "format"), str, allowed).split(",")
    if any(f not in FORMATS for f in formats):
        raise m.error(("settings", "format"), f"unknown mesh format in {','.join(formats)!r}", allowed)
    fps = m.get(("settings", "fps"), (int, float), "the pose's frames per second", required=False, default=None)
    mesh_files = m.get(("settings", "mesh_files"), str, " or ".join(MESH_FILES), required=False, default="muscle")
    if mesh_files not in MESH_FILES:
        raise m.error(("settings", "mesh_files"), f"mesh_files is {mesh_files!r}", " or ".join(MESH_FILES))
    names, colors = [], []
    for i, mu in enumerate(muscles_raw):
        m.get(("muscles", i), dict, "an object {name, color, ...}")
        name = m.get(("muscles", i, "name"), str, "a muscle name")
        if not is_name(name):
            raise m.error(("muscles", i, "name"), f"{name!r} is not a muscle name", NAME_ALLOWED)
        names.append(name)
        colors.append(_color(mu.get("color", [0.7, 0.3, 0.3]), m.mark(("muscles", i, "color"))))
    bones_raw = m.get(("bones",), list, "a list of {name, mesh, stick_from}", required=False, default=[])
    bone_names, bone_meshes, stick_from = [], {}, []
    for i, b in enumerate(bones_raw):
        m.get(("bones", i), dict, "an object {name, mesh, stick_from}")
        name = m.get(("bones", i, "name"), str, "a bone name")
        mesh = m.get(("bones", i, "mesh"), (str, type(None)), "a path in the run folder or null",
                     required=False, default=None)
        if mesh is not None and not _plain(mesh):
            raise m.error(("bones", i, "mesh"), f"{mesh!r} leaves the run folder", "a path inside the run folder")
        bone_names.append(name)
        stick_from.append(m.get(("bones", i, "stick_from"), (str, type(None)), "a bone name or null",
                                required=False, default=None))
        if mesh:
            bone_meshes[i] = mesh
    framing, first_frame = recorded_framing(m)
    follow_bone, ground, footprint = recorded_follow(m)
    settings = recorded_render_settings(m)
    selected = all_frames if frames is None else tuple(int(f) for f in frames)

    # pass 1: topology from the first frame, bounds over every frame (frame by frame: a file
    # per frame with every muscle is read once)
    sources = per_frame_sources(run_dir, names, formats, all_frames, fps, mesh_files)
    muscles, lo, hi = [], np.full(3, np.inf), np.full(3, -np.inf)
    nv: list[int] = []
    for k, f in enumerate(all_frames):
        for j, (name, color, src) in enumerate(zip(names, colors, sources)):
            pos, _, faces = src.read(f)
            if k == 0:
                muscles.append(SceneMuscle(name, color, faces))
                nv.append(len(pos))
            elif len(pos) != nv[j]:
                raise InputError(Mark(str(src.where(f))), f"{len(pos)} vertices, frame {all_frames[0]} has {nv[j]}",
                                 "every frame has the same vertex count")
            lo, hi = np.minimum(lo, pos.min(0)), np.maximum(hi, pos.max(0))
    bounds = np.stack([lo, hi]) if muscles else np.zeros((2, 3))

    from axdf_cli.render.renderer import bone_layout

    meshes = {}
    for i, mesh in bone_meshes.items():
        v, _, faces = load_triangles(run_dir / mesh)
        meshes[i] = (v, faces)
    parents = [bone_names.index(s) if s in bone_names else -1 for s in stick_from]
    extent = float(np.ptp(framing if framing is not None else bounds, axis=0).max())
    layout = bone_layout(bone_names, parents, meshes, extent)
    world = _read_bones_csv(run_dir / BONES_CSV, selected, bone_names if layout.bones else [])
    bone_world = layout.transforms(world)
    targets = None
    if target_bone is not None:
        name, where = target_bone
        if name not in bone_names:
            raise InputError(where, f"the camera's target bone {name!r} is not a bone of this run",
                             "bones: " + ", ".join(bone_names))
        targets = _read_bones_csv(run_dir / BONES_CSV, all_frames, [name])[:, 0, :3, 3]
    follow = None
    if follow_bone is not None and framing is not None:
        if follow_bone not in bone_names:
            raise m.error(("framing", "follow"), f"{follow_bone!r} is not a bone of this run",
                          "bones: " + ", ".join(bone_names))
        follow = follow_rows(_read_bones_csv(run_dir / BONES_CSV, all_frames, [follow_bone])[:, 0, :3, 3])
    layer_sources = _layer_sources(run_dir, m, formats, all_frames)
    layers = tuple(SceneLayer(name, kind, src.read(all_frames[0])[2], color) for name, kind, color, src in layer_sources)
    scene = Scene(tuple(muscles), layout.bones, bounds.astype(np.float64), all_frames,
                  framing=framing, first_frame=first_frame, targets=targets, follow=follow,
                  ground=ground, footprint=footprint, layers=layers)

    source = RunFrames(run_dir, names, formats, all_frames, fps, selected, bone_world, sources, mesh_files,
                       layers=tuple((name, src.fmt) for name, _, _, src in layer_sources))
    return scene, source, settings


def _layer_sources(run_dir: Path, m: Manifest, formats, all_frames) -> list:
    """The parts the run's stages added (its manifest's ``parts``: the skin of a run with
    ``--skin``), each with its meshes, one file per frame of a per-frame format:
    [(name, kind, colour, :class:`_FrameFiles`)]."""
    files = m.data.get("files") if isinstance(m.data, dict) else None
    parts = m.data.get("parts", []) if isinstance(m.data, dict) else []
    if not isinstance(files, dict) or not all_frames:
        return []
    if not isinstance(parts, list):
        raise m.error(("parts",), "parts is not a list", "a list of {name, kind, color} as axdf run writes")
    out = []
    for k, p in enumerate(parts):
        kinds = [x.value for x in Kind]
        if not (isinstance(p, dict) and isinstance(p.get("name"), str) and p.get("kind") in kinds
                and isinstance(p.get("color"), list) and len(p["color"]) == 3):
            raise m.error(("parts", k), "not a part", f"{{name, kind, color}} with kind one of {', '.join(kinds)}")
        fmt = next((f for f in formats if FORMATS[f].layout == "frame"
                    and mesh_relpath(p["name"], all_frames[0], f) in files), None)
        if fmt is None:
            raise m.error(("parts", k), f"part {p['name']!r} has no meshes per frame in this run",
                          "render a run that wrote its parts as PLY or OBJ (--format ply)")
        out.append((p["name"], Kind(p["kind"]), tuple(float(c) for c in p["color"]),
                    _FrameFiles(run_dir, p["name"], fmt)))
    return out


def per_frame_sources(run_dir: Path, names, formats, all_frames, fps, mesh_files: str = "muscle") -> list:
    """Every muscle's :func:`muscle_frames`; with ``mesh_files`` ``frame`` they share one
    reader of the files per frame (of the first per-frame format the run wrote)."""
    shared = None
    if mesh_files == "frame":
        fmt = next((f for f in formats if FORMATS[f].layout == "frame"), None)
        shared = _OneFilePerFrame(run_dir, fmt) if fmt is not None else None
    return [muscle_frames(run_dir, n, formats, all_frames, fps, shared) for n in names]


class RunFrames:
    """A finished run's frames for the renderer (a :class:`~axdf_cli.render.framefiles.FrameSource`):
    each muscle's mesh read a frame at a time (its per-frame files, or its per-sequence file,
    opened in the process that reads: a render worker opens its own), normals computed where
    the format has none; the bones' transforms of the ``selected`` frames."""

    def __init__(self, run_dir: Path, names, formats, all_frames, fps, selected, bone_world, sources=None,
                 mesh_files: str = "muscle", layers=()):
        self.run_dir, self.names, self.formats, self.all_frames, self.fps = run_dir, names, formats, all_frames, fps
        self.mesh_files = mesh_files
        self.layers = tuple(layers)  # (name, format) of each part the stages added: each chunk carries them
        self.selected = tuple(selected)
        self.bone_world = bone_world  # (len(selected), n_scene_bones, 4, 4)
        self._sources = sources

    def __getstate__(self) -> dict:
        return dict(self.__dict__, _sources=None)  # files are opened again where they are read

    def chunks(self, frames) -> Iterator[FrameChunk]:
        """One-frame chunks of ``frames`` (some of ``selected``), in order."""
        if self._sources is None:
            self._sources = per_frame_sources(self.run_dir, self.names, self.formats, self.all_frames, self.fps,
                                              self.mesh_files)
        row = {f: k for k, f in enumerate(self.selected)}
        layer_src = [_FrameFiles(self.run_dir, name, fmt) for name, fmt in self.layers]
        for f in frames:
            ps, ns = [], []
            for src in self._sources:
                pos, nrm = _with_normals(*src.read(f))
                ps.append(pos[None])
                ns.append(nrm[None])
            layers = []
            for src in layer_src:
                pos, nrm = _with_normals(*src.read(f))
                layers.append((pos[None], nrm[None]))
            yield FrameChunk(np.array([f]), tuple(ps), tuple(ns), self.bone_world[row[f]:row[f] + 1], tuple(layers))


def _with_normals(pos: np.ndarray, nrm: np.ndarray | None, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A mesh read back, with its normals computed where the format has none."""
    if nrm is None:
        from axdf_cli.render.renderer import vertex_normals
        nrm = vertex_normals(pos, faces)
    return pos, nrm


def recorded_render_settings(m: Manifest) -> RenderSettings:
    """The render settings in a run's manifest (``settings.render``; defaults when the run was
    not rendered), enabled."""
    m.get(("settings",), dict, "an object of the run's settings", required=False)
    raw = m.get(("settings", "render"), (dict, type(None)), "the render settings or null", required=False)
    if raw is not None and "camera_file" in raw:  # a run pinned by --camera: rendered again, it is framed
        raw = {k: v for k, v in raw.items() if k != "camera_file"}
    return replace(parse_render_settings(raw, m.mark(("settings", "render"))) if raw is not None
                   else RenderSettings(), enabled=True)


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
