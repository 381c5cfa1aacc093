"""USD: one stage per run, written with Pixar's ``usd-core`` (``pxr``).

Layout (paths relative to the run folder, :mod:`axdf_cli.fileio.runfolder`; every reference is
relative, so the folder moves whole)::

    scene.usda          the stage a user opens: metadata (Z up, metersPerUnit 1,
                        timeCodesPerSecond = framesPerSecond = the pose's fps, start and end
                        time codes = the first and last frame), /axdf/muscles/<m> each
                        referencing usd/<m>.usdc, /axdf/bones/<bone> Xforms with time-sampled
                        xformOp:translate + xformOp:orient (the bone frame in the world, as in
                        bones.csv) over their mesh <bone>_mesh (from usd/bones.usdc),
                        /axdf/camera (the render settings' view)
    usd/<m>.usdc        one layer per muscle: a UsdGeomMesh (default prim) with its topology
                        written once (faceVertexCounts, faceVertexIndices, rightHanded, no
                        subdivision), points, normals (vertex) and extent time-sampled at the
                        frame numbers, displayColor; the same stage metadata, so it opens alone
    usd/bones.usdc      every bone mesh (bone-local), /bones/<bone>

A time code is a frame number. Names that are not USD identifiers (``.``, ``-``, a leading
digit) become ``_``; a name met twice gets ``_2``.

Memory: a muscle's layer is authored when its sequence is complete (the pass evaluates all
muscles chunk by chunk); until then its frames are spooled as raw float32 to a temporary file
beside it, so the run holds one muscle's layer at a time, never all of them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.errors import EnvironmentProblem
from axdf_cli.formats.mesh import MeshReadError
from axdf_cli.formats.packed import PointSequence, SequenceWriter

ROOT = "/axdf"
SPOOL_BLOCK = 128  # frames read back from a muscle's spool at a time
FOCAL_LENGTH = 50.0  # lens units (tenths of a scene unit); only aperture / focal length matters


def pxr():
    """The ``pxr`` modules (Sdf, Usd, UsdGeom, Vt, Gf, Tf); a missing usd-core is exit 3 with the install hint."""
    try:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, Vt
    except ImportError:
        raise EnvironmentProblem("--format usd needs Pixar's USD Python modules (pxr), which are not installed",
                                 "pip install usd-core") from None
    return Sdf, Usd, UsdGeom, Vt, Gf, Tf


def prim_names(names) -> list[str]:
    """Valid, unique USD prim names for ``names``, in order."""
    from axdf_cli.fileio.yamlio import unique_names

    *_, Tf = pxr()
    return unique_names(Tf.MakeValidIdentifier(n) for n in names)


def _metadata(stage, frames, fps: float) -> None:
    _, _, UsdGeom, *_ = pxr()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    stage.SetTimeCodesPerSecond(float(fps))
    stage.SetFramesPerSecond(float(fps))
    stage.SetStartTimeCode(float(frames[0]))
    stage.SetEndTimeCode(float(frames[-1]))


def _samples(layer, path, times, values, make) -> None:
    """Author ``values[k]`` at time ``times[k]`` on the attribute ``path`` (Sdf level, one
    change block: much faster than the Usd API per sample)."""
    Sdf = pxr()[0]
    with Sdf.ChangeBlock():
        for t, v in zip(times, values):
            layer.SetTimeSample(path, float(t), make(v))


def _new_stage():
    Sdf, Usd, *_ = pxr()
    layer = Sdf.Layer.CreateAnonymous(".usdc")
    return layer, Usd.Stage.Open(layer)


def write_muscle_layer(path: Path | str, info, faces: np.ndarray, blocks) -> None:
    """Write one muscle's layer to ``path`` (``.usdc``). ``blocks`` yields the frames in order
    as (points (C, V, 3), normals (C, V, 3)) float32 blocks."""
    Sdf, Usd, UsdGeom, Vt, Gf, _ = pxr()
    layer, stage = _new_stage()
    _metadata(stage, info.frames, info.fps)
    mesh = UsdGeom.Mesh.Define(stage, "/" + prim_names([info.name or "muscle"])[0])
    stage.SetDefaultPrim(mesh.GetPrim())
    faces = np.asarray(faces, np.int32)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces.reshape(-1))))
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, info.color))]))
    pa, na, ea = mesh.CreatePointsAttr(), mesh.CreateNormalsAttr(), mesh.CreateExtentAttr()
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    vec3f = lambda a: Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a))  # noqa: E731
    k = 0
    for points, normals in blocks:
        times = info.frames[k:k + len(points)]
        k += len(points)
        # extent[f] = [min over v of points[f, v], max over v]; reduced along a contiguous
        # last axis (numpy's reduce over the middle axis of (C, V, 3) is ~20x slower)
        xyz = np.ascontiguousarray(points.transpose(0, 2, 1))  # (C, 3, V)
        extent = np.stack([xyz.min(axis=2, initial=np.inf), xyz.max(axis=2, initial=-np.inf)], axis=1)
        _samples(layer, pa.GetPath(), times, points, vec3f)
        _samples(layer, na.GetPath(), times, normals, vec3f)
        _samples(layer, ea.GetPath(), times, extent.astype(np.float32), vec3f)
    if k != len(info.frames):
        raise ValueError(f"{k} frames given for {len(info.frames)}")
    layer.Export(str(path))


class UsdWriter(SequenceWriter):
    """A muscle's ``usd/<m>.usdc``: frames spooled (raw float32: all points, then all
    normals) to a temporary beside it, authored and exported at :meth:`finish`."""

    extension = "usdc"

    def __init__(self, path, info, faces, n_vertices, sha256: bool = True):
        pxr()
        super().__init__(path, info, faces, n_vertices, sha256)
        self.spool = atomic.StreamingFile(self.path.with_name(self.path.name + ".spool"))

    def _chunk(self, k0, positions, normals):
        at = k0 * self.n_vertices * 12
        self.spool.pwrite(positions, at)
        self.spool.pwrite(normals, self.n_frames * self.n_vertices * 12 + at)

    def _close(self):
        F, V = self.n_frames, self.n_vertices
        step = SPOOL_BLOCK

        def blocks():  # read back with read(2) in blocks of frames: no page-by-page faults
            for s in range(0, F, step):
                c = min(step, F - s)
                p = np.fromfile(self.spool.tmp, "<f4", c * V * 3, offset=s * V * 12).reshape(c, V, 3)
                n = np.fromfile(self.spool.tmp, "<f4", c * V * 3, offset=(F + s) * V * 12).reshape(c, V, 3)
                yield p, n

        write_muscle_layer(self.file.tmp, self.info, self.faces, blocks())
        self.spool.discard()
        return None

    def abort(self):
        super().abort()
        self.spool.discard()


def write_bones_layer(path: Path | str, bones) -> None:
    """``bones``: [(name, vertices (V, 3) float32 bone-local, faces (T, 3) int32)] -> /bones/<bone> meshes."""
    Sdf, Usd, UsdGeom, Vt, Gf, _ = pxr()
    layer, stage = _new_stage()
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    scope = UsdGeom.Scope.Define(stage, "/bones")
    stage.SetDefaultPrim(scope.GetPrim())
    for prim, (_, v, f) in zip(prim_names(b[0] for b in bones), bones):
        mesh = UsdGeom.Mesh.Define(stage, f"/bones/{prim}")
        f = np.asarray(f, np.int32)
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(v, np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(f), 3, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(f.reshape(-1))))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([v.min(0), v.max(0)]).astype(np.float32)))
    layer.Export(str(path))


def write_stage(path: Path | str, frames, fps: float, muscles, bones, bone_rows: np.ndarray, camera=None,
                layers=()) -> None:
    """The run's root stage (``scene.usda``); references are paths relative to its folder.

    muscles: [(name, layer)] (``usd/<m>.usdc``); bones: [(name, layer or None)]: a bone with
    a mesh references ``/bones/<bone>`` in that layer (``usd/bones.usdc``);
    bone_rows: (F, B, 7) x y z qw qx qy qz, each bone's frame in the world per frame;
    camera: None or a dict with ``world_to_camera`` (F, 4, 4) OpenCV axes (x right, y down,
    z forward), ``K`` (3, 3) pixels, ``size`` (W, H), ``near``, ``far``;
    layers: [(name, layer)]: the parts the run's stages add (the skin: ``usd/skin.usdc``), each
    a mesh under the root next to the muscles."""
    Sdf, Usd, UsdGeom, Vt, Gf, _ = pxr()
    layer = Sdf.Layer.CreateNew(str(path))  # at its own path: the relative references resolve
    stage = Usd.Stage.Open(layer)
    _metadata(stage, frames, fps)
    root = UsdGeom.Xform.Define(stage, ROOT)
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.Scope.Define(stage, f"{ROOT}/muscles")
    for prim, (_, ref) in zip(prim_names(n for n, _ in muscles), muscles):
        p = stage.DefinePrim(f"{ROOT}/muscles/{prim}")
        p.GetReferences().AddReference("./" + ref)
    for prim, (_, ref) in zip(prim_names(n for n, _ in layers), layers):
        stage.DefinePrim(f"{ROOT}/{prim}").GetReferences().AddReference("./" + ref)
    UsdGeom.Scope.Define(stage, f"{ROOT}/bones")
    for b, (prim, (_, ref)) in enumerate(zip(prim_names(n for n, _ in bones), bones)):
        x = UsdGeom.Xform.Define(stage, f"{ROOT}/bones/{prim}")
        t, q = x.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble), x.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        rows = bone_rows[:, b]
        _samples(layer, t.GetAttr().GetPath(), frames, rows, lambda r: Gf.Vec3d(*map(float, r[:3])))
        _samples(layer, q.GetAttr().GetPath(), frames, rows, lambda r: Gf.Quatd(float(r[3]), Gf.Vec3d(*map(float, r[4:7]))))
        if ref:
            m = stage.DefinePrim(f"{ROOT}/bones/{prim}/{prim}_mesh")
            m.GetReferences().AddReference("./" + ref, f"/bones/{prim}")
    if camera is not None:
        _camera(stage, layer, frames, camera)
    layer.Save()


def usd_camera_matrices(world_to_camera: np.ndarray) -> np.ndarray:
    """(F, 4, 4) OpenCV world-to-camera -> (F, 4, 4) USD camera-to-world (column vectors;
    the USD camera looks down its -Z with +Y up, OpenCV's down +Z with +Y down)."""
    flip = np.diag([1.0, -1.0, -1.0, 1.0])
    # M[f] = inv(W2C[f]) @ flip
    return np.linalg.inv(np.asarray(world_to_camera, np.float64)) @ flip


def _camera(stage, layer, frames, camera: dict) -> None:
    _, _, UsdGeom, _, Gf, _ = pxr()
    cam = UsdGeom.Camera.Define(stage, f"{ROOT}/camera")
    W, H = camera["size"]
    K = np.asarray(camera["K"], np.float64)
    cam.CreateFocalLengthAttr(FOCAL_LENGTH)
    cam.CreateHorizontalApertureAttr(float(FOCAL_LENGTH * W / K[0, 0]))
    cam.CreateVerticalApertureAttr(float(FOCAL_LENGTH * H / K[1, 1]))
    cam.CreateClippingRangeAttr(Gf.Vec2f(float(camera["near"]), float(camera["far"])))
    op = cam.AddTransformOp()
    M = usd_camera_matrices(camera["world_to_camera"])
    gf = lambda m: Gf.Matrix4d(m.T.tolist())  # noqa: E731  (USD multiplies row vectors: the transpose)
    if np.all(M == M[:1]):
        op.Set(gf(M[0]))
    else:
        _samples(layer, op.GetAttr().GetPath(), frames, M, gf)


# ----------------------------------------------------------------------------- reading
class _Frames:
    """A time-sampled Vec3f array attribute read one frame at a time (``seq[k]`` -> (V, 3)
    float32): the layer stays on disk (usdc is memory-mapped), so memory stays bounded."""

    def __init__(self, stage, attr, times, n_vertices):
        self.stage, self.attr, self.times = stage, attr, times  # the stage kept open while read
        self.shape = (len(times), n_vertices, 3)

    def __len__(self):
        return self.shape[0]

    def __getitem__(self, k):
        a = np.asarray(self.attr.Get(self.times[k]), np.float32)
        if a.shape != self.shape[1:]:
            raise MeshReadError(f"{self.attr.GetPath()} at time {self.times[k]:g} has shape {a.shape}, "
                                f"expected {self.shape[1:]}")
        return a


def read_usd(path: Path | str) -> PointSequence:
    """A muscle layer (``usd/<m>.usdc``: its default prim a Mesh) -> :class:`PointSequence`
    with frames read lazily; triangles only."""
    Sdf, Usd, UsdGeom, *_ = pxr()
    try:  # anonymous: never a stale copy from pxr's layer registry when the file was rewritten
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
    except Exception as e:  # pxr raises Tf.ErrorException for unreadable layers
        raise MeshReadError(f"not a readable USD layer ({str(e).strip().splitlines()[-1]})") from None
    if layer is None:
        raise MeshReadError("not a readable USD layer")
    stage = Usd.Stage.Open(layer)
    prim = stage.GetDefaultPrim()
    if not prim or not prim.IsA(UsdGeom.Mesh):
        raise MeshReadError("the USD layer's default prim is not a Mesh")
    mesh = UsdGeom.Mesh(prim)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], np.int64)
    idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], np.int64)
    if len(counts) and not np.all(counts == 3):
        raise MeshReadError("faces are not all triangles")
    if counts.sum() != len(idx):
        raise MeshReadError("faceVertexCounts and faceVertexIndices disagree")
    pa, na = mesh.GetPointsAttr(), mesh.GetNormalsAttr()
    times = pa.GetTimeSamples()
    if not times:
        raise MeshReadError("points have no time samples")
    n_vertices = len(pa.Get(times[0]))
    normals = _Frames(stage, na, times, n_vertices) if na.GetTimeSamples() == times else None
    return PointSequence(np.asarray(times, np.float64), _Frames(stage, pa, times, n_vertices), normals,
                         idx.reshape(-1, 3).astype(np.int32), stage.GetTimeCodesPerSecond())


def verify_usd(path: Path | str) -> None:
    """A muscle layer's checks as far as USD allows (it has no checksum): it opens as a
    layer whose default prim is a triangle Mesh (:func:`read_usd`), its time codes are
    finite and strictly increasing, and every time sample holds as many finite points (and
    normals) as the first."""
    from axdf_cli.formats.packed import check_frame_times

    seq = read_usd(path)
    check_frame_times(seq.frames, "USD time samples")
    n = seq.points.shape[1]
    for k in range(len(seq.frames)):
        for what, arr in (("points", seq.points), ("normals", seq.normals)):
            if arr is None:
                continue
            a = np.asarray(arr[k])
            if a.shape != (n, 3) or not np.isfinite(a).all():
                raise MeshReadError(f"USD {what} at time {seq.frames[k]:g}: shape {a.shape}"
                                    + ("" if a.shape != (n, 3) else ", not all finite") + f"; ({n}, 3) finite")
