"""The data set's one door into the rest of axdf: the run machinery, render settings and the
OpenSim motion reader. Everything the data-set room needs from other rooms is imported here,
so that when those rooms move, only this module follows them.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from axdf_cli.specs import Pose
from axdf_cli.render.camera import intrinsics, look_at  # noqa: F401  (the conventions of camera.json)
from axdf_cli.render.renderer import id_map  # noqa: F401  (the EXR id pass's table)
from axdf_cli.render.passes import FRAME_WRITERS  # noqa: F401  (image passes: png, exr)
from axdf_cli.specs.render import RenderSettings, parse_render_settings, settings_to_dict  # noqa: F401
from axdf_cli.specs.render import parse_camera  # noqa: F401  (a job's camera: mapping)
from axdf_cli.pipeline import RunPlan, build_stages, evaluate_chunks, execute, load_bone_mesh  # noqa: F401
from axdf_cli.pipeline.stages import stages_record  # noqa: F401  (dataset.json names the stages)
from axdf_cli.pipeline.execute import (bulk_overlap_text, overlaps_in_bulk,  # noqa: F401  (muscles that overlap
                                       pack_command_line)  # in bulk, as a run tells them)
from axdf_cli.pipeline.plan import display_path, load_muscle_specs  # noqa: F401  (as a run's manifest shows paths)
from axdf_cli.workers import WorkerDied, one_thread, process_map  # noqa: F401  (worker processes, as axdf run's)
from axdf_cli.fileio.runfolder import own_entry  # noqa: F401  (the lock and temporaries axdf leaves while writing)
from axdf_cli.model.skeleton import forward_kinematics


def sequence_plan(pose: Pose, frames: np.ndarray, muscles, models, fmt: str, out: Path, inputs: dict,
                  stages: tuple = (), bone_meshes: dict | None = None) -> RunPlan:
    """A run plan for one sequence: the data set's muscles and models (built once per worker)
    over an in-memory pose, with the data set's stages (``build_stages``, made with its
    context). Bone meshes are stored once for the whole data set, not per run: ``bone_meshes``
    reach the contact stage only (``collision_meshes``), so a sequence collides as ``axdf run``."""
    return RunPlan(pose=pose, muscles=list(muscles), models=list(models), frames=np.asarray(frames),
                   formats=(fmt,), out=Path(out), inputs=dict(inputs), render=None, bone_meshes={},
                   stages=tuple(stages), collision_meshes=bone_meshes)


def run_sequence(plan: RunPlan, resume: bool) -> dict:
    """Write the sequence's meshes, stats.csv, bones.csv and manifest.json (``axdf run``'s own
    code); returns its summary, whose ``stats`` is (F, M, 6) length, volume, ratio, tension,
    twist, scale."""
    return execute(plan, resume=resume, overwrite=not resume)


def written_meshes(plan: RunPlan, frame: int) -> tuple[list, list]:
    """The muscles of one frame as the run wrote them: per muscle (V, 3) float32 positions and
    normals, read back from the run folder (cheaper than evaluating again, and exactly what
    was written)."""
    from axdf_cli.formats import FORMATS
    from axdf_cli.fileio.runfolder import mesh_relpath

    read = FORMATS[plan.fmt].reader
    pos, nrm = [], []
    for name in plan.names:
        m = read((plan.out / mesh_relpath(name, int(frame), plan.fmt)).read_bytes())
        pos.append(m.vertices.astype(np.float32))
        nrm.append(m.normals.astype(np.float32))
    return pos, nrm


def build_models(specs, skeleton) -> list:
    """The muscle models at the skeleton's rest pose, as a run plan builds them."""
    from axdf_cli.model.muscle import MuscleModel

    rest = forward_kinematics(skeleton, skeleton.rest_coordinates()[None])[0]
    return [MuscleModel(s, skeleton.bone_index, rest, skeleton) for s in specs]


def motion_pose(path: Path, skeleton, name: str, fps: float | None = None) -> Pose:
    """An OpenSim motion (.mot/.sto) as a Pose of ``skeleton``, read and converted by the
    importer (columns to coordinates, the degrees/radians rule, resampling to ``fps``)."""
    from axdf_cli.importers.osim_import import motion_doc as pose_doc
    from axdf_cli.importers.storage import read_storage

    table = read_storage(path)
    model = SimpleNamespace(coordinates={c.name: c for c in skeleton.coordinates}, source=skeleton.source)
    doc = pose_doc(model, table, None, name, "", fps, [], {}, [])
    series: dict = {}
    for frame, row in doc["keys"].items():
        for c, v in row.items():
            series.setdefault(c, ([], []))
            series[c][0].append(int(frame))
            series[c][1].append(float(v))
    keys = {c: (tuple(f), tuple(v)) for c, (f, v) in series.items()}
    first, last = doc["frames"]
    return Pose(name, skeleton, float(doc["fps"]), int(first), int(last), "linear", keys, {}, {},
                str(path), skeleton.source)


def qpos_pose(path: Path, skeleton, name: str, fps: float | None = None, where=None) -> Pose:
    """A MuJoCo ``qpos`` motion (an npz: ``qpos`` frames × nq, optional ``fps``) as a Pose of a
    skeleton that ``axdf import mjcf`` wrote, read as ``axdf import mjcf --motion`` reads it
    (importers/qpos.py: the qpos layout from the skeleton's bones and coordinates, hinges in
    degrees, quaternions as X-Y-Z Euler angles; coupled joints follow their polynomials).
    ``fps`` overrides the archive's (as ``--fps``); ``where``: the data set's entry, for errors."""
    from axdf_cli.importers.qpos import qpos_coordinates, read_motion, skeleton_qpos

    joints, nq = skeleton_qpos(skeleton, where)
    q, own_fps = read_motion(path, nq)
    frames = tuple(range(len(q)))
    keys = {c: (frames, tuple(float(x) for x in v)) for c, v in qpos_coordinates(joints, q, str(path)).items()}
    return Pose(name, skeleton, float(fps or own_fps), 0, len(q) - 1, "linear", keys, {}, {}, str(path),
                skeleton.source)


def retarget_pose(path: Path, map_path: Path, skeleton, name: str, step: int = 1, scale: float | None = None,
                  policy=None) -> Pose:
    """Motion capture (a BVH take, an npz of joints) as a Pose of ``skeleton``, fitted through
    the retarget map as ``axdf retarget`` fits it (the map's ``onto:`` gives way to the data
    set's skeleton)."""
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.tools.retarget import as_pose, load_map, retarget

    rmap = load_map(map_path, skeleton, policy)
    return as_pose(retarget(rmap, read_motion(path, scale=scale, step=step)), name)


def without_meshes(skeleton):
    """The skeleton with its bones' mesh paths dropped (the data set stores bone meshes once)."""
    return replace(skeleton, bones=tuple(replace(b, mesh=None) for b in skeleton.bones))

