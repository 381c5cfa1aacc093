"""The run's manifest: its schema (:func:`manifest_dict`) and the run's identity, which
``--resume`` compares so that one run folder never mixes the outputs of two runs.

A run is the same run when its tool version, inputs (sha256), settings (each stage's record
among them, and every flag that changes an output: ``clamp_ranges``), frames and
:func:`run_identity` are the same. The identity is what the numbers depend on beyond the
inputs: the model's sources (every ``.py`` below ``axdf_cli/model/`` and
``axdf_cli/tolerances.py``, one sha256), each stage's own sources (:func:`stage_sources`: the
module that defines it, e.g. ``pipeline/skin_stage.py``, one sha256 per file) and every numeric
constant of :mod:`axdf_cli.tolerances` by name, so that a refusal names the constant or the
file that changed. The tools' constants (:mod:`axdf_cli.tools.constants`: fitting, retargeting,
packing) are no part of it: no run reads them.
"""
from __future__ import annotations

import functools
import hashlib
import json
import numbers
import sys
from pathlib import Path

import axdf_cli
from axdf_cli import __version__
from axdf_cli import tolerances
from axdf_cli.errors import InputError
from axdf_cli.fileio.runfolder import RUN_IDENTITY, bone_mesh_relpath, describe_differences
from axdf_cli.pipeline.plan import RunPlan, display_path
from axdf_cli.pipeline.stages import stages_record

#: The manifest key of :func:`run_identity`.
IDENTITY = "identity"


@functools.lru_cache(maxsize=1)
def model_sources_sha() -> str:
    """sha256 over the model's sources: every ``.py`` below ``axdf_cli/model/`` and
    ``axdf_cli/tolerances.py``, each by its path relative to the package and its bytes (read
    once per process: sources do not change under a running process)."""
    root = Path(axdf_cli.__file__).parent
    files = sorted([*root.joinpath("model").rglob("*.py"), root / "tolerances.py"],
                   key=lambda p: p.relative_to(root).as_posix())
    h = hashlib.sha256()
    for p in files:
        h.update(p.relative_to(root).as_posix().encode() + b"\0")
        h.update(p.read_bytes() + b"\0")
    return h.hexdigest()


def _numeric(v) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, numbers.Real):
        return True
    return isinstance(v, (tuple, list)) and bool(v) and all(_numeric(x) for x in v)


def tolerance_values() -> dict:
    """Every numeric constant of :mod:`axdf_cli.tolerances` (numbers and tuples of numbers),
    by name, as JSON holds them (read now: a constant set at run time counts)."""
    return {name: json.loads(json.dumps(v)) for name, v in sorted(vars(tolerances).items())
            if name.isupper() and _numeric(v)}


def stage_source_files(stage) -> dict[str, Path]:
    """A stage's own source files, name -> path: the module that defines its class and any it
    names in ``sources`` (a tuple of paths relative to the package). A file of the package is
    named by its path relative to the package (``pipeline/skin_stage.py``), a module outside it
    (a test's or a plug-in's stage) by its file's name: no absolute path goes into a manifest."""
    root = Path(axdf_cli.__file__).parent.resolve()
    path = Path(sys.modules[type(stage).__module__].__file__).resolve()
    own = path.relative_to(root).as_posix() if path.is_relative_to(root) else path.name
    return dict(sorted({own: path, **{rel: root / rel for rel in stage.sources}}.items()))


def stage_sources(stage) -> list[str]:
    """The names of :func:`stage_source_files`, sorted."""
    return list(stage_source_files(stage))


def source_sha(name: str, path: Path | None = None) -> str:
    """sha256 of a source file (``path``; default the package's file ``name``)."""
    path = Path(axdf_cli.__file__).parent / name if path is None else path
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def stages_identity(stages) -> dict:
    """Each stage's sources (:func:`stage_source_files`): name -> {file: sha256} (read now:
    the files are few and small)."""
    return {s.name: {n: source_sha(n, p) for n, p in stage_source_files(s).items()} for s in stages}


def run_identity(plan: RunPlan | None = None) -> dict:
    """The manifest's ``identity``: ``model`` (:func:`model_sources_sha`), ``tolerances``
    (:func:`tolerance_values`) and, for a plan with stages, ``stages``
    (:func:`stages_identity`)."""
    out = {"model": model_sources_sha(), "tolerances": tolerance_values()}
    if plan is not None and plan.stages:
        out["stages"] = stages_identity(plan.stages)
    return out


def identity_differences(old, new: dict) -> list[str]:
    """What differs between an earlier manifest's ``identity`` and ours, in words: each
    tolerance that changed, by name, then whether the model's sources changed."""
    if not isinstance(old, dict):
        return ["the interrupted run records no identity of the model (an older axdf wrote it)"]
    out = []
    a, b = old.get("tolerances"), new["tolerances"]
    a = a if isinstance(a, dict) else {}
    for k in sorted(set(a) | set(b)):
        if a.get(k) != b.get(k):
            out.append(f"tolerances.{k} " + ("is new" if k not in a else "is gone" if k not in b
                                             else f"{json.dumps(a[k])} -> {json.dumps(b[k])}"))
    if old.get("model") != new["model"]:
        out.append("the model's sources changed (sha256 differs)")
    a, b = old.get("stages"), new.get("stages") or {}
    a = a if isinstance(a, dict) else {}
    for name in sorted(set(a) | set(b)):
        fa, fb = a.get(name), b.get(name)
        if fa == fb:
            continue
        if fa is None or fb is None:
            out.append(f"the {name} stage's sources are " + ("new" if fa is None else "gone"))
            continue
        fa = fa if isinstance(fa, dict) else {}
        out += [f"the {name} stage's source {rel} " + ("is new" if rel not in fa else "is gone" if rel not in fb
                                                         else "changed (sha256 differs)")
                for rel in sorted(set(fa) | set(fb)) if fa.get(rel) != fb.get(rel)]
    return out


def render_dict(settings) -> dict | None:
    """The manifest's ``settings.render``: None when the run renders nothing."""
    if settings is None or not settings.enabled:
        return None
    from axdf_cli.specs.render import settings_to_dict

    return settings_to_dict(settings)


def manifest_dict(plan: RunPlan, files: dict, warnings: list, complete: bool, extra: dict | None = None) -> dict:
    """The run's manifest (runfolder.MANIFEST_KEYS gives the order on disk): what went in
    (inputs' sha256, settings, the model's :func:`run_identity`, frames), what the run holds
    (muscles, bones, warnings, ``ranges``: the coordinates the pose takes outside their ranges,
    ``files``: relative path -> sha256) and ``extra`` (bounds, framing, gl)."""
    m = {
        "tool": "axdf",
        "version": __version__,
        "complete": complete,
        "inputs": dict(sorted(plan.inputs.items())),
        "settings": {
            "format": plan.fmt,
            "pose": plan.pose.name,
            "skeleton": plan.pose.skeleton.name,
            "fps": plan.pose.fps,
            "render": render_dict(plan.render),
        },
        "identity": run_identity(plan),
        "frames": [int(f) for f in plan.frames],
        "muscles": [
            {"name": s.name, "group": s.group, "color": [round(c, 6) for c in s.color],
             "source": display_path(Path(s.source), plan.base),
             "volume": s.volume, "vertices": int(m.n_vertices), "faces": int(len(m.faces)),
             "rest_length": round(m.l0, 12), "rest_volume": float(f"{m.v0:.12g}")}
            for s, m in zip(plan.muscles, plan.models)
        ],
        "bones": [{"name": b.name, "mesh": bone_mesh_relpath(b.name) if b.mesh else None,
                   "stick_from": plan.pose.skeleton.bones[p].name if p >= 0 else None}
                  for b, p in zip(plan.pose.skeleton.bones, plan.pose.skeleton.stick_parents())],
        "warnings": warnings,
        "files": files,
    }
    if plan.layers:  # the parts the stages add (left out without: such runs keep their manifests)
        m["parts"] = [{"name": p.name, "kind": p.kind.value, "color": [round(float(c), 6) for c in p.color],
                       "vertices": p.n_vertices, "faces": int(len(p.faces))} for p in plan.layers]
    if plan.mesh_files != "muscle":  # (the default is left unsaid: earlier runs' manifests stay the same)
        m["settings"]["mesh_files"] = plan.mesh_files
    if plan.pose.clamp_ranges:  # (--clamp-ranges, a job's or pose's clamp_ranges: the pose is sampled otherwise)
        m["settings"]["clamp_ranges"] = True
    if plan.outside:  # (left out when every coordinate keeps to its range: such runs keep their manifests)
        m["ranges"] = [o.record() for o in plan.outside]
    stages = stages_record(plan.stages)
    if stages is not None:  # (left out without stages: such a run's settings name none)
        m["settings"]["stages"] = stages
    if extra:
        m.update(extra)
    return m


def check_resume(plan: RunPlan, previous) -> None:
    """--resume finishes the same run only: the same tool version, inputs (sha256), settings,
    frames and model (:func:`run_identity`); otherwise exit 2 naming every difference."""
    new = manifest_dict(plan, {}, [], complete=False)
    changed = describe_differences(previous, new)
    if previous.data.get(IDENTITY) != new[IDENTITY]:
        changed += identity_differences(previous.data.get(IDENTITY), new[IDENTITY])
    if changed:
        first = next(k for k in RUN_IDENTITY + (IDENTITY,) if previous.data.get(k) != new[k])
        raise InputError(previous.mark((first,)),
                         f"--resume would mix two runs: {'; '.join(changed)}",
                         "resume with the inputs and settings of the interrupted run, or pass --overwrite")
