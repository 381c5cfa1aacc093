"""The partition of space (axdf_cli/geometry/partition.py) and the fits it feeds: tissues on
known geometry (spheres and a box, whose signed distances are known in closed form), every
point given to at most one territory with the gap between neighbours, the deepest tissue
winning, a higher level winning outright, the measure by depth, a mesh as a bound, and
``axdf fit --inside`` keeping a fitted surface inside a mesh it would otherwise cross, and
``axdf atlas --partition`` on the Visible Human's calf (skipped without ../shared/data):
territories that share no space, and a library fitted into them.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import trimesh

from axdf_cli.geometry.partition import MeshField, Tissue, _inside_coarse_to_fine, depth_inside, partition
from axdf_cli.geometry.winding import winding_numbers
from cli_in_folder import run_cli
from conftest import REPO_ROOT
from osim_common import DATA
from test_hostile_round6 import ATLAS_FILES, MAP

H = 0.001  # the grid spacing (m)
GAP = 0.0005


def sphere(centre, radius, subdivisions=4) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + np.asarray(centre, float), np.asarray(m.faces)


def box(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    m = trimesh.creation.box(extents=hi - lo)
    m.apply_translation(0.5 * (lo + hi))
    m = m.subdivide().subdivide().subdivide()  # libigl's distances do not need it; the winding's sampling does
    return np.asarray(m.vertices), np.asarray(m.faces)


def grid_points(lo, hi, step) -> np.ndarray:
    axes = [np.arange(a, b + 1e-12, step) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


@pytest.fixture(scope="module")
def two_spheres():
    """Two spheres of 20 mm crossing by 8 mm (centres 32 mm apart on x) and a box bone through
    the right one's far side."""
    a = Tissue("a", *sphere([-0.016, 0, 0], 0.020), level=1)
    b = Tissue("b", *sphere([0.016, 0, 0], 0.020), level=1)
    bone = Tissue("bone", *box([0.024, -0.03, -0.03], [0.05, 0.03, 0.03]), level=2, territory=False)
    return (a, b, bone), partition([a, b, bone], H, GAP)


def test_every_point_belongs_to_at_most_one_territory_with_the_gap_between(two_spheres):
    """At every point of a fine grid over both spheres, at most one territory is positive, and
    where two come near each other the two values sum to at most minus the gap (their edges lie
    the gap apart)."""
    _, part = two_spheres
    pts = grid_points([-0.04, -0.022, -0.022], [0.04, 0.022, 0.022], 0.0007)
    ta, tb = part.value("a", pts), part.value("b", pts)
    assert (ta > 0).sum() > 1000 and (tb > 0).sum() > 1000
    assert not ((ta > 0) & (tb > 0)).any()
    both = (ta > -0.9 * H) & (tb > -0.9 * H)  # the seam between them (outside its box T reads -H)
    assert both.sum() > 100
    assert (ta[both] + tb[both]).max() <= -GAP + 0.3 * H


def test_the_seam_lies_where_the_two_depths_are_equal(two_spheres):
    """Equal spheres: the seam is the plane x = 0, each territory's edge gap/2 from it; away from
    the seam each territory is its sphere (T = the exact depth, within the grid's error)."""
    _, part = two_spheres
    y = np.linspace(-0.01, 0.01, 9)
    on = np.stack([np.zeros_like(y), y, np.zeros_like(y)], axis=1)
    # on the seam: T = (d_a - d_b - gap) / 2 = -gap / 2
    assert np.abs(part.value("a", on) + 0.5 * GAP).max() < 0.25 * H
    assert np.abs(part.value("b", on) + 0.5 * GAP).max() < 0.25 * H
    # the far side of a: T is a's own depth, 20 mm - distance from its centre
    far = np.array([[-0.016 - r, 0.0, 0.0] for r in (0.0, 0.005, 0.012, 0.018)])
    exact = 0.020 - np.linalg.norm(far - [-0.016, 0, 0], axis=1)
    assert np.abs(part.value("a", far) - exact).max() < 0.6 * H


def test_a_higher_level_wins_outright_and_keeps_the_gap(two_spheres):
    """The box bone takes b's far side: no point of b's territory is within the gap of the box."""
    (_, b, bone), part = two_spheres
    pts = grid_points([0.02, -0.015, -0.015], [0.036, 0.015, 0.015], 0.0005)
    inside_box = pts[:, 0] > 0.024
    tb = part.value("b", pts)
    assert (tb[inside_box] < 0).all()
    near = (pts[:, 0] > 0.024 - GAP + 0.1 * H)
    assert (tb[near] <= 0.25 * H).all()
    # 1 mm from the box, 13 mm deep in b: T = 1 mm - gap (the box's margin is what binds)
    assert part.value("b", np.array([[0.023, 0.0, 0.0]]))[0] == pytest.approx(0.001 - GAP, abs=0.3 * H)
    s = part.surface("b")
    assert s is not None and trimesh.Trimesh(*s, process=False).is_watertight
    assert s[0][:, 0].max() <= 0.024 - GAP + 0.5 * H


def test_the_deepest_tissue_wins_where_meshes_cross():
    """A small sphere on the surface of a big one: the points deeper in the small one go to it,
    the big one keeps the rest; their surfaces cross no deeper than the gap allows."""
    big = Tissue("big", *sphere([0, 0, 0], 0.025), level=1)
    small = Tissue("small", *sphere([0.022, 0, 0], 0.008), level=1)
    part = partition([big, small], H, GAP)
    # the small one's centre: 8 mm deep in it, 3 mm deep in the big one -> small's
    c = np.array([[0.022, 0.0, 0.0]])
    assert part.value("small", c)[0] > 0.002 and part.value("big", c)[0] < 0
    # deep in the big one: big's
    assert part.value("big", np.array([[0.0, 0.0, 0.0]]))[0] > 0.02
    meshes = [part.surface("big"), part.surface("small")]
    pts = np.concatenate([m[0] for m in meshes])
    own = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(meshes)])
    assert depth_inside(pts, own, meshes).max() < 0.25 * H
    # while the two spheres themselves cross 5 mm deep
    src = [(big.vertices, big.faces), (small.vertices, small.faces)]
    spts = np.concatenate([m[0] for m in src])
    sown = np.concatenate([np.full(len(m[0]), i) for i, m in enumerate(src)])
    assert depth_inside(spts, sown, src).max() > 0.004


def test_a_lower_level_takes_the_room_left():
    """A tissue of a lower level (a muscle the atlas lacks) keeps only what is the gap clear of a
    higher one, however deep it lies."""
    atlas = Tissue("atlas", *sphere([0, 0, 0], 0.015), level=1)
    lacked = Tissue("lacked", *sphere([0.01, 0, 0], 0.015), level=0)
    part = partition([atlas, lacked], H, GAP)
    # 10 mm deep in lacked but 5 mm inside atlas: atlas'
    p = np.array([[0.01 - 0.005 - 0.0049, 0.0, 0.0], [0.0, 0.0, 0.0]])
    assert (part.value("lacked", p) < 0).all()
    s = part.surface("lacked")
    v = s[0]
    assert np.linalg.norm(v, axis=1).min() >= 0.015 + GAP - 0.5 * H


def test_depth_inside_is_the_exact_depth_on_a_sphere():
    """Points at known depths in a sphere: the measure returns them; its own points count 0."""
    v, f = sphere([0, 0, 0], 0.02, subdivisions=5)
    r = np.array([0.0, 0.005, 0.015, 0.0199, 0.021, 0.03])
    pts = np.stack([r, np.zeros_like(r), np.zeros_like(r)], axis=1)
    d = depth_inside(pts, np.full(len(pts), -1), [(v, f)])
    assert np.allclose(d[:4], 0.02 - r[:4], atol=2e-5)
    assert (d[4:] == 0).all()
    assert (depth_inside(pts, np.zeros(len(pts), int), [(v, f)]) == 0).all()


def test_inside_coarse_to_fine_is_the_exact_winding_even_for_a_sheet_thinner_than_the_grid():
    """A slab 1.2 mm thick on a 1 mm grid: the coarse pass (every second point) misses it, the
    exact pass near triangles recovers it; the result is the full winding number's."""
    v, f = box([-0.02, -0.02, -0.0006], [0.02, 0.02, 0.0006])
    axes = [np.arange(-0.025, 0.025, H), np.arange(-0.025, 0.025, H), np.arange(-0.005, 0.005, H) + 0.0003]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    got = _inside_coarse_to_fine(v, f, pts, axes, tuple(len(a) for a in axes)).ravel()
    full = np.abs(winding_numbers(v, f, pts)) > 0.5
    assert full.sum() > 1000
    assert (got == full).all()


def test_a_mesh_field_is_its_signed_distance_and_grows_inward():
    v, f = sphere([0, 0, 0], 0.02, subdivisions=5)
    fld = MeshField(v, f)
    pts = np.array([[0.01, 0, 0], [0, 0.025, 0], [0, 0, -0.019]])
    assert np.allclose(fld.value(pts), [0.01, -0.005, 0.001], atol=5e-5)
    g = fld.inward(pts)
    assert np.allclose(g, [[-1, 0, 0], [0, -1, 0], [0, 0, 1]], atol=0.03)


# ------------------------------------------------------------------ axdf fit --inside


def rounded_box_tube(rows=60, around=96, length=0.30, p=6.0, a=0.03, b=0.02):
    """A closed tube along z from 0.92 to 0.62 m whose section is a superellipse |x/a|^p +
    |y/b|^p = 1 (flat faces, tight corners) tapering to its tips: 8-point outlines fitted by
    least squares overshoot its faces."""
    s = np.linspace(0.0, 1.0, rows)[1:-1]
    k = np.sin(np.pi * s) ** 0.5
    th = np.arange(around) * 2 * np.pi / around
    c, sn = np.cos(th), np.sin(th)
    rx, ry = a * np.sign(c) * np.abs(c) ** (2 / p), b * np.sign(sn) * np.abs(sn) ** (2 / p)
    z = 0.92 - length * s
    ring = np.stack([k[:, None] * rx, k[:, None] * ry, np.broadcast_to(z[:, None], (len(s), around))],
                    axis=-1).reshape(-1, 3)
    v = np.concatenate([[[0, 0, 0.92]], ring, [[0, 0, 0.92 - length]]])
    n = len(s)
    ring_f = []
    for i in range(n - 1):
        for j in range(around):
            q0, q1 = 1 + i * around + j, 1 + i * around + (j + 1) % around
            ring_f += [[q0, q1, q0 + around], [q0 + around, q1, q1 + around]]
    base, last = 1 + (n - 1) * around, len(v) - 1
    f = [[0, 1 + (j + 1) % around, 1 + j] for j in range(around)] + ring_f + \
        [[base + j, base + (j + 1) % around, last] for j in range(around)]
    m = trimesh.Trimesh(v, np.array(f), process=True)
    if m.volume < 0:
        m.invert()
    return m


def _outside(d, out, mesh) -> np.ndarray:
    """How far (m) each vertex of the fitted muscle ``d/out/muscles/box.yaml`` at rest lies
    outside ``mesh``."""
    from axdf_cli.model.muscle import MuscleModel
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import RefPolicy, load_muscle_file, load_skeleton

    skel = load_skeleton(Path(d) / "leg.yaml", RefPolicy())
    rest = forward_kinematics(skel, skel.rest_coordinates()[None])[0]
    spec = load_muscle_file(Path(d) / out / "muscles" / "box.yaml")[0]
    v = MuscleModel(spec, skel.bone_index, rest, skel).rest_vertices.astype(np.float64)
    return np.maximum(-MeshField(mesh.vertices, mesh.faces).value(v), 0.0)


def test_fit_inside_keeps_the_surface_inside_a_mesh_the_plain_fit_crosses(tmp_path, capsys):
    from test_fit import SKELETON

    (tmp_path / "leg.yaml").write_text(SKELETON)
    mesh = rounded_box_tube()
    mesh.export(tmp_path / "box.stl")
    for out, extra in (("plain", ()), ("inside", ("--inside",))):
        assert run_cli(tmp_path, "fit", "box.stl", "--skeleton", "leg.yaml", "--out", out, "--sections", "8",
                       "--quiet", *extra) == 0
    plain = _outside(tmp_path, "plain", mesh)
    held = _outside(tmp_path, "inside", mesh)
    assert (plain > 2.5e-4).mean() > 0.05 and plain.max() > 0.8e-3  # the plain fit overshoots the faces
    assert (held > 2.5e-4).mean() <= 0.005 and held.max() < 0.5e-3
    (m,) = json.loads((tmp_path / "inside" / "fit_report.json").read_text())["muscles"]
    assert m["iou"] >= 0.9 and abs(m["volume_ratio"] - 1) <= 0.08, m
    # the report measures the same thing on the written file
    assert m["outside_over_0.25mm"] == pytest.approx((held > 2.5e-4).mean(), abs=1e-9)
    assert m["outside_farthest_mm"] == pytest.approx(1000 * held.max(), rel=1e-3)  # (the STL read back: float32)
    assert "Kept inside each mesh" in (tmp_path / "inside" / "FIT.md").read_text()
    assert "outside_over_1mm" not in json.loads((tmp_path / "plain" / "fit_report.json").read_text())["muscles"][0]


# ------------------------------------------------------------------ axdf atlas --partition

# the small atlas of test_hostile_round6 (soleus onto gait2392) with the medial gastrocnemius
VHF_FILES = ATLAS_FILES + ("Right/VHF_Right_Muscle_GastrocnemiusMedial_smooth.ply",)
CALF_MAP = MAP + "  med_gas: [GastrocnemiusMedial]\n"
GAIT2392 = REPO_ROOT / "poses" / "skeletons" / "gait2392.yaml"


def _calf(d: Path, capsys, *argv) -> tuple[int, str]:
    """``axdf atlas --partition`` of the calf atlas, its map and a library of its three muscles
    (tibialis posterior, which the map lacks, among them) in ``d``: (exit code, stdout)."""
    vhf = DATA / "atlas" / "visible_human_female"
    if not (vhf / "Right").is_dir():
        pytest.skip(f"the Visible Human atlas not found at {vhf}")
    for rel in VHF_FILES:
        (d / "atlas" / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(vhf / rel, d / "atlas" / rel)
    (d / "lib").mkdir()
    for n in ("soleus_r", "med_gas_r", "tib_post_r"):
        shutil.copy(REPO_ROOT / "muscles" / "gait2392" / f"{n}.yaml", d / "lib")
    (d / "map.yaml").write_text(CALF_MAP)
    capsys.readouterr()
    rc = run_cli(d, "atlas", "atlas", "--onto", str(GAIT2392), "--map", "map.yaml", "--muscles", "lib", "--out", "out",
                 "--sides", "r", "--partition", *argv)
    got = capsys.readouterr()
    assert rc == 0, got.err
    return rc, got.out


def _depth(meshes: dict) -> np.ndarray:
    names = list(meshes)
    pts = np.concatenate([meshes[n][0] for n in names])
    own = np.concatenate([np.full(len(meshes[n][0]), i) for i, n in enumerate(names)])
    return depth_inside(pts, own, [meshes[n] for n in names])


def test_atlas_partition_gives_the_calf_territories_that_share_no_space(tmp_path, capsys):
    """Soleus and medial gastrocnemius of the Visible Human registered onto gait2392, with
    tibialis posterior (which this map lacks) from the model: the registered meshes cross by
    centimetres; the territories, written as closed meshes, by nothing deeper than 0.25 mm, and
    not into a bone; each keeps most of its volume; the report says so, and so does stdout."""
    _, out = _calf(tmp_path, capsys, "--register-only")
    rep = json.loads((tmp_path / "out" / "atlas_report.json").read_text())["partition"]
    assert rep["lacked"] == ["tib_post_r"] and rep["empty"] == []
    assert rep["registered"]["inside_muscle_over_1mm"] > 0.03 and rep["registered"]["deepest_mm"] > 5
    assert rep["territories"]["inside_muscle_over_0.25mm"] == 0.0
    assert rep["territories"]["inside_bone_over_1mm"] == 0.0
    assert set(rep["volume_ratio"]) == {"soleus_r", "med_gas_r", "tib_post_r"}
    assert min(rep["volume_ratio"].values()) > 0.6 and rep["volume_ratio"]["med_gas_r"] > 0.9
    meshes = {}
    for n in rep["volume_ratio"]:
        m = trimesh.load(tmp_path / "out" / "territories" / f"{n}.ply", process=False)
        assert m.is_watertight and m.volume > 0, n
        meshes[n] = (np.asarray(m.vertices), np.asarray(m.faces))
    assert _depth(meshes).max() < 2.5e-4  # measured again here, on the PLY files as written
    assert "partition: 3 territories into out/territories" in out
    assert json.loads((tmp_path / "out" / "manifest.json").read_text())["settings"]["partition"] is True


def test_atlas_partition_fits_the_library_into_the_territories(tmp_path, capsys):
    """Without --register-only, each territory is fitted and held inside it: the three muscles
    are fitted (none copied), each measured against its registered atlas mesh too, and the
    library at rest shares no space (measured 0.23 mm deepest; the library fitted to the
    registered meshes themselves puts 12% of its vertices more than 1 mm inside another, 11.7 mm
    deepest). Where the model's coarse tibia cuts a notch into the medial gastrocnemius'
    territory below the knee, 8-point outlines cannot follow it: 4.8% of that fit's vertices
    stay more than 1 mm outside (inside the bone)."""
    from axdf_cli.tools.atlas_partition import depth_shares, model_rest_meshes
    from axdf_cli.tools.atlas_library import rest_state

    _, out = _calf(tmp_path, capsys, "--sections", "8")
    rep = json.loads((tmp_path / "out" / "atlas_report.json").read_text())
    fitted = {m["muscle"]: m for m in rep["fitted"]}
    assert set(fitted) == {"soleus_r", "med_gas_r", "tib_post_r"} and rep["kept"] == []
    assert set(m for m in fitted if "atlas" in fitted[m]) == {"soleus_r", "med_gas_r"}
    for m in fitted.values():
        assert m["iou"] >= 0.7 and m["outside_over_1mm"] <= 0.08, m
        assert m.get("atlas", {"iou": 1})["iou"] >= 0.6, m
    skel, rest, bones = rest_state(GAIT2392)
    got = depth_shares(model_rest_meshes(tmp_path / "out" / "muscles", list(fitted), skel, rest), bones)
    assert got["inside_muscle_over_0.25mm"] <= 0.002 and got["deepest_mm"] < 1.0, got
    assert got["inside_bone_over_1mm"] <= 0.02, got
    assert rep["partition"]["registered"]["inside_muscle_over_1mm"] > 0.03
    assert "fitted into the territories: against the registered atlas meshes IoU" in out
