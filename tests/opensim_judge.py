"""OpenSim itself as the judge of imported muscle paths (OpenSim 4.6 Python API, test extra).

Both sides are driven with the same coordinates: the axdf pose's, sampled at its frames and
converted to OpenSim units (degrees → radians for rotational coordinates). OpenSim gives
``Muscle.getLength`` (the path length, wrap arcs included) and ``getCurrentPath`` (path
points, wrap tangent points included); axdf gives each muscle's axis arc length
(:class:`~axdf_cli.model.muscle.FrameResult.length`, the ``length`` column of stats.csv).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from axdf_cli.specs import RefPolicy, expand_muscle_paths, load_muscle_file, load_pose
from axdf_cli.model.muscle import MuscleModel
from axdf_cli.model.pose import sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics


def pose_coordinates(pose_path: Path, frames=None):
    """(pose, frames, q (F, C) in axdf units)."""
    pose = load_pose(pose_path, RefPolicy.for_command([pose_path]))
    frames = pose.frames if frames is None else np.asarray(frames)
    return pose, frames, sample_coordinates(pose, frames)


class OpenSimModel:
    """An .osim model in OpenSim, posed by axdf coordinate rows.

    Only the free coordinates are set from axdf's row. The dependent coordinate of a
    CoordinateCouplerConstraint is left to OpenSim: ``Model.assemble`` satisfies the model's
    constraints by moving the coordinates it does not track, the dependent ones (the free
    ones keep their values, checked by :meth:`check_free`), so the coupling itself is judged,
    not copied from axdf."""

    def __init__(self, osim: Path):
        import opensim

        self.osim = opensim
        self.model = opensim.Model(str(osim))
        self.state = self.model.initSystem()
        self.coords = {c.getName(): c for c in self.model.getCoordinateSet()}
        self.dependent = {n for n, c in self.coords.items() if c.isDependent(self.state)}
        self.muscles = [self.model.getMuscles().get(i) for i in range(self.model.getMuscles().getSize())]
        self.names = [m.getName() for m in self.muscles]

    def set_pose(self, skel, q_row: np.ndarray) -> None:
        for name, i in skel.coord_index.items():
            if name not in self.coords or name in self.dependent:
                continue
            c = self.coords[name]
            v = float(q_row[i])
            if skel.coordinates[i].type == "rotation":
                v = math.radians(v)
            c.setValue(self.state, v, False)
        if self.dependent:
            self.model.assemble(self.state)
        self.model.realizePosition(self.state)

    def values(self, skel) -> np.ndarray:
        """The current coordinates (C,) in axdf's order and units (the dependent ones as
        OpenSim's assembly left them)."""
        out = np.zeros(len(skel.coordinates))
        for name, i in skel.coord_index.items():
            v = self.coords[name].getValue(self.state)
            out[i] = math.degrees(v) if skel.coordinates[i].type == "rotation" else v
        return out

    def lengths(self, skel, q: np.ndarray) -> np.ndarray:
        """Muscle lengths (F, M) in metres, frames in order (OpenSim keeps wrap history).
        Every free coordinate must keep the value set (OpenSim clamps a coordinate to its
        range; an assembly could move one): else the two sides would be posed differently."""
        out = np.empty((len(q), len(self.muscles)))
        free = [i for n, i in skel.coord_index.items() if n in self.coords and n not in self.dependent]
        for f, row in enumerate(q):
            self.set_pose(skel, row)
            drift = np.abs(self.values(skel)[free] - row[free])
            assert drift.max(initial=0.0) < 1e-6, f"frame {f}: OpenSim moved a free coordinate by {drift.max():.3g}"
            for j, m in enumerate(self.muscles):
                out[f, j] = m.getLength(self.state)
        return out

    def current_path(self, muscle: str) -> np.ndarray:
        """Ground positions (K, 3) of the current path's points (wrap points included), for
        the last pose set."""
        m = self.model.getMuscles().get(muscle)
        path = m.getGeometryPath().getCurrentPath(self.state)
        pts = []
        for k in range(path.getSize()):
            p = path.get(k)
            g = p.getLocationInGround(self.state)
            pts.append([g[0], g[1], g[2]])
        return np.array(pts)


def axdf_lengths(muscle_dir: Path, pose, frames: np.ndarray, names: list[str] | None = None):
    """Axis arc lengths (F, M) of the muscles in ``muscle_dir`` over ``frames``: (names, lengths)."""
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    policy = RefPolicy.for_command([muscle_dir])  # an import anywhere (a test's tmp_path) may be judged
    specs = [s for f in expand_muscle_paths([(Path(muscle_dir), None)], policy) for s in load_muscle_file(f)]
    if names is not None:
        by = {s.name: s for s in specs}
        specs = [by[n] for n in names if n in by]
    q = sample_coordinates(pose, frames)
    world = forward_kinematics(skel, q)
    out = np.empty((len(frames), len(specs)))
    for j, s in enumerate(specs):
        out[:, j] = MuscleModel(s, skel.bone_index, rest, skel).axis_length(world, q)
    return [s.name for s in specs], out


def compare(osim: Path, muscle_dir: Path, pose_path: Path, frames=None):
    """Relative length error per muscle and frame: (names, axdf (F, M), opensim (F, M))."""
    pose, frames, q = pose_coordinates(pose_path, frames)
    om = OpenSimModel(osim)
    ref = om.lengths(pose.skeleton, q)
    names, ours = axdf_lengths(muscle_dir, pose, frames, om.names)
    idx = [om.names.index(n) for n in names]
    return names, ours, ref[:, idx]


def summary(names, ours, ref) -> dict:
    rel = np.abs(ours - ref) / ref
    worst = rel.max(axis=0)
    j = int(np.argmax(worst))
    return {"muscles": len(names), "beyond_1pct": int(np.sum(worst > 0.01)), "worst_muscle": names[j],
            "worst_rel": float(worst[j]), "per_muscle": dict(zip(names, worst.tolist()))}


if __name__ == "__main__":  # python tests/opensim_judge.py: the table for the report
    import json
    import sys

    root = Path(__file__).resolve().parents[1]
    data = root.parent / "shared" / "data" / "opensim"
    cases = {"arm26": (data / "arm26" / "arm26.osim", root / "muscles" / "arm26", root / "poses" / "arm26_flex.yaml"),
             "gait2392": (data / "gait2392" / "gait2392_thelen2003muscle.osim", root / "muscles" / "gait2392",
                          root / "poses" / "gait2392_walk.yaml")}
    if len(sys.argv) == 4:  # python tests/opensim_judge.py MODEL.osim MUSCLE_DIR POSE.yaml: any import
        cases = {"given": tuple(Path(a) for a in sys.argv[1:])}
        sys.argv[1:] = ["given"]
    for name in sys.argv[1:] or list(cases):
        s = summary(*compare(*cases[name]))
        per = sorted(s.pop("per_muscle").items(), key=lambda kv: -kv[1])[:8]
        print(name, json.dumps(s), "worst:", ", ".join(f"{k} {v:.2%}" for k, v in per))
