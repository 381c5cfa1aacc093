"""What the data set adds to the run machinery and the motion readers: a sequence's run plan
and its run (``axdf run``'s own code), the meshes a run wrote read back, the muscle models at
rest, and motions read as poses of the data set's skeleton (OpenSim, MuJoCo ``qpos``, motion
capture through a retarget map). The data-set room imports everything else it needs from
the modules that own it.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from axdf_cli.model.skeleton import forward_kinematics
from axdf_cli.pipeline import RunPlan, execute
from axdf_cli.specs import Pose


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


def written_layers(plan: RunPlan, frame: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The parts the stages added (``plan.layers``: the skin) at one frame as the run wrote them
    (``meshes/<part>/``): per part, (V, 3) float32 positions and normals."""
    from axdf_cli.formats import FORMATS
    from axdf_cli.fileio.runfolder import mesh_relpath

    out = []
    for part in plan.layers:
        m = FORMATS[plan.fmt].reader((plan.out / mesh_relpath(part.name, int(frame), plan.fmt)).read_bytes())
        out.append((m.vertices.astype(np.float32), m.normals.astype(np.float32)))
    return out


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
                  policy=None) -> tuple[Pose, list[str]]:
    """Motion capture (a BVH take, an npz of joints) as a Pose of ``skeleton``, fitted through
    the retarget map as ``axdf retarget`` fits it (the map's ``onto:`` gives way to the data
    set's skeleton), and the warnings ``axdf retarget`` would print for it (the take's unit,
    the fit's checks)."""
    from axdf_cli.importers.mocap import read_motion
    from axdf_cli.tools.retarget import as_pose, load_map, retarget
    from axdf_cli.tools.retarget_checks import fit_warnings

    rmap = load_map(map_path, skeleton, policy)
    mocap = read_motion(path, scale=scale, step=step)
    res = retarget(rmap, mocap)
    return as_pose(res, name), list(mocap.warnings) + fit_warnings(res)


def without_meshes(skeleton):
    """The skeleton with its bones' mesh paths dropped (the data set stores bone meshes once)."""
    return replace(skeleton, bones=tuple(replace(b, mesh=None) for b in skeleton.bones))

