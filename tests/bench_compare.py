"""Time `axdf compare` on a synthetic run: 10 muscles x 50 frames of meshes (40x24 tubes,
962 vertices) plus 50 PNG + 50 EXR frames of 256x256. Not collected by pytest; run with
``.venv/bin/python tests/bench_compare.py [--obj]``.

Cases: identical copies (byte-equal fast path), and every file perturbed within tolerance
(llvmpipe-like noise on all images, 1e-7 m on all vertices), which decodes and measures
every file, computing FLIP for every image."""
from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

sys.path.insert(0, str(Path(__file__).parent))
from compare_helpers import make_run, tube, write_exr, write_obj, write_ply  # noqa: E402

from axdf_cli.cli.main import main  # noqa: E402
from axdf_cli.compare.images import read_exr  # noqa: E402


def perturb(run: Path, fmt: str, rng) -> None:
    writer = write_ply if fmt == "ply" else write_obj
    for i in range(10):
        for fr in range(50):
            v, n, f = tube(fr, i, 40, 24)
            writer(run / f"meshes/m{i}/m{i}_{fr:04d}.{fmt}", v + np.float32(1e-7), n, f)
    for fr in range(50):
        p = run / f"frames/{fr:04d}.png"
        g = np.asarray(Image.open(p)).astype(int)
        Image.fromarray(np.clip(g + rng.integers(-1, 2, g.shape), 0, 255).astype(np.uint8)).save(p)
        e = run / f"frames/{fr:04d}.exr"
        ch = read_exr(e)
        ch = {k: (v + (rng.random(v.shape) * 1e-3).astype(v.dtype)) if k in "RGB" else v for k, v in ch.items()}
        write_exr(e, ch)


def timed(argv) -> tuple[int, float]:
    t = time.perf_counter()
    code = main(argv)
    return code, time.perf_counter() - t


if __name__ == "__main__":
    fmt = "obj" if "--obj" in sys.argv else "ply"
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        g = make_run(tmp / "golden", muscles=10, frames=50, size=256, fmt=fmt, resolution=(40, 24))
        a = make_run(tmp / "actual", muscles=10, frames=50, size=256, fmt=fmt, resolution=(40, 24))
        n = sum(1 for p in a.rglob("*") if p.is_file())
        code, s = timed(["compare", str(a), str(g), "-q", "--report", str(tmp / "r.json")])
        print(f"{fmt}: {n} files, identical: exit {code}, {s:.2f} s")
        perturb(a, fmt, np.random.default_rng(0))
        code, s = timed(["compare", str(a), str(g), "-q", "--report", str(tmp / "r.json")])
        print(f"{fmt}: {n} files, all perturbed within tolerance: exit {code}, {s:.2f} s")
