"""Labels of a sequence: joint centres, cameras, projections, visibility, and the npz file.

Conventions (those of ``camera.json``, OpenCV): camera x right, y down, z forward;
``world_to_camera`` (4, 4) maps world points (Z up, metres) to camera coordinates; ``K`` is
in pixels, pixel (0, 0) is the top-left pixel with its centre at (0.5, 0.5), so a point
projects to ``(u, v) = (K @ p_cam)[:2] / p_cam.z`` and lies in pixel ``(floor(u), floor(v))``
(OpenCV puts pixel centres at integers: ``cv2.projectPoints`` with ``K`` less 0.5 in ``cx``
and ``cy`` gives the same pixels as OpenCV counts them).

Joint centres: the joint of bone b is the origin of its joint frame, ``world_b @
[post_offset_b, 1]`` (the bone's origin when it has no ``post_offset``); the root's joint is
its own origin. A joint is **visible** in a view when it projects inside the image, in front
of the camera, and the depth pass at its pixel is background or at most
``visibility_tolerance`` (default 0.1 m) in front of the joint: a joint centre lies inside
its bones and muscles, a few centimetres behind the surface that shows it, while a limb that
hides it is farther in front.

Sphere cameras aim at the subject: with ``target: auto`` the centre of the box around the
moving bones' joint centres and mesh boxes (:func:`axdf_cli.render.framing.skeleton_points`), over the sequence
(``per: sequence``, carried along with a subject that travels farther than it is tall:
:func:`axdf_cli.render.framing.sequence_targets`) or at the frame (``per: frame``); a bone
target is the bone's origin at each frame. ``per: sequence`` draws the direction and distance
once, and the camera keeps them while its target moves. Near and far planes keep the box.
"""
from __future__ import annotations

import io
import math
import zipfile

import numpy as np

from axdf_cli.dataset.sampling import sphere_direction, sphere_draw
from axdf_cli.dataset.spec import DatasetSpec, Sequence
from axdf_cli.render.camera import FRAME_MARGIN, fit_distance, look_at
from axdf_cli.render.framing import sequence_targets

FLESH_MARGIN = 0.3  # metres of flesh kept inside the clip range beyond the subject's box
NEAR_MIN = 0.01  # metres


def view_cameras(spec: DatasetSpec, seq: Sequence, frames: np.ndarray, subject: np.ndarray,
                 world: np.ndarray, skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cameras of every view at every frame, from the skeleton only (never the muscles):
    ``subject`` (F, P, 3) are the points of :func:`axdf_cli.render.framing.skeleton_points`. Returns ``K`` (V, 3, 3),
    ``world_to_camera`` (F, V, 4, 4), ``clip`` (F, V, 2) near and far."""
    from axdf_cli.render.camera import intrinsics, look_at

    W, H = spec.render.size
    nf = len(frames)
    lo, hi = subject.reshape(-1, 3).min(0), subject.reshape(-1, 3).max(0)
    centre = 0.5 * (lo + hi)
    radius = 0.5 * float(np.linalg.norm(hi - lo)) + FLESH_MARGIN
    up = np.array([0.0, 0.0, 1.0])
    if spec.rig is not None:
        K = np.stack([intrinsics(W, H, c.fov) for c in spec.rig])
        auto = sequence_targets(skeleton, world, subject, "auto")  # (F, 3): follows a travelling subject
        w2c = np.stack([np.stack([look_at(c.position, np.subtract(auto[fi] if c.target is None else c.target,
                                                                  c.position), c.up) for c in spec.rig])
                        for fi in range(nf)]) if nf else np.empty((0, len(spec.rig), 4, 4))
        dist = np.linalg.norm(np.array([c.position for c in spec.rig]) - centre, axis=1)
        dist = np.broadcast_to(dist, (nf, len(spec.rig)))
    else:
        sph = spec.sphere
        K = np.stack([intrinsics(W, H, sph.fov)] * sph.views)
        w2c = np.empty((nf, sph.views, 4, 4))
        dist = np.empty((nf, sph.views))
        targets = sequence_targets(skeleton, world, subject, sph.target)  # (F, 3)
        tan_y = math.tan(math.radians(sph.fov) / 2) * (1 - 2 * FRAME_MARGIN)
        tans = (tan_y * W / H, tan_y)
        seq_rel = (subject - targets[:, None]).reshape(-1, 3) if nf else np.zeros((0, 3))
        least: dict = {}  # per: sequence, view -> the distance that shows the whole sequence
        for fi, f in enumerate(frames):
            key = int(f) if sph.per == "frame" else 0
            if sph.target == "auto" and sph.per == "frame":
                tgt = 0.5 * (subject[fi].min(0) + subject[fi].max(0))
            else:
                tgt = targets[fi]
            for v in range(sph.views):
                az, el, d = sphere_draw(spec, seq, key, v)
                direction = sphere_direction(np.array(az), np.array(el))
                if sph.whole and len(seq_rel):  # never so near that the subject leaves the picture
                    if sph.per == "frame":
                        d = max(d, _least_distance(subject[fi] - tgt, direction, up, tans))
                    else:
                        if v not in least:
                            least[v] = _least_distance(seq_rel, direction, up, tans)
                        d = max(d, least[v])
                pos = tgt + d * direction
                w2c[fi, v] = look_at(pos, tgt - pos, up)
                dist[fi, v] = np.linalg.norm(pos - centre)
    near = np.maximum(NEAR_MIN, 0.5 * (dist - radius))
    far = dist + radius + 1.0
    return K, w2c, np.stack([near, far], axis=-1)


def _least_distance(rel: np.ndarray, direction: np.ndarray, up: np.ndarray, tans: tuple) -> float:
    """The least distance along ``direction`` from the target at which a camera looking at it
    shows every point ``rel`` (N, 3, relative to the target) inside the image less
    ``FRAME_MARGIN`` at each border (:func:`axdf_cli.render.camera.fit_distance`)."""
    R = look_at(np.zeros(3), -np.asarray(direction, np.float64), up)[:3, :3]
    return fit_distance(rel, R, tans[0], tans[1])


def project(K: np.ndarray, world_to_camera: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (F, V, J, 2) and camera depth (F, V, J) of world ``points`` (F, J, 3) in every
    view: ``K`` (V, 3, 3), ``world_to_camera`` (F, V, 4, 4)."""
    # c[f,v,j,i] = sum_k R[f,v,i,k] p[f,j,k] + t[f,v,i]
    c = np.einsum("fvik,fjk->fvji", world_to_camera[..., :3, :3], points) + world_to_camera[:, :, None, :3, 3]
    z = c[..., 2]
    # h[f,v,j,i] = sum_k K[v,i,k] c[f,v,j,k]
    h = np.einsum("vik,fvjk->fvji", K, c)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = h[..., :2] / z[..., None]
    return uv, z


def visibility(uv: np.ndarray, z: np.ndarray, depth: np.ndarray, tolerance: float) -> np.ndarray:
    """(F, V, J) bool: inside the image, in front of the camera, and not hidden in the depth
    pass ``depth`` (F, V, H, W) (0 = background) by more than ``tolerance`` metres."""
    F, V, H, W = depth.shape
    px = np.floor(np.nan_to_num(uv, nan=-1.0, posinf=-1.0, neginf=-1.0)).astype(np.int64)
    inside = (z > 0) & (px[..., 0] >= 0) & (px[..., 0] < W) & (px[..., 1] >= 0) & (px[..., 1] < H)
    col = np.clip(px[..., 0], 0, W - 1)
    row = np.clip(px[..., 1], 0, H - 1)
    f = np.arange(F)[:, None, None]
    v = np.arange(V)[None, :, None]
    d = depth[f, v, row, col]  # (F, V, J)
    return inside & ((d <= 0) | (z <= d + tolerance))


def npz_bytes(arrays: dict) -> bytes:
    """An ``.npz`` (``np.load`` reads it) with fixed zip timestamps, so equal arrays give equal
    bytes (``np.savez`` stamps the current time). Arrays are stored uncompressed, in order."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_STORED) as zf:
        for name, arr in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.external_attr = 0o644 << 16
            data = io.BytesIO()
            np.lib.format.write_array(data, np.asarray(arr), allow_pickle=False)
            zf.writestr(info, data.getvalue())
    return buf.getvalue()
