"""Make muscles/gait2392_atlas from the Visible Human Female atlas (`make atlas`).

    python scripts/atlas_library.py [--data DIR] [--out muscles/gait2392_atlas] [--sides r,l] [--sections N]
    python scripts/atlas_library.py --transform FILE [--data DIR] [--sides r]

DIR: the atlas folder (default ../shared/data/atlas/visible_human_female). The leg's atlas
muscles are registered onto gait2392 at rest and fitted under gait2392's names
(axdf_cli/tools/atlas_library.py; docs/FIT.md "Atlas onto a skeleton"); the muscles the atlas
lacks are copied from muscles/gait2392. The folder is replaced as a whole.

--transform FILE writes, instead, the registration's landmark similarity of one leg (the first of
--sides) as an `axdf fit --transform` file: the route for fitting the atlas' meshes, in their
scan frame and millimetres, onto the skeleton with `axdf fit --units mm --transform FILE`.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

CREDIT = """# gait2392 muscles fitted to the Visible Human Female atlas

Made by `make atlas` (scripts/atlas_library.py; docs/FIT.md, "Atlas onto a skeleton"): the
atlas' muscles of the {legs} registered onto gait2392's skeleton at rest (landmarks, then a
thin-plate warp onto the model's bones) and fitted as axis muscles under gait2392's names
(axdf_cli/data/atlas_gait2392.yaml). The muscles not fitted (the legs not registered, and what the atlas lacks: {kept}) are copied from
muscles/gait2392. atlas_report.json holds the registration's residuals and each fit's error.

## Credit (CC BY 4.0)

The muscle shapes derive from the lower extremity geometry of the Visible Human Female by the
Center for Orthopaedic Biomechanics, University of Denver (CC BY 4.0,
https://doi.org/10.56902/COB.vh.2022.0): Andreassen, T. E., Hume, D. R., Hamilton, L. D.,
Walker, K. E., Higinbotham, S. E., & Shelburne, K. B. "Three-dimensional lower extremity
musculoskeletal geometry of the Visible Human Female and Male." Scientific Data 10 (2023),
https://doi.org/10.1038/s41597-022-01905-2. They were registered, split and refitted here
(changes made). The data is provided "as is" (the atlas' LICENSE-README.txt).
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared/data/atlas/visible_human_female"))
    ap.add_argument("--out", default=str(ROOT / "muscles/gait2392_atlas"))
    ap.add_argument("--skeleton", default=str(ROOT / "poses/skeletons/gait2392.yaml"))
    ap.add_argument("--old", default=str(ROOT / "muscles/gait2392"))
    ap.add_argument("--sides", default="r")
    ap.add_argument("--sections", type=int, default=None)
    ap.add_argument("--transform", default=None, metavar="FILE",
                    help="write the leg's landmark similarity as an `axdf fit --transform` file, and nothing else")
    args = ap.parse_args()
    from axdf_cli.errors import InputError
    from axdf_cli.tools.atlas_library import build_library, landmark_transform

    if args.transform:
        try:
            text = landmark_transform(Path(args.data), Path(args.skeleton), args.sides.split(",")[0])
        except InputError as e:
            print(f"axdf: {e}" if e.where is None else str(e), file=sys.stderr)
            return 2
        tmp = Path(args.transform + ".partial")
        tmp.write_text(text)
        os.replace(tmp, args.transform)
        print(f"wrote {args.transform}")
        return 0

    t0 = time.time()

    def phase(text):
        print(f"[{time.time() - t0:6.1f} s] {text}", flush=True)

    def muscle(name, e):
        print(f"[{time.time() - t0:6.1f} s]   {name}: IoU {e['iou']:.3f}, volume {e['volume_ratio']:.3f}", flush=True)

    try:
        files, report = build_library(Path(args.data), Path(args.skeleton), Path(args.old),
                                      tuple(args.sides.split(",")), args.sections, muscle, phase)
    except InputError as e:
        print(f"axdf: {e}" if e.where is None else str(e), file=sys.stderr)
        return 2
    legs = " and ".join({"r": "right leg", "l": "left leg"}[s] for s in args.sides.split(","))
    files["README.md"] = CREDIT.format(legs=legs, kept=", ".join(report["kept"])).encode()
    out = Path(args.out)
    tmp = out.with_name(out.name + ".partial")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    for rel, data in sorted(files.items()):
        (tmp / rel).write_bytes(data)
    shutil.rmtree(out, ignore_errors=True)
    os.replace(tmp, out)
    phase(f"wrote {len(files)} files into {out} ({len(report['fitted'])} fitted, {len(report['kept'])} copied)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
