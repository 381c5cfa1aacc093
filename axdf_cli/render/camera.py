"""Cameras: named views, automatic framing over the whole sequence, orbit, explicit cameras.

World frame (fixed for axdf): Z up, metres, right-handed (as in Blender). A body faces -Y.

- ``front`` looks along +Y (camera at -Y), image up = +Z, +X to the right.
- ``side`` looks along -X (camera at +X), image up = +Z, +Y to the right.
- ``top`` looks down -Z (camera above), image up = +Y, +X to the right.
- ``auto`` a three-quarter view from front, +X side and above (direction ``AUTO_FROM``).
- ``sheet`` front, side and top side by side in one image (each panel ``size``), like the
  paper's figures; all three panels share one camera distance, so they share one scale.

Camera convention written to ``camera.json`` (OpenCV): camera axes x right, y down, z
forward (the viewing direction); ``world_to_camera`` is the 4x4 matrix taking world points
(metres) to camera coordinates; ``K`` is in pixels of the written image, pixel (0, 0) is
the top-left pixel and its centre is at (0.5, 0.5); a world point P projects to
``(u, v, 1) ~ K @ (world_to_camera @ [P, 1])[:3]`` and its camera depth is the z coordinate.
For a sheet each panel has its own camera whose ``K`` already includes the panel's
horizontal offset, so projected pixels are pixels of the whole sheet.

Automatic framing uses ``Scene.bounds`` (every muscle over every frame): one fixed distance
is chosen for the whole sequence (for an orbit, the largest over all its angles), so the
camera never jumps and every muscle stays in view.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from axdf_cli.render.settings import RenderSettings

# Fraction of the image kept free at each border by automatic framing.
FRAME_MARGIN = 0.06
# Direction from the target to the camera for view "auto" (front, +X side, above).
AUTO_FROM = (0.6, -1.0, 0.45)
# Smallest extent (metres) used for framing, so a point-like scene still frames.
MIN_EXTENT = 1e-3

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


def _box_corners(bounds: np.ndarray) -> np.ndarray:
    """(8, 3) corners of a (2, 3) AABB, grown to at least MIN_EXTENT each way."""
    lo, hi = np.asarray(bounds, float)
    c = 0.5 * (lo + hi)
    half = np.maximum(0.5 * (hi - lo), 0.5 * MIN_EXTENT)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    return c + signs * half


def fit_distance(corners_rel: np.ndarray, R: np.ndarray, tan_x: float, tan_y: float) -> float:
    """Smallest distance along ``-forward`` from the target that shows every corner.

    ``corners_rel``: (8, 3) corners minus the target; ``R``: (3, 3) world-to-camera rotation;
    ``tan_x``, ``tan_y``: tangents of the half fields of view, already shrunk by the margin.
    A corner p (camera axes) at distance D has depth D + p_z and must satisfy
    |p_x| <= tan_x (D + p_z) and |p_y| <= tan_y (D + p_z).
    """
    p = corners_rel @ R.T  # (8, 3)
    need = np.maximum(np.abs(p[:, 0]) / tan_x, np.abs(p[:, 1]) / tan_y) - p[:, 2]
    return float(need.max())


def panel_count(settings: RenderSettings) -> int:
    """Views side by side in one image: three for a sheet, else one."""
    return len(SHEET_VIEWS) if settings.view == "sheet" and settings.camera is None else 1


def sequence_cameras(bounds: np.ndarray, frames: tuple[int, ...] | list[int],
                     settings: RenderSettings) -> list[list[Camera]]:
    """Cameras for every frame: ``[frame index][panel]``; fixed unless ``orbit`` is set."""
    W, H = settings.size
    frames = list(frames)
    first = frames[0] if frames else 0
    angles = [settings.orbit * (f - first) for f in frames]
    corners = _box_corners(bounds)
    if settings.camera is not None:
        return [[_explicit(settings, corners, a)] for a in angles]

    views = SHEET_VIEWS if settings.view == "sheet" else (settings.view,)
    fov = settings.fov
    tan_y = math.tan(math.radians(fov) / 2) * (1 - 2 * FRAME_MARGIN)
    tan_x = tan_y * W / H
    target = corners.mean(axis=0)
    # one distance for every view, frame and orbit angle: no jumping, one scale per sheet
    dist = MIN_EXTENT
    for a in sorted(set(angles)) or [0.0]:
        Rz = rot_z(a)
        for v in views:
            fwd, up = (Rz @ np.asarray(x) for x in VIEW_AXES[v])
            R = look_at(np.zeros(3), fwd, up)[:3, :3]
            dist = max(dist, fit_distance(corners - target, R, tan_x, tan_y))
    out = []
    for a in angles:
        Rz = rot_z(a)
        panel = []
        for i, v in enumerate(views):
            fwd, up = (Rz @ np.asarray(x) for x in VIEW_AXES[v])
            fwd = fwd / np.linalg.norm(fwd)
            M = look_at(target - dist * fwd, fwd, up)
            near, far = _clip_range(M, corners)
            panel.append(Camera(v, intrinsics(W, H, fov, i * W), M, (i * W, 0, W, H), near, far))
        out.append(panel)
    return out


def _explicit(settings: RenderSettings, corners: np.ndarray, angle: float) -> Camera:
    cam = settings.camera
    W, H = settings.size
    target = np.asarray(cam.target, float)
    Rz = rot_z(angle)
    pos = target + Rz @ (np.asarray(cam.position, float) - target)
    up = Rz @ np.asarray(cam.up, float)
    M = look_at(pos, target - pos, up)
    near, far = _clip_range(M, corners)
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
        "convention": ("OpenCV: camera x right, y down, z forward; world_to_camera maps world "
                       "(Z up, metres) to camera; K in pixels, pixel (0,0) top-left with centre "
                       "(0.5,0.5); depth Z = camera z in metres (0 = background)"),
        "width": W * n_panels,
        "height": H,
        "views": [c.view for c in cameras[0]] if cameras else [],
        "ids": ids,
        "frames": [{"frame": int(f), "cameras": [c.to_json() for c in cams]}
                   for f, cams in zip(frames, cameras)],
    }
