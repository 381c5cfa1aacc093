"""Planning a run: load and check every input, build the muscle models. Writes nothing."""
from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from axdf_cli.fileio import atomic
from axdf_cli.errors import InputError, Mark
from axdf_cli.formats import parse_formats
from axdf_cli.specs import Job, Pose, RefPolicy, expand_muscle_paths, load_muscle_file, load_pose
from axdf_cli.model.muscle import MuscleModel, MuscleSpec
from axdf_cli.model.pose import activation_problems, muscle_range_warnings, parse_frames, subject_points
from axdf_cli.model.skeleton import forward_kinematics

DEFAULT_OUT = "out/run"


@dataclass
class RunPlan:
    pose: Pose
    muscles: list[MuscleSpec]
    models: list[MuscleModel]
    frames: np.ndarray  # (F,) selected output frames
    formats: tuple  # --format names in the order given: per-frame (ply, obj) and per-sequence (usd, pc2, ...)
    out: Path
    inputs: dict  # display path -> sha256
    render: object = None  # RenderSettings (enabled or not)
    warnings: list = field(default_factory=list)
    notes: list = field(default_factory=list)  # remarks printed with --verbose; not warnings
    bone_meshes: dict = field(default_factory=dict)  # bone index -> (vertices (V,3) f4, faces (T,3) i4, file bytes)
    frame_warnings: list = field(default_factory=list)  # [(frame index, muscle index, message)] known before evaluation
    contact_on: bool = True  # muscles and bones collide (--no-contact, a job's contact: false)
    contact: object = None  # model.contact.ContactModel once built (prepare_contact); None: no contact stage

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.muscles]

    @property
    def fmt(self) -> str:
        """The formats as ``--format`` takes them: ``ply`` or ``ply,usd``."""
        return ",".join(self.formats)

    @property
    def rendering(self) -> bool:
        return self.render is not None and self.render.enabled


def display_path(p: Path) -> str:
    """A path for the manifest: relative to the current folder when below it."""
    return _display_path(str(p), os.getcwd())


@functools.lru_cache(maxsize=4096)
def _display_path(p: str, cwd: str) -> str:
    # cached: a manifest names every muscle's source, and is written several times a run
    try:
        return Path(os.path.relpath(Path(p).resolve(), Path(cwd).resolve())).as_posix()
    except ValueError:
        return Path(p).resolve().as_posix()


def job_render_settings(job: Job | None):
    """The job's ``render:`` settings, parsed by the loader (rendering off without a job)."""
    from axdf_cli.specs.render import RenderSettings

    return job.render if job is not None else RenderSettings()


def load_muscle_specs(files) -> list[MuscleSpec]:
    """Every muscle of ``files``, in order; a name defined twice, or no muscle at all, is an error."""
    specs: list[MuscleSpec] = []
    seen: dict[str, str] = {}
    for fpath in files:
        for spec in load_muscle_file(fpath):
            if spec.name in seen:
                raise InputError(Mark(str(fpath), 1, 1), f"muscle {spec.name!r} is also defined in {seen[spec.name]}",
                                 "muscle names are unique within a run")
            seen[spec.name] = str(fpath)
            specs.append(spec)
    if not specs:
        raise InputError(None, "no muscles found", "give muscle YAML files")
    return specs


def plan_run(job: Job | None, *, muscle_args=None, pose_arg=None, out_arg=None, fmt_arg=None,
             frames_arg=None, render=None, policy: RefPolicy | None = None, clamp_ranges: bool = False,
             contact: bool | None = None) -> RunPlan:
    """Load and check every input; build the muscle models. Writes nothing.

    ``render``: the RenderSettings to use (None: the job's ``render:``); ``policy``: where
    referenced files may lie (default: the job's); ``clamp_ranges``: hold coordinates inside
    their ranges (as the pose's ``clamp_ranges``); ``contact``: muscles and bones collide (None:
    the job's ``contact:``, default on)."""
    policy = policy or (job.policy if job is not None else RefPolicy())
    if pose_arg is not None:
        pose_path, pose_mark = Path(pose_arg), Mark(str(pose_arg))
    elif job is not None:
        pose_path, pose_mark = job.pose
    else:
        raise InputError(None, "no pose given", "give a JOB.yaml or --pose FILE")
    if not pose_path.is_file():
        raise InputError(pose_mark, f"pose file {str(pose_path)!r} not found", "an existing pose YAML file")
    pose = load_pose(pose_path, policy)
    if clamp_ranges:
        from dataclasses import replace

        pose = replace(pose, clamp_ranges=True)

    if muscle_args:
        entries = [(Path(m), Mark(str(m))) for m in muscle_args]
    elif job is not None:
        entries = list(job.muscles)
    else:
        raise InputError(None, "no muscles given", "give a JOB.yaml or --muscles PATH ...")
    files = expand_muscle_paths(entries, policy, Path(job.source).parent if not muscle_args else None)
    specs = load_muscle_specs(files)
    seen = [s.name for s in specs]  # in run order (activation_problems lists them)

    warnings, notes = activation_problems(pose, seen)

    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    models = [MuscleModel(s, skel.bone_index, rest, skel) for s in specs]

    if frames_arg is not None:
        frames = parse_frames(frames_arg, Mark("--frames"), pose.first, pose.last)
    elif job is not None and job.frames is not None:
        frames = parse_frames(job.frames, job.frames_mark, pose.first, pose.last)
    else:
        frames = pose.frames
    if fmt_arg:
        formats = parse_formats(fmt_arg, Mark("--format"))
    elif job is not None and job.format is not None:
        formats = job.format  # (parsed by the job reader)
    else:
        formats = ("ply",)
    check_formats(formats, frames, Mark("--frames") if frames_arg is not None else
                  (job.frames_mark if job is not None and job.frames is not None else Mark(pose.source)))
    if out_arg is not None:
        if not str(out_arg).strip():
            raise InputError(Mark("--out"), "the output folder is empty text", "give a folder, e.g. --out out/run")
        out = Path(out_arg)
    elif job is not None and job.out is not None:  # (the job reader refuses an empty one)
        out = Path(job.out)
    else:
        out = Path(DEFAULT_OUT)
    if render is None:
        render = job_render_settings(job)

    bone_meshes = {i: load_bone_mesh(b.mesh, pose.skeleton_path) for i, b in enumerate(skel.bones) if b.mesh}
    if contact is None:
        contact = job.contact if job is not None else True

    inputs = {}
    srcs = ([job.source] if job is not None else []) + [pose.source, pose.skeleton_path] + [str(f) for f in files]
    srcs += sorted({b.mesh for b in skel.bones if b.mesh})
    for s in srcs:
        if Path(s).is_file():
            inputs[display_path(Path(s))] = atomic.sha256_file(s)
    return RunPlan(pose, specs, models, frames, formats, out, inputs, render=render, warnings=warnings,
                   bone_meshes=bone_meshes, notes=notes, frame_warnings=muscle_range_warnings(pose, frames, specs),
                   contact_on=contact)


def prepare_contact(plan: RunPlan) -> RunPlan:
    """The plan with its contact stage built (the bones' distance fields: seconds, so only
    for a run that evaluates, not for validate or --dry-run). With contact off the stage only
    measures (stats.csv's inside_muscle, inside_bone, depth); the meshes are those without it."""
    if plan.contact is not None:
        return plan
    from dataclasses import replace

    from axdf_cli.model import contact as contact_model

    rest = forward_kinematics(plan.pose.skeleton, plan.pose.skeleton.rest_coordinates()[None])[0]
    return replace(plan, contact=contact_model.build(plan.muscles, plan.models, rest, plan.bone_meshes,
                                                     enabled=plan.contact_on))


def check_formats(formats, frames, frames_mark: Mark) -> None:
    """What the selected formats need, checked before anything is written: evenly spaced
    frames for point caches; Pixar's USD modules for usd (exit 3 with the install hint)."""
    from axdf_cli.formats.pc2 import check_frames

    caches = [f for f in formats if f in ("pc2", "mdd")]
    why = check_frames(frames) if caches else None
    if why:
        raise InputError(frames_mark, f"frames {_frames_text(frames)} for {', '.join(caches)}",
                         why + "; or write usd or npz, which keep any frames")
    if "usd" in formats:
        from axdf_cli.formats.usd import pxr

        pxr()


def _frames_text(frames) -> str:
    f = [int(x) for x in frames]
    return ",".join(map(str, f)) if len(f) <= 8 else ",".join(map(str, f[:8])) + ",..."


def load_bone_mesh(path: str, skeleton_file: str):
    """Read a bone's mesh (PLY or OBJ triangles, one read) → (vertices, faces, PLY bytes for the
    run's ``bones/<bone>.ply``: the file itself when it is a PLY, else the triangles written as
    one); bad files are input errors."""
    from axdf_cli.formats import PlyWriter, load_triangles_and_bytes

    if not Path(path).is_file():
        raise InputError(Mark(skeleton_file), f"bone mesh {path} not found", "a PLY file relative to the skeleton file")
    (v, _, f), data = load_triangles_and_bytes(path)
    if len(f) == 0:
        raise InputError(Mark(str(path)), "bone mesh has no triangles", "a PLY or OBJ mesh with at least one triangle")
    if not np.isfinite(v).all():
        raise InputError(Mark(str(path)), "non-finite vertex coordinates", "finite numbers only")
    if Path(path).suffix.lower() != "." + PlyWriter.extension:
        data = PlyWriter(f).encode(v)
    return np.ascontiguousarray(v, dtype=np.float32), f, data


def framing(plan: RunPlan) -> np.ndarray:
    """What the automatic camera frames: the skeleton over the whole pose (not the muscles,
    not the selected frames), rounded to 1 µm so that the manifest holds it exactly."""
    pts = subject_points(plan.pose, {i: v for i, (v, _, _) in plan.bone_meshes.items()})
    return np.round(pts, 6) + 0.0
