"""``axdf pack``: a body's muscles made to share space at the rest pose (axdf_cli/model/pack.py).

Reads muscle files and the skeleton they are defined on (with its bone meshes), packs their
rest shapes and returns the bytes of the packed muscle files (same names, every section an
``outline:``), ``pack_report.json`` and ``PACK.md``. Nothing is written here.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli import runtime
from axdf_cli import tolerances as tol
from axdf_cli.tools import constants as tc
from axdf_cli.errors import InputError, Mark
from axdf_cli.fileio import fieldcache
from axdf_cli.importers import emit
from axdf_cli.fileio.outputs import UniqueFiles
from axdf_cli.tools.muscle_files import file_doc, load_muscle_files
from axdf_cli.model import contact, pack
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.geometry.bones import load_bone_mesh
from axdf_cli.pipeline.plan import plan_run
from axdf_cli.specs import RefPolicy, load_pose, load_skeleton

REPORT = "pack_report.json"
SUMMARY = "PACK.md"


@dataclass
class PackOutputs:
    files: dict  # output name -> bytes
    report: dict
    inputs: list = field(default_factory=list)  # every file read


def build_pack(muscle_files: list[Path], skeleton_path: Path | str, policy: RefPolicy | None = None,
               rounds: int | None = None, progress=None, pose_path: Path | str | None = None,
               frames: str | None = None, on_phase=None) -> PackOutputs:
    """Pack every muscle of ``muscle_files`` (defined on the skeleton at ``skeleton_path``);
    with ``pose_path``, polished over that pose's ``frames`` as well (default: at most
    tc.PACK_POSE_FRAMES of its frames, evenly spaced). ``on_phase(text)`` is told as each
    phase starts, ``progress(round, figures)`` as each round ends."""
    on_phase = on_phase or (lambda text: None)
    skeleton_path = Path(skeleton_path)
    skel = load_skeleton(skeleton_path, policy)
    by_file, specs = [], []
    for path, file_specs in load_muscle_files(muscle_files, "packed"):
        by_file.append((path, len(file_specs)))
        specs += file_specs
    if not specs:
        raise InputError(None, "no muscles found", "give muscle YAML files")
    check_size(specs)
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    on_phase(f"the models of {len(specs)} muscles")
    models = [MuscleModel(s, skel.bone_index, rest, skel) for s in specs]
    meshes = {i: load_bone_mesh(b.mesh, str(skeleton_path)) for i, b in enumerate(skel.bones) if b.mesh}
    on_phase(f"the bones' distance fields ({len(meshes)} meshes) and the muscles' contact pairs")
    cm = contact.build(specs, models, rest, meshes, field_cache=fieldcache.cached)
    kw = {} if rounds is None else {"iterations": rounds}
    if pose_path is not None:
        on_phase(f"the frames of {Path(pose_path).name} to polish over")
    poses, pose_record, pose_inputs = (None, None, []) if pose_path is None else \
        _pose_frames(muscle_files, skel, Path(pose_path), frames, policy, [sp.name for sp in specs])
    on_phase(f"{rounds or tol.PACK_ITERATIONS} rounds of territory, fit and growth, then at most "
             f"{tol.PACK_POLISH_ROUNDS} of polish")
    res = pack.pack(specs, models, skel, rest, cm, progress=progress, poses=poses, threads=runtime.use_threads(), **kw)

    files: dict[str, bytes] = UniqueFiles()
    k = 0
    for path, n in by_file:
        packed = res.specs[k:k + n]
        k += n
        header = (f"{', '.join(s.name for s in packed)}: packed by `axdf pack` from {path.name} on "
                  f"{skeleton_path.name} (axdf_cli/model/pack.py; report: {REPORT}).")
        files[path.name] = emit.dump_yaml(emit.rounded(file_doc(packed)), header=header).encode()
    report = _report(specs, res, skeleton_path)
    if pose_record is not None:
        report["pose"] = pose_record
    files[REPORT] = (json.dumps(report, indent=1, sort_keys=True) + "\n").encode()
    files[SUMMARY] = _summary(report).encode()
    inputs = [skeleton_path] + [Path(b.mesh) for b in skel.bones if b.mesh] + list(muscle_files) + pose_inputs
    inputs = list({str(Path(p).resolve()): p for p in inputs}.values())  # each file once (the pose's skeleton)
    return PackOutputs(dict(files), report, [str(p) for p in inputs])


def check_size(specs) -> None:
    """Refuse, before any work, muscles too fine to pack in bounded memory: the packer holds
    about tc.PACK_BYTES_PER_VERTEX for each vertex of every muscle at once."""
    counts = [s.resolution[0] * s.resolution[1] for s in specs]
    total = sum(counts)
    if total <= tc.PACK_MAX_VERTICES:
        return
    big = max(range(len(specs)), key=counts.__getitem__)
    s = specs[big]
    raise InputError(Mark(s.source or s.name, 1, 1) if s.source else None,
                     f"the muscles to pack hold {total:,} vertices (largest: {s.name}, resolution "
                     f"{s.resolution[0]}x{s.resolution[1]}), about "
                     f"{total * tc.PACK_BYTES_PER_VERTEX / 2 ** 30:.0f} GiB of memory to pack",
                     f"at most {tc.PACK_MAX_VERTICES:,} vertices in one pack: lower the muscles' "
                     "resolution, or pack fewer files at once")


def _pose_frames(muscle_files, skel, pose_path: Path, frames: str | None, policy, names):
    """The frames of a pose to polish over: (``poses(specs, models)`` for
    :func:`axdf_cli.model.pack.pack`, the report's record, the files read). The muscles are
    evaluated as ``axdf run`` would, without any stage (contact is what the polish runs)."""
    from dataclasses import replace

    from axdf_cli.pipeline.evaluate import evaluate_plan
    from axdf_cli.pipeline.stages import switched

    if not pose_path.is_file():
        raise InputError(Mark("--pose"), f"pose file {str(pose_path)!r} not found", "an existing pose YAML file")
    pose = load_pose(pose_path, policy or RefPolicy())
    if [(b.name, b.parent) for b in pose.skeleton.bones] != [(b.name, b.parent) for b in skel.bones]:
        raise InputError(Mark(str(pose_path)), f"the pose's skeleton {Path(pose.skeleton_path).name} is not "
                         f"{Path(skel.source).name}, the one the muscles are packed on",
                         "a pose of the --skeleton's bones")
    plan = plan_run(None, muscle_args=[str(f) for f in muscle_files], pose_arg=str(pose_path), frames_arg=frames,
                    policy=policy or RefPolicy(), stages={name: False for name in switched()})
    if plan.names != names:  # (the same files, read the same way)
        raise InputError(Mark(str(pose_path)), "the pose's run reads other muscles than the pack", "the same muscle files")
    if frames is None and len(plan.frames) > tc.PACK_POSE_FRAMES:
        pick = np.unique(np.round(np.linspace(0, len(plan.frames) - 1, tc.PACK_POSE_FRAMES)).astype(np.int64))
        plan = replace(plan, frames=plan.frames[pick])

    def poses(specs, models):
        p = replace(plan, muscles=list(specs), models=list(models))
        verts: dict = {}
        world = []
        for chunk, results in evaluate_plan(p):
            world.append(chunk.world)
            for j, r in results:
                verts.setdefault(j, []).append(r.vertices)
        return np.linalg.inv(np.concatenate(world)), [np.concatenate(verts[j]) for j in range(len(models))]

    record = {"file": Path(pose_path).name, "frames": [int(f) for f in plan.frames]}
    return poses, record, [Path(plan.pose.source), Path(plan.pose.skeleton_path)]


def _report(specs, res: "pack.PackResult", skeleton_path: Path) -> dict:
    ratio = res.volume / res.volume0
    rows = []
    for i, s in enumerate(specs):
        rows.append({"muscle": s.name, "inside_muscle": [round(float(res.before[i, 0]), 6), round(float(res.after[i, 0]), 6)],
                     "inside_bone": [round(float(res.before[i, 1]), 6), round(float(res.after[i, 1]), 6)],
                     "depth": [round(float(res.before[i, 2]), 6), round(float(res.after[i, 2]), 6)],
                     "volume": [round(float(res.volume0[i]), 9), round(float(res.volume[i]), 9)],
                     "volume_ratio": round(float(ratio[i]), 6), "scale": round(float(res.scale[i]), 6)})
    return {
        "skeleton": skeleton_path.name,
        "muscles": rows,
        "rounds": [[round(float(x), 6) for x in h] for h in res.history], "round_kept": res.kept + 1,
        "territory_rounds": res.territory_rounds,
        "rounds_columns": ["inside_muscle", "inside_bone", "depth_max", "volume_ratio_min", "volume_ratio_max"],
        "before": _totals(res.before, res.volume0, res.volume0),
        "after": _totals(res.after, res.volume0, res.volume),
    }


def _totals(meas: np.ndarray, v0: np.ndarray, v: np.ndarray) -> dict:
    r = v / v0
    return {"inside_muscle": round(float(meas[:, 0].mean()), 6), "inside_bone": round(float(meas[:, 1].mean()), 6),
            "depth_max": round(float(meas[:, 2].max()), 6), "volume_total": round(float(v.sum()), 9),
            "volume_ratio_min": round(float(r.min()), 6), "volume_ratio_median": round(float(np.median(r)), 6)}


def _summary(report: dict) -> str:
    b, a = report["before"], report["after"]
    lines = [f"# Packed muscles on {report['skeleton']}", "",
             "The rest shapes made to share space (`axdf pack`; docs/METHOD.md, Packing). Shares are of",
             "each muscle's rest vertices, averaged over the muscles; depth is the deepest penetration.", ""]
    if "pose" in report:
        fr = report["pose"]["frames"]
        lines += [f"Polished over {len(fr)} frames of `{report['pose']['file']}` ({fr[0]} to {fr[-1]}; `--pose`) "
                  "as well as the rest pose.", ""]
    lines += ["| at the rest pose | before | after |", "|---|---|---|",
              f"| inside another muscle | {100 * b['inside_muscle']:.2f}% | {100 * a['inside_muscle']:.2f}% |",
              f"| inside a bone | {100 * b['inside_bone']:.2f}% | {100 * a['inside_bone']:.2f}% |",
              f"| deepest penetration | {1000 * b['depth_max']:.1f} mm | {1000 * a['depth_max']:.1f} mm |",
              f"| total volume | {1000 * b['volume_total']:.3f} L | {1000 * a['volume_total']:.3f} L |",
              f"| smallest / median volume kept | | {a['volume_ratio_min']:.3f} / {a['volume_ratio_median']:.3f} |",
              "", "Muscles that kept less than 95% of their volume (boxed in by bone and neighbours):", ""]
    short = [m for m in report["muscles"] if m["volume_ratio"] < 0.95]
    lines += [f"- {m['muscle']}: {m['volume_ratio']:.3f}" for m in short] or ["- none"]
    return "\n".join(lines) + "\n"

