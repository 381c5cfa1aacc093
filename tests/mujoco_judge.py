"""MuJoCo itself as the judge of imported MJCF models (``mujoco`` Python bindings, test extra).

Both sides are driven by the same ``qpos``: MuJoCo sets it and computes ``ten_length`` of
each muscle's tendon (``mj_kinematics``, ``mj_comPos``, ``mj_tendon``); axdf imports the model
and the motion (``axdf import mjcf --motion``) and gives each muscle's axis arc length at the
pose's frames (:class:`~axdf_cli.model.muscle.FrameResult.length`, stats.csv's ``length``).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))

import myo_motion  # noqa: E402  (scripts/: the motions and couplings)
import myo_sim_xml  # noqa: E402  (scripts/: myo-sim models as MJCF files)

from opensim_judge import pose_coordinates  # noqa: E402


def axdf_lengths(muscle_dir: Path, pose, frames: np.ndarray, names: list[str]):
    """Axis arc lengths (F, M) of the muscles in ``muscle_dir`` (in ``names``' order) over
    ``frames``: (names, lengths)."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import load_muscle_file

    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    by = {s.name: s for f in sorted(Path(muscle_dir).glob("*.yaml")) for s in load_muscle_file(f)}
    specs = [by[n] for n in names if n in by]
    q = sample_coordinates(pose, frames)
    world = forward_kinematics(skel, q)
    out = np.empty((len(frames), len(specs)))
    for j, s in enumerate(specs):
        out[:, j] = MuscleModel(s, skel.bone_index, rest, skel).axis_length(world, q)
    return [s.name for s in specs], out


class MujocoModel:
    """An MJCF model in MuJoCo, posed by qpos rows."""

    def __init__(self, xml: Path):
        import mujoco

        self.mj = mujoco
        self.model = mujoco.MjModel.from_xml_path(str(xml))
        self.data = mujoco.MjData(self.model)
        m = self.model
        acts = [a for a in range(m.nu) if m.actuator_trntype[a] == mujoco.mjtTrn.mjTRN_TENDON
                and m.actuator_gaintype[a] == mujoco.mjtGain.mjGAIN_MUSCLE]
        self.names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in acts]
        self.tendons = [int(m.actuator_trnid[a, 0]) for a in acts]

    def set(self, qpos: np.ndarray) -> None:
        self.data.qpos[:] = qpos
        self.mj.mj_kinematics(self.model, self.data)
        self.mj.mj_comPos(self.model, self.data)
        self.mj.mj_tendon(self.model, self.data)

    def lengths(self, qpos: np.ndarray) -> np.ndarray:
        """ten_length (F, M) of the muscles' tendons, metres."""
        out = np.empty((len(qpos), len(self.tendons)))
        for f, row in enumerate(qpos):
            self.set(row)
            out[f] = self.data.ten_length[self.tendons]
        return out

    def body_poses(self, qpos_row: np.ndarray) -> tuple[list[str], np.ndarray, np.ndarray]:
        """(body names, xpos (B, 3), xmat (B, 3, 3)) without the world body."""
        self.set(qpos_row)
        m = self.model
        names = [self.mj.mj_id2name(m, self.mj.mjtObj.mjOBJ_BODY, b) for b in range(1, m.nbody)]
        return names, self.data.xpos[1:].copy(), self.data.xmat[1:].reshape(-1, 3, 3).copy()


def random_qpos(model, count: int, seed: int) -> np.ndarray:
    """qpos (count, nq): every limited hinge and slide uniform in its range, the rest at qpos0,
    coupled joints from their polynomials."""
    rng = np.random.default_rng(seed)
    q = np.tile(model.qpos0, (count, 1))
    for j in range(model.njnt):
        if model.jnt_type[j] in (2, 3) and model.jnt_limited[j]:
            q[:, model.jnt_qposadr[j]] = rng.uniform(*model.jnt_range[j], size=count)
    return myo_motion.fill_couplings(model, q)


def import_and_compare(xml: Path, qpos: np.ndarray, fps: float, out: Path, **kw):
    """Import ``xml`` with the motion ``qpos`` into ``out`` and compare every muscle's length:
    (names, axdf (F, M), mujoco (F, M))."""
    from axdf_cli.cli.main import main

    out.parent.mkdir(parents=True, exist_ok=True)
    npz = out.parent / f"{out.name}_motion.npz"  # an input: beside the import's own folder, not in it
    with open(npz, "wb") as fh:
        np.savez(fh, qpos=qpos, fps=np.float64(fps))
    args = ["import", "mjcf", str(xml), "--motion", str(npz), "--out", str(out), "--name", "judged", "-q",
            "--no-meshes", "--pose-name", "motion"]
    for k, v in kw.items():
        args += [f"--{k.replace('_', '-')}", str(v)]
    assert main(args) == 0
    pose, frames, _ = pose_coordinates(out / "motion.yaml")
    mj = MujocoModel(xml)
    ref = mj.lengths(qpos)
    names, ours = axdf_lengths(out / "muscles", pose, frames, mj.names)
    idx = [mj.names.index(n) for n in names]
    return names, ours, ref[:, idx]


def summary(names, ours, ref) -> dict:
    rel = np.abs(ours - ref) / ref
    worst = rel.max(axis=0)
    j = int(np.argmax(worst))
    return {"muscles": len(names), "frames": int(ours.shape[0]), "beyond_1pct": int(np.sum(worst > 0.01)),
            "worst_muscle": names[j], "worst_rel": float(worst[j]), "per_muscle": dict(zip(names, worst.tolist()))}


if __name__ == "__main__":  # python tests/mujoco_judge.py [myolegs:gait myoarm:arm26 myoarm:random ...]
    import json
    import tempfile

    import mujoco

    for case in sys.argv[1:] or ["myolegs:gait", "myoarm:arm26", "myoarm:random", "myolegs:random"]:
        name, motion = case.split(":")
        with tempfile.TemporaryDirectory() as tmp:
            xml = Path(tmp) / f"{name}.xml"
            xml.write_text(myo_sim_xml.export(name))
            model = mujoco.MjModel.from_xml_path(str(xml))
            if motion == "random":
                q, fps = random_qpos(model, 40, 7), 30.0
            else:
                q, fps = myo_motion.motion_qpos(motion, model)
            s = summary(*import_and_compare(xml, q, fps, Path(tmp) / "out"))
            per = sorted(s.pop("per_muscle").items(), key=lambda kv: -kv[1])[:6]
            print(case, json.dumps(s), "worst:", ", ".join(f"{k} {v:.3%}" for k, v in per))
