"""``axdf import bvh``: BVH motion capture → skeleton + pose, checked against an independent FK.

The reference here parses the BVH text itself and computes every joint's and end site's
world position straight from the BVH definition (``T(offset + position channels) ·
R(rotation channels in file order)`` down the hierarchy, Y-up), then maps it to axdf's world
(scale, then Y-up → Z-up facing -Y: ``(x, y, z) → (x, -z, y)``). axdf's forward kinematics of
the imported skeleton and pose must agree to 1e-6 of the scale at several frames.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cli_in_folder import run_cli

REPO = Path(__file__).resolve().parents[1]
CMU = REPO.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"
needs_cmu = pytest.mark.skipif(not CMU.is_file(), reason=f"CMU BVH not found at {CMU}")

# ZXY at the root without position channels, YXZ and XZY below, a joint with position
# channels placed after its rotations, end sites, centimetres.
SMALL_BVH = """\
HIERARCHY
ROOT pelvis
{
\tOFFSET 1.5 90.0 -2.0
\tCHANNELS 3 Zrotation Xrotation Yrotation
\tJOINT spine
\t{
\t\tOFFSET 0.0 12.0 1.0
\t\tCHANNELS 3 Yrotation Xrotation Zrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0.0 60.0 3.0
\t\t}
\t}
\tJOINT leg.r
\t{
\t\tOFFSET -9.0 -6.0 0.5
\t\tCHANNELS 6 Xrotation Zrotation Yrotation Xposition Yposition Zposition
\t\tJOINT foot r
\t\t{
\t\t\tOFFSET 1.0 -80.0 2.0
\t\t\tCHANNELS 2 Xrotation Zrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.0 -4.0 15.0
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 4
Frame Time: 0.0416667
"""


def small_bvh(rows: int = 4, seed: int = 7) -> str:
    rng = np.random.default_rng(seed)
    data = rng.uniform(-120, 120, size=(rows, 14))
    data[:, 9:12] = rng.uniform(-5, 5, size=(rows, 3))  # leg.r positions (cm)
    return SMALL_BVH + "".join(" ".join(f"{v:.6f}" for v in r) + "\n" for r in data)


# ----------------------------------------------------------------------------- reference FK


def reference_positions(text: str, scale: float) -> tuple[list[str], np.ndarray]:
    """Joint names (end sites as ``<parent> End Site``) and world positions (F, J, 3) in axdf's world."""
    head, motion = text.split("MOTION")
    toks = re.findall(r"[{}]|[^\s{}]+", head)
    joints = []  # (name, parent, offset, channels)
    stack = []
    i = 0
    while i < len(toks):
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            j = i + 1
            while toks[j] != "{":
                j += 1
            joints.append([" ".join(toks[i + 1:j]), stack[-1] if stack else -1, None, []])
            stack.append(len(joints) - 1)
            i = j + 1
        elif t == "End":
            joints.append([joints[stack[-1]][0] + " End Site", stack[-1], None, []])
            stack.append(len(joints) - 1)
            i += 3
        elif t == "OFFSET":
            joints[stack[-1]][2] = np.array([float(x) for x in toks[i + 1:i + 4]])
            i += 4
        elif t == "CHANNELS":
            n = int(toks[i + 1])
            joints[stack[-1]][3] = toks[i + 2:i + 2 + n]
            i += 2 + n
        elif t == "}":
            stack.pop()
            i += 1
        else:
            i += 1
    rows = [ln.split() for ln in motion.strip().split("\n")[2:]]
    data = np.array(rows, dtype=np.float64)

    def rot(axis: str, deg: np.ndarray) -> np.ndarray:
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        m = np.zeros((len(deg), 3, 3))
        a, b = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
        k = 3 - a - b
        m[:, k, k] = 1
        m[:, a, a] = c
        m[:, b, b] = c
        m[:, a, b] = -s
        m[:, b, a] = s
        return m

    nf = len(data)
    world_r = np.zeros((len(joints), nf, 3, 3))
    world_p = np.zeros((len(joints), nf, 3))
    col = 0
    for k, (name, parent, offset, chans) in enumerate(joints):
        local_t = np.broadcast_to(offset, (nf, 3)).copy()
        local_r = np.broadcast_to(np.eye(3), (nf, 3, 3)).copy()
        for c in chans:
            v = data[:, col]
            col += 1
            if c.endswith("position"):
                local_t[:, "XYZ".index(c[0])] += v
            else:
                local_r = local_r @ rot(c[0], v)
        if parent < 0:
            world_r[k], world_p[k] = local_r, local_t
        else:
            world_r[k] = world_r[parent] @ local_r
            world_p[k] = world_p[parent] + np.einsum("fij,fj->fi", world_r[parent], local_t)
    p = world_p.transpose(1, 0, 2) * scale
    return [j[0] for j in joints], np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)


def imported_positions(tmp_path: Path, out: str, frames) -> tuple[object, np.ndarray]:
    """The imported skeleton and its bones' world origins (F, B, 3) at ``frames``."""
    from axdf_cli.specs import RefPolicy, load_pose
    from axdf_cli.model.pose import sample_coordinates
    from axdf_cli.model.skeleton import forward_kinematics

    (pose_file,) = (tmp_path / out).glob("*.yaml")
    pose = load_pose(pose_file, RefPolicy((tmp_path,)))
    q = sample_coordinates(pose, np.asarray(frames))
    return pose, forward_kinematics(pose.skeleton, q)[:, :, :3, 3]


# ----------------------------------------------------------------------------- tests


def imported_bone_names(path: Path) -> list[str]:
    """The importer's bone names, in the file's joint order (the reference's order too)."""
    from axdf_cli.importers.bvh import bone_names, read_bvh

    return bone_names(read_bvh(path))


def test_small_bvh_other_channel_orders_no_root_translation(tmp_path):
    text = small_bvh()
    (tmp_path / "in.bvh").write_text(text)
    assert run_cli(tmp_path, "import", "bvh", "in.bvh", "--out", "imp", "--scale", "cm", "-q") == 0
    frames = [0, 1, 2, 3]
    pose, world = imported_positions(tmp_path, "imp", frames)
    names, ref = reference_positions(text, 0.01)
    assert names == ["pelvis", "spine", "spine End Site", "leg.r", "foot r", "foot r End Site"]
    bones = imported_bone_names(tmp_path / "in.bvh")
    assert bones == ["pelvis", "spine", "spine_end", "leg.r", "foot_r", "foot_r_end"]
    bi = pose.skeleton.bone_index
    got = world[:, [bi[b] for b in bones]]
    assert np.max(np.abs(got - ref[frames])) < 1e-6 * 0.01
    assert pose.fps == 24.0  # Frame Time 0.0416667 is 1/24 to the digits written
    # the root has no position channels: it stays at its offset (scaled, Z-up)
    assert np.allclose(world[:, bi["pelvis"]], [0.015, 0.02, 0.9], atol=1e-12)


@needs_cmu
def test_cmu_walk_matches_reference_fk(tmp_path):
    text = CMU.read_text()
    assert run_cli(tmp_path, "import", "bvh", str(CMU), "--out", "imp", "-q") == 0
    frames = [0, 1, 250, 500, 994]
    pose, world = imported_positions(tmp_path, "imp", frames)
    names, ref = reference_positions(text, 1.0)
    bones = imported_bone_names(CMU)
    assert [b.removesuffix("_end") for b in bones] == [n.removesuffix(" End Site") for n in names]
    bi = pose.skeleton.bone_index
    got = world[:, [bi[b] for b in bones]]
    assert np.max(np.abs(got - ref[frames])) < 1e-6
    assert pose.fps == 120.0 and pose.last == 994
    assert len(bones) == 38 and sum(b.endswith("_end") for b in bones) == 7
    # Z-up and facing -Y: the head is above the hips, the toes are in front of the ankles (-Y)
    from axdf_cli.model.skeleton import forward_kinematics

    w0 = forward_kinematics(pose.skeleton, pose.skeleton.rest_coordinates()[None])[0, :, :3, 3]
    assert w0[bi["Head"], 2] > w0[bi["Hips"], 2] + 0.3
    assert w0[bi["RightToe"], 1] < w0[bi["RightAnkle"], 1] - 0.05
    assert w0[bi["RightHip"], 0] < 0 < w0[bi["LeftHip"], 0]  # the right side is -X, as in Blender


@needs_cmu
def test_step_keeps_every_nth_row(tmp_path):
    assert run_cli(tmp_path, "import", "bvh", str(CMU), "--out", "imp", "--step", "4", "-q") == 0
    pose, world = imported_positions(tmp_path, "imp", [0, 10, 248])
    names, ref = reference_positions(CMU.read_text(), 1.0)
    bi = pose.skeleton.bone_index
    got = world[:, [bi[b] for b in imported_bone_names(CMU)]]
    assert pose.fps == 30.0 and pose.last == 248
    assert np.max(np.abs(got - ref[[0, 40, 992]])) < 1e-6


def test_unit_guess_from_height():
    from axdf_cli.importers.bvh import BVH, Joint, guess_unit
    from axdf_cli.errors import Mark

    def skel(h):
        js = (Joint("a", -1, (0.0, 0.0, 0.0), (), False, Mark("x")), Joint("a End Site", 0, (0.0, h, 0.0), (), True, Mark("x")))
        return BVH("x", js, 0.01, "0.01", np.zeros((1, 0)), Mark("x"))

    assert guess_unit(skel(170.0))[0] == "cm"
    assert guess_unit(skel(1.75))[0] == "m"
    assert guess_unit(skel(67.0))[0] == "in"
    assert guess_unit(skel(1800.0))[0] == "mm"


def test_guess_is_printed_and_applied(tmp_path, capsys):
    text = small_bvh()
    (tmp_path / "in.bvh").write_text(text)
    assert run_cli(tmp_path, "import", "bvh", "in.bvh", "--out", "imp") == 0
    out = capsys.readouterr().out
    # rest height: end sites from the foot (y = 90 - 6 - 80 - 4 = 0) to the spine's (90 + 12 + 60 = 162)
    assert "height 162 units: looks like centimetres" in out and "using --scale 0.01" in out
    skel_text = (tmp_path / "imp" / "skeletons" / "in.yaml").read_text()
    assert "offset: [0.015, 0.9, -0.02]" in skel_text


# ----------------------------------------------------------------------------- bad input


def _bad(tmp_path, capsys, text: str, *extra: str) -> str:
    (tmp_path / "bad.bvh").write_text(text)
    rc = run_cli(tmp_path, "import", "bvh", "bad.bvh", "--out", "imp", "--scale", "1", *extra)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert not (tmp_path / "imp").exists()  # nothing written
    assert "Traceback" not in err
    return err.strip()


def test_unbalanced_braces(tmp_path, capsys):
    good = small_bvh()
    # a '}' missing: the hierarchy ends (at MOTION) with the root's brace still open
    lines = good.split("\n")
    k = max(i for i, ln in enumerate(lines) if ln == "}")
    err = _bad(tmp_path, capsys, "\n".join(lines[:k] + lines[k + 1:]))
    assert err.startswith(f"bad.bvh:{k + 1}:1: the '{{' of 'pelvis' (line 3) is never closed")
    # one '}' too many
    err = _bad(tmp_path, capsys, good.replace("\t\t\t}\n\t\t}\n\t}\n}", "\t\t\t}\n\t\t}\n\t}\n}\n}"))
    assert err.startswith("bad.bvh:30:1: '}' without a matching '{'; balanced braces"), err


def test_channel_count_mismatch(tmp_path, capsys):
    text = small_bvh().replace("CHANNELS 3 Yrotation Xrotation Zrotation", "CHANNELS 4 Yrotation Xrotation Zrotation")
    err = _bad(tmp_path, capsys, text)
    assert err.startswith("bad.bvh:10:3: CHANNELS 4 (line 9) lists 3 channel names, then 'End'"), err
    text = small_bvh().replace("CHANNELS 3 Yrotation Xrotation Zrotation", "CHANNELS 2 Yrotation Xrotation Zrotation")
    err = _bad(tmp_path, capsys, text)
    assert err.startswith("bad.bvh:9:34: CHANNELS 2 (line 9) is followed by more channel names"), err


def test_motion_row_value_count(tmp_path, capsys):
    lines = small_bvh().split("\n")
    lines[-3] = " ".join(lines[-3].split()[:-1])  # the third row loses a value
    err = _bad(tmp_path, capsys, "\n".join(lines))
    assert re.match(rf"bad\.bvh:{len(lines) - 2}:\d+: motion row has 13 values; 14 values", err), err


def test_non_numeric_motion(tmp_path, capsys):
    lines = small_bvh().split("\n")
    w = lines[-4].split(" ")
    w[5] = "1.2.3"
    lines[-4] = " ".join(w)
    col = len(" ".join(w[:5])) + 2
    err = _bad(tmp_path, capsys, "\n".join(lines))
    assert err.startswith(f"bad.bvh:{len(lines) - 3}:{col}: motion value '1.2.3' is not a number"), err
    lines = small_bvh().split("\n")
    lines[-2] = lines[-2].replace(lines[-2].split()[0], "nan", 1)
    err = _bad(tmp_path, capsys, "\n".join(lines))
    assert err.startswith(f"bad.bvh:{len(lines) - 1}:1: motion value 'nan'"), err


def test_truncated_file(tmp_path, capsys):
    text = small_bvh()
    cut = text[: text.rindex("\n", 0, len(text) - 1) + 1]  # the last row is missing
    err = _bad(tmp_path, capsys, cut)
    assert re.match(r"bad\.bvh:\d+:1: the file ends after 3 of 4 motion rows \('Frames: 4' at line 31; truncated\?\)",
                    err), err
    err = _bad(tmp_path, capsys, text[:200])  # cut inside the hierarchy, in the middle of an OFFSET
    assert err.startswith("bad.bvh:12:17: the hierarchy ends where OFFSET z was expected"), err
    err = _bad(tmp_path, capsys, "\n".join(text.split("\n")[:20]))  # cut after foot's '{'
    assert err.startswith("bad.bvh:20:4: the '{' of 'foot r' (line 20) is never closed"), err


def test_frames_count_that_lies(tmp_path, capsys):
    err = _bad(tmp_path, capsys, small_bvh().replace("Frames: 4", "Frames: 3"))
    assert err.startswith("bad.bvh:36:1: more motion rows than 'Frames: 3' (line 31) says"), err
    err = _bad(tmp_path, capsys, small_bvh().replace("Frames: 4", "Frames: 9"))
    assert "the file ends after 4 of 9 motion rows" in err
    err = _bad(tmp_path, capsys, small_bvh().replace("Frames: 4", "Frames: four"))
    assert err.startswith("bad.bvh:31:9: Frames is 'four'"), err


def test_other_malformed_hierarchies(tmp_path, capsys):
    good = small_bvh()
    cases = [
        (good.replace("OFFSET 0.0 12.0 1.0", "OFFSET 0.0 twelve 1.0"), r"bad\.bvh:8:14: OFFSET y is 'twelve'"),
        (good.replace("\t\tOFFSET 0.0 12.0 1.0\n", ""), r"bad\.bvh:6:2: 'spine' has no OFFSET"),
        (good.replace("Xposition", "Wposition"), r"bad\.bvh:18:\d+: CHANNELS 6 \(line 18\) lists 3 channel names, then 'Wposition'"),
        (good.replace("JOINT spine", "JOINT pelvis"), r"bad\.bvh:6:2: joint 'pelvis' is defined twice \(first at line 2\)"),
        (good.replace("MOTION\n", ""), r"bad\.bvh:30:1: 'Frames:' where MOTION was expected"),
        (good.replace("Frames: 4", "Frames: 4\nMOTION"), r"bad\.bvh:32:1: 'MOTION' where 'Frame Time:' was expected"),
        (good.replace("HIERARCHY", "HIERARCHIE"), r"bad\.bvh:1:1: file starts with 'HIERARCHIE'"),
        (good.replace("Frame Time: 0.0416667", "Frame Time: 0"), r"bad\.bvh:32:13: Frame Time is '0'"),
    ]
    for text, pattern in cases:
        err = _bad(tmp_path, capsys, text)
        assert re.match(pattern, err), (pattern, err)


def test_not_a_file_and_binary(tmp_path, capsys):
    from axdf_cli.cli.main import main

    assert main(["import", "bvh", str(tmp_path / "missing.bvh"), "--out", str(tmp_path / "o")]) == 2
    assert "missing.bvh: file not found; an existing .bvh file" in capsys.readouterr().err
    (tmp_path / "bin.bvh").write_bytes(b"HIERARCHY\n\xff\xfe")
    assert main(["import", "bvh", str(tmp_path / "bin.bvh"), "--out", str(tmp_path / "o")]) == 2
    assert "bin.bvh:2:1: byte 0xff is not UTF-8" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("suffix,command", [(".bvh", "axdf retarget"), (".mot", "axdf import osim"),
                                            (".sto", "axdf import osim")])
def test_pose_flag_names_the_import_command(tmp_path, capsys, suffix, command):
    """A motion given as --pose names the command that makes a pose of it: a BVH take is fitted
    onto the muscles' skeleton by `axdf retarget` (tests/test_first_hour.py follows that hint)."""
    from axdf_cli.cli.main import main

    motion = tmp_path / f"walk{suffix}"
    motion.write_text(small_bvh())
    rc = main(["run", "--muscles", str(REPO / "muscles" / "demo"), "--pose", str(motion),
               "--out", str(tmp_path / "out"), "--allow-outside"])
    err = capsys.readouterr().err
    assert rc == 2 and command in err and str(motion) in err, err
    assert not (tmp_path / "out").exists()


def test_crlf_file_imports_the_same(tmp_path):
    text = small_bvh()
    (tmp_path / "a.bvh").write_text(text)
    (tmp_path / "b.bvh").write_bytes(text.replace("\n", "\r\n").encode())
    for n in ("a", "b"):
        assert run_cli(tmp_path, "import", "bvh", f"{n}.bvh", "--out", n, "--name", "s", "--scale", "cm", "-q") == 0
    for rel in ("skeletons/s.yaml", "s.yaml"):
        a, b = (tmp_path / "a" / rel).read_text(), (tmp_path / "b" / rel).read_text()
        assert a.replace("a.bvh", "b.bvh") == b
