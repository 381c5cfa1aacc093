"""Synthetic run folders for the ``axdf compare`` tests (the layout of SPEC.md, "Output folder
of a run"), written with small writers of our own: binary PLY, OBJ, PNG (Pillow), OpenEXR."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

SIZE = 64  # image side in the tests: 4096 pixels, so the default 0.1% allows 4 failing pixels


def tube(frame: int, seed: int, along: int = 10, around: int = 12):
    """A closed tube (a muscle stand-in): vertices ``(V, 3) float32``, normals ``(V, 3)``,
    faces ``(T, 3) int32``. Moves a little with ``frame``."""
    rng = np.random.default_rng(seed)
    length, radius = 0.3, 0.03 * (1 + 0.2 * rng.random())
    s = np.linspace(0, 1, along)
    a = np.linspace(0, 2 * np.pi, around, endpoint=False)
    r = radius * (0.3 + np.sin(np.pi * s)) * (1 + 0.01 * frame)  # (along,)
    x = np.repeat(s * length, around)
    y = (r[:, None] * np.cos(a)[None, :]).ravel()
    z = (r[:, None] * np.sin(a)[None, :]).ravel()
    v = np.stack([x, y + 0.1 * seed, z], axis=1)
    n = np.stack([np.zeros_like(x), np.cos(np.tile(a, along)), np.sin(np.tile(a, along))], axis=1)
    # caps: one vertex each end
    v = np.vstack([v, [[-0.01, 0.1 * seed, 0]], [[length + 0.01, 0.1 * seed, 0]]])
    n = np.vstack([n, [[-1, 0, 0]], [[1, 0, 0]]])
    faces = []
    for i in range(along - 1):
        for j in range(around):
            p, q = i * around + j, i * around + (j + 1) % around
            faces += [[p, q, q + around], [p, q + around, p + around]]
    c0, c1 = len(v) - 2, len(v) - 1
    for j in range(around):
        faces.append([c0, (j + 1) % around, j])
        last = (along - 1) * around
        faces.append([c1, last + j, last + (j + 1) % around])
    return v.astype(np.float32), n.astype(np.float32), np.asarray(faces, np.int32)


def write_ply(path: Path, v: np.ndarray, n: np.ndarray, f: np.ndarray) -> None:
    """Binary little-endian PLY as `axdf run` writes it: float32 x y z nx ny nz, uchar-int lists."""
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
              "property float x\nproperty float y\nproperty float z\n"
              "property float nx\nproperty float ny\nproperty float nz\n"
              f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    vert = np.hstack([v, n]).astype("<f4")
    face = np.zeros(len(f), np.dtype([("n", "u1"), ("i", "<i4", (3,))]))
    face["n"] = 3
    face["i"] = f
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(header + vert.tobytes() + face.tobytes())


def write_obj(path: Path, v: np.ndarray, n: np.ndarray, f: np.ndarray) -> None:
    lines = [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in v]
    lines += [f"vn {x:.9g} {y:.9g} {z:.9g}" for x, y, z in n]
    lines += ["f " + " ".join(f"{i + 1}//{i + 1}" for i in tri) for tri in f]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def blob(cx: float, cy: float, radius: float, size: int = SIZE) -> np.ndarray:
    """A shaded sphere on a transparent background: ``(size, size, 4) float32`` in [0, 1]."""
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float64)
    dx, dy = (xx - cx) / radius, (yy - cy) / radius
    rr = dx * dx + dy * dy
    inside = rr < 1
    nz = np.sqrt(np.clip(1 - rr, 0, 1))
    shade = np.clip(0.2 + 0.8 * (0.5 * nz - 0.4 * dx - 0.3 * dy), 0, 1) * inside
    img = np.zeros((size, size, 4))
    img[..., 0] = shade * 0.9
    img[..., 1] = shade * 0.35
    img[..., 2] = shade * 0.3
    img[..., 3] = inside
    return img.astype(np.float32)


def write_png(path: Path, rgba: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray((np.clip(rgba, 0, 1) * 255 + 0.5).astype(np.uint8), "RGBA").save(path)


def exr_channels(rgba: np.ndarray) -> dict:
    """The AOVs of SPEC.md from a blob: R G B A half, Z and N.* float32, id uint32."""
    inside = rgba[..., 3] > 0
    h, w = inside.shape
    return {
        "R": rgba[..., 0].astype(np.float16), "G": rgba[..., 1].astype(np.float16),
        "B": rgba[..., 2].astype(np.float16), "A": rgba[..., 3].astype(np.float16),
        "Z": np.where(inside, 2.0 + 0.1 * rgba[..., 0], np.inf).astype(np.float32),
        "N.X": np.where(inside, 0.1, 0.0).astype(np.float32),
        "N.Y": np.where(inside, 0.2, 0.0).astype(np.float32),
        "N.Z": np.where(inside, 0.97, 0.0).astype(np.float32),
        "id": np.where(inside, 3, 0).astype(np.uint32),
    }


def write_exr(path: Path, channels: dict) -> None:
    import OpenEXR

    path.parent.mkdir(parents=True, exist_ok=True)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {k: np.ascontiguousarray(v) for k, v in channels.items()}) as f:
        f.write(str(path))


def make_run(root: Path, muscles: int = 3, frames: int = 4, size: int = SIZE, fmt: str = "ply",
             seed: int = 0, resolution: tuple[int, int] = (10, 12)) -> Path:
    """A complete synthetic run folder; the same arguments give the same bytes."""
    names = [f"m{i}" for i in range(muscles)]
    writer = write_ply if fmt == "ply" else write_obj
    for i, name in enumerate(names):
        for fr in range(frames):
            v, n, f = tube(fr, seed + i, *resolution)
            writer(root / "meshes" / name / f"{name}_{fr:04d}.{fmt}", v, n, f)
    for fr in range(frames):
        img = blob(size * 0.45 + fr, size * 0.5, size * 0.2, size)
        write_png(root / "frames" / f"{fr:04d}.png", img)
        write_exr(root / "frames" / f"{fr:04d}.exr", exr_channels(img))
    rows = ["frame,muscle,length,volume,volume_ratio,tension,twist"]
    for fr in range(frames):
        for i, name in enumerate(names):
            rows.append(f"{fr},{name},{0.3 + 0.001 * fr:.9g},{1.2345e-4 * (1 + i):.9g},1,0,{0.5 * fr:.9g}")
    (root / "stats.csv").write_text("\n".join(rows) + "\n")
    rows = ["frame,bone,x,y,z,qw,qx,qy,qz"]
    for fr in range(frames):
        rows.append(f"{fr},humerus,0,0,0,1,0,0,0")
        rows.append(f"{fr},radius,0.3,{0.001 * fr:.9g},0,0.99,0,0.1,0")
    (root / "bones.csv").write_text("\n".join(rows) + "\n")
    cam = {"K": [[size, 0, size / 2], [0, size, size / 2], [0, 0, 1]],
           "world_to_camera": {str(fr): [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -2], [0, 0, 0, 1]]
                               for fr in range(frames)}}
    (root / "camera.json").write_text(json.dumps(cam, indent=1))
    manifest = {"tool": "axdf", "version": "0.1.0",
                "inputs": [{"path": "muscles/m0.yaml", "sha256": "a" * 64},
                           {"path": "poses/flex.yaml", "sha256": "b" * 64}],
                "settings": {"format": fmt, "size": [size, size]},
                "frames": list(range(frames)), "gl_renderer": f"llvmpipe seed {seed}",
                "outputs": {"stats.csv": "c" * 64}}
    (root / "manifest.json").write_text(json.dumps(manifest, indent=1))
    return root


def tree_bytes(root: Path) -> dict[str, bytes]:
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
