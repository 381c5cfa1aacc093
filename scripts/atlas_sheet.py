"""The old library, the atlas library and the atlas' meshes side by side:

    python scripts/atlas_sheet.py SHEET.png [--body leg|arm|myobody] [--old DIR] [--atlas DIR]
                                [--frame N] [--size 240x320] [--registered DIR]

``--body leg`` (the default, gait2392 and the Visible Human): three rows, the thighs from the
front, the gluteal region from behind, the calves from behind. ``--body arm`` (myoarm and
BodyParts3D, docs/myoarm_atlas.png): the shoulder from the front and from behind and the arm
from the side, the moving columns at poses/jobs/myoarm_raise.yaml's frame. ``--body myobody``
(the whole body's right shoulder, docs/myobody_shoulder.png): the same views of myobody's tubes
and muscles/myobody_atlas, the moving columns at poses/jobs/myobody_atlas_raise.yaml's frame
(with contact; the skin it wears is not drawn); ``--registered build/atlas_myobody_upper/registered``
takes the meshes `make atlas-myobody` registered instead of registering again. Five columns: the old library and the atlas library at the skeleton's rest pose
(poses/gait2392_rest.yaml), the atlas' own muscle meshes registered onto gait2392 at rest
(axdf_cli/tools/atlas_library.py ``registered_meshes``, as `axdf atlas` writes them: the meshes the library was fitted to;
the muscles the atlas lacks are drawn from the atlas library), then both libraries at the
walk's frame (poses/jobs/gait2392_walk.yaml, with its contact stage). Each panel is an
``axdf render`` of an ``axdf run`` with an explicit camera aimed from the bones' positions in
the run's bones.csv. docs/gait2392_atlas.png (README, "The shipped jobs"; docs/FIT.md) is made
this way. Needs the atlas (../shared/data/atlas/visible_human_female).
"""
from __future__ import annotations

import argparse
import csv
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from axdf_cli.cli.main import main as axdf  # noqa: E402

# view -> (bone the camera aims between, the other bone, the share of the way, direction to
# the camera (world: -y is the body's front, +z up), distance m, vertical field of view deg)
VIEWS = {
    "thigh, front": ("femur_r", "tibia_r", 0.5, (-0.15, -1.0, 0.0), 1.9, 24.0),
    "gluteal, back": ("pelvis", "femur_r", 0.9, (0.0, 1.0, 0.05), 1.9, 22.0),
    "calf, back": ("tibia_r", "calcn_r", 0.45, (0.1, 1.0, 0.0), 1.9, 22.0),
}
ARM_VIEWS = {
    "shoulder, front": ("clavicle_r", "humerus_r", 0.6, (-0.35, -1.0, 0.1), 1.3, 26.0),
    "shoulder, back": ("scapula_r", "humerus_r", 0.5, (-0.35, 1.0, 0.1), 1.3, 26.0),
    "arm, side": ("humerus_r", "ulna_r", 0.6, (-1.0, -0.25, 0.0), 1.8, 30.0),
}
# the whole body's right shoulder: wider, the arm raised sideways seen from above, not along it
BODY_VIEWS = {
    "shoulder, front": ("clavicle_r", "humerus_r", 0.8, (-0.35, -1.0, 0.1), 1.7, 30.0),
    "shoulder, back": ("scapula_r", "humerus_r", 0.8, (-0.35, 1.0, 0.1), 1.7, 30.0),
    "shoulder, above": ("clavicle_r", "humerus_r", 0.8, (-0.2, -0.6, 1.0), 1.6, 30.0),
}
# body -> skeleton, map, the model's muscles, atlas folder, sides, the rest pose (file, frame),
# the moving job, the default frame, the old and the atlas library, the views
BODIES = {
    "leg": ("poses/skeletons/gait2392.yaml", "atlases/gait2392.yaml", "muscles/gait2392", "visible_human_female",
            ("r", "l"), ("poses/gait2392_rest.yaml", None), "poses/jobs/gait2392_walk.yaml", 62,
            "muscles/gait2392_packed", "muscles/gait2392_atlas", VIEWS),
    "arm": ("poses/skeletons/myoarm.yaml", "atlases/myoarm.yaml", "muscles/myoarm", "bodyparts3d_upper",
            ("r",), ("poses/myoarm_raise.yaml", 0), "poses/jobs/myoarm_raise.yaml", 40,
            "muscles/myoarm", "muscles/myoarm_atlas", ARM_VIEWS),
    "myobody": ("poses/skeletons/myobody.yaml", "atlases/myoarm.yaml", "muscles/myobody", "bodyparts3d_upper",
                ("r", "l"), ("poses/myobody_raise.yaml", 0), "poses/jobs/myobody_atlas_raise.yaml", 40,
                "muscles/myobody", "muscles/myobody_atlas", BODY_VIEWS),
}
HEAD_H, LABEL_W = 18, 92


def bone_positions(run: Path, frame: int) -> dict:
    with open(run / "bones.csv") as fh:
        return {r["bone"]: np.array([float(r["x"]), float(r["y"]), float(r["z"])])
                for r in csv.DictReader(fh) if int(r["frame"]) == frame}


def do(args: list[str]) -> None:
    if axdf(args + ["-q"]):
        raise SystemExit(f"axdf {' '.join(args)} failed")


def atlas_run(atlas_rest: Path, out: Path, data: Path, body: tuple, registered: Path | None = None) -> None:
    """A copy of the atlas library's rest run with each fitted muscle's mesh replaced by the
    atlas mesh it was fitted to (a run folder reads any PLY per muscle and frame); ``registered``:
    those meshes as `axdf atlas` wrote them (DIR/registered/NAME.ply)."""
    from axdf_cli.tools.atlas import Atlas
    from axdf_cli.tools.atlas_library import registered_meshes, rest_state, write_ply
    from axdf_cli.tools.tables import load_atlas_map

    skeleton, amap, model, _, sides = body[:5]
    shutil.copytree(atlas_rest, out)
    if registered is not None:
        for mesh in sorted(Path(registered).glob("*.ply")):
            target = out / "meshes" / mesh.stem / f"{mesh.stem}_0000.ply"
            if target.is_file():
                shutil.copyfile(mesh, target)
        return
    skel, rest, bones = rest_state(ROOT / skeleton)
    atlas = Atlas(data, load_atlas_map(ROOT / amap))
    carried, _ = registered_meshes(atlas, skel, rest, bones, ROOT / model, sides,
                                   lambda text: print(f"atlas_sheet: {text}", flush=True))
    for name, v, f in carried:
        target = out / "meshes" / name / f"{name}_0000.ply"
        if target.is_file():
            write_ply(target, v, f)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sheet", type=Path)
    ap.add_argument("--body", choices=sorted(BODIES), default="leg")
    ap.add_argument("--old", help="the library before (default: the body's model or packed library)")
    ap.add_argument("--atlas", help="the atlas library (default: the body's)")
    ap.add_argument("--data", type=Path, help="the atlas folder (default: the body's in ../shared/data/atlas)")
    ap.add_argument("--frame", type=int, help="the moving columns' frame (default: the body's)")
    ap.add_argument("--size", default="240x320")
    ap.add_argument("--registered", type=Path, help="the registered meshes `axdf atlas` wrote (DIR/registered)")
    args = ap.parse_args(argv)
    body = BODIES[args.body]
    (rest_pose, rest_frame), job, views = body[5], body[6], body[10]
    old_lib, atlas_lib = args.old or body[8], args.atlas or body[9]
    data = args.data or ROOT.parent / "shared/data/atlas" / body[3]
    frame = body[7] if args.frame is None else args.frame
    w, h = (int(x) for x in args.size.split("x"))
    with tempfile.TemporaryDirectory(prefix="axdf-sheet-") as tmp:
        tmp = Path(tmp)
        runs = []  # (label, run folder, frame)
        for label, lib in (("old", old_lib), ("atlas", atlas_lib)):
            do(["run", "--muscles", str(ROOT / lib), "--pose", str(ROOT / rest_pose), "--format", "ply",
                "--no-render", "--out", str(tmp / f"{label}_rest")]
               + ([] if rest_frame is None else ["--frames", str(rest_frame)]))
            runs.append((f"{label}, rest", tmp / f"{label}_rest", 0))
        atlas_run(tmp / "atlas_rest", tmp / "meshes_rest", data, body, args.registered)
        runs.append(("atlas meshes, rest", tmp / "meshes_rest", 0))
        for label, lib in (("old", old_lib), ("atlas", atlas_lib)):
            do(["run", str(ROOT / job), "--muscles", str(ROOT / lib), "--frames",
                str(frame), "--format", "ply", "--no-render", "--out", str(tmp / f"{label}_walk")])
            runs.append((f"{label}, frame {frame}", tmp / f"{label}_walk", frame))
        sheet = Image.new("RGB", (LABEL_W + w * len(runs), HEAD_H + h * len(views)), (255, 255, 255))
        draw = ImageDraw.Draw(sheet)
        font = ImageFont.load_default()
        for c, (label, _, _) in enumerate(runs):
            draw.text((LABEL_W + c * w + 4, 3), label, fill=(0, 0, 0), font=font)
        for r, (view, (a, b, t, towards, dist, fov)) in enumerate(views.items()):
            draw.text((4, HEAD_H + r * h + h // 2 - 6), view, fill=(0, 0, 0), font=font)
            for c, (label, run, frame) in enumerate(runs):
                pos = bone_positions(run, frame)
                target = (1 - t) * pos[a] + t * pos[b]
                d = np.asarray(towards, float)
                eye = target + dist * d / np.linalg.norm(d)
                out = tmp / f"render_{r}_{c}"
                do(["render", str(run), "--out", str(out), "--size", f"{w}x{h}", "--fov", str(fov),
                    "--camera-position=" + ",".join(f"{x:.4f}" for x in eye),
                    "--camera-target=" + ",".join(f"{x:.4f}" for x in target), "--background", "1,1,1"]
                   + (["--skin-view", "off"] if (run / "meshes" / "skin").is_dir() else []))
                img = Image.open(next((out / "frames").glob("*.png"))).convert("RGB")
                sheet.paste(img, (LABEL_W + c * w, HEAD_H + r * h))
        sheet.save(args.sheet, optimize=True)
    print(f"atlas_sheet: wrote {args.sheet}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
