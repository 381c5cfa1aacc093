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
from axdf_cli.geometry.bones import load_bone_mesh
from axdf_cli.specs import Job, Pose, RefPolicy, expand_muscle_paths, load_muscle_file, load_pose
from axdf_cli.model.muscle import MuscleModel, MuscleSpec
from axdf_cli.model.pose import activation_problems, muscle_range_warnings, outside_ranges, parse_frames
from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline.stages import build_stages

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
    stages: tuple = ()  # the run's stages (axdf_cli.pipeline.stages: build_stages), in order within each scope
    collision_meshes: dict | None = None  # bone meshes contact uses where the run stores none (a data set's sequences)
    mesh_files: str = "muscle"  # formats.MESH_FILES: per-frame formats one file per muscle per frame, or per frame
    outside: tuple = ()  # model.pose.OutsideRange per coordinate the pose takes outside its range at frames
    base: Path | None = None  # the folder the manifest names inputs from (input_base); None: the current folder

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.muscles]

    @functools.cached_property
    def layers(self) -> tuple:
        """The parts the stages add to every frame (:class:`axdf_cli.parts.Part`), in stage
        order: the run's parts are its muscles (part j: muscle j), then these."""
        return tuple(p for s in self.stages for p in s.parts(self))

    @property
    def contact_meshes(self) -> dict:
        """The bone meshes contact and the skin push against: the run's, else those a data
        set's sequence carries without storing them (``collision_meshes``)."""
        return self.bone_meshes or self.collision_meshes or {}

    @property
    def fmt(self) -> str:
        """The formats as ``--format`` takes them: ``ply`` or ``ply,usd``."""
        return ",".join(self.formats)

    @property
    def rendering(self) -> bool:
        return self.render is not None and self.render.enabled


def display_path(p: Path, base: Path | None = None) -> str:
    """A path for the manifest: relative to ``base`` (a run's :func:`input_base`), else to the
    current folder, when below it."""
    return _display_path(str(p), os.getcwd() if base is None else str(base))


def input_base(paths) -> Path:
    """The deepest folder that holds every one of ``paths`` (their real locations): the folder
    a run's manifest names its inputs from, so that the same inputs are named the same, with the
    same bytes, from whatever folder the run is started (the shipped jobs: the project's root)."""
    folders = [str(Path(p).resolve().parent) for p in paths]
    return Path(os.path.commonpath(folders)) if folders else Path(os.getcwd()).resolve()


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
             stages=None, mesh_files_arg=None, skin_arg=None) -> RunPlan:
    """Load and check every input; build the muscle models. Writes nothing.

    ``render``: the RenderSettings to use (None: the job's ``render:``); ``policy``: where
    referenced files may lie (default: the job's); ``clamp_ranges``: hold coordinates inside
    their ranges (as the pose's ``clamp_ranges``); ``stages``: stage name -> on, from the
    command line and the job (:func:`axdf_cli.pipeline.stages.build_stages`; default every
    registered stage); ``mesh_files_arg``: ``--mesh-files`` (None: the job's ``mesh_files:``,
    else ``muscle``); ``skin_arg``: ``--skin FILE`` (None: the job's ``skin:``, else no skin)."""
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
    mesh_files = plan_mesh_files(job, mesh_files_arg, formats)
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
    check_camera_bone(render, pose.skeleton)

    bone_meshes = {i: load_bone_mesh(b.mesh, pose.skeleton_path) for i, b in enumerate(skel.bones) if b.mesh}

    srcs = ([job.source] if job is not None else []) + [pose.source, pose.skeleton_path] + [str(f) for f in files]
    srcs += sorted({b.mesh for b in skel.bones if b.mesh})
    skin = plan_skin(job, skin_arg, skel, policy, specs)
    built = build_stages(stages, specs, skin=skin)
    if skin is not None:
        srcs += [str(s) for s in skin.files]
    srcs = [s for s in srcs if Path(s).is_file()]
    base = input_base(srcs)
    inputs = {display_path(Path(s), base): atomic.sha256_file(s) for s in srcs}
    if any(st.name == "jiggle" for st in built):
        notes += jiggle_notes(pose, specs)
    plan = RunPlan(pose, specs, models, frames, formats, out, inputs, render=render, warnings=warnings,
                   bone_meshes=bone_meshes, notes=notes, frame_warnings=muscle_range_warnings(pose, frames, specs),
                   stages=built, mesh_files=mesh_files, outside=tuple(outside_ranges(pose, frames)), base=base)
    named = {s.name: s for s in specs}
    for part in plan.layers:  # (a part's meshes lie in meshes/<name>/, as a muscle's)
        if part.name in named:
            raise InputError(Mark(str(named[part.name].source)), f"a muscle is named {part.name!r}, as the "
                             f"{part.kind.value} part a stage adds", "rename the muscle")
    plan.warnings.extend(w for st in built for w in st.warnings(plan))
    return plan


def plan_skin(job: Job | None, arg, skeleton, policy: RefPolicy, specs):
    """The run's skin (:func:`axdf_cli.specs.skin.load_skin`, checked against the run's
    skeleton: its bones must be the skeleton's), from ``--skin`` else the job's ``skin:``; None
    without one. No muscle may be named as the skin's meshes are (``meshes/skin/``)."""
    from axdf_cli.pipeline.skin_stage import SKIN_NAME
    from axdf_cli.specs.skin import load_skin

    if arg is not None:
        path, mark = Path(arg), Mark("--skin")
    elif job is not None and job.skin is not None:
        path, mark = job.skin
    else:
        return None
    if not path.is_file():
        raise InputError(mark, f"skin file {str(path)!r} not found", "a skin file written by axdf skin (docs/SKIN.md)")
    clash = [s for s in specs if s.name == SKIN_NAME]
    if clash:
        raise InputError(Mark(str(clash[0].source)), f"a muscle is named {SKIN_NAME!r}, as the run's skin meshes are",
                         "rename the muscle, or run without a skin")
    return load_skin(path, skeleton, policy)


def plan_mesh_files(job: Job | None, arg, formats) -> str:
    """How the per-frame formats' files are cut (:data:`axdf_cli.formats.MESH_FILES`): the
    flag's word, else the job's, else ``muscle``. ``frame`` needs a per-frame format among
    ``formats`` (it says nothing about the per-sequence ones)."""
    from axdf_cli.formats import of_layout, parse_mesh_files

    if arg is not None:
        value, mark = parse_mesh_files(arg, Mark("--mesh-files")), Mark("--mesh-files")
    elif job is not None and job.mesh_files is not None:
        value, mark = job.mesh_files
    else:
        return "muscle"
    if value == "frame" and not of_layout("frame", formats):
        raise InputError(mark, f"mesh files per frame, but the formats {','.join(formats)} hold no per-frame "
                         "mesh", "add ply or obj to the formats, or leave mesh_files out")
    return value


def jiggle_notes(pose: Pose, specs) -> list[str]:
    """Remarks on ``jiggle:`` frequencies that the pose's frames cannot show: above the
    Nyquist frequency fps / 2 the ring aliases between frames (the motion is still exact)."""
    over: dict[float, list[str]] = {}  # highest frequency -> muscles
    for s in specs:
        j = s.jiggle
        top = 0.0 if j is None else max(j.frequency, j.tensed_frequency or 0.0)
        if top > 0.5 * pose.fps:
            over.setdefault(top, []).append(s.name)
    out = []
    for top, names in sorted(over.items()):
        who = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        out.append(f"jiggle at up to {top:g} Hz ({who}) is above half the pose's {pose.fps:g} fps: the ring "
                   "aliases between frames (a pose with more frames per second shows it)")
    return out


def check_formats(formats, frames, frames_mark: Mark) -> None:
    """What the selected formats need (their ``FORMATS`` entries), checked before anything is
    written: the frames they can hold (evenly spaced for point caches); what the machine needs
    to write them (Pixar's USD modules for usd: exit 3 with the install hint)."""
    from axdf_cli.formats import FORMATS, frames_problem, of_layout

    cannot, why = frames_problem(formats, frames)
    if why:
        keep = [n for n in of_layout("sequence") if FORMATS[n].frames == "any"]
        raise InputError(frames_mark, f"frames {_frames_text(frames)} for {', '.join(cannot)}",
                         why + f"; or write {' or '.join(keep)}, which keep any frames")
    for name in formats:
        if FORMATS[name].check is not None:
            FORMATS[name].check()


def _frames_text(frames) -> str:
    f = [int(x) for x in frames]
    return ",".join(map(str, f)) if len(f) <= 8 else ",".join(map(str, f[:8])) + ",..."


def camera_targets(plan: RunPlan, frames=None) -> np.ndarray | None:
    """(F, 3) the origin of the render camera's target bone at ``frames`` (default: the plan's),
    or None when the camera does not aim at a bone."""
    from axdf_cli.model.pose import sample_coordinates

    cam = plan.render.camera if plan.render is not None else None
    if cam is None or cam.target_bone is None:
        return None
    frames = plan.frames if frames is None else np.asarray(frames)
    b = plan.pose.skeleton.bone_index[cam.target_bone]
    return forward_kinematics(plan.pose.skeleton, sample_coordinates(plan.pose, frames))[:, b, :3, 3]


def check_camera_bone(render, skel) -> None:
    """A camera that aims at a bone names a bone of the skeleton (checked before any output)."""
    cam = render.camera if render is not None else None
    if cam is not None and cam.target_bone is not None and cam.target_bone not in skel.bone_index:
        raise InputError(cam.target_mark, f"the camera's target bone {cam.target_bone!r} is not a bone of "
                         f"skeleton {skel.name!r}", "bones: " + ", ".join(b.name for b in skel.bones))
