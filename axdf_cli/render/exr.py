"""OpenEXR data passes, written with the OpenEXR 3.x Python bindings.

Channels (scanline image, ZIP compression, no varying attributes, so identical input gives
identical bytes):

=========================  ======  =========================================================
channel                    type    content
=========================  ======  =========================================================
R, G, B, A                 HALF    linear colour, premultiplied by A (as composited)
Z                          FLOAT   camera depth in metres (OpenCV z); 0 = background
N.X, N.Y, N.Z              FLOAT   world-space unit normal; 0 = background
id                         UINT    0 = background, 1..M muscles, M+1.. bones (camera.json)
=========================  ======  =========================================================
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.errors import EnvironmentProblem

CHANNEL_TYPES = {"R": np.float16, "G": np.float16, "B": np.float16, "A": np.float16,
                 "Z": np.float32, "N.X": np.float32, "N.Y": np.float32, "N.Z": np.float32,
                 "id": np.uint32, "under.id": np.uint32, "under.Z": np.float32, "part.id": np.uint32}


def exr_channels(rgba: np.ndarray, depth: np.ndarray, normals: np.ndarray, ids: np.ndarray,
                 under: tuple[np.ndarray, np.ndarray] | None = None, parts: np.ndarray | None = None) -> dict:
    """Name -> (H, W) array of the type in :data:`CHANNEL_TYPES`; ``under``: an opaque skin's
    muscle-under-skin pass (``under.id``: the muscle's id, ``under.Z``: metres under the skin);
    ``parts``: its body-part pass (``part.id``: 1 + the part's index, 0 off the skin)."""
    ch = {}
    for i, c in enumerate("RGBA"):
        ch[c] = np.ascontiguousarray(rgba[..., i], dtype=np.float16)
    ch["Z"] = np.ascontiguousarray(depth, dtype=np.float32)
    for i, c in enumerate(("N.X", "N.Y", "N.Z")):
        ch[c] = np.ascontiguousarray(normals[..., i], dtype=np.float32)
    ch["id"] = np.ascontiguousarray(ids, dtype=np.uint32)
    if under is not None:
        ch["under.id"] = np.ascontiguousarray(under[0], dtype=np.uint32)
        ch["under.Z"] = np.ascontiguousarray(under[1], dtype=np.float32)
    if parts is not None:
        ch["part.id"] = np.ascontiguousarray(parts, dtype=np.uint32)
    return ch


def write_exr(path: Path, channels: dict) -> str:
    """Write ``channels`` (name -> (H, W) array) atomically; return the file's sha256."""
    try:
        import OpenEXR
    except ImportError as e:
        raise EnvironmentProblem(f"cannot import OpenEXR ({e})",
                                 "pip install 'OpenEXR>=3.2' (make setup does this)") from None
    path = Path(path)
    atomic.ensure_dir(path.parent)
    tmp = atomic.temp_path(path)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    try:
        with atomic.deferred_signals():
            try:
                with OpenEXR.File(header, channels) as f:
                    f.write(str(tmp))
                os.replace(tmp, path)
            except BaseException:
                tmp.unlink(missing_ok=True)
                raise
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise EnvironmentProblem(f"{path}: cannot write ({e.strerror})",
                                 "choose a writable --out folder with free space") from None
    except RuntimeError as e:  # OpenEXR reports I/O failures as RuntimeError
        tmp.unlink(missing_ok=True)
        raise EnvironmentProblem(f"{path}: cannot write EXR ({e})",
                                 "choose a writable --out folder with free space") from None
    return atomic.sha256_file(path)
