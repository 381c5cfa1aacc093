"""Shared fixtures: the repository root, the demo library, and a small synthetic skeleton.

The synthetic ``chain`` skeleton is five bones b0..b4 stacked along -Z, 0.1 m apart at rest:

- ``stretch`` (translation coordinate, rest 0) lengthens every link by ``0.1 * stretch`` m
  through a coupled linear DOF, so the whole chain stretches *uniformly* by ``1 + stretch``;
- ``bend`` rotates b3 (and b4 with it) about +X at b3's joint;
- ``roll`` rotates b4 about -Z, i.e. about the muscle's own tangent at its insertion.

The ``chainm`` muscle has one axis point at the origin of each bone, so its axis is a
straight line at rest and stays straight (and on the roll axis) when only ``stretch`` and
``roll`` move. Everything is tiny (21 x 16 vertices) so the suite stays fast.
"""
from __future__ import annotations

from axdf_cli import runtime

runtime.configure()  # threads and numba's kernel cache, as the command line sets them (before numpy)

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

# tests import their shared helpers (compare_helpers, render_helpers, ...) by module name
sys.path.insert(0, str(Path(__file__).parent))

REPO_ROOT = Path(__file__).resolve().parents[1]

#: Every test module's tier (a pytest marker of the same name, pyproject.toml): `make test`
#: runs all of them, `make test-fast` the unit tier. A test module named in none is refused
#: at collection, so a new one says where it belongs.
TIERS = {
    "unit": ("axis_points", "batch", "bspline", "coupled", "formats_table", "house", "inputs", "jiggle_law",
             "kernel", "keypoints", "muscle", "paths", "path_inside", "rmf", "writers_fast", "render_settings",
             "dataset_sampling", "runtime", "jiggle_preroll", "bvh_units", "fit_unit", "skin_unit", "skinning", "bench_page",
             "tables", "geometry"),
    "integration": ("bellies", "bench_smoke", "bvh_import", "camera", "cli", "compare", "compare_formats", "contact",
                    "dataset", "dataset_amodal", "dataset_bench", "dataset_labels", "gait2392", "jiggle_run",
                    "meshes", "mjcf_import", "osim_cli", "outputs", "pack", "packed", "rajagopal", "render_cli",
                    "render_jobs", "render_output", "retarget", "retarget_myobody", "stages", "transfer",
                    "transfer_paths", "retarget_fit", "first_hour", "first_hour_two", "framing", "outputs_per_frame", "fit",
                    "skin", "skin_stage", "atlas", "atlas_myoarm", "atlas_cli", "skin_outputs", "dataset_skin", "volume_twist", "run_identity",
                    "one_height", "layers", "partition"),
    "judges": ("blender", "mjcf_judge", "opensim_judge", "osim_fk", "osim_muscles"),
    "hostile": ("compare_hostile", "fuzz_yaml", "hostile", "inputs_hostile", "robustness", "safety", "hostile_import",
                "hostile_run", "hostile_skin", "fit_hostile", "hostile_round6"),
}
TIER_OF = {f"test_{name}": tier for tier, names in TIERS.items() for name in names}


def pytest_collection_modifyitems(config, items):
    untiered = set()
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1]
        tier = TIER_OF.get(module)
        if tier is None:
            untiered.add(module)
        else:
            item.add_marker(getattr(pytest.mark, tier))
    if untiered:
        raise pytest.UsageError(f"test modules in no tier: {', '.join(sorted(untiered))}; "
                                "name each in tests/conftest.py TIERS")


def pytest_sessionstart(session):
    """Say so when numba's kernels compile on this run (a cold cache): minutes on 2 cores,
    paid once, before the first test that needs them."""
    from kernel_cache import cache_report

    line = cache_report()
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if line and reporter is not None:
        reporter.write_line(line)
DEMO_MUSCLE_FILES = sorted((REPO_ROOT / "muscles" / "demo").glob("*.yaml"))
DEMO_POSE = REPO_ROOT / "poses" / "demo.yaml"
DEMO_JOB = REPO_ROOT / "poses" / "jobs" / "demo.yaml"
DEMO_SKELETON = REPO_ROOT / "poses" / "skeletons" / "human_r.yaml"

CHAIN_SKELETON_YAML = """\
skeleton: chain
coordinates:
  stretch: {type: translation, default: 0}
  bend: {type: rotation, default: 0}
  roll: {type: rotation, default: 0}
bones:
  - name: b0
  - name: b1
    parent: b0
    offset: [0, 0, -0.1]
    dofs:
      - {coord: stretch, type: translation, axis: [0, 0, -1], function: {linear: [0.1, 0]}}
  - name: b2
    parent: b1
    offset: [0, 0, -0.1]
    dofs:
      - {coord: stretch, type: translation, axis: [0, 0, -1], function: {linear: [0.1, 0]}}
  - name: b3
    parent: b2
    offset: [0, 0, -0.1]
    dofs:
      - {coord: stretch, type: translation, axis: [0, 0, -1], function: {linear: [0.1, 0]}}
      - {coord: bend, type: rotation, axis: [1, 0, 0]}
  - name: b4
    parent: b3
    offset: [0, 0, -0.1]
    dofs:
      - {coord: stretch, type: translation, axis: [0, 0, -1], function: {linear: [0.1, 0]}}
      - {coord: roll, type: rotation, axis: [0, 0, -1]}
"""

CHAIN_MUSCLE_YAML = """\
muscle: chainm
color: [0.8, 0.2, 0.2]
volume: exact
axis:
  - {bone: b0, at: [0, 0, 0]}
  - {bone: b1, at: [0, 0, 0]}
  - {bone: b2, at: [0, 0, 0]}
  - {bone: b3, at: [0, 0, 0]}
  - {bone: b4, at: [0, 0, 0]}
sections:
  - {t: 0.2, radii: [0.02, 0.015], angle: 0}
  - {t: 0.4, radii: [0.025, 0.018], angle: 10}
  - {t: 0.6, radii: [0.025, 0.018], angle: 10}
  - {t: 0.8, radii: [0.02, 0.015], angle: 0}
resolution: [21, 16]
"""

CHAIN_COORDS = ("stretch", "bend", "roll")


# ----------------------------------------------------------------------------- helpers


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Signed volume of a closed triangle mesh (divergence theorem), in float64."""
    v = np.asarray(vertices, dtype=np.float64)
    a, b, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def ring_vector_area(ring: np.ndarray) -> float:
    """Magnitude of the vector area of a closed polygon (R, 3): its area when planar."""
    c = ring.mean(axis=0)
    return 0.5 * float(np.linalg.norm(np.cross(ring - c, np.roll(ring, -1, axis=0) - c).sum(axis=0)))


def rings(vertices: np.ndarray, resolution) -> np.ndarray:
    """Ring vertices (..., U-2, A, 3) of a tessellated muscle (poles dropped)."""
    along, around = resolution
    return vertices[..., 1:-1, :].reshape(*vertices.shape[:-2], along - 2, around, 3)


def random_rigid(rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """A random proper rigid motion (4, 4)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    m = np.eye(4)
    m[:3, :3] = q
    m[:3, 3] = rng.normal(size=3) * scale
    return m


def write_pose(folder: Path, name: str, keys: dict, frames, *, skeleton: str = "chain.yaml",
               activation: dict | None = None, interpolation: str = "linear", fps: int = 24) -> Path:
    doc = {"pose": name, "skeleton": skeleton, "fps": fps, "frames": list(frames),
           "interpolation": interpolation, "keys": keys}
    if activation:
        doc["activation"] = activation
    path = Path(folder) / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def run_main(argv, capsys):
    """Call the CLI in process: (exit code, stdout, stderr)."""
    from axdf_cli.cli.main import main

    capsys.readouterr()
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def main_or_hang(argv, timeout: float = 120.0) -> int:
    """The CLI's exit code, called in a thread: a command that hangs (blocked on a FIFO, an
    endless read) fails the test after ``timeout`` seconds instead of stalling the suite."""
    import threading

    from axdf_cli.cli.main import main

    box: dict = {}
    t = threading.Thread(target=lambda: box.setdefault("rc", main([str(a) for a in argv])), daemon=True)
    t.start()
    t.join(timeout)
    assert not t.is_alive(), f"axdf {' '.join(map(str, argv))} still running after {timeout} s"
    return box["rc"]


def all_files(folder: Path) -> dict[str, bytes]:
    folder = Path(folder)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------- fixtures


@pytest.fixture
def repo_root(monkeypatch) -> Path:
    """Run the test from the repository root (the CLI resolves relative paths from there)."""
    monkeypatch.chdir(REPO_ROOT)
    return REPO_ROOT


@pytest.fixture(scope="session")
def chain_files(tmp_path_factory) -> Path:
    """A folder holding chain.yaml (skeleton) and chainm.yaml (muscle)."""
    d = tmp_path_factory.mktemp("chain")
    (d / "chain.yaml").write_text(CHAIN_SKELETON_YAML)
    (d / "chainm.yaml").write_text(CHAIN_MUSCLE_YAML)
    return d


@pytest.fixture(scope="session")
def chain_skeleton(chain_files):
    from axdf_cli.specs import load_skeleton

    return load_skeleton(chain_files / "chain.yaml")


@pytest.fixture(scope="session")
def chain_spec(chain_files):
    from axdf_cli.specs import load_muscle_file

    (spec,) = load_muscle_file(chain_files / "chainm.yaml")
    return spec


@pytest.fixture(scope="session")
def chain_world(chain_skeleton):
    """world(**coords) for one or many frames: scalars or (F,) arrays → (F, 5, 4, 4)."""
    from axdf_cli.model.skeleton import forward_kinematics

    cidx = chain_skeleton.coord_index

    def world(**coords) -> np.ndarray:
        n = max([np.size(v) for v in coords.values()] + [1])
        q = np.tile(chain_skeleton.rest_coordinates(), (n, 1))
        for k, v in coords.items():
            q[:, cidx[k]] = v
        return forward_kinematics(chain_skeleton, q)

    return world


@pytest.fixture(scope="session")
def chain_model(chain_skeleton, chain_world):
    """make(**spec_overrides) → MuscleModel of the chain muscle on the chain skeleton."""
    from axdf_cli.model.muscle import MuscleModel

    def make(spec, **overrides):
        spec = dataclasses.replace(spec, **overrides) if overrides else spec
        return MuscleModel(spec, chain_skeleton.bone_index, chain_world()[0])

    return make


@pytest.fixture(scope="session")
def demo():
    """The demo skeleton, muscle specs and models at rest (built once)."""
    from axdf_cli.specs import load_muscle_file, load_pose
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics

    pose = load_pose(DEMO_POSE)
    skel = pose.skeleton
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    specs = [s for f in DEMO_MUSCLE_FILES for s in load_muscle_file(f)]
    models = [MuscleModel(s, skel.bone_index, rest) for s in specs]
    return dataclasses.make_dataclass("Demo", ["pose", "skel", "rest", "specs", "models"])(
        pose, skel, rest, specs, models)


def demo_extreme_coordinates(skel, rng: np.random.Generator, n_random: int = 12) -> np.ndarray:
    """(F, C) coordinates: every coordinate at both ends of its range, plus random combinations."""
    rest = skel.rest_coordinates()
    qs = []
    for i, c in enumerate(skel.coordinates):
        for v in c.range:
            q = rest.copy()
            q[i] = v
            qs.append(q)
    for _ in range(n_random):
        qs.append(np.array([rng.uniform(*c.range) for c in skel.coordinates]))
    return np.array(qs)


@pytest.fixture(scope="session", autouse=True)
def contact_kernels_compiled():
    """Contact's kernels compiled (or loaded from numba's cache) before any test, both the
    threaded ones (this process) and their serial twins (a worker's), as
    a run's first use would: a test that stops a worker (SIGTERM) must find it working, not
    compiling, where Python prints the interrupt it raises inside LLVM's callback as
    "Exception ignored" (a worker compiling on a cold cache is stopped all the same)."""
    from axdf_cli.model import contact

    U, A = 12, 16
    th = 2.0 * np.pi * np.arange(A) / A
    meshes = []
    for dy, r in ((0.0, 0.02), (0.012, 0.004)):  # a thin one inside a thick one: every path runs
        s = np.linspace(0.01, 0.19, U - 2)
        rings = np.stack([np.repeat(s, A), np.tile(dy + r * np.cos(th), U - 2), np.tile(r * np.sin(th), U - 2)], 1)
        meshes.append(np.concatenate([[[0.0, dy, 0.0]], rings, [[0.2, dy, 0.0]]]))
    model = contact.ContactModel(~np.eye(2, dtype=bool), contact.pair_shares(np.zeros(2)), contact.BoneFields.pack([]),
                                 ((U, A), (U, A)), np.zeros(2))
    for threads in (True, False):
        contact.resolve_frame(model, meshes, np.eye(4)[None], volumes=np.zeros(2), threads=threads)
    yield
