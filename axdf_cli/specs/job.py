"""Job files (``muscles:``, ``pose:``, ``out:``, ``format:``, ``mesh_files:``, ``frames:``,
``clamp_ranges:``, ``render:``, ``skin:``) → a frozen :class:`Job`."""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from axdf_cli.errors import InputError, Mark
from axdf_cli.formats import parse_formats, parse_mesh_files
from axdf_cli.specs.render import parse_render_settings
from axdf_cli.specs.refs import RefPolicy
from axdf_cli.fileio.yamlio import Fields, item_marks, load_yaml


#: Job keys that switch a stage of the pipeline on or off (axdf_cli.pipeline.stages.STAGES; a
#: test checks the two agree): `jiggle: false`, as --no-jiggle; `contact: false`, as --no-contact.
STAGE_KEYS = ("jiggle", "contact", "penetration")
JOB_KEYS = ("muscles", "pose", "out", "format", "mesh_files", "frames", "clamp_ranges", "render", "skin") + STAGE_KEYS


@dataclass(frozen=True)
class Job:
    source: str
    muscles: tuple  # ((Path, Mark), ...) files, folders or globs, resolved against the job's folder
    pose: tuple | None  # (Path, Mark)
    out: Path | None  # resolved against the job's folder
    format: tuple | None  # the formats, parsed (axdf_cli.formats.parse_formats), or None
    frames: object  # raw frames spec or None
    frames_mark: Mark | None
    render: object  # RenderSettings (disabled when the job has no `render:`)
    policy: RefPolicy = RefPolicy()  # the policy the job was read with (its muscles are read with it)
    stages: tuple = ()  # ((stage, True | False), ...): what the job's STAGE_KEYS say, in that order; unsaid: absent
    mesh_files: tuple | None = None  # (one of formats.MESH_FILES, Mark) or None: the job's `mesh_files:`
    clamp_ranges: bool = False  # `clamp_ranges: true`, as --clamp-ranges: coordinates held inside their ranges
    skin: tuple | None = None  # (Path, Mark): the job's `skin:` file (docs/SKIN.md), resolved against its folder


def load_job(path: Path | str, policy: RefPolicy | None = None) -> Job:
    policy = policy or RefPolicy()
    path = Path(path)
    doc = load_yaml(path)
    top = Mark(str(path), 1, 1)
    f = Fields(doc, top, "job file", keys=JOB_KEYS)
    raw = f.raw("muscles", required=True)
    entries = [raw] if isinstance(raw, str) else raw
    if not isinstance(entries, list) or not entries:
        raise InputError(f.vmark("muscles"), "muscles is empty or not a list", "a path, folder or glob, or a list of them")
    marks = item_marks(entries, f.vmark("muscles")) if isinstance(raw, list) else [f.vmark("muscles")]
    muscles = []
    for e, m in zip(entries, marks):
        if not isinstance(e, str) or not e:
            raise InputError(m, f"muscle path is {e!r}", "a path, folder or glob relative to the job file")
        muscles.append((policy.resolve(path, e, m), m))
    pose_ref = f.string("pose", required=True)
    pose = (policy.resolve(path, pose_ref, f.vmark("pose")), f.vmark("pose"))
    out = f.string("out", default=None)
    if out is not None:
        out = Path(os.path.normpath(policy.resolve(path, out, f.vmark("out"), "out")))
    fmt = parse_formats(f.raw("format"), f.vmark("format")) if f.has("format") else None
    mesh_files = (parse_mesh_files(f.raw("mesh_files"), f.vmark("mesh_files")), f.vmark("mesh_files")) \
        if f.has("mesh_files") else None
    frames = f.raw("frames")
    frames_mark = f.vmark("frames") if frames is not None else None
    render = parse_render_settings(f.raw("render"), f.vmark("render") if f.has("render") else top)
    stages = tuple((k, f.boolean(k)) for k in STAGE_KEYS if f.has(k))
    clamp = f.boolean("clamp_ranges", default=False)
    skin = None
    if f.has("skin"):
        ref = f.string("skin", required=True)
        skin = (policy.resolve(path, ref, f.vmark("skin"), "skin"), f.vmark("skin"))
    f.done()
    return Job(str(path), tuple(muscles), pose, out, fmt, frames, frames_mark, render, policy, stages, mesh_files,
               clamp, skin)
