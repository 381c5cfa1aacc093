"""Compile every command's numba kernels into the kernel cache now, so that no first ``axdf
fit``, ``axdf skin``, ``axdf dataset build`` or ``axdf run`` compiles for minutes later
(``make demo`` runs this first; ``make warm`` alone).

numba compiles a kernel for the argument types of its first call, so the honest way to compile
what a command runs is to run the command: each step below runs one command in process, on the
smallest input of the repository's own files that reaches its kernels, in a temporary folder
that is removed afterwards. A step whose kernels are all cached already takes seconds.

    python scripts/warm_kernels.py            # from the repository root
"""
from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT / "poses" / "skeletons" / "gait2392.yaml"

#: A data set of one frame of the walk in two sequences (so that ``--jobs 2`` starts its
#: workers, whose kernels are the serial twins), each seen once, small, with the skin: what
#: ``axdf dataset build`` compiles for the shipped data-set files and the README's recipe.
DATASET = """\
dataset: warm
seed: 1
skeleton: {root}/poses/skeletons/gait2392.yaml
muscles: {root}/muscles/gait2392_packed
skin: {root}/skins/gait2392/skin.yaml
motions:
  walk: {{pose: {root}/poses/gait2392_walk.yaml, frames: "18:19"}}
sequences:
  - {{motion: walk}}
  - {{sample: perturb, around: walk, count: 1, spread: {{default: 2}}}}
activation: motion
cameras:
  sphere: {{views: 1, distance: [3.5, 3.7], elevation: [0, 25], azimuth: [-150, 150], fov: 30, per: sequence}}
render: {{size: [32, 64], passes: [png, exr]}}
format: ply
"""


def steps(tmp: Path) -> list[tuple[str, list[str]]]:
    """(what, argv) of each step, in order: a later step may read what an earlier one wrote."""
    one = tmp / "one_muscle"
    one.mkdir()
    shutil.copy(ROOT / "muscles" / "gait2392_atlas" / "soleus_r.yaml", one)
    (tmp / "warm.yaml").write_text(DATASET.format(root=ROOT))
    allow = ["--allow-outside"]
    return [
        ("axdf run (the walk's kernels, with contact and the skin)",
         ["run", "--muscles", str(ROOT / "muscles" / "gait2392_packed"), "--pose", str(ROOT / "poses" / "gait2392_walk.yaml"),
          "--frames", "18:19", "--skin", str(ROOT / "skins" / "gait2392" / "skin.yaml"), "--render", "--size", "32x64",
          "--out", str(tmp / "run"), "--quiet", *allow]),
        ("axdf run (one atlas muscle at rest, the mesh axdf fit reads next)",
         ["run", "--muscles", str(one), "--pose", str(ROOT / "poses" / "gait2392_rest.yaml"), "--no-render",
          "--out", str(tmp / "rest"), "--quiet", *allow]),
        ("axdf fit", ["fit", str(tmp / "rest" / "meshes" / "soleus_r" / "soleus_r_0000.ply"), "--skeleton", str(GAIT),
                      "--sections", "8", "--out", str(tmp / "fit"), "--quiet"]),
        ("axdf skin", ["skin", "--skeleton", str(GAIT), "--muscles", str(ROOT / "muscles" / "gait2392_packed"), "--push",
                       "--out", str(tmp / "skin"), "--quiet", *allow]),
        ("axdf dataset build", ["dataset", "build", str(tmp / "warm.yaml"), "--out", str(tmp / "dataset"), "--jobs", "2",
                                "--quiet", *allow]),
    ]


def main() -> int:
    from axdf_cli import runtime

    runtime.configure()
    from axdf_cli.cli.main import main as axdf

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="axdf-warm-") as d:
        todo = steps(Path(d))
        for i, (what, argv) in enumerate(todo, 1):
            missing, total = runtime.cold_kernels(argv[0])
            print(f"warm {i}/{len(todo)}: {what}: " + (f"up to {missing} of {total} kernels to compile" if missing
                                                       else "cached"), file=sys.stderr, flush=True)
            t = time.perf_counter()
            with runtime.compile_progress(lambda text: print(text, file=sys.stderr, flush=True)):
                rc = axdf(argv)
            if rc != 0:
                print(f"warm: {what} exited {rc} (argv: axdf {' '.join(argv)})", file=sys.stderr)
                return rc
            print(f"warm {i}/{len(todo)}: done in {time.perf_counter() - t:.0f} s", file=sys.stderr, flush=True)
    print(f"warm: every command's kernels are in {runtime.kernel_cache()} ({time.perf_counter() - t0:.0f} s)",
          file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
