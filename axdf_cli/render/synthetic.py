"""Synthetic scenes for tests and the benchmark: ellipsoid 'muscles' that move and bulge
over time around a capsule-like 'bone' that rotates. Deterministic (no randomness)."""
from __future__ import annotations

import math

import numpy as np

from axdf_cli.render.scene import FrameChunk, Scene, SceneBone, SceneMuscle

PALETTE = ((0.75, 0.16, 0.14), (0.85, 0.45, 0.12), (0.70, 0.62, 0.15), (0.25, 0.55, 0.22),
           (0.12, 0.50, 0.60), (0.18, 0.30, 0.70), (0.45, 0.22, 0.62), (0.72, 0.22, 0.45))


def uv_sphere(rings: int, segments: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere: (V, 3) float64 vertices (two poles + rings*segments) and (T, 3) int32
    faces, counter-clockwise seen from outside."""
    th = np.pi * (np.arange(1, rings + 1) / (rings + 1))  # polar angle
    ph = 2 * np.pi * np.arange(segments) / segments
    st, ct = np.sin(th)[:, None], np.cos(th)[:, None]
    ring = np.stack([st * np.cos(ph), st * np.sin(ph), np.broadcast_to(ct, (rings, segments))], -1)
    v = np.concatenate([[[0, 0, 1]], ring.reshape(-1, 3), [[0, 0, -1]]])
    idx = 1 + np.arange(rings * segments).reshape(rings, segments)
    nxt = np.roll(idx, -1, axis=1)
    faces = [np.stack([np.zeros(segments, int), idx[0], nxt[0]], 1)]
    for r in range(rings - 1):
        a, b, c, d = idx[r], nxt[r], idx[r + 1], nxt[r + 1]
        faces += [np.stack([a, c, d], 1), np.stack([a, d, b], 1)]
    south = len(v) - 1
    faces.append(np.stack([np.full(segments, south), nxt[-1], idx[-1]], 1))
    return v, np.concatenate(faces).astype(np.int32)


def synthetic_scene(n_muscles: int = 4, verts: int = 600, n_frames: int = 4, with_bone: bool = True,
                    first_frame: int = 0) -> tuple[Scene, list[FrameChunk]]:
    """A Scene and one FrameChunk per frame; muscles are ellipsoids arranged around +Z."""
    segments = max(8, int(round(math.sqrt(2 * verts))))
    rings = max(3, int(round((verts - 2) / segments)))
    unit, faces = uv_sphere(rings, segments)
    frames = tuple(range(first_frame, first_frame + n_frames))
    muscles = tuple(SceneMuscle(f"m{i:02d}", PALETTE[i % len(PALETTE)], faces) for i in range(n_muscles))
    pos = [np.empty((n_frames, len(unit), 3), np.float32) for _ in range(n_muscles)]
    nrm = [np.empty((n_frames, len(unit), 3), np.float32) for _ in range(n_muscles)]
    for k in range(n_frames):
        t = k / max(n_frames - 1, 1)
        for i in range(n_muscles):
            ang = 2 * np.pi * i / max(n_muscles, 1)
            bulge = 1.0 + 0.25 * math.sin(2 * np.pi * t + i)
            radii = np.array([0.03 * bulge, 0.03 * bulge, 0.12 / math.sqrt(bulge)])
            centre = np.array([0.07 * math.cos(ang), 0.07 * math.sin(ang), 0.02 * math.sin(2 * np.pi * t)])
            tilt = 0.2 * math.sin(ang + 2 * np.pi * t)
            R = np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]])
            p = unit * radii
            n = unit / radii  # ellipsoid normal: gradient of sum (x/r)^2
            n /= np.linalg.norm(n, axis=1, keepdims=True)
            pos[i][k] = p @ R.T + centre
            nrm[i][k] = n @ R.T
    bones = ()
    bone_world = np.zeros((n_frames, 0, 4, 4))
    if with_bone:
        bv, bf = uv_sphere(6, 12)
        bv = bv * np.array([0.012, 0.012, 0.2])
        bones = (SceneBone("bone", bv.astype(np.float32), bf),)
        bone_world = np.zeros((n_frames, 1, 4, 4))
        for k in range(n_frames):
            a = 0.3 * math.sin(2 * np.pi * k / max(n_frames, 1))
            c, s = math.cos(a), math.sin(a)
            bone_world[k, 0] = [[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0.02], [0, 0, 0, 1]]
    allp = np.concatenate([p.reshape(-1, 3) for p in pos]) if n_muscles else np.zeros((1, 3))
    bounds = np.stack([allp.min(0), allp.max(0)]).astype(np.float64)
    scene = Scene(muscles=muscles, bones=bones, bounds=bounds, frames=frames)
    chunks = [FrameChunk(frames=np.array([f]), positions=tuple(p[k:k + 1] for p in pos),
                         normals=tuple(n[k:k + 1] for n in nrm), bone_world=bone_world[k:k + 1])
              for k, f in enumerate(frames)]
    return scene, chunks
