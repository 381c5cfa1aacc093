"""``axdf import mjcf`` on small hand-written MuJoCo models, judged by MuJoCo itself: each
joint type (bone poses against ``xpos``/``xmat``), couplings (chains, constants, refs), each
wrap kind with and without a sidesite (path length against ``ten_length``), MJCF's frames
(includes, default classes, childclass, ``<frame>``, euler/axisangle/xyaxes/zaxis in degrees),
bone meshes (against MuJoCo's own placed vertices), npz motions (quaternions round-trip), and
bad input (``FILE:LINE:COL`` for XML, the array and index for npz; exit 2, nothing written)."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from axdf_cli.cli.main import main

mujoco = pytest.importorskip("mujoco", reason="the MuJoCo judge needs `pip install mujoco` (test extra)")

# A model with every joint type, a coupling chain, frames, defaults, includes and every wrap kind.
MAIN = """<mujoco model="toy">
  <compiler angle="degree" eulerseq="xyz" meshdir="assets" inertiafromgeom="true"/>
  <option><flag gravity="disable"/></option>
  <include file="defaults.xml"/>
  <asset><mesh name="box" file="box.stl" scale="1 -1 1.5"/></asset>
  <worldbody>
    <site name="w0" pos="0.3 0.1 1.2"/>
    <body name="base" pos="0 0 1" euler="10 20 30">
      <freejoint name="root"/>
      <geom type="mesh" mesh="box" pos="0.01 0.02 0.03" axisangle="1 1 0 40"/>
      <site name="b0" pos="0.05 0.02 0.1"/>
      <site name="side_in" pos="0.0 -0.1 -0.2"/>
      <body name="upper" pos="0.1 0 -0.05" xyaxes="0 1 0 -1 0 0" childclass="limb">
        <joint name="shoulder" type="ball" pos="0 0 0.02"/>
        <geom type="capsule" size="0.01 0.05"/>
        <geom name="ball_wrap" type="sphere" size="0.04" pos="0 0 -0.15"/>
        <site name="u1" pos="0.03 0.0 -0.05"/>
        <site name="u_side" pos="0.09 0.02 -0.15"/>
        <frame pos="0 0 -0.3" zaxis="0 1 1">
          <body name="lower" pos="0 0 0">
            <joint name="elbow" axis="0 1 0" pos="0.01 0 0" ref="10" range="-20 120"/>
            <joint name="slide1" type="slide" axis="1 0 0"/>
            <joint name="twist" axis="0 0 1" pos="0 0.01 0" range="-90 90"/>
            <geom name="cyl_wrap" type="cylinder" fromto="-0.02 -0.05 0.02 -0.02 0.05 0.0" size="0.025"/>
            <site name="l1" pos="0.0 0.02 -0.2"/>
            <site name="l_side" pos="-0.08 0.0 0.01"/>
            <body name="hand" pos="0 0 -0.25">
              <joint name="wrist" axis="1 0 0" range="-60 60"/>
              <geom type="capsule" size="0.01 0.03"/>
              <site name="h1" pos="0.01 0 -0.05"/>
            </body>
          </body>
        </frame>
      </body>
    </body>
  </worldbody>
  <equality>
    <joint joint1="slide1" joint2="elbow" polycoef="0.001 0.01 -0.002 0 0"/>
    <joint joint1="twist" joint2="slide1" polycoef="0 5 100 0 0"/>
  </equality>
  <include file="muscles.xml"/>
</mujoco>
"""
DEFAULTS = """<mujocoinclude>
  <default>
    <joint limited="auto"/>
    <default class="limb">
      <joint type="hinge" damping="1"/>
      <site size="0.005"/>
      <default class="wrapcls"><geom type="sphere"/></default>
    </default>
    <default class="m"><general gaintype="muscle" dyntype="muscle" biastype="muscle" gainprm="0.6 1.2 300 200 0.5 1.6 1.5 1.3 1.2" biasprm="0.6 1.2 300 200 0.5 1.6 1.5 1.3 1.2"/></default>
  </default>
</mujocoinclude>
"""
MUSCLES = """<mujocoinclude>
  <tendon>
    <spatial name="t_sphere_side"><site site="b0"/><geom geom="ball_wrap" sidesite="u_side"/><site site="l1"/></spatial>
    <spatial name="t_sphere_inside"><site site="b0"/><geom geom="ball_wrap" sidesite="side_in"/><site site="l1"/></spatial>
    <spatial name="t_sphere"><site site="w0"/><site site="u1"/><geom geom="ball_wrap"/><site site="l1"/></spatial>
    <spatial name="t_cyl_side"><site site="u1"/><geom geom="cyl_wrap" sidesite="l_side"/><site site="h1"/></spatial>
    <spatial name="t_cyl"><site site="u1"/><geom geom="cyl_wrap"/><site site="h1"/></spatial>
  </tendon>
  <actuator>
    <muscle name="m_sphere_side" tendon="t_sphere_side" force="400" lengthrange="0.2 0.4"/>
    <general name="m_sphere_inside" class="m" tendon="t_sphere_inside" lengthrange="0.2 0.4"/>
    <muscle name="m_sphere" tendon="t_sphere" force="300" lengthrange="0.3 0.6" range="0.5 1.5"/>
    <muscle name="m_cyl_side" tendon="t_cyl_side" force="250" lengthrange="0.3 0.5"/>
    <muscle name="m_cyl" tendon="t_cyl" lengthrange="0.3 0.5"/>
    <motor name="not_a_muscle" joint="wrist"/>
  </actuator>
</mujocoinclude>
"""


def _stl(path: Path) -> None:
    import trimesh

    box = trimesh.creation.box(extents=(0.04, 0.06, 0.1))
    box.apply_translation((0.01, 0.0, -0.02))
    path.write_bytes(trimesh.exchange.stl.export_stl(box))


@pytest.fixture(scope="module")
def toy(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("toy")
    (d / "assets").mkdir()
    _stl(d / "assets" / "box.stl")
    (d / "toy.xml").write_text(MAIN)
    (d / "defaults.xml").write_text(DEFAULTS)
    (d / "muscles.xml").write_text(MUSCLES)
    return d / "toy.xml"


def _random_qpos(m, count: int, seed: int) -> np.ndarray:
    """qpos (count, nq): hinges in range (or ±90°), the free joint moved, the ball turned; the
    coupled joints from their polynomials (slide1 from elbow, twist from slide1)."""
    rng = np.random.default_rng(seed)
    q = np.tile(m.qpos0, (count, 1))
    for j in range(m.njnt):
        a = m.jnt_qposadr[j]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE:
            q[:, a:a + 3] += rng.normal(scale=0.3, size=(count, 3))
            quat = rng.normal(size=(count, 4))
            q[:, a + 3:a + 7] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        elif m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL:
            quat = rng.normal(size=(count, 4))
            q[:, a:a + 4] = quat / np.linalg.norm(quat, axis=1, keepdims=True)
        else:
            lo, hi = m.jnt_range[j] if m.jnt_limited[j] else (-1.5, 1.5)
            q[:, a] = rng.uniform(lo, hi, size=count)
    for e in range(m.neq):  # in order: slide1 follows elbow, then twist follows slide1
        a1, a2 = m.jnt_qposadr[m.eq_obj1id[e]], m.jnt_qposadr[m.eq_obj2id[e]]
        x = q[:, a2] - m.qpos0[a2]
        q[:, a1] = m.qpos0[a1] + np.polynomial.polynomial.polyval(x, m.eq_data[e, :5])
    return q


def _import(xml: Path, out: Path, qpos: np.ndarray | None = None, *extra: str) -> int:
    args = ["import", "mjcf", str(xml), "--out", str(out), "-q", "--name", "toy"]
    if qpos is not None:
        npz = out.parent / f"{out.name}_motion.npz"
        with open(npz, "wb") as fh:
            np.savez(fh, qpos=qpos, fps=np.float64(25.0))
        args += ["--motion", str(npz), "--pose-name", "motion"]
    return main(args + list(extra))


@pytest.fixture(scope="module")
def judged(toy, tmp_path_factory):
    """(MuJoCo model, qpos (F, nq), the import's folder, axdf skeleton, q (F, C), world (F, B, 4, 4))."""
    from axdf_cli.specs import load_pose
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics

    m = mujoco.MjModel.from_xml_path(str(toy))
    qpos = _random_qpos(m, 25, 3)
    out = tmp_path_factory.mktemp("imp") / "toy"
    assert _import(toy, out, qpos) == 0
    pose = load_pose(out / "motion.yaml")
    q = sample_coordinates(pose, pose.frames)
    return m, qpos, out, pose.skeleton, q, forward_kinematics(pose.skeleton, q)


def test_every_joint_type_places_bones_as_mujoco(judged):
    m, qpos, out, skel, q, world = judged
    d = mujoco.MjData(m)
    for f in range(len(qpos)):
        d.qpos[:] = qpos[f]
        mujoco.mj_kinematics(m, d)
        for b in range(1, m.nbody):
            name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
            w = world[f, skel.bone_index[name]]
            np.testing.assert_allclose(w[:3, 3], d.xpos[b], atol=1e-7, err_msg=f"{name} frame {f}")
            np.testing.assert_allclose(w[:3, :3], d.xmat[b].reshape(3, 3), atol=1e-7, err_msg=f"{name} frame {f}")


def test_couplings_are_dofs_of_the_joint_they_follow(judged):
    """slide1 follows elbow by its polynomial, twist follows slide1 (a chain: composed), and
    neither is a coordinate; elbow's ref (10°) is its default and its DOF turns by q − ref."""
    import yaml

    _, _, out, skel, _, _ = judged
    assert set(skel.coord_index) == {"root_tx", "root_ty", "root_tz", "root_rx", "root_ry", "root_rz",
                                     "shoulder_rx", "shoulder_ry", "shoulder_rz", "elbow", "wrist"}
    doc = yaml.safe_load((out / "skeletons" / "toy.yaml").read_text())
    assert doc["coordinates"]["elbow"] == {"type": "rotation", "default": 10.0, "range": [-20.0, 120.0]}
    lower = next(b for b in doc["bones"] if b["name"] == "lower")
    slide, twist = [d for d in lower["dofs"] if d.get("coord") == "elbow" and "polynomial" in d.get("function", {})]
    x = np.linspace(-20, 120, 7)  # degrees of elbow
    d_rad = np.radians(x - 10.0)
    slide_m = 0.001 + 0.01 * d_rad - 0.002 * d_rad ** 2
    np.testing.assert_allclose(np.polynomial.polynomial.polyval(x, slide["function"]["polynomial"]), slide_m, atol=1e-9)
    twist_deg = np.degrees(5 * slide_m + 100 * slide_m ** 2)
    np.testing.assert_allclose(np.polynomial.polynomial.polyval(x, twist["function"]["polynomial"]), twist_deg, rtol=1e-7,
                               atol=1e-9)
    elbow = next(d for d in lower["dofs"] if d.get("coord") == "elbow" and "linear" in d.get("function", {}))
    assert elbow["function"]["linear"] == [1.0, -10.0]


@pytest.mark.parametrize("muscle", ["m_sphere_side", "m_sphere_inside", "m_sphere", "m_cyl_side", "m_cyl"])
def test_each_wrap_kind_matches_mujoco_ten_length(judged, muscle):
    """The wrapped path (MuJoCo's rules: sidesite outside, inside, none; sphere and infinite
    cylinder) has MuJoCo's length at every frame."""
    from axdf_cli.specs import load_muscle_file
    from axdf_cli.model.paths.path import PathModel

    m, qpos, out, skel, q, world = judged
    d = mujoco.MjData(m)
    a = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, muscle)
    t = m.actuator_trnid[a, 0]
    ref = np.empty(len(qpos))
    wrapped = np.zeros(len(qpos), bool)
    for f in range(len(qpos)):
        d.qpos[:] = qpos[f]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        mujoco.mj_tendon(m, d)
        ref[f] = d.ten_length[t]
        wrapped[f] = d.ten_wrapnum[t] > m.tendon_num[t] - 1
    (spec,) = load_muscle_file(out / "muscles" / f"{muscle}.yaml")
    pm = PathModel(spec.path, skel.bone_index, skel.coord_index)
    _, length, _ = pm.wrapped(world, q)
    np.testing.assert_allclose(length, ref, rtol=1e-6, atol=0)  # the files' rounding: 0.1 µm, 9 digits
    assert wrapped.any(), "the test poses never wrap this tendon"
    # (the axis's 1% is judged on the real models, tests/test_mjcf_judge.py: these poses turn the
    # ball and free joints anywhere, far outside a body's motion)
    assert spec.path.wraps[0].shape == ("mujoco_cylinder" if "cyl" in muscle else "mujoco_sphere")
    assert (spec.path.wraps[0].side is not None) == ("side" in muscle or "inside" in muscle)


def test_muscle_numbers_and_report(judged):
    import json

    _, _, out, _, _, _ = judged
    r = json.loads((out / "import_report.json").read_text())
    rows = {x["muscle"]: x for x in r["muscles"]}
    assert set(rows) == {"m_sphere_side", "m_sphere_inside", "m_sphere", "m_cyl_side", "m_cyl"}
    # L0 = (0.6 - 0.3) / (1.5 - 0.5); LT = 0.3 - 0.5 L0
    assert rows["m_sphere"]["optimal_fiber_length"] == pytest.approx(0.3)
    assert rows["m_sphere"]["tendon_slack_length"] == pytest.approx(0.15)
    assert rows["m_sphere_inside"]["force"] == pytest.approx(300.0)  # gainprm[2] through the class
    assert rows["m_cyl"]["force"] == pytest.approx(200.0) and rows["m_cyl"]["notes"]  # force -1: scale assumed
    assert {i["name"] for i in r["ignored"]} == {"not_a_muscle"}
    assert all(x["slenderness"] >= 1.5 - 1e-6 for x in r["muscles"])
    assert "/" not in (out / "IMPORT.md").read_text().split("Source:")[1].split("\n")[0].replace("`/`", "")


def test_bone_mesh_is_placed_as_mujoco_places_it(judged, toy):
    """The body's PLY (bone-local) posed by the bone equals MuJoCo's mesh vertices posed by the
    geom (mesh scale with a mirror, geom axisangle in degrees); the mirror turns the faces so
    they stay outward."""
    import trimesh

    from axdf_cli.formats import load_triangles

    m, qpos, out, skel, q, world = judged
    v, _, faces = load_triangles(out / "skeletons" / "meshes" / "toy" / "base.ply")
    d = mujoco.MjData(m)
    d.qpos[:] = qpos[0]
    mujoco.mj_kinematics(m, d)
    g = next(i for i in range(m.ngeom) if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_MESH)
    mid = m.geom_dataid[g]
    mv = m.mesh_vert[m.mesh_vertadr[mid]:m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
    theirs = mv @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
    w = world[0, skel.bone_index["base"]]
    ours = np.asarray(v, float) @ w[:3, :3].T + w[:3, 3]
    # same point sets (MuJoCo may reorder or merge vertices): every vertex of each near the other's
    from scipy.spatial import cKDTree

    assert cKDTree(theirs).query(ours)[0].max() < 1e-6 and cKDTree(ours).query(theirs)[0].max() < 1e-6
    mesh = trimesh.Trimesh(np.asarray(v, float), np.asarray(faces), process=True)
    assert mesh.volume > 0  # outward after the mirror


def test_npz_motion_round_trips_quaternions(judged):
    """The pose's ball and free coordinates give back the npz's quaternions (up to sign), hinges
    its radians, the fps its own."""
    from axdf_cli.importers.qpos import euler_to_quat
    from axdf_cli.specs import load_pose

    m, qpos, out, skel, q, _ = judged
    pose = load_pose(out / "motion.yaml")
    assert pose.fps == 25
    ci = skel.coord_index
    for joint, a in (("root", 3), ("shoulder", 7)):
        e = q[:, [ci[f"{joint}_r{x}"] for x in "xyz"]]
        back = euler_to_quat(e)
        orig = qpos[:, a:a + 4]
        sign = np.sign(np.sum(back * orig, axis=1))[:, None]
        np.testing.assert_allclose(back * sign, orig, atol=1e-7)  # angles written to 9 digits (1e-6°)
    np.testing.assert_allclose(q[:, [ci[f"root_t{x}"] for x in "xyz"]], qpos[:, 0:3], atol=1e-9)
    np.testing.assert_allclose(q[:, ci["elbow"]], np.degrees(qpos[:, 11]), atol=1e-7)


def test_euler_unwrap_keeps_frames_continuous():
    from axdf_cli.importers.qpos import euler_to_quat, quat_to_euler, unwrap_degrees

    ang = np.linspace(0, 4 * np.pi, 200)  # two full turns about X
    quat = np.stack([np.cos(ang / 2), np.sin(ang / 2), 0 * ang, 0 * ang], axis=1)
    e = unwrap_degrees(quat_to_euler(quat))
    assert np.max(np.abs(np.diff(e, axis=0))) < 5.0
    np.testing.assert_allclose(e[:, 0], np.degrees(ang), atol=1e-6)
    back = euler_to_quat(e)
    np.testing.assert_allclose(np.abs(np.sum(back * quat, axis=1)), 1.0, atol=1e-12)


# ----------------------------------------------------------------------------- bad input

POS = re.compile(r"(?P<file>[^\s:]+\.xml):(?P<line>\d+):(?P<col>\d+): ")


def _bad(tmp_path, capsys, text: str, files: dict | None = None, qpos=None, npz_bytes: bytes | None = None):
    d = tmp_path / "bad"
    d.mkdir(exist_ok=True)
    (d / "m.xml").write_text(text)
    for k, v in (files or {}).items():
        (d / k).write_text(v)
    args = ["import", "mjcf", str(d / "m.xml"), "--out", str(d / "out"), "-q"]
    if qpos is not None or npz_bytes is not None:
        npz = d / "q.npz"
        if npz_bytes is not None:
            npz.write_bytes(npz_bytes)
        else:
            with open(npz, "wb") as fh:
                np.savez(fh, **qpos)
        args += ["--motion", str(npz)]
    rc = main(args)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert not (d / "out").exists(), "nothing is written on bad input"
    assert "Traceback" not in err
    return err


SMALL = """<mujoco>
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="j" type="{jt}" axis="0 1 0"/>
      <site name="s1" pos="0 0 0.1"/><site name="s2" pos="0.1 0 0"/>
    </body>
  </worldbody>
  {extra}
</mujoco>
"""


@pytest.mark.parametrize("case, line, col, words", [
    ("<mujoco><worldbody><body></worldbody></mujoco>", 1, 28, "malformed XML"),
    (SMALL.format(jt="hinge2", extra=""), 4, 7, "joint type 'hinge2'"),
    (SMALL.format(jt="hinge", extra='<tendon><spatial name="t"><site site="s1"/><site site="nope"/></spatial></tendon>'),
     8, 46, "unknown site 'nope'"),
    (SMALL.format(jt="hinge", extra='<equality><joint joint1="j" joint2="zz"/></equality>'), 8, 13, "unknown joint 'zz'"),
    (SMALL.format(jt="hinge", extra="").replace('pos="0 0 1"', 'pos="0 0 x"'), 3, 5, "not a list of numbers"),
    (SMALL.format(jt="hinge", extra="").replace('pos="0 0 1"', 'pos="0 0 1" quat="0 0 0 0"'), 3, 5, "quat is zero"),
    (SMALL.format(jt="ball", extra='<equality><joint joint1="j"/></equality>'), 8, 13, "on ball joint"),
    (SMALL.format(jt="hinge", extra='<tendon><spatial name="t"><site site="s1"/><geom geom="g"/><site site="s2"/>'
                                    '</spatial></tendon>'), 8, 46, "unknown geom 'g'"),
    (SMALL.format(jt="hinge", extra='<actuator><muscle name="m" tendon="none"/></actuator>'), 8, 13, "unknown tendon"),
])
def test_bad_mjcf_is_refused_at_its_position(tmp_path, capsys, case, line, col, words):
    err = _bad(tmp_path, capsys, case)
    m = POS.search(err)
    assert m and (int(m["line"]), int(m["col"])) == (line, col), err
    assert words in err, err


def test_include_cycle_and_missing_include(tmp_path, capsys):
    err = _bad(tmp_path, capsys, '<mujoco>\n  <include file="a.xml"/>\n</mujoco>\n',
               {"a.xml": '<mujocoinclude>\n <include file="a.xml"/>\n</mujocoinclude>\n'})
    assert "a.xml:2:2: 'a.xml' includes itself" in err, err
    err = _bad(tmp_path, capsys, '<mujoco>\n  <include file="none.xml"/>\n</mujoco>\n')
    assert "m.xml:2:3: included file 'none.xml' not found" in err, err


@pytest.mark.parametrize("arrays, words", [
    ({"pos": np.zeros((3, 1))}, "no array qpos (arrays: pos)"),
    ({"qpos": np.zeros((3, 2))}, "qpos has shape (3, 2)"),
    ({"qpos": np.array([[0.1], [0.2], [np.nan]])}, "qpos[2, 0] = nan"),
    ({"qpos": np.zeros((3, 1)), "fps": np.array([0.0])}, "fps = "),
    ({"qpos": np.array([["a"], ["b"]])}, "qpos has dtype <U1"),
])
def test_bad_npz_names_the_array_and_index(tmp_path, capsys, arrays, words):
    err = _bad(tmp_path, capsys, SMALL.format(jt="hinge", extra=""), qpos=arrays)
    assert f"q.npz: {words}" in err, err


def test_bad_npz_quaternion_and_not_an_archive(tmp_path, capsys):
    err = _bad(tmp_path, capsys, SMALL.format(jt="ball", extra=""), qpos={"qpos": np.zeros((2, 4))})
    assert "q.npz: qpos[0, 0:4] is a zero quaternion (joint 'j')" in err, err
    err = _bad(tmp_path, capsys, SMALL.format(jt="hinge", extra=""), npz_bytes=b"not a zip at all")
    assert "q.npz: not a numpy .npz archive" in err, err


def test_names_become_axdf_names(tmp_path):
    """A body name with a space (myo-sim's "Full Body") becomes Full_Body; the report says so."""
    import json

    d = tmp_path / "n"
    d.mkdir()
    (d / "m.xml").write_text(SMALL.format(jt="hinge", extra="").replace('name="a"', 'name="Full Body"'))
    assert main(["import", "mjcf", str(d / "m.xml"), "--out", str(d / "out"), "-q"]) == 0
    r = json.loads((d / "out" / "import_report.json").read_text())
    assert r["renamed"] == [{"kind": "body", "mjcf": "Full Body", "axdf": "Full_Body"}]
    assert "name: Full_Body" in next((d / "out" / "skeletons").glob("*.yaml")).read_text()


def test_angles_in_degrees_and_orientation_forms_match_mujoco(tmp_path):
    """euler (with a mixed intrinsic/extrinsic eulerseq), axisangle, xyaxes and zaxis, in
    degrees, place bodies as MuJoCo does."""
    from axdf_cli.specs import load_skeleton
    from axdf_cli.model.skeleton import forward_kinematics

    text = """<mujoco><compiler angle="degree" eulerseq="zYx"/><default><geom size="0.01"/></default><worldbody>
      <body name="e" pos="0.1 0.2 0.3" euler="30 -40 70"><joint name="h1"/><geom/>
        <body name="aa" pos="0 0.1 0" axisangle="0.2 1 0.3 75"><joint name="h2" axis="1 0 0"/><geom/>
          <body name="xy" pos="0.1 0 0" xyaxes="0 1 0.2 -1 0 0"><joint name="h3" axis="0 0 1" pos="0.02 0 0"/><geom/>
            <body name="z" pos="0 0 0.1" zaxis="0.3 -0.2 1"/></body></body></body></worldbody></mujoco>"""
    (tmp_path / "o.xml").write_text(text)
    assert main(["import", "mjcf", str(tmp_path / "o.xml"), "--out", str(tmp_path / "o"), "-q", "--name", "o"]) == 0
    m = mujoco.MjModel.from_xml_path(str(tmp_path / "o.xml"))
    d = mujoco.MjData(m)
    skel = load_skeleton(tmp_path / "o" / "skeletons" / "o.yaml")
    rng = np.random.default_rng(1)
    qpos = rng.uniform(-1, 1, size=3)
    d.qpos[:] = qpos
    mujoco.mj_kinematics(m, d)
    qc = np.zeros(len(skel.coordinates))
    for i, n in enumerate(("h1", "h2", "h3")):
        qc[skel.coord_index[n]] = math.degrees(qpos[i])
    world = forward_kinematics(skel, qc[None])[0]
    for b in range(1, m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        np.testing.assert_allclose(world[skel.bone_index[name], :3, 3], d.xpos[b], atol=1e-7)
        np.testing.assert_allclose(world[skel.bone_index[name], :3, :3], d.xmat[b].reshape(3, 3), atol=1e-7)


# ----------------------------------------------------------------------------- qpos motions in data sets


def test_imported_skeleton_gives_mujocos_qpos_layout(judged):
    """A data set's qpos motion is read against the skeleton alone: the qpos index of every
    joint that is a coordinate, read back from the imported skeleton's bones and coordinates
    (free, ball, a hinge with a ref, anchors, a chain of couplings), is MuJoCo's own."""
    from axdf_cli.importers.qpos import skeleton_qpos

    m, _, _, skel, _, _ = judged
    joints, nq = skeleton_qpos(skel)
    assert nq == m.nq
    kinds = {int(mujoco.mjtJoint.mjJNT_FREE): "free", int(mujoco.mjtJoint.mjJNT_BALL): "ball",
             int(mujoco.mjtJoint.mjJNT_SLIDE): "slide", int(mujoco.mjtJoint.mjJNT_HINGE): "hinge"}
    want = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, k): (kinds[int(m.jnt_type[k])], int(m.jnt_qposadr[k]))
            for k in range(m.njnt)}
    for coupled in ("slide1", "twist"):  # no coordinates: their qpos values are not read
        del want[coupled]
    assert {j.joint: (j.kind, j.address) for j in joints} == want


def _qpos_dataset(d: Path, out: Path, npz: str, extra: str = "") -> Path:
    """A data set on the imported toy (its skeleton and muscles) with one qpos motion."""
    (d / "ds.yaml").write_text(f"""dataset: toy_qpos
seed: 3
skeleton: {out / 'skeletons' / 'toy.yaml'}
muscles: {out / 'muscles'}
motions:
  q: {{motion: {npz}{extra}}}
sequences:
  - {{motion: q}}
cameras:
  sphere: {{views: 1, distance: [1.5, 1.6]}}
render: {{size: [32, 32], supersample: 1}}
""")
    return d / "ds.yaml"


def test_a_data_set_reads_a_qpos_motion_as_import_mjcf_does(judged, tmp_path, capsys):
    """`motions: {q: {motion: FILE.npz}}` on a skeleton imported by axdf import mjcf: the same
    coordinates as the import's own pose (to the pose file's 9 digits), every frame, the
    archive's fps or the entry's; the data set's labels carry them."""
    from axdf_cli.dataset.spec import load_dataset, load_motion
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.specs import RefPolicy

    m, qpos, out, skel, q, _ = judged
    npz = out.parent / f"{out.name}_motion.npz"  # the import's motion (fps 25)
    spec = load_dataset(_qpos_dataset(tmp_path, out, str(npz)), policy=RefPolicy(allow_outside=True))
    pose = load_motion(spec, "q")
    assert pose.fps == 25 and (pose.first, pose.last) == (0, len(qpos) - 1)
    np.testing.assert_allclose(sample_coordinates(pose, pose.frames), q, atol=1e-6)
    spec = load_dataset(_qpos_dataset(tmp_path, out, str(npz), ", fps: 50"), policy=RefPolicy(allow_outside=True))
    assert load_motion(spec, "q").fps == 50
    rc = main(["dataset", "build", str(_qpos_dataset(tmp_path, out, str(npz), ", frames: '0:24:12'")), "--out",
               str(tmp_path / "d"), "-q", "--allow-outside"])
    assert rc == 0, capsys.readouterr().err
    labels = np.load(tmp_path / "d" / "seq_00000" / "labels.npz")
    names = list(labels["coord_names"])
    np.testing.assert_allclose(labels["coords"], q[[0, 12, 24]][:, [skel.coord_index[c] for c in names]], atol=1e-6)


@pytest.mark.parametrize("arrays, words", [
    (lambda q: {"qpos": np.where(np.arange(q.shape[1]) == 2, np.nan, q)}, "q.npz: qpos[0, 2] = nan"),
    (lambda q: {"qpos": q[:, :-1]}, "q.npz: qpos has shape (25, 14); (frames, 15): the model's nq"),
    (lambda q: {"qpos": q, "fps": np.array([-1.0])}, "q.npz: fps = "),
    (lambda q: {"jpos": q}, "q.npz: no array qpos (arrays: jpos)"),
    (lambda q: {"qpos": np.where(np.arange(q.shape[1])[None] < 7, 0.0, q)}, "q.npz: qpos[0, 3:7] is a zero quaternion"),
])
def test_a_data_sets_bad_qpos_is_exit_2_naming_the_array_and_index(judged, tmp_path, capsys, arrays, words):
    m, qpos, out, _, _, _ = judged
    np.savez(tmp_path / "q.npz", **arrays(qpos))
    rc = main(["dataset", "build", str(_qpos_dataset(tmp_path, out, "q.npz")), "--out", str(tmp_path / "d"),
               "--allow-outside"])
    err = capsys.readouterr().err
    assert rc == 2 and words in err and "Traceback" not in err, err
    assert not (tmp_path / "d").exists()


def test_a_qpos_motion_needs_a_skeleton_from_import_mjcf(tmp_path, capsys):
    """gait2392's coordinates are no MuJoCo joints in qpos order: refused at the motion."""
    repo = Path(__file__).resolve().parents[1]
    np.savez(tmp_path / "q.npz", qpos=np.zeros((2, 23)))
    (tmp_path / "ds.yaml").write_text(f"""dataset: g
skeleton: {repo / 'poses' / 'skeletons' / 'gait2392.yaml'}
muscles: {repo / 'muscles' / 'gait2392' / 'soleus_r.yaml'}
motions:
  q: {{motion: q.npz}}
sequences:
  - {{motion: q}}
cameras:
  sphere: {{views: 1, distance: [3, 3.5]}}
""")
    rc = main(["dataset", "build", str(tmp_path / "ds.yaml"), "--out", str(tmp_path / "d"), "--allow-outside"])
    err = capsys.readouterr().err
    assert rc == 2 and "ds.yaml:5:" in err and "is not a MuJoCo joint in qpos order" in err, err
    assert not (tmp_path / "d").exists()
