"""A hostile round on the importers (``import mjcf``, ``import osim``, the motion
readers): each test is a small hand-written model or file that once gave exit 70, a hang, a
huge allocation, an output ``axdf validate`` refuses, or a refusal of what MuJoCo loads.

Bad input: exit 2, ``FILE:LINE:COL`` (or ``FILE``) naming the value and what is allowed, and
nothing written. Models are written here (no shipped data needed); the CLI runs in process.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from conftest import main_or_hang, run_main

# ----------------------------------------------------------------------------- fixtures

MJCF = """<mujoco>
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="j" type="hinge" axis="0 1 0" range="-30 30"/>
      <site name="s1" pos="0 0 0.1"/><site name="s2" pos="0.1 0 0"/><site name="s3" pos="0.1 0 0"/>
      {geom}
      <body name="b" pos="0 0 -0.3">
        <joint name="k" axis="0 1 0" range="-30 30"/><site name="s4" pos="0 0 -0.1"/>
      </body>
    </body>
  </worldbody>
  {asset}
  <tendon><spatial name="t">{sites}</spatial></tendon>
  <actuator><muscle name="m" tendon="t" {muscle}/></actuator>
</mujoco>
"""


def mjcf(sites='<site site="s1"/><site site="s4"/>', muscle="", geom="", asset="") -> str:
    return MJCF.format(sites=sites, muscle=muscle, geom=geom, asset=asset)


OSIM = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
<Model name="tiny">
<Ground name="ground"/>
<BodySet name="bodyset"><objects>
<Body name="upper"><attached_geometry>{geom}</attached_geometry><mass>1</mass></Body>
<Body name="lower"><mass>1</mass></Body>
</objects></BodySet>
<JointSet name="jointset"><objects>
<WeldJoint name="base">
<socket_parent_frame>ground_offset</socket_parent_frame><socket_child_frame>upper_offset</socket_child_frame>
<frames>
<PhysicalOffsetFrame name="ground_offset"><socket_parent>/ground</socket_parent><translation>0 1 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
<PhysicalOffsetFrame name="upper_offset"><socket_parent>/bodyset/upper</socket_parent><translation>0 0 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
</frames>
</WeldJoint>
<PinJoint name="knee">
<socket_parent_frame>upper_knee</socket_parent_frame><socket_child_frame>lower_knee</socket_child_frame>
<coordinates><Coordinate name="knee_angle"><default_value>0</default_value><range>-2 0</range></Coordinate></coordinates>
<frames>
<PhysicalOffsetFrame name="upper_knee"><socket_parent>/bodyset/upper</socket_parent><translation>0 -0.4 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
<PhysicalOffsetFrame name="lower_knee"><socket_parent>/bodyset/lower</socket_parent><translation>0 0 0</translation><orientation>0 0 0</orientation></PhysicalOffsetFrame>
</frames>
</PinJoint>
</objects></JointSet>
<ForceSet name="forceset"><objects>{forces}</objects></ForceSet>
</Model>
</OpenSimDocument>
"""
OSIM_MUSCLE = """<Thelen2003Muscle name="{name}"><GeometryPath name="geometrypath"><PathPointSet><objects>
<PathPoint name="p1"><socket_parent_frame>/bodyset/upper</socket_parent_frame><location>{p1}</location></PathPoint>
<PathPoint name="p2"><socket_parent_frame>/bodyset/{b2}</socket_parent_frame><location>{p2}</location></PathPoint>
</objects></PathPointSet></GeometryPath>
<max_isometric_force>500</max_isometric_force><optimal_fiber_length>0.1</optimal_fiber_length>
<tendon_slack_length>0.2</tendon_slack_length></Thelen2003Muscle>"""
OSIM_FUNCTION_PATH = """<Thelen2003Muscle name="fb"><FunctionBasedPath name="path"/>
<max_isometric_force>500</max_isometric_force><optimal_fiber_length>0.1</optimal_fiber_length>
<tendon_slack_length>0.2</tendon_slack_length></Thelen2003Muscle>"""
OSIM_MESH = """<Mesh name="upper_geom"><scale_factors>{scale}</scale_factors><mesh_file>bone.vtp</mesh_file></Mesh>"""
VTP = """<?xml version="1.0"?>
<VTKFile type="PolyData" version="0.1">
<PolyData><Piece NumberOfPoints="3" NumberOfPolys="1">
<Points><DataArray type="Float32" NumberOfComponents="3" format="ascii">{points}</DataArray></Points>
<Polys><DataArray type="Int32" Name="connectivity" format="ascii">0 1 2</DataArray>
<DataArray type="Int32" Name="offsets" format="ascii">3</DataArray></Polys>
</Piece></PolyData></VTKFile>
"""
GOOD_POINTS = "0 0 0 0.1 0 0 0 0.1 0"


def osim_muscle(name="m", p1="0 -0.1 0.02", b2="lower", p2="0 -0.1 0.02") -> str:
    return OSIM_MUSCLE.format(name=name, p1=p1, b2=b2, p2=p2)


def osim(forces: str | None = None, geom: str = "") -> str:
    return OSIM.format(forces=osim_muscle() if forces is None else forces, geom=geom)


def write(folder: Path, files: dict) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (folder / name).write_bytes(data if isinstance(data, bytes) else data.encode())
    return folder


def imported(tmp_path, capsys, kind: str, files: dict, *extra) -> tuple[int, str, Path]:
    """``axdf import KIND`` of the first file of ``files`` (written in tmp/in): (exit, stderr, out)."""
    d = write(tmp_path / "in", files)
    out = tmp_path / "out"
    rc, _, err = run_main(["import", kind, d / next(iter(files)), "--out", out, "-q", *extra], capsys)
    assert "Traceback" not in err and "internal error" not in err, err
    return rc, err, out


def refused(tmp_path, capsys, kind: str, files: dict, *extra) -> str:
    rc, err, out = imported(tmp_path, capsys, kind, files, *extra)
    assert rc == 2, err
    assert not out.exists(), "nothing is written on bad input"
    return err


def validates(capsys, out: Path) -> None:
    """Every file the import wrote passes ``axdf validate``."""
    files = sorted(str(p) for p in out.rglob("*") if p.suffix == ".yaml")  # a skeleton checks its meshes
    rc, o, err = run_main(["validate", *files], capsys)
    assert rc == 0, o + err


def position(err: str, name: str) -> tuple[int, int]:
    m = re.search(re.escape(name) + r":(\d+):(\d+): ", err)
    assert m, err
    return int(m[1]), int(m[2])


def line_of(text: str, needle: str) -> int:
    return text[:text.index(needle)].count("\n") + 1


# ----------------------------------------------------------------------------- exit 70 on small models


@pytest.mark.parametrize("sites", ['<site site="s1"/><site site="s1"/>', '<site site="s2"/><site site="s3"/>'],
                         ids=["one-site-twice", "coincident-sites"])
def test_a_zero_length_tendon_is_skipped_with_a_warning_not_exit_70(tmp_path, capsys, sites):
    """A tendon through one site twice, or through two sites at one place: ZeroDivisionError
    (exit 70). The muscle cannot hold a belly: it is listed as not imported, with a warning at
    its actuator, and the rest imports."""
    text = mjcf(sites=sites)
    rc, err, out = imported(tmp_path, capsys, "mjcf", {"m.xml": text})
    assert rc == 0, err
    assert position(err, "m.xml") == (line_of(text, "<muscle"), 13) and "muscle 'm' skipped" in err, err
    assert not (out / "muscles").exists()
    validates(capsys, out)


def test_coincident_osim_path_points_are_skipped_with_a_warning(tmp_path, capsys):
    text = osim(osim_muscle(b2="upper"))
    rc, err, out = imported(tmp_path, capsys, "osim", {"m.osim": text})
    assert rc == 0, err
    assert position(err, "m.osim")[0] == line_of(text, "<Thelen2003Muscle") and "muscle 'm' skipped" in err, err
    validates(capsys, out)


def test_a_negative_muscle_scale_with_the_default_force_is_refused_at_the_actuator(tmp_path, capsys):
    """`<muscle scale="-200">` (force -1, MuJoCo's default): a math domain error (exit 70)."""
    text = mjcf(muscle='scale="-200"')
    err = refused(tmp_path, capsys, "mjcf", {"m.xml": text})
    assert position(err, "m.xml") == (line_of(text, "<muscle"), 13), err
    assert "scale -200" in err and "a positive force" in err, err


@pytest.mark.parametrize("forces", ["", OSIM_FUNCTION_PATH], ids=["empty-forceset", "function-based-path"])
def test_an_osim_model_with_no_path_muscle_imports_its_skeleton_with_a_warning(tmp_path, capsys, forces):
    """A user importing a skeleton-only model wants the skeleton: it is written, and the warning
    says that no muscle was."""
    rc, err, out = imported(tmp_path, capsys, "osim", {"m.osim": osim(forces)})
    assert rc == 0, err
    assert "no muscle with a path to import: only the skeleton is written" in err, err
    validates(capsys, out)


def _chain(n: int, poly: str) -> str:
    bodies = "".join(f'<body name="b{i}" pos="0 0 -0.1"><joint name="j{i}" axis="0 1 0" range="-30 30"/>'
                     for i in range(n + 1)) + "</body>" * (n + 1)
    eq = "\n".join(f'  <joint joint1="j{i + 1}" joint2="j{i}" polycoef="{poly}"/>' for i in range(n))
    return f"<mujoco>\n<worldbody>{bodies}</worldbody>\n<equality>\n{eq}\n</equality>\n</mujoco>\n"


@pytest.mark.parametrize("n, poly, words", [
    (10, "0 1 1 1 1", "coefficient of"),  # overflowed to NaN (exit 70)
    (12, "0 0.5 0 0 0.1", "degree 256"),  # the degree grows as 4^n: hung
])
def test_a_long_chain_of_couplings_is_refused_at_the_coupling_and_never_hangs(tmp_path, capsys, n, poly, words):
    from axdf_cli import tolerances as tol

    text = _chain(n, poly)
    d = write(tmp_path / "in", {"m.xml": text})
    rc = main_or_hang(["import", "mjcf", d / "m.xml", "--out", tmp_path / "out", "-q"], timeout=120)
    err = capsys.readouterr().err
    assert rc == 2 and not (tmp_path / "out").exists(), err
    line, _ = position(err, "m.xml")
    assert text.splitlines()[line - 1].lstrip().startswith("<joint joint1="), err
    assert words in err and (f"at most {tol.COUPLING_MAX_DEGREE}" in err or "within" in err), err


def test_a_long_chain_of_linear_couplings_still_imports(tmp_path, capsys):
    """The bound is on the composed degree: 20 linear links compose to a line."""
    rc, err, out = imported(tmp_path, capsys, "mjcf", {"m.xml": _chain(20, "0.01 0.9 0 0 0")})
    assert rc == 0, err
    validates(capsys, out)


# ----------------------------------------------------------------------------- bone meshes of NaN or inf

OBJ = "v 0 0 0\nv {x} 0 0\nv 0 0.1 0\nf 1 2 3\n"


@pytest.mark.parametrize("mesh_attrs, x, words", [
    ('refquat="0 0 0 0"', "0.1", "refquat is zero"),
    ("", "1e300", "vertex 1 has x = 1e+300"),  # inf once written as float32
], ids=["zero-refquat", "obj-vertex-1e300"])
def test_mjcf_bone_meshes_that_validate_refuses_are_refused_at_the_mesh(tmp_path, capsys, mesh_attrs, x, words):
    """Exit 0 after writing a PLY of NaN (refquat 0 0 0 0) or inf (a vertex of 1e300)."""
    text = mjcf(geom='<geom type="mesh" mesh="bone"/>',
                asset=f'<asset><mesh name="bone" file="bone.obj" {mesh_attrs}/></asset>')
    err = refused(tmp_path, capsys, "mjcf", {"m.xml": text, "bone.obj": OBJ.format(x=x)})
    assert position(err, "m.xml") == (line_of(text, "<mesh "), 10), err
    assert words in err and "'bone'" in err, err


def test_an_osim_vtp_point_of_nan_is_refused_at_the_vtp_line(tmp_path, capsys):
    vtp = VTP.format(points="0 0 0 0.1 0 0 nan 0.1 0")
    err = refused(tmp_path, capsys, "osim", {"m.osim": osim(geom=OSIM_MESH.format(scale="1 1 1")), "bone.vtp": vtp})
    assert position(err, "bone.vtp")[0] == line_of(vtp, "<DataArray"), err
    assert "point 2 of Points has x = nan" in err and "finite" in err, err


def test_osim_scale_factors_of_1e300_are_refused_at_the_mesh(tmp_path, capsys):
    text = osim(geom=OSIM_MESH.format(scale="1e300 1 1"))
    err = refused(tmp_path, capsys, "osim", {"m.osim": text, "bone.vtp": VTP.format(points=GOOD_POINTS)})
    assert position(err, "m.osim")[0] == line_of(text, "<Mesh "), err
    assert "<scale_factors> 1e+300 1 1" in err and "within ±1e+09 m" in err, err


def test_bone_meshes_scaled_to_a_point_are_refused_at_the_mesh(tmp_path, capsys):
    """An OSIM <scale_factors> of 0 and an MJCF mesh scale of 1e-300 (0 in float32) wrote bone
    meshes collapsed to one point, with exit 0 (found by a fresh hostile round)."""
    text = osim(geom=OSIM_MESH.format(scale="0 0 0"))
    err = refused(tmp_path / "osim", capsys, "osim", {"m.osim": text, "bone.vtp": VTP.format(points=GOOD_POINTS)})
    assert position(err, "m.osim")[0] == line_of(text, "<Mesh "), err
    assert "0 m across once placed" in err and "at least 1e-06 m across" in err, err
    text = mjcf(geom='<geom type="mesh" mesh="bone"/>',
                asset='<asset><mesh name="bone" file="bone.obj" scale="1e-300 1e-300 1e-300"/></asset>')
    err = refused(tmp_path / "mjcf", capsys, "mjcf", {"m.xml": text, "bone.obj": OBJ.format(x="0.1")})
    assert position(err, "m.xml") == (line_of(text, "<mesh "), 10) and "0 m across once placed" in err, err


def test_a_muscle_mujoco_refuses_for_its_lmin_and_lmax_is_refused(tmp_path, capsys):
    """MuJoCo requires lmin < 1 < lmax of a muscle ("lmin<1<lmax required in muscle")."""
    text = mjcf(muscle='lmin="2" lmax="1"')
    err = refused(tmp_path, capsys, "mjcf", {"m.xml": text})
    assert position(err, "m.xml") == (line_of(text, "<muscle"), 13), err
    assert "lmin 2 lmax 1" in err and "lmin < 1 < lmax" in err, err


def test_good_bone_meshes_still_import_and_validate(tmp_path, capsys):
    rc, err, out = imported(tmp_path, capsys, "osim", {"m.osim": osim(geom=OSIM_MESH.format(scale="2 2 2")),
                                                       "bone.vtp": VTP.format(points=GOOD_POINTS)})
    assert rc == 0, err
    validates(capsys, out)


# ----------------------------------------------------------------------------- npz motions that claim too much


def _npz_claiming(member: str, dtype: np.dtype, shape: tuple, payload: bytes = b"") -> bytes:
    """An .npz whose member's header claims ``shape`` of ``dtype`` and holds ``payload`` (deflated):
    what a small file may claim, read by nothing that trusts it."""
    import io
    import zipfile

    head = io.BytesIO()
    np.lib.format.write_array_header_2_0(head, {"descr": np.lib.format.dtype_to_descr(np.dtype(dtype)),
                                                "fortran_order": False, "shape": shape})
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr(f"{member}.npy", head.getvalue() + payload)
    return buf.getvalue()


def test_a_qpos_npz_is_refused_by_its_header_before_its_data_is_read(tmp_path, capsys):
    """A 3.1 MB npz whose qpos expanded to 3.3 GB was read whole before its shape was checked.
    Here the header claims 10^9 frames with no data behind it: refused by shape, from the header."""
    rng = np.random.default_rng(37)
    payload = rng.bytes(64)
    d = write(tmp_path / "in", {"m.xml": mjcf(), "q.npz": _npz_claiming("qpos", np.float64, (10 ** 9, 2), payload)})
    rc, _, err = run_main(["import", "mjcf", d / "m.xml", "--motion", d / "q.npz", "--out", tmp_path / "out", "-q"],
                          capsys)
    assert rc == 2 and "q.npz: qpos has 1000000000 frames" in err, err
    assert not (tmp_path / "out").exists()


def test_a_joints_npz_with_huge_name_strings_is_refused_from_its_header(tmp_path, capsys):
    """`names` of dtype <U1000000 took 4.1 GB and exited 0."""
    from axdf_cli.errors import InputError
    from axdf_cli.importers.mocap import read_npz_joints

    import io
    import zipfile

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for key, arr in (("joints", np.zeros((2, 1000, 3))), ):
            b = io.BytesIO()
            np.lib.format.write_array(b, arr)
            z.writestr(f"{key}.npy", b.getvalue())
    # names: 1000 strings claimed 1,000,000 characters wide (4 GB once read), almost no bytes stored
    head = _npz_claiming("names", np.dtype("<U1000000"), (1000,))
    with zipfile.ZipFile(io.BytesIO(head)) as src, zipfile.ZipFile(buf, "a", zipfile.ZIP_DEFLATED) as z:
        z.writestr("names.npy", src.read("names.npy"))
    p = tmp_path / "j.npz"
    p.write_bytes(buf.getvalue())
    with pytest.raises(InputError) as e:
        read_npz_joints(p)
    assert "j.npz: names" in str(e.value) and "<U1000000" in str(e.value) and "200 characters" in str(e.value)


# ----------------------------------------------------------------------------- include diamonds


def test_an_include_diamond_parses_each_file_once(tmp_path, capsys, monkeypatch):
    """5 levels of files each including the next 10 times took 51 s: every path to a file
    parsed it afresh (111,111 parses). Each file is parsed once; cycles are still refused at
    the include that closes them."""
    from axdf_cli.importers import mjcf as reader

    files = {"m.xml": '<mujoco>\n  <include file="l1.xml"/>\n  <worldbody><body name="a"><joint name="j"/>'
                      "</body></worldbody>\n</mujoco>\n"}
    for k in range(1, 5):
        files[f"l{k}.xml"] = "<mujocoinclude>\n" + f'  <include file="l{k + 1}.xml"/>\n' * 10 + "</mujocoinclude>\n"
    files["l5.xml"] = "<mujocoinclude>\n  <compiler angle=\"degree\"/>\n</mujocoinclude>\n"
    parsed = []
    real = reader.parse_xml
    monkeypatch.setattr(reader, "parse_xml", lambda path: parsed.append(Path(path).name) or real(path))
    rc, err, out = imported(tmp_path, capsys, "mjcf", files)
    assert rc == 0, err
    assert sorted(parsed) == sorted(files), parsed[:20]
    validates(capsys, out)


def test_a_cycle_below_a_diamond_is_still_refused_where_it_closes(tmp_path, capsys):
    files = {"m.xml": '<mujoco>\n  <include file="a.xml"/>\n  <include file="b.xml"/>\n</mujoco>\n',
             "a.xml": '<mujocoinclude>\n  <include file="c.xml"/>\n</mujocoinclude>\n',
             "b.xml": '<mujocoinclude>\n  <include file="c.xml"/>\n</mujocoinclude>\n',
             "c.xml": '<mujocoinclude>\n\n  <include file="a.xml"/>\n</mujocoinclude>\n'}
    err = refused(tmp_path, capsys, "mjcf", files)
    assert "c.xml:3:3: 'a.xml' includes itself" in err, err


# ----------------------------------------------------------------------------- what MuJoCo loads


#: MyoSuite's leg/myolegs.xml in its repository (MyoHub/myo_sim) includes the torso's and the
#: legs' asset files, each with a top-level <default> holding nested classes: MuJoCo reads
#: every top-level <default> as class main (xml_native_reader.cc, mjXReader::Default).
MYOLEGS = {
    "leg/myolegs.xml": """<mujoco model="legs">
  <include file="../torso/assets/torso_assets.xml"/>
  <include file="../leg/assets/legs_assets.xml"/>
  <compiler angle="radian"/>
  <worldbody>
    <body name="pelvis" pos="0 0 1" childclass="torso">
      <site name="s0" pos="0 0 0"/>
      <body name="femur" pos="0 0 -0.1" childclass="legs">
        <joint name="hip"/><geom type="sphere" size="0.05"/>
        <site name="s1" pos="0 0 -0.3"/>
      </body>
    </body>
  </worldbody>
  <tendon><spatial name="t"><site site="s0"/><site site="s1"/></spatial></tendon>
  <actuator><general name="m" tendon="t" class="leg_muscle" lengthrange="0.2 0.4"/></actuator>
</mujoco>
""",
    "torso/assets/torso_assets.xml": """<mujocoinclude>
  <default>
    <default class="torso"><geom rgba="1 1 1 1"/></default>
  </default>
</mujocoinclude>
""",
    "leg/assets/legs_assets.xml": """<mujocoinclude>
  <default>
    <joint axis="1 0 0"/>
    <default class="legs">
      <joint limited="true" range="-1 1"/>
      <default class="leg_muscle">
        <general gaintype="muscle" biastype="muscle" dyntype="muscle" gainprm="0.75 1.05 300 200 0.5 1.6 1.5 1.3 1.2 0"
                 biasprm="0.75 1.05 300 200 0.5 1.6 1.5 1.3 1.2 0"/>
      </default>
    </default>
  </default>
</mujocoinclude>
""",
}


def test_top_level_defaults_in_several_included_files_are_all_class_main(tmp_path, capsys):
    """"default class 'main' defined twice" refused MyoSuite's leg/myolegs.xml, which MuJoCo loads."""
    import yaml

    d = tmp_path / "in"
    for name, text in MYOLEGS.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(text)
    out = tmp_path / "out"
    rc, _, err = run_main(["import", "mjcf", d / "leg/myolegs.xml", "--out", out, "-q", "--name", "legs"], capsys)
    assert rc == 0, err
    skel = yaml.safe_load((out / "skeletons" / "legs.yaml").read_text())
    hip = next(b for b in skel["bones"] if b["name"] == "femur")["dofs"][0]
    assert hip["axis"] == [1.0, 0.0, 0.0], hip  # main's joint axis, from the second file's <default>
    assert skel["coordinates"]["hip"]["range"] == pytest.approx([-57.29577951, 57.29577951]), skel["coordinates"]
    assert (out / "muscles" / "m.yaml").is_file()
    validates(capsys, out)
    try:
        import mujoco
    except ImportError:
        return
    mujoco.MjModel.from_xml_path(str(d / "leg/myolegs.xml"))  # MuJoCo loads the same files


def test_a_nested_default_class_defined_twice_is_still_refused(tmp_path, capsys):
    files = dict(MYOLEGS)
    files["torso/assets/torso_assets.xml"] = files["torso/assets/torso_assets.xml"].replace('class="torso"',
                                                                                            'class="legs"')
    d = tmp_path / "in"
    for name, text in files.items():
        (d / name).parent.mkdir(parents=True, exist_ok=True)
        (d / name).write_text(text)
    rc, _, err = run_main(["import", "mjcf", d / "leg/myolegs.xml", "--out", tmp_path / "out", "-q"], capsys)
    assert rc == 2 and "legs_assets.xml:4:5: default class 'legs' defined twice" in err, err


# ----------------------------------------------------------------------------- positions and sizes


def test_a_muscle_that_cannot_be_sized_is_refused_at_its_actuator_not_at_generated_text(tmp_path, capsys):
    """A force of 1e-300 N: the error named '<m>:8:23' (the generated muscle text) or was exit 70."""
    text = mjcf(muscle='force="1e-300"')
    err = refused(tmp_path, capsys, "mjcf", {"m.xml": text})
    assert position(err, "m.xml") == (line_of(text, "<muscle"), 13) and "muscle 'm'" in err, err
    assert "<m>" not in err, err


def test_an_absurdly_large_imported_muscle_is_warned_at_its_position(tmp_path, capsys):
    """A site 700 km away gave a 711 km belly without a word."""
    from axdf_cli import tolerances as tol

    text = mjcf(muscle='force="1e8" lengthrange="1 400000"').replace('name="s4" pos="0 0 -0.1"',
                                                                     'name="s4" pos="0 0 -700000"')
    rc, err, out = imported(tmp_path, capsys, "mjcf", {"m.xml": text})
    assert rc == 0, err
    assert position(err, "m.xml") == (line_of(text, "<muscle"), 13), err
    assert "beyond any human or animal muscle" in err and f"paths up to {tol.IMPORT_PLAUSIBLE_PATH:g} m" in err, err


def test_an_ordinary_muscle_is_not_warned_about_its_size(tmp_path, capsys):
    rc, err, out = imported(tmp_path, capsys, "mjcf", {"m.xml": mjcf(muscle='force="500" lengthrange="0.2 0.4"')})
    assert rc == 0 and "beyond any" not in err, err
