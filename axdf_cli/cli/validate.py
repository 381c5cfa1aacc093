"""Check muscle, skeleton, pose, job, transfer and dataset files with the same checks as run; write nothing.

A job is planned exactly as ``axdf run JOB`` plans it (muscles on the pose's bones, frames,
bone meshes, the ``render:`` block). Muscle files given together with a pose are checked on
that pose's skeleton, as ``axdf run --muscles ... --pose ...`` would. Files named here, and
their folders, are trusted roots for the paths inside them (as for ``axdf run``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from axdf_cli.errors import InputError, Mark


def add_args(p) -> None:
    p.add_argument("files", nargs="+", metavar="FILE", help="YAML files of any kind (detected from their keys)")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")
    p.add_argument("--strict", action="store_true",
                   help="fail on the warnings `axdf run --strict` refuses before evaluating")


def _bone_meshes(skel) -> str:
    """Read every bone mesh of ``skel`` as a run does; a short description."""
    from axdf_cli.geometry.bones import load_bone_mesh

    meshes = [b.mesh for b in skel.bones if b.mesh]
    for m in meshes:
        load_bone_mesh(m, skel.source)
    return f", {len(meshes)} bone meshes" if meshes else ""


def _plan(job=None, pose=None, muscles=None, allow_outside=False):
    """Plan as ``axdf run`` does (the same function), writing nothing."""
    from axdf_cli.cli.run import plan_from_args

    return plan_from_args(argparse.Namespace(
        job=job, pose=pose, muscles=muscles, out=None, format=None, frames=None, render=None,
        allow_outside=allow_outside, clamp_ranges=False))


def validate_file(path: Path, policy, args) -> tuple[str, str | None, list[str]]:
    """Validate one file: (description, kind, warnings). Raises InputError."""
    from axdf_cli import specs as loaders
    from axdf_cli.fileio.yamlio import load_yaml

    doc = load_yaml(path)
    kind = loaders.detect_kind(doc)
    if isinstance(doc, dict) and "dataset" in doc:  # (it also names muscles: look first)
        from axdf_cli.dataset.worker import build_context

        ctx = build_context(path, policy=policy)
        return (f"data set {ctx.spec.name}: {len(ctx.sequences)} sequences, {len(ctx.muscles)} muscles, "
                f"{len(ctx.spec.views)} view(s)"), "dataset", []
    if isinstance(doc, dict) and "skin" in doc and kind != "job":  # (it also names a skeleton: look first;
        # a job's skin: names the skin it wears)
        from axdf_cli.specs.skin import load_skin

        k = load_skin(path, policy=policy)
        return (f"skin {k.name}: {len(k.vertices)} vertices on {len(k.bones)} bones of {k.skeleton}, "
                f"{len(k.regions)} fat regions"), "skin", []
    if kind == "skeleton":
        s = loaders.load_skeleton(path, policy)
        return f"skeleton {s.name}: {len(s.bones)} bones, {len(s.coordinates)} coordinates{_bone_meshes(s)}", kind, []
    if kind == "pose":
        p = loaders.load_pose(path, policy)
        return (f"pose {p.name}: frames {p.first}..{p.last}, {len(p.keys)} keyed coordinates"
                f"{_bone_meshes(p.skeleton)}"), kind, []
    if kind == "muscle":
        ms = loaders.load_muscle_file(path)
        return f"muscle file: {', '.join(m.name for m in ms)}", kind, []
    if kind == "job":
        plan = _plan(job=str(path), allow_outside=args.allow_outside)
        return f"job: {len(plan.models)} muscles x {len(plan.frames)} frames", kind, _plan_warnings(plan)
    if kind == "transfer":
        from axdf_cli.tools.transfer import load_map

        m = load_map(path, policy=policy)
        return f"transfer map {m.name}: {len(m.pairs)} bones, {m.skel_a.name} -> {m.skel_b.name}", kind, []
    if kind == "retarget":
        from axdf_cli.tools.retarget import load_map as load_retarget_map

        r = load_retarget_map(path, policy=policy)
        joints = sorted({j for p in r.points for j, _ in p.sources})
        return (f"retarget map {r.name}: {len(r.points)} points of {r.skeleton.name} from {len(joints)} mocap "
                "joints (checked against a motion by axdf retarget)"), kind, []
    raise loaders.kind_error(doc, Mark(str(path), 1, 1))


def _plan_warnings(plan) -> list[str]:
    return list(plan.warnings) + [f"{plan.names[j]} frame {int(plan.frames[i])}: {msg}"
                                  for i, j, msg in plan.frame_warnings]


def run(args) -> int:
    from axdf_cli.specs import RefPolicy

    policy = RefPolicy.for_command(args.files, args.allow_outside)
    errors = 0
    kinds: dict[str, list[str]] = {}
    warnings: list[str] = []

    def report(f, fn):
        nonlocal errors
        try:
            desc, kind, warns = fn()
        except InputError as e:
            print(str(e), file=sys.stderr)
            errors += 1
            return
        for w in warns:
            print(f"warning: {w}", file=sys.stderr)
        warnings.extend(warns)
        if kind:
            kinds.setdefault(kind, []).append(f)
        if not args.quiet:
            print(f"{f}: ok ({desc})")

    for f in args.files:
        report(f, lambda f=f: validate_file(Path(f), policy, args))
    # muscles named beside a pose: on that pose's bones, as `axdf run --muscles ... --pose ...`
    if kinds.get("muscle") and kinds.get("pose"):
        for pose in kinds["pose"]:
            def cross(pose=pose):
                plan = _plan(pose=pose, muscles=kinds["muscle"], allow_outside=args.allow_outside)
                return (f"{len(plan.models)} muscles on skeleton {plan.pose.skeleton.name} x "
                        f"{len(plan.frames)} frames", None, _plan_warnings(plan))

            report(f"{' '.join(kinds['muscle'])} with {pose}", cross)
    if args.strict and warnings and not errors:
        print(f"axdf: {len(warnings)} warning(s) with --strict", file=sys.stderr)
        return 2
    return 2 if errors else 0
