"""Real motions as ``qpos`` npz files for the myo-sim models (``axdf import mjcf --motion``).

    python scripts/myo_motion.py gait MODEL.xml OUT.npz    # MyoSuite's sample gait cycle
    python scripts/myo_motion.py arm26 MODEL.xml OUT.npz [STO]   # OpenSim arm26's elbow flexion

- ``gait``: ``poses/motions/myosuite_sample_gait_cycle.csv``, copied unchanged from MyoSuite
  3.0.0 (``myosuite/envs/myo/assets/leg/sample_gait_cycle.csv``, Apache-2.0): 247 rows of one
  stride, hip, knee and ankle angles of both legs in radians (the right leg's knee and ankle
  are the columns ``osl_knee_angle_r``, ``osl_ankle_angle_r``). It has no time column; 200
  fps makes the stride 1.24 s. Every other frame is kept (100 fps, 124 frames). The root
  stays where the model's ``standing`` posture (myo-sim's keyframe) puts it; the pelvis
  angles are not used.
- ``arm26``: ``arm26_Kinematics_q.sto`` of OpenSim's arm26 (the shared data; CC BY 3.0): an
  elbow flexion 0 → 90° over 0.96 s (its shoulder moves by < 0.1°), resampled to 60 fps,
  applied to ``elbow_flexion_r``.

Joints the source does not name stay at qpos0; joints coupled by ``<equality><joint>`` get
their polynomial of the joint they follow (MuJoCo's own numbers, ``eq_data``), so MuJoCo's
state satisfies its constraints. Needs ``mujoco`` (and ``myo-sim`` for the posture).
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
GAIT_CSV = ROOT / "poses" / "motions" / "myosuite_sample_gait_cycle.csv"
GAIT_COLUMNS = {"hip_flexion_l": "hip_flexion_l", "hip_adduction_l": "hip_adduction_l",
                "hip_rotation_l": "hip_rotation_l", "hip_flexion_r": "hip_flexion_r",
                "hip_adduction_r": "hip_adduction_r", "hip_rotation_r": "hip_rotation_r",
                "knee_angle_l": "knee_angle_l", "knee_angle_r": "osl_knee_angle_r",
                "ankle_angle_l": "ankle_angle_l", "ankle_angle_r": "osl_ankle_angle_r"}
GAIT_FPS = 200.0
GAIT_STEP = 2
ARM26_STO = ROOT.parent / "shared" / "data" / "opensim" / "arm26" / "arm26_Kinematics_q.sto"
ARM26_FPS = 60.0


def fill_couplings(model, qpos: np.ndarray) -> np.ndarray:
    """qpos (F, nq) with every joint coupled by an active joint equality set from its polynomial
    (in order, so chains resolve when listed in order)."""
    import mujoco

    q = qpos.copy()
    for e in range(model.neq):
        if model.eq_type[e] != mujoco.mjtEq.mjEQ_JOINT or not model.eq_active0[e]:
            continue
        a1 = model.jnt_qposadr[model.eq_obj1id[e]]
        c = model.eq_data[e, :5]
        if model.eq_obj2id[e] < 0:
            q[:, a1] = model.qpos0[a1] + c[0]
            continue
        a2 = model.jnt_qposadr[model.eq_obj2id[e]]
        x = q[:, a2] - model.qpos0[a2]
        q[:, a1] = model.qpos0[a1] + c[0] + c[1] * x + c[2] * x ** 2 + c[3] * x ** 3 + c[4] * x ** 4
    return q


def base_qpos(model, posture: str | None) -> np.ndarray:
    """qpos0, or myo-sim's named posture for the model (its root height and joint values)."""
    import mujoco

    q = model.qpos0.copy()
    if posture is None:
        return q
    import json

    from myo_sim.build.keyframes import POSTURES_PATH

    table = json.loads(Path(POSTURES_PATH).read_text())["models"]
    entry = next((v[posture] for v in table.values() if posture in v), None)
    if entry is None:
        return q
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
        if name in entry["joints"]:
            q[model.jnt_qposadr[j]] = entry["joints"][name]
    root = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "root")
    if root >= 0:
        q[model.jnt_qposadr[root] + 2] = entry["root_z"]
    return q


def joint_values(kind: str, sto: Path | None = None) -> tuple[dict[str, np.ndarray], float]:
    """Joint name → values (F,) in radians, and fps, of a source motion (``sto``: arm26's
    kinematics file, default the shared data's)."""
    if kind == "gait":
        rows = list(csv.reader(GAIT_CSV.open()))
        head, data = rows[0], np.array(rows[1:], dtype=np.float64)[::GAIT_STEP]
        return {j: data[:, head.index(c)] for j, c in GAIT_COLUMNS.items()}, GAIT_FPS / GAIT_STEP
    if kind == "arm26":
        sys.path.insert(0, str(ROOT))
        from axdf_cli.importers.storage import read_storage

        t = read_storage(sto or ARM26_STO)
        times = np.arange(t.time[0], t.time[-1] + 1e-9, 1.0 / ARM26_FPS)
        elbow = np.interp(times, t.time, t.data[:, t.labels.index("r_elbow_flex")])  # degrees
        return {"elbow_flexion_r": np.radians(elbow)}, ARM26_FPS
    raise SystemExit(f"unknown motion {kind!r}: gait or arm26")


def motion_qpos(kind: str, model, sto: Path | None = None) -> tuple[np.ndarray, float]:
    """(qpos (F, nq), fps) of a source motion on a compiled MuJoCo model."""
    import mujoco

    values, fps = joint_values(kind, sto)
    n = len(next(iter(values.values())))
    q = np.tile(base_qpos(model, "standing" if kind == "gait" else None), (n, 1))
    for name, v in values.items():
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise SystemExit(f"the model has no joint {name!r}")
        q[:, model.jnt_qposadr[j]] = v
    return fill_couplings(model, q), fps


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) not in (3, 4):
        print("usage: python scripts/myo_motion.py gait|arm26 MODEL.xml OUT.npz [arm26_Kinematics_q.sto]", file=sys.stderr)
        return 2
    import mujoco

    model = mujoco.MjModel.from_xml_path(argv[1])
    q, fps = motion_qpos(argv[0], model, Path(argv[3]) if len(argv) == 4 else None)
    out = Path(argv[2])
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "wb") as fh:
        np.savez(fh, qpos=q, fps=np.float64(fps))
    print(f"{out}: {len(q)} frames at {fps:g} fps")
    return 0


if __name__ == "__main__":
    sys.exit(main())
