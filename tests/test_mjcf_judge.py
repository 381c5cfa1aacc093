"""MuJoCo itself as the judge of ``axdf import mjcf`` on MyoSuite's models (myo-sim): every
muscle's axis length within 1% of MuJoCo's ``ten_length`` at every frame of real motions and
of seeded random poses in the joints' ranges, and the shipped libraries (muscles/myoarm,
muscles/myobody) over their own poses."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco", reason="the MuJoCo judge needs `pip install mujoco` (test extra)")
pytest.importorskip("myo_sim", reason="MyoSuite's models need `pip install myo-sim` (test extra)")

from mujoco_judge import (REPO, MujocoModel, axdf_lengths, import_and_compare, myo_motion,  # noqa: E402
                          myo_sim_xml, random_qpos)
from osim_common import needs_data  # noqa: E402
from opensim_judge import pose_coordinates  # noqa: E402

LENGTH_TOL = 0.01  # relative: every muscle at every frame


@pytest.fixture(scope="module")
def xmls(tmp_path_factory):
    d = tmp_path_factory.mktemp("myo")
    out = {}
    for name in ("myolegs", "myoarm", "myofullbody"):
        out[name] = d / f"{name}.xml"
        out[name].write_text(myo_sim_xml.export(name))
    return out


def _check(names, ours, ref, count):
    assert len(names) == count and ours.shape == ref.shape
    worst = (np.abs(ours - ref) / ref).max(axis=0)
    bad = {n: f"{w:.2%}" for n, w in zip(names, worst) if w > LENGTH_TOL}
    assert not bad, bad
    return float(worst.max())


def test_myolegs_gait_cycle_coupled_knee(xmls, tmp_path):
    """MyoSuite's sample gait cycle on myolegs: 80 muscles, the knee's 7 coupled joints per leg
    (translations, rotations, the patella) following their polynomials."""
    model = mujoco.MjModel.from_xml_path(str(xmls["myolegs"]))
    q, fps = myo_motion.motion_qpos("gait", model)
    assert len(q) == 124 and np.ptp(q[:, model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT,
                                                                              "knee_angle_r")]]) > 1.0
    _check(*import_and_compare(xmls["myolegs"], q, fps, tmp_path / "legs"), 80)


def test_myolegs_random_poses(xmls, tmp_path):
    model = mujoco.MjModel.from_xml_path(str(xmls["myolegs"]))
    _check(*import_and_compare(xmls["myolegs"], random_qpos(model, 30, 11), 30.0, tmp_path / "legs_r"), 80)


@needs_data
def test_myoarm_elbow_flexion(xmls, tmp_path):
    """OpenSim arm26's measured elbow flexion (0 → 90°) on myoarm: 63 muscles, the shoulder's
    11 coupled joints (scapulohumeral rhythm) at rest."""
    model = mujoco.MjModel.from_xml_path(str(xmls["myoarm"]))
    q, fps = myo_motion.motion_qpos("arm26", model)
    _check(*import_and_compare(xmls["myoarm"], q, fps, tmp_path / "arm"), 63)


def test_myoarm_random_poses(xmls, tmp_path):
    """Every hinge of the arm, wrist and fingers uniform in its range (seeded): the shoulder's
    couplings move the clavicle and scapula, the fingers fold the flexors' paths."""
    model = mujoco.MjModel.from_xml_path(str(xmls["myoarm"]))
    _check(*import_and_compare(xmls["myoarm"], random_qpos(model, 40, 7), 30.0, tmp_path / "arm_r"), 63)


@needs_data
@pytest.mark.parametrize("lib, source, motion, pose, count, step", [
    ("myoarm", "myoarm", "arm26", "myoarm_elbow.yaml", 63, 1),
    ("myobody", "myofullbody", "gait", "myobody_gait.yaml", 416, 8),
])
def test_shipped_library_against_mujoco(xmls, lib, source, motion, pose, count, step):
    """The shipped muscles over their shipped pose against MuJoCo posed by the same motion."""
    model = MujocoModel(xmls[source])
    q, _ = myo_motion.motion_qpos(motion, model.model)
    p, frames, _ = pose_coordinates(REPO / "poses" / pose)
    assert len(frames) == len(q)
    frames, q = frames[::step], q[::step]
    ref = model.lengths(q)
    names, ours = axdf_lengths(REPO / "muscles" / lib, p, frames, model.names)
    assert names == model.names
    _check(names, ours, ref, count)


@pytest.mark.parametrize("lib, source", [("myoarm", "myoarm"), ("myobody", "myofullbody")])
def test_shipped_skeleton_gives_mujocos_qpos_layout(xmls, lib, source):
    """Data sets read a qpos motion against the skeleton alone: the shipped skeleton gives
    MuJoCo's nq and the qpos index of every joint that is a coordinate (myobody: its free root,
    the lumbar and knee couplings, 51 coupled joints in all, whose values are not read)."""
    from axdf_cli.importers.qpos import skeleton_qpos
    from axdf_cli.specs import load_skeleton

    joints, nq = skeleton_qpos(load_skeleton(REPO / "poses" / "skeletons" / f"{lib}.yaml"))
    m = mujoco.MjModel.from_xml_path(str(xmls[source]))
    assert nq == m.nq
    for j in joints:
        k = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.joint)
        assert k >= 0 and m.jnt_qposadr[k] == j.address and len(j.coords) == {0: 6, 1: 3}.get(int(m.jnt_type[k]), 1), j
    assert m.njnt - len(joints) == m.neq  # the rest are the coupled joints


def test_a_data_set_reads_myobodys_gait_as_the_import_did(tmp_path):
    """MyoSuite's gait cycle as qpos, read by a data set on the shipped myobody skeleton, gives
    the shipped pose (make import wrote it from the same qpos with axdf import mjcf)."""
    from axdf_cli.dataset.door import qpos_pose
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import load_pose

    shipped = load_pose(REPO / "poses" / "myobody_gait.yaml")
    xml = tmp_path / "myofullbody.xml"
    xml.write_text(myo_sim_xml.export("myofullbody"))
    q, fps = myo_motion.motion_qpos("gait", mujoco.MjModel.from_xml_path(str(xml)))
    np.savez(tmp_path / "gait.npz", qpos=q, fps=np.float64(fps))
    pose = qpos_pose(tmp_path / "gait.npz", shipped.skeleton, "gait")
    assert pose.fps == shipped.fps and pose.last == shipped.last
    np.testing.assert_allclose(sample_coordinates(pose, pose.frames), sample_coordinates(shipped, shipped.frames),
                               atol=1e-6)
