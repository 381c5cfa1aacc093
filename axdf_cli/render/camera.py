"""Cameras: named views, automatic framing over the whole sequence, orbit, explicit cameras.

World frame (fixed for axdf): Z up, metres, right-handed (as in Blender). A body faces -Y.

- ``front`` looks along +Y (camera at -Y), image up = +Z, +X to the right.
- ``side`` looks along -X (camera at +X), image up = +Z, +Y to the right.
- ``top`` looks down -Z (camera above), image up = +Y, +X to the right.
- ``auto`` a three-quarter view from front, +X side and above (direction ``AUTO_FROM``).
- ``sheet`` front, side and top side by side in one image (each panel ``size``), like the
  paper's figures; all three panels share one camera distance, so they share one scale.

Camera convention written to ``camera.json`` (:data:`CONVENTION`): OpenCV's camera axes, x
right, y down, z forward (the viewing direction); ``world_to_camera`` is the 4x4 matrix taking
world points (metres) to camera coordinates; ``K`` is in pixels of the written image, pixel
(0, 0) is the top-left pixel and its centre is at (0.5, 0.5) (OpenCV's is at (0, 0): its
``cv2.projectPoints`` wants ``K`` with ``cx - 0.5``, ``cy - 0.5``); a world point P projects to
``(u, v, 1) ~ K @ (world_to_camera @ [P, 1])[:3]`` and its camera depth is the z coordinate.
For a sheet each panel has its own camera whose ``K`` already includes the panel's
horizontal offset, so projected pixels are pixels of the whole sheet.

Automatic framing frames ``Scene.framing`` (points whose hull holds the subject over the
pose; what they are is :mod:`axdf_cli.render.framing`'s rule; ``Scene.bounds`` when a scene
has none): the camera never depends on which frames are written, so a ``--frames`` subset
leaves every frame's camera as it was. A following camera (``Scene.follow``) is the fixed
camera of the framing points carried by each frame's offset (:func:`follow_moves`). For a fixed view
the fit is exact and centred: the distance is the least that shows every point inside the
image less ``FRAME_MARGIN`` at each border, and the camera is shifted sideways so that the
projected subject sits in the middle both ways (:func:`fit_distance_view`, :func:`centre_shift`). The panels of a sheet
share the largest of their distances (one scale). An orbit turns about the framing centre
at one distance that fits every angle of a full turn.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from axdf_cli.render.framing import MIN_EXTENT, framing_points
from axdf_cli.specs.render import RenderSettings

#: camera.json's ``convention``: the axes are OpenCV's, the pixel centres are not.
CONVENTION = ("camera axes as OpenCV: x right, y down, z forward; world_to_camera maps world (Z up, metres) "
              "to camera; K in pixels of the written image with pixel centres at half-integers: pixel (i, j) "
              "(column i, row j from the top-left) spans [i, i+1) x [j, j+1), its centre is (i+0.5, j+0.5), "
              "and a point projecting to (u, v) lies in pixel (floor(u), floor(v)); OpenCV puts pixel centres "
              "at integers, so for cv2.projectPoints use K with cx - 0.5 and cy - 0.5; depth Z = camera z in "
              "metres (0 = background)")
# Fraction of the image kept free at each border by automatic framing.
FRAME_MARGIN = 0.04
# Orbit angles (degrees apart) over a full turn whose fits give an orbit's one distance.
ORBIT_FIT_STEP = 1.0
# Direction from the target to the camera for view "auto" (front, +X side, above).
AUTO_FROM = (0.6, -1.0, 0.45)

# view -> (forward, up) in world coordinates
VIEW_AXES = {
    "front": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    "side": ((-1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
    "top": ((0.0, 0.0, -1.0), (0.0, 1.0, 0.0)),
    "auto": (tuple(-x for x in AUTO_FROM), (0.0, 0.0, 1.0)),
}
SHEET_VIEWS = ("front", "side", "top")


@dataclass(frozen=True)
class Camera:
    view: str  # front | side | top | auto | camera
    K: np.ndarray  # (3, 3) float64 intrinsics in pixels of the whole image
    world_to_camera: np.ndarray  # (4, 4) float64, OpenCV axes (x right, y down, z forward)
    viewport: tuple[int, int, int, int]  # (x0, y0, w, h) panel in pixels, y0 from the top
    near: float  # clip distances along z, metres
    far: float

    def projection_gl(self, scale: int = 1) -> np.ndarray:
        """(4, 4) float64 clip-from-camera matrix for the panel viewport rendered ``scale`` x.

        Maps OpenCV camera coordinates to GL clip space such that after reading the
        framebuffer back and flipping its rows, pixel (u, v) of the panel matches ``K``.
        """
        x0, y0, w, h = self.viewport
        fx, fy = self.K[0, 0], self.K[1, 1]
        cx, cy = self.K[0, 2] - x0, self.K[1, 2] - y0
        n, f = self.near, self.far
        return np.array([
            [2 * fx / w, 0.0, 2 * cx / w - 1.0, 0.0],
            [0.0, -2 * fy / h, 1.0 - 2 * cy / h, 0.0],
            [0.0, 0.0, (f + n) / (f - n), -2 * f * n / (f - n)],
            [0.0, 0.0, 1.0, 0.0],
        ])

    def to_json(self) -> dict:
        return {"view": self.view, "K": self.K.tolist(),
                "world_to_camera": self.world_to_camera.tolist(),
                "viewport": list(self.viewport), "near": self.near, "far": self.far}


def look_at(position, forward, up) -> np.ndarray:
    """(4, 4) world-to-camera (OpenCV axes) for a camera at ``position`` looking along ``forward``."""
    z = np.asarray(forward, float)
    z = z / np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, float))
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)  # image down
    R = np.stack([x, y, z])  # rows: camera axes in world coordinates
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = -R @ np.asarray(position, float)
    return M


def intrinsics(width: int, height: int, fov_deg: float, x0: int = 0) -> np.ndarray:
    """(3, 3) K for a panel of ``width`` x ``height`` pixels starting at column ``x0``."""
    f = 0.5 * height / math.tan(math.radians(fov_deg) / 2)
    return np.array([[f, 0.0, x0 + 0.5 * width], [0.0, f, 0.5 * height], [0.0, 0.0, 1.0]])


def rot_z(deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def fit_distance(corners_rel: np.ndarray, R: np.ndarray, tan_x: float, tan_y: float) -> float:
    """Smallest distance along ``-forward`` from the target that shows every point.

    ``corners_rel``: (N, 3) points minus the target; ``R``: (3, 3) world-to-camera rotation;
    ``tan_x``, ``tan_y``: tangents of the half fields of view, already shrunk by the margin.
    A point p (camera axes) at distance D has depth D + p_z and must satisfy
    |p_x| <= tan_x (D + p_z) and |p_y| <= tan_y (D + p_z).
    """
    p = corners_rel @ R.T  # (N, 3)
    need = np.maximum(np.abs(p[:, 0]) / tan_x, np.abs(p[:, 1]) / tan_y) - p[:, 2]
    return float(need.max())


def fit_distance_view(points: np.ndarray, R: np.ndarray, tan_x: float, tan_y: float) -> float:
    """The least distance at which view rotation ``R`` can show every point (shifted sideways).

    With q = R p (camera axes about the world origin) and the camera at (s_x, s_y, -D) in
    those axes, point i is in view when |q_x - s_x| <= tan_x (q_z + D) (and alike in y). For
    a given D the allowed s_x form the interval [max(q_x - tan_x q_z) - tan_x D,
    min(q_x + tan_x q_z) + tan_x D], non-empty from D_x = (max(q_x - tan_x q_z) -
    min(q_x + tan_x q_z)) / (2 tan_x) on. The least distance is max(D_x, D_y) (points in front)."""
    q = points @ R.T
    d_x = ((q[:, 0] - tan_x * q[:, 2]).max() - (q[:, 0] + tan_x * q[:, 2]).min()) / (2 * tan_x)
    d_y = ((q[:, 1] - tan_y * q[:, 2]).max() - (q[:, 1] + tan_y * q[:, 2]).min()) / (2 * tan_y)
    extent = float(np.max(points.max(axis=0) - points.min(axis=0)))
    return float(max(d_x, d_y, float(-q[:, 2].min()) + 1e-3 * max(extent, MIN_EXTENT)))


def centre_shift(points: np.ndarray, R: np.ndarray, dist: float, tans: tuple[float, float]) -> np.ndarray:
    """The sideways shift (s_x, s_y) at distance ``dist`` (>= :func:`fit_distance_view`) that
    centres the projected points: max_i u_i = -min_i u_i with u_i = (q_i - s) / (q_z,i + dist),
    solved by bisection inside the interval where every point is in view (at its ends the
    points touch one edge, so the balance changes sign there)."""
    q = points @ R.T
    depth = q[:, 2] + dist
    out = np.empty(2)
    for k, t in enumerate(tans):
        lo = (q[:, k] - t * depth).max()
        hi = (q[:, k] + t * depth).min()
        for _ in range(60):  # the balance decreases in s
            s = 0.5 * (lo + hi)
            u = (q[:, k] - s) / depth
            lo, hi = (s, hi) if u.max() + u.min() > 0 else (lo, s)
        out[k] = 0.5 * (lo + hi)
    return out


def _view_axes(view: str, angle: float) -> tuple[np.ndarray, np.ndarray]:
    Rz = rot_z(angle)
    fwd, up = (Rz @ np.asarray(x, float) for x in VIEW_AXES[view])
    return fwd / np.linalg.norm(fwd), up


def panel_count(settings: RenderSettings) -> int:
    """Views side by side in one image: three for a sheet, else one."""
    return len(SHEET_VIEWS) if settings.view == "sheet" and settings.camera is None else 1


def sequence_cameras(scene, settings: RenderSettings) -> list[list[Camera]]:
    """Cameras for every frame of ``scene.frames``: ``[frame index][panel]``; fixed unless
    ``orbit`` is set (the angle counts from ``scene.first_frame``, the pose's first frame, so
    it too is the same for any subset of frames)."""
    if settings.pinned is not None:
        return pinned_cameras(settings.pinned, scene.frames)
    W, H = settings.size
    frames = [int(f) for f in scene.frames]
    first = getattr(scene, "first_frame", None)
    first = first if first is not None else (frames[0] if frames else 0)
    angles = [settings.orbit * (f - first) for f in frames]
    points = framing_points(scene)
    moves = follow_moves(scene, len(frames))
    if settings.camera is not None:
        targets = bone_targets(scene, settings, len(frames))
        offset = follow_offset(settings, points) if settings.camera.follows else None
        return [[_explicit(settings, points + o, a, t, offset)] for a, t, o in zip(angles, targets, moves)]

    views = SHEET_VIEWS if settings.view == "sheet" else (settings.view,)
    fov = settings.fov
    tan_y = math.tan(math.radians(fov) / 2) * (1 - 2 * FRAME_MARGIN)
    tan_x = tan_y * W / H
    if settings.orbit == 0.0:
        # fixed views: each centred on the subject, all at the largest distance (one scale)
        rots = {v: look_at(np.zeros(3), *_view_axes(v, 0.0))[:3, :3] for v in views}
        dist = max(fit_distance_view(points, R, tan_x, tan_y) for R in rots.values())
        panel = []
        for i, v in enumerate(views):
            R = rots[v]
            shift = centre_shift(points, R, dist, (tan_x, tan_y))
            M = np.eye(4)
            M[:3, :3] = R
            M[:3, 3] = -np.array([shift[0], shift[1], -dist])
            near, far = _clip_range(M, points)
            panel.append(Camera(v, intrinsics(W, H, fov, i * W), M, (i * W, 0, W, H), near, far))
        return [[_moved(c, o) for c in panel] for o in moves]
    # orbit: about the framing centre, one distance fitting every angle of a full turn
    target = 0.5 * (points.min(axis=0) + points.max(axis=0))
    dist = MIN_EXTENT
    for a in np.arange(0.0, 360.0, ORBIT_FIT_STEP):
        for v in views:
            fwd, up = _view_axes(v, float(a))
            dist = max(dist, fit_distance(points - target, look_at(np.zeros(3), fwd, up)[:3, :3], tan_x, tan_y))
    out = []
    for a, o in zip(angles, moves):
        panel = []
        for i, v in enumerate(views):
            fwd, up = _view_axes(v, a)
            M = look_at(target + o - dist * fwd, fwd, up)
            near, far = _clip_range(M, points + o)
            panel.append(Camera(v, intrinsics(W, H, fov, i * W), M, (i * W, 0, W, H), near, far))
        out.append(panel)
    return out


def pinned_cameras(pinned, frames) -> list[list[Camera]]:
    """The cameras of a camera file (``--camera``: :class:`~axdf_cli.specs.render.PinnedCameras`)
    for each of ``frames``, exactly as the file holds them (each frame's own; a fixed camera's
    for any frame). A frame the file has no camera for is a ValueError (checked earlier, as an
    input error, by :func:`~axdf_cli.specs.render.check_pinned`)."""
    out = []
    for f in frames:
        views = pinned.views_for(int(f))
        if views is None:
            raise ValueError(f"{pinned.source} has no camera for frame {int(f)}")
        out.append([Camera(v.view, np.array(v.K, np.float64), np.array(v.world_to_camera, np.float64),
                           tuple(v.viewport), float(v.near), float(v.far)) for v in views])
    return out


def follow_moves(scene, n: int) -> np.ndarray:
    """(F, 3) how far a following camera has moved at each of ``scene.frames``
    (``scene.follow``; zeros for a fixed camera): the framing points are relative to it."""
    follow = getattr(scene, "follow", None)
    if follow is None:
        return np.zeros((n, 3))
    follow = np.asarray(follow, dtype=np.float64)
    if follow.shape != (n, 3):
        raise ValueError(f"Scene.follow must hold {n} offsets")
    return follow


def _moved(cam: Camera, offset: np.ndarray) -> Camera:
    """``cam`` carried by ``offset`` (world, metres): same orientation, intrinsics and clip range."""
    if not offset.any():
        return cam
    M = cam.world_to_camera.copy()
    M[:3, 3] -= M[:3, :3] @ offset  # x_cam = R (x - offset) + t
    return Camera(cam.view, cam.K, M, cam.viewport, cam.near, cam.far)


def bone_targets(scene, settings: RenderSettings, n: int) -> list:
    """Per frame of ``scene.frames``: the camera's target bone's origin (3,), or None for a
    point target (``scene.targets`` holds the bone's positions)."""
    cam = settings.camera
    if cam is None or cam.target_bone is None:
        return [None] * n
    targets = getattr(scene, "targets", None)
    if targets is None or len(targets) != n:
        raise ValueError(f"the camera aims at bone {cam.target_bone!r}: Scene.targets must hold its {n} positions")
    return [np.asarray(t, dtype=np.float64) for t in targets]


def follow_offset(settings: RenderSettings, points: np.ndarray) -> np.ndarray:
    """(3,) the offset from a followed bone to the camera: the camera's ``offset``, or the
    ``auto`` view's direction at the distance that shows every framing point about their
    centre (:func:`fit_distance`), so the framed subject fits whatever the bone does."""
    cam = settings.camera
    if cam.offset is not None:
        return np.asarray(cam.offset, dtype=np.float64)
    W, H = settings.size
    tan_y = math.tan(math.radians(cam.fov) / 2) * (1 - 2 * FRAME_MARGIN)
    fwd, up = _view_axes("auto", 0.0)
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    dist = fit_distance(points - centre, look_at(np.zeros(3), fwd, up)[:3, :3], tan_y * W / H, tan_y)
    return -max(dist, MIN_EXTENT) * fwd


def _explicit(settings: RenderSettings, points: np.ndarray, angle: float, bone: np.ndarray | None = None,
              offset: np.ndarray | None = None) -> Camera:
    """The explicit camera at one frame: ``bone`` is its target bone's origin at that frame, or
    None (a point target); ``offset``: from the bone to a camera that follows it
    (:func:`follow_offset`)."""
    cam = settings.camera
    W, H = settings.size
    centre = 0.5 * (points.min(axis=0) + points.max(axis=0))
    if bone is not None:
        target = bone
        position = target + offset if cam.follows else np.asarray(cam.position, float)
    else:
        target = np.asarray(cam.target if cam.target is not None else centre, float)
        position = np.asarray(cam.position, float)
    Rz = rot_z(angle)
    pos = target + Rz @ (position - target)
    up = Rz @ np.asarray(cam.up, float)
    fwd = target - pos
    if np.linalg.norm(fwd) < 1e-12:
        fwd = Rz @ np.array([0.0, 1.0, 0.0])  # a fixed camera the bone passed through: look ahead
    if np.linalg.norm(np.cross(fwd, up)) < 1e-9 * max(np.linalg.norm(fwd), 1e-12):
        up = Rz @ np.array([0.0, 1.0, 0.0])  # looking along up (a default target straight below)
    M = look_at(pos, fwd, up)
    near, far = _clip_range(M, points)
    return Camera("camera", intrinsics(W, H, cam.fov), M, (0, 0, W, H), near, far)


def _clip_range(M: np.ndarray, corners: np.ndarray) -> tuple[float, float]:
    """Near and far planes that keep the framed box (and generous room around it)."""
    z = corners @ M[:3, :3].T[:, 2] + M[2, 3]
    diag = float(np.linalg.norm(corners.max(0) - corners.min(0)))
    near = max(float(z.min()) * 0.25, diag * 1e-3, 1e-4)
    far = max(float(z.max()) * 4.0 + diag, near * 100.0)
    return near, far


def camera_json(cameras: list[list[Camera]], frames, settings: RenderSettings, ids: dict) -> dict:
    """The content of ``camera.json``."""
    W, H = settings.size
    n_panels = len(cameras[0]) if cameras else 1
    return {
        "convention": CONVENTION,
        "width": W * n_panels,
        "height": H,
        "views": [c.view for c in cameras[0]] if cameras else [],
        "ids": ids,
        "frames": [{"frame": int(f), "cameras": [c.to_json() for c in cams]}
                   for f, cams in zip(frames, cameras)],
    }
