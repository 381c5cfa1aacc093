"""Fit a body to a skeleton: ``axdf skin --skeleton SKEL --out DIR [--muscles DIR] [--push]``.

MakeHuman's CC0 body (axdf_cli/data/makehuman/) is fitted to the skeleton at its rest pose
(axdf_cli/tools/skin.py; docs/SKIN.md): scaled per segment from joint landmarks, turned onto
the skeleton's bones, its rig's weights carried onto the skeleton's bones, a fat thickness per
region. DIR receives ``skin.yaml`` (the skin file), ``skin_rest.ply``, ``skin_weights.npz``,
``skin_fat.npz``, ``skin_report.json`` and ``manifest.json``. With ``--muscles`` the muscles'
vertices at rest outside the skin are counted (and with ``--push`` the rest skin is moved out
over them). Bad input writes nothing (exit 2).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from axdf_cli.cli.importer import add_overwrite_arg

REPORT = "skin_report.json"


def add_args(p) -> None:
    p.add_argument("--skeleton", required=True, metavar="SKELETON", help="skeleton YAML to fit the body to")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--muscles", metavar="DIR", default=None,
                   help="a folder of the skeleton's muscles: count their vertices at rest outside the skin")
    p.add_argument("--push", action="store_true",
                   help="with --muscles: move the rest skin outward until the muscles lie inside it")
    p.add_argument("--strict", action="store_true", help="refuse (exit 2) where a warning would be printed")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    add_overwrite_arg(p)


def run(args) -> int:
    import numpy as np

    from axdf_cli.tools import constants as tol
    from axdf_cli.errors import InputError, Mark, UsageError
    from axdf_cli.fileio.outputs import OutputSet, check_outputs, write_outputs
    from axdf_cli.specs import RefPolicy, load_skeleton
    from axdf_cli.tools import skin as sk

    if args.push and args.muscles is None:
        raise UsageError("--push needs --muscles (the skin is pushed out over them)")
    named = [args.skeleton] + ([args.muscles] if args.muscles else [])
    policy = RefPolicy.for_command(named, args.allow_outside)
    out = OutputSet(args.out, "skin")
    check_outputs(out, inputs=named, overwrite=args.overwrite, input_dirs=[args.muscles] if args.muscles else [])
    body = sk.load_body()
    skel = load_skeleton(Path(args.skeleton), policy)
    fit = sk.fit_body(skel, body, Mark(args.skeleton))
    off = fit.height / fit.stature - 1.0
    report = {"skeleton": skel.name, "family": fit.family, "stature": round(fit.stature, 4),
              "height": round(fit.height, 4), "height_off": round(off, 4), "rest_height": round(fit.rest_height, 4),
              "scale": round(fit.scale, 4), "vertices": len(fit.vertices), "bones": fit.bones}
    warnings = []
    if abs(off) > tol.SKIN_HEIGHT_TOLERANCE:
        warnings.append(f"the body is {fit.height:.3f} m tall, {100 * off:+.1f}% off the skeleton's estimated "
                        f"stature {fit.stature:.3f} m")
    inputs = [args.skeleton, str(sk.BODY_FILE)]
    if args.muscles:
        from axdf_cli.geometry.bones import rest_bone_meshes
        from axdf_cli.geometry.winding import inside
        from axdf_cli.geometry.grow import grow_over
        from axdf_cli.tools.skin_muscles import bone_points, clear_bones, rest_muscle_vertices

        def outside(v, p):  # how many of points p lie outside the skin (vertices v)
            return int((~inside(v, fit.faces, p)).sum())

        pts, n_muscles, files = rest_muscle_vertices(Path(args.muscles), skel, policy)
        inputs += [str(p) for p in files]
        before = outside(fit.vertices, pts)
        m = {"muscles": n_muscles, "vertices": len(pts), "outside_before": before}
        if args.push:  # over the bones' meshes too (a skull larger than the body's head)
            from axdf_cli.model.skeleton import bones_below

            wears = {skel.bones[i].name for i in bones_below(skel, {skel.bone_index[b] for b in fit.bones})}
            worn = rest_bone_meshes(skel, args.skeleton, lambda b: b.name in wears, cap=True).values()
            meshes = [(v, f) for v, f, _ in worn]
            bone_pts = bone_points(meshes)
            inputs += [str(p) for _, _, p in worn]
            m["bone_points"] = len(bone_pts)
            m["bone_points_outside_before"] = outside(fit.vertices, bone_pts)
            pushed = grow_over(fit.vertices, fit.faces, np.concatenate([pts, bone_pts]))
            pushed, m["skin_vertices_out_of_bones"] = clear_bones(pushed, fit.faces, meshes)
            m["bone_points_outside_after"] = outside(pushed, bone_pts)
            m["outside_after"] = outside(pushed, pts)
            m["push_max"] = round(float(np.linalg.norm(pushed - fit.vertices, axis=1).max()), 4)
            fit.vertices = pushed
        report["muscles"] = m
    for w in warnings:
        if args.strict:
            raise InputError(Mark(args.skeleton), w, "a skeleton whose proportions the body can take (docs/SKIN.md)")
        print(f"axdf: warning: {w}", file=sys.stderr)
    region, fat = sk.fat_map(body, fit)
    report["summary"] = (f"Stature {fit.stature:.3f} m (estimated), body {fit.height:.3f} m ({100 * off:+.1f}%).")
    for name, data in sk.skin_files(fit, skel, region, fat, report).items():
        out.add(Path(args.out) / name, data, "output")
    text = json.dumps(report, indent=1, sort_keys=True, allow_nan=False)  # (the fit is finite: fit_body)
    out.add(Path(args.out) / REPORT, (text + "\n").encode(), "output")
    write_outputs(out, inputs=inputs, overwrite=args.overwrite, input_dirs=[args.muscles] if args.muscles else [])
    if not args.quiet:
        print(f"skin for {skel.name} ({fit.family}): body {fit.height:.3f} m, skeleton's stature {fit.stature:.3f} m "
              f"(estimated), {100 * off:+.1f}%; {len(fit.vertices)} vertices on {len(fit.bones)} bones")
        if args.muscles:
            m = report["muscles"]
            line = f"muscle vertices outside the skin at rest: {m['outside_before']} of {m['vertices']}"
            if args.push:
                line += f" -> {m['outside_after']} after the push (at most {1000 * m['push_max']:.0f} mm)"
            print(line)
            if args.push:
                print(f"bone points outside the skin at rest: {m['bone_points_outside_before']} of {m['bone_points']} "
                      f"-> {m['bone_points_outside_after']}; skin vertices moved out of bones: "
                      f"{m['skin_vertices_out_of_bones']}")
        print(f"skin file: {Path(args.out) / sk.SKIN_FILE}")
    return 0
