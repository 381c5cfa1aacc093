"""BVH length units from the body's height (``axdf import bvh``, ``axdf retarget``).

- An unscaled CMU take (the shared walk with its OFFSETs and root positions divided by the
  CMU conversions' 0.056444 m unit) imports as a 1.4-2.1 m person in CMU units, joint for joint
  where the scaled take puts them; the scaled take stays in metres. The unit and the stature
  are printed.
- ``--units`` overrides the choice (as ``--scale`` does); both at once is a usage error.
- A skeleton no unit makes a person is scaled to a typical height, with a warning on stderr.
- The unit rules themselves: a 170-unit span is centimetres, a 24-unit one CMU's.
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
#: metres per length unit of the CMU database's BVH conversions (1/0.45 inch), as written in
#: the shared file's name: it was scaled by this
CMU_UNIT = 0.056444


def unscaled_cmu(path: Path) -> Path:
    """The shared CMU walk with its lengths back in CMU units: every OFFSET and the root's
    three position channels (the first three values of each motion row) divided by CMU_UNIT."""
    out, motion = [], False
    for line in CMU.read_text().splitlines():
        words = line.split()
        if words and words[0] == "OFFSET":
            indent = line[:len(line) - len(line.lstrip())]
            line = indent + "OFFSET " + " ".join(f"{float(v) / CMU_UNIT:.6f}" for v in words[1:])
        elif words and words[0] == "Frame" and words[1] == "Time:":
            motion = True
        elif motion and words:
            line = " ".join([f"{float(v) / CMU_UNIT:.6f}" for v in words[:3]] + words[3:])
        out.append(line)
    path.write_text("\n".join(out) + "\n")
    return path


def imported_rest(folder: Path, name: str) -> np.ndarray:
    """(B, 3) rest positions (metres, axdf's world) of the skeleton an import wrote."""
    from axdf_cli.model.skeleton import forward_kinematics
    from axdf_cli.specs import load_skeleton

    skel = load_skeleton(folder / "skeletons" / f"{name}.yaml")
    return forward_kinematics(skel, skel.rest_coordinates()[None])[0, :, :3, 3]


def stature_printed(out: str) -> float:
    m = re.search(r"a ([0-9.]+) m person", out)
    assert m, out
    return float(m.group(1))


@needs_cmu
def test_an_unscaled_cmu_take_imports_as_a_person(tmp_path, capsys):
    unscaled_cmu(tmp_path / "walk.bvh")
    assert run_cli(tmp_path, "import", "bvh", "walk.bvh", "--out", "raw", "--step", "100") == 0
    out = capsys.readouterr().out
    assert "CMU units" in out, out
    assert 1.4 <= stature_printed(out) <= 2.1
    assert run_cli(tmp_path, "import", "bvh", str(CMU), "--out", "scaled", "--step", "100", "--name", "walk") == 0
    out = capsys.readouterr().out
    assert "looks like metres" in out and "using --scale 1 " in out, out
    assert 1.4 <= stature_printed(out) <= 2.1
    raw, scaled = imported_rest(tmp_path / "raw", "walk"), imported_rest(tmp_path / "scaled", "walk")
    # the same person: 0.0254 / 0.45 against the file's 0.056444 (and its 6 printed decimals)
    assert np.abs(raw - scaled).max() < 1e-4
    height = np.ptp(raw[:, 2])
    assert 1.2 < height < 2.1  # joints and end sites at rest, metres


@needs_cmu
def test_retarget_reads_an_unscaled_cmu_take_in_cmu_units(tmp_path):
    from axdf_cli.importers.mocap import read_bvh_joints

    raw = read_bvh_joints(unscaled_cmu(tmp_path / "walk.bvh"), step=50)
    scaled = read_bvh_joints(CMU, step=50)
    assert np.abs(raw.positions - scaled.positions).max() < 1e-4
    assert any("CMU units" in n for n in raw.notes) and not raw.warnings


@needs_cmu
def test_units_override_the_height(tmp_path, capsys):
    unscaled_cmu(tmp_path / "walk.bvh")
    assert run_cli(tmp_path, "import", "bvh", "walk.bvh", "--out", "in", "--step", "100", "--units", "in") == 0
    out = capsys.readouterr().out
    assert "BVH unit: inches (given)" in out and stature_printed(out) < 1.0, out
    assert np.ptp(imported_rest(tmp_path / "in", "walk")[:, 2]) < 0.7  # what inches make of it
    assert run_cli(tmp_path, "import", "bvh", "walk.bvh", "--out", "both", "--units", "in", "--scale", "1") == 2
    assert "not allowed with" in capsys.readouterr().err
    assert not (tmp_path / "both").exists()


SMALL = """\
HIERARCHY
ROOT hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
\tJOINT leg
\t{
\t\tOFFSET 0 -HALF 0
\t\tCHANNELS 3 Zrotation Yrotation Xrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -HALF 0
\t\t}
\t}
}
MOTION
Frames: 1
Frame Time: 0.0333333
0 0 0 0 0 0 0 0 0
"""


def test_no_unit_makes_a_person_so_a_typical_one_is_made(tmp_path, capsys):
    """A 5-unit span is no unit's person (5.8 m, 0.33 m in CMU units, ...): scaled to 1.7 m."""
    from axdf_cli import tolerances as tol

    (tmp_path / "odd.bvh").write_text(SMALL.replace("HALF", "2.5"))
    assert run_cli(tmp_path, "import", "bvh", "odd.bvh", "--out", "imp") == 0
    cap = capsys.readouterr()
    assert "axdf: warning: no length unit makes this BVH a 1.4-2.1 m person" in cap.err, cap.err
    assert "--units" in cap.err
    assert stature_printed(cap.out) == tol.TYPICAL_STATURE
    span = np.ptp(imported_rest(tmp_path / "imp", "odd")[:, 2])
    assert abs(span - tol.TYPICAL_STATURE * tol.STATURE_SPAN_RATIO) < 1e-6


@pytest.mark.parametrize("span, unit", [(170.0, "cm"), (1.75, "m"), (67.0, "in"), (1650.0, "mm"), (24.3, "cmu"),
                                        (1.3, "m"), (5.0, None), (0.62, None)])
def test_the_unit_whose_person_is_in_the_band(span, unit):
    from axdf_cli.importers.bvh import BVH, Joint, choose_unit, guess_unit
    from axdf_cli.errors import Mark

    js = (Joint("a", -1, (0.0, 0.0, 0.0), (), False, Mark("x")), Joint("a End Site", 0, (0.0, span, 0.0), (), True,
                                                                         Mark("x")))
    bvh = BVH("x", js, 0.01, "0.01", np.zeros((1, 0)), Mark("x"))
    assert guess_unit(bvh) == (unit, span)
    choice = choose_unit(bvh)
    assert 1.4 <= choice.stature <= 2.1
    assert choice.how == ("height" if unit else "typical")
    given = choose_unit(bvh, 0.0254)
    assert (given.unit, given.how, given.scale) == ("in", "given", 0.0254)
