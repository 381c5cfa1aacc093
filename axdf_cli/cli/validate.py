"""Check muscle, skeleton, pose and job files with the same checks as run; write nothing."""
from __future__ import annotations

from pathlib import Path

from axdf_cli.errors import InputError, Mark


def add_args(p) -> None:
    p.add_argument("files", nargs="+", metavar="FILE", help="YAML files of any kind (detected from their keys)")
    p.add_argument("--allow-outside", action="store_true",
                   help="allow paths inside YAML files to leave the project folder tree")


def validate_file(path: Path) -> str:
    """Validate one file; return a one-line description. Raises InputError."""
    from axdf_cli import loaders
    from axdf_cli.yamlio import load_yaml

    doc = load_yaml(path)
    kind = loaders.detect_kind(doc)
    if kind == "skeleton":
        s = loaders.load_skeleton(path)
        return f"skeleton {s.name}: {len(s.bones)} bones, {len(s.coordinates)} coordinates"
    if kind == "pose":
        p = loaders.load_pose(path)
        return f"pose {p.name}: frames {p.first}..{p.last}, {len(p.keys)} keyed coordinates"
    if kind == "muscle":
        ms = loaders.load_muscle_file(path)
        return f"muscle file: {', '.join(m.name for m in ms)}"
    if kind == "job":
        from axdf_cli import run as runner

        job = loaders.load_job(path)
        plan = runner.plan_run(job)
        return f"job: {len(plan.models)} muscles x {len(plan.frames)} frames"
    if isinstance(doc, dict) and "transfer" in doc:
        from axdf_cli.transfer import load_map

        m = load_map(path)
        return f"transfer map {m.name}: {len(m.pairs)} bones, {m.skel_a.name} -> {m.skel_b.name}"
    raise InputError(Mark(str(path), 1, 1), "unknown kind of file",
                     "a skeleton (skeleton:, bones:), pose (pose:, keys:), muscle (muscle:), job (muscles:, pose:) "
                     "or transfer map (transfer:, bones:)")


def run(args) -> int:
    from axdf_cli.loaders import set_ref_policy
    from axdf_cli.yamlio import real_path

    errors = 0
    for f in args.files:
        set_ref_policy([Path.cwd(), real_path(f).parent], args.allow_outside)
        try:
            desc = validate_file(Path(f))
        except InputError as e:
            print(str(e), file=__import__("sys").stderr)
            errors += 1
            continue
        if not args.quiet:
            print(f"{f}: ok ({desc})")
    return 2 if errors else 0
