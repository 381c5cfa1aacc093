"""The per-model tables as data (axdf_cli/tools/tables.py, axdf_cli/data/*.yaml): the packaged
files give the tables the code held (a few known entries of each), they ship with the package
(pyproject.toml package-data), and a broken copy is refused at the entry's line and column,
saying what is wrong and what is allowed."""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from axdf_cli.errors import InputError
from axdf_cli.tools import tables as T
from conftest import REPO_ROOT

ATLAS_MAP = Path(__file__).resolve().parent.parent / "atlases" / "gait2392.yaml"
DATA_FILES = (T.RIG_FILE, T.FAMILIES_FILE)  # (the atlas map is an input, as muscles are: atlases/)


def test_the_rig_is_makehumans():
    rig = T.rig()
    assert rig.parts["pelvis"] == ("trunk", ("root", "pelvis.L", "pelvis.R", "spine05"))
    assert rig.parts["toes_r"] == ("foot_r", ("toe1-1.R", "toe2-1.R", "toe3-1.R", "toe4-1.R", "toe5-1.R"))
    assert list(rig.parts)[:6] == ["pelvis", "abdomen", "chest", "neck", "head", "thigh_l"]
    assert rig.segments["trunk"] == (None, "hip_c", "shoulder_c")
    assert rig.segments["hand_l"] == ("forearm_l", "wrist_l", "knuckle3_l")
    assert rig.segments["finger2_3_r"] == ("finger2_2_r", "dip2_r", None)  # the fingertip: carried
    assert list(rig.segments)[-1] == "head" and len(rig.segments) == 14 + 2 + 2 * 15
    # a finger on a skeleton without finger bones moves with the hand; the forearm's distal half
    # takes half the palm's turn
    assert rig.fallback["finger1_1_l"] == "hand_l" and rig.fallback["forearm2_r"] == "forearm_r"
    assert len(rig.fallback) == 2 * 16 and not set(rig.fallback.values()) & set(rig.fallback)
    assert rig.across["hand_l"] == ("knuckle2_l", "knuckle5_l") and rig.turn["forearm2_l"] == 0.5
    assert rig.landmarks["cmc1_l"] == ("finger1-1.L",) and rig.landmarks["dip5_r"] == ("finger5-3.R",)
    assert rig.keep_length == {"foot_l", "foot_r"}
    assert rig.landmarks["toe_l"] == ("toe2-1.L",) and rig.landmarks["neck"] == ("neck01",)
    assert rig.centres == {"hip_c": ("hip_l", "hip_r"), "shoulder_c": ("shoulder_l", "shoulder_r")}
    assert rig.lower_belly == "spine05"


def test_the_families_are_the_joint_map():
    fams = {f.name: f for f in T.families()}
    assert [f.name for f in T.families()] == ["myobody", "Rajagopal2016", "gait2392", "CMU"]
    g = fams["gait2392"]
    assert g.points == {"shoulder_l": ("torso", (0.003155, 0.3715, -0.17)),
                        "shoulder_r": ("torso", (0.003155, 0.3715, 0.17))}
    assert g.landmarks == {"hip_l": "femur_l", "hip_r": "femur_r", "knee_l": "tibia_l", "knee_r": "tibia_r",
                           "ankle_l": "talus_l", "ankle_r": "talus_r", "toe_l": "toes_l", "toe_r": "toes_r"}
    assert g.bind["hand_l"] == "torso" and g.bind["foot_r"] == "calcn_r" and g.back == 0.03 and g.up is None
    assert fams["myobody"].bind["abdomen"] == "lumbar3" and fams["myobody"].landmarks["wrist_r"] == "lunate_r"
    assert fams["myobody"].back == 0.05 and fams["Rajagopal2016"].landmarks["wrist_l"] == "hand_l"
    cmu = fams["CMU"]
    assert cmu.landmarks["hip_l"] == "LeftHip" and cmu.landmarks["wrist_r"] == "RightWrist"
    assert cmu.bind["hand_l"] == "lhand" and cmu.bind["hand_r"] == "rhand" and cmu.back == 0.0
    assert all(set(f.bind) == set(T.rig().parts) for f in fams.values())
    # myobody has finger bones; the others hold the fingers on the hand
    my = fams["myobody"]
    assert my.bind["finger1_1_l"] == "firstmc_l" and my.bind["finger3_2_r"] == "midph3_r"
    assert my.landmarks["knuckle2_l"] == "2proxph_l" and my.landmarks["ip1_r"] == "distal_thumb_r"
    assert fams["Rajagopal2016"].bind["finger4_3_l"] == "hand_l" and g.bind["finger2_1_r"] == "torso"
    assert cmu.bind["finger5_1_r"] == "rhand" and my.bind["forearm2_l"] == my.bind["forearm_l"] == "radius_l"


def test_the_atlas_map_is_gait2392s():
    a = T.load_atlas_map(ATLAS_MAP)
    assert a.files == "{folder}/VHF_{folder}_{kind}_{name}_smooth.ply" and "CC BY 4.0" in a.credit
    assert a.sides == {"r": "Right", "l": "Left"}
    assert a.muscles["semiten"] == ("Semitendinosus", "Semitendonosus") and len(a.muscles) == 29
    assert a.split["glut_max"] == (("GluteusMaximus",), ("glut_max1", "glut_max2", "glut_max3"))
    assert {k: (v.cartilage, v.other, v.bone) for k, v in a.landmarks.items()} == {
        "hip": ("FemurHead", False, "femur"), "hip_other": ("FemurHead", True, "femur"),
        "knee": ("FemurDistal", False, "tibia"), "ankle": ("Talus", False, "talus")}
    assert a.bones[0] == (("Tibia", "Fibula"), "tibia", True, False)
    assert a.bones[2][1:] == ("calcn", False, False) and a.bones[2][0][0] == "Calcaneous"
    assert a.suffixes == {"r": ("_r", "_r"), "l": ("_l", "_l")} and a.close == ()
    assert "ercspn" in a.kept and "Plantaris" in a.unused


def test_the_tables_ship_with_the_package():
    globs = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["axdf_cli"]
    package = REPO_ROOT / "axdf_cli"
    shipped = {p for g in globs for p in package.glob(g)}
    assert set(DATA_FILES) <= shipped, sorted(str(p) for p in set(DATA_FILES) - shipped)


def broken(tmp_path: Path, source: Path, old: str, new: str, token: str) -> tuple[Path, int, int]:
    """A copy of ``source`` with ``old`` (once in it) replaced by ``new``: its path, and the
    line and column of ``token`` (in ``new``) in the copy."""
    text = source.read_text()
    assert text.count(old) == 1, old
    at = text.index(old) + new.index(token)
    copy = text.replace(old, new)
    path = tmp_path / source.name
    path.write_text(copy)
    return path, copy.count("\n", 0, at) + 1, at - (copy.rfind("\n", 0, at) + 1) + 1


def refused(load, path: Path, line: int, col: int) -> InputError:
    with pytest.raises(InputError) as e:
        load(path)
    err = e.value
    assert (err.where.file, err.where.line, err.where.col) == (str(path), line, col), str(err)
    assert str(err).startswith(f"{path}:{line}:{col}: ") and "; " in str(err)
    return err


def families_of(path):
    return T.load_families(path, T.rig())


@pytest.mark.parametrize("old,new,token,says", [
    # an unknown part (a misspelt key made per side): at the key, with the nearest
    ('      thigh_{s}: "{side}Hip"', '      thighs_{s}: "{side}Hip"', "thighs", "unknown part 'thighs_l'"),
    # an unknown landmark
    ("      wrist_{s}: lunate_{s}", "      wirst_{s}: lunate_{s}", "wirst", "did you mean 'wrist_l'?"),
    # a bone of the wrong type
    ("      abdomen: lumbar3", "      abdomen: [lumbar3]", "[", "part abdomen's bone is a list"),
    # a placeholder there is none of
    ('      hand_{s}: "{s}hand"', '      hand_{s}: "{c}hand"', '"', "unknown placeholder"),
    # a number that is a string, and a point of two coordinates
    ("    back: 0.05", "    back: deep", "deep", "back is the string 'deep'"),
    ("at: [0.003155, 0.3715, 0.17]", "at: [0.3715, 0.17]", "[", "at has 2 values"),
    # a key a family has not
    ("  - name: CMU\n", "  - name: CMU\n    spine: 0.1\n", "spine", "unknown key 'spine' in a family"),
])
def test_a_broken_family_is_refused_where_it_is(tmp_path, old, new, token, says):
    err = refused(families_of, *broken(tmp_path, T.FAMILIES_FILE, old, new, token))
    assert says in str(err)


def test_a_family_that_binds_no_bone_for_a_part_is_refused_at_its_bind(tmp_path):
    old = "    bind:\n      pelvis: pelvis\n      abdomen: lumbar3\n      chest: torso\n      neck: neck\n"
    new = "    bind:\n      pelvis: pelvis\n      abdomen: lumbar3\n      chest: torso\n"
    err = refused(families_of, *broken(tmp_path, T.FAMILIES_FILE, old, new, "pelvis"))
    assert "family myobody binds no bone for part neck" in str(err) and "a bone for every part" in str(err)


@pytest.mark.parametrize("old,new,token,says", [
    ("  toe_l: [toe2-1.L]", "  toe_l: toe2-1.L", "toe2", "landmark toe_l's bones is not a list of names"),
    ("  hand_r: {segment: hand_r,", "  hand_r: {segment: hand,", "hand,", "unknown segment 'hand'"),
    ("  head: {parent: trunk, from: neck,", "  head: {parent: trunk, from: nek,", "nek", "unknown landmark 'nek'"),
    ("keep_length: true}\n  upperarm_l", "keep_length: 1}\n  upperarm_l", "1}", "keep_length must be true or false"),
    # a finger bound as a part that is not there
    ("bones: [finger2-1.L], as: hand_l}", "bones: [finger2-1.L], as: hands_l}", "hands_l", "unknown part 'hands_l'"),
    # across: two landmarks, turn: a share, and only with across:
    ("to: pip3_l, across: [knuckle2_l, knuckle5_l]}", "to: pip3_l, across: [knuckle2_l]}", "[knuckle2_l]",
     "across names 1 landmarks"),
    ("to: wrist_r, across: [knuckle2_r, knuckle5_r], turn: 0.5}", "to: wrist_r, across: [knuckle2_r, knuckle5_r], "
     "turn: 2}", "2}", "turn"),
    ("from: ip1_r, to: null, across: [knuckle2_r, knuckle5_r]}", "from: ip1_r, to: null, turn: 0.5}", "0.5",
     "has turn: but no across:"),
])
def test_a_broken_rig_is_refused_where_it_is(tmp_path, old, new, token, says):
    err = refused(T.load_rig, *broken(tmp_path, T.RIG_FILE, old, new, token))
    assert says in str(err)


def test_a_rig_bone_the_body_lacks_is_refused_at_its_entry(tmp_path):
    from axdf_cli.tools import skin as sk

    path, line, col = broken(tmp_path, T.RIG_FILE, "  knee_l: [lowerleg01.L]", "  knee_l: [lowerleg1.L]", "lower")
    with pytest.raises(InputError) as e:
        sk.check_rig(T.load_rig(path), sk.load_body())
    assert e.value.where == (str(path), line, col)
    assert "rig bone 'lowerleg1.L' is not in the body; did you mean 'lowerleg01.L'?" in str(e.value)


@pytest.mark.parametrize("old,new,token,says", [
    ("bone: calcn, both: false}", "bone: calcn, both: 0}", "0}", "both must be true or false"),
    ("  knee: {cartilage: FemurDistal, leg: same,", "  knee: {cartilage: FemurDistal, leg: left,", "left",
     "leg is one of same, other"),
    ("  tfl: [TensorFasciaeLatae]", "  tfl: TensorFasciaeLatae", "Tensor", "muscle tfl's atlas names is not a list"),
    ("sides: {r: Right, l: Left}", "sides: {r: Right, x: Left}", "x:", "unknown side 'x'"),
    ("kept: [", "keep: [", "keep", "unknown key 'keep' in the atlas map"),
    ('files: "{folder}/VHF_', 'files: "../{folder}/VHF_', "\"../", "is not an atlas file pattern"),
    ('files: "{folder}/VHF_', 'files: "{side}/VHF_', "\"{side}", "is not an atlas file pattern"),
    ("kept: [", "articulated: 1\nkept: [", "1\n", "articulated must be true or false"),
])
def test_a_broken_atlas_map_is_refused_where_it_is(tmp_path, old, new, token, says):
    err = refused(T.load_atlas_map, *broken(tmp_path, ATLAS_MAP, old, new, token))
    assert says in str(err)


MYOARM_MAP = ATLAS_MAP.parent / "myoarm.yaml"


@pytest.mark.parametrize("old,new,token,says", [
    ("  RHMIN: {atlas:", "  RHMIN: {atlass:", "atlass", "unknown key 'atlass' in added muscle RHMIN"),
    ("bones: [neck, scapula]}", "bones: neck}", "neck}", "added muscle LEVSCAP's bones is not a list"),
    ("  RHMAJ: {atlas:", "  DELT1: {atlas:", "DELT1: {", "added muscle DELT1 is named twice"),
])
def test_a_broken_added_muscle_is_refused_where_it_is(tmp_path, old, new, token, says):
    err = refused(T.load_atlas_map, *broken(tmp_path, MYOARM_MAP, old, new, token))
    assert says in str(err)


def test_atlas_map_of_bodyparts3d_resolves_every_file():
    """atlases/myoarm.yaml: side words in names, a globbed pattern, centroid landmarks and
    suffixes per side; every landmark's and warped bone's file and every muscle resolves to one
    file of the BodyParts3D folder (when the shared data is here)."""
    from pathlib import Path

    from axdf_cli.tools.atlas import Atlas
    from axdf_cli.tools.tables import load_atlas_map

    m = load_atlas_map(Path(__file__).resolve().parent.parent / "atlases" / "myoarm.yaml")
    assert m.muscle_name("DELT1", "r") == "DELT1" and m.bone_name("humerus", "r") == "humerus_r"
    assert m.muscle_name("DELT1", "l") == "DELT1_l" and m.on_side("DELT1", "r") and not m.on_side("DELT1_l", "r")
    assert m.landmarks["humerus"].centroid == ("{Side}_humerus",) and m.landmarks["humerus"].cartilage is None
    assert m.articulated and not load_atlas_map(Path(__file__).resolve().parent.parent / "atlases" /
                                                "gait2392.yaml").articulated
    root = Path(__file__).resolve().parents[2] / "shared" / "data" / "atlas" / "bodyparts3d_upper"
    if not root.is_dir():
        import pytest
        pytest.skip("no BodyParts3D atlas in ../shared/data")
    atlas = Atlas(root, m)
    atlas.check(["r", "l"])
    # the shoulder girdle's muscles myoarm lacks: shape muscles on their bones
    assert m.added["TRAP2"] == (("Transverse_part_of_{side}_trapezius",), ("torso", "scapula"))
    assert set(m.added) == {"TRAP1", "TRAP2", "TRAP3", "RHMAJ", "RHMIN", "LEVSCAP"}
    assert m.added_bones("TRAP1", "l", {"head", "neck", "clavicle_l"}) == ["head", "neck", "clavicle_l"]
    assert m.added_bones("TRAP1", "l", {"head", "neck", "clavicle_r"}) is None
    for src in list(m.muscles.values()) + [a for a, _ in m.split.values()] + [a for a, _ in m.added.values()]:
        for side in ("r", "l"):
            assert atlas.path(side, "Muscle", src[0]).is_file(), (side, src)
    assert atlas.path("l", "Muscle", "Clavicular_part_of_{side}_deltoid").name == "FMA34681_Clavicular_part_of_left_deltoid.ply"


def test_rajagopal_legs_map_names_myobodys_leg_muscles():
    """atlases/rajagopal_legs.yaml: the Visible Human's legs under Rajagopal's names, every one a
    muscle of myobody on both sides, carried articulated."""
    from pathlib import Path

    from axdf_cli.tools.tables import load_atlas_map

    repo = Path(__file__).resolve().parent.parent
    m = load_atlas_map(repo / "atlases" / "rajagopal_legs.yaml")
    assert m.articulated
    names = list(m.muscles) + [q for _, parts in m.split.values() for q in parts] + list(m.kept)
    for side in ("r", "l"):
        for n in names:
            assert (repo / "muscles" / "myobody" / f"{m.muscle_name(n, side)}.yaml").is_file(), (n, side)
