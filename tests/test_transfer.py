"""``axdf transfer``: muscles moved onto another skeleton through a bone map.

Invariants: an identity map reproduces the muscles; a skeleton scaled by 1.3 scales every
axis point, rest length and radius by 1.3 (volume by 1.3³); a T-pose skeleton (the arm
rotated at the shoulder) keeps the arm muscles' bone-local points (the map's segments align
the rest poses; a leaf bone gets its rotation from ``rotate``). The shipped CMU library is
what ``make import`` produces, and its job runs. Bad maps: exit 2 at FILE:LINE:COL.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from cli_in_folder import run_cli

REPO = Path(__file__).resolve().parents[1]
HUMAN = REPO / "poses" / "skeletons" / "human_r.yaml"
DEMO = REPO / "muscles" / "demo"
CMU_SKEL = REPO / "poses" / "skeletons" / "cmu_131_01.yaml"
CMU_MAP = REPO / "poses" / "maps" / "human_r_to_cmu.yaml"
CMU_BVH = REPO.parent / "shared" / "data" / "bvh" / "cmu_131_01_walk_scaled.bvh"

HUMAN_BONES = ["pelvis", "femur_r", "tibia_r", "foot_r", "thorax", "scapula_r", "humerus_r", "ulna_r", "radius_r"]


def write_map(path: Path, entries: dict, name: str = "m") -> Path:
    path.write_text(yaml.safe_dump({"transfer": name, "bones": entries}, sort_keys=False))
    return path


def scaled_skeleton(path: Path, factor: float, humerus_orient=None) -> Path:
    """human_r with every offset times ``factor`` (no meshes); optionally the humerus re-oriented."""
    doc = yaml.safe_load(HUMAN.read_text())
    doc["skeleton"] = "human_r_b"
    for b in doc["bones"]:
        b.pop("mesh", None)
        if "offset" in b:
            b["offset"] = [v * factor for v in b["offset"]]
        if humerus_orient is not None and b["name"] == "humerus_r":
            b["orient"] = humerus_orient
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def transfer(tmp_path: Path, to: Path, map_path: Path, out: str = "out", *extra: str) -> tuple[int, Path]:
    rc = run_cli(tmp_path, "transfer", str(DEMO), "--from", str(HUMAN), "--to", str(to), "--map", str(map_path),
                 "--out", out, "-q", "--allow-outside", *extra)
    return rc, tmp_path / out


def load_specs(folder: Path) -> dict:
    from axdf_cli.specs import load_muscle_file

    return {s.name: s for f in sorted(folder.glob("*.yaml")) for s in load_muscle_file(f)}


def flat_sizes(spec) -> np.ndarray:
    return np.concatenate([np.ravel(s.radii if s.radii is not None else s.outline) for s in spec.sections])


def test_identity_map_reproduces_the_muscles(tmp_path):
    m = write_map(tmp_path / "id.yaml", {b: b for b in HUMAN_BONES})
    rc, out = transfer(tmp_path, HUMAN, m)
    assert rc == 0
    src, got = load_specs(DEMO), load_specs(out)
    assert sorted(src) == sorted(got) and len(src) == 7
    for name, a in src.items():
        b = got[name]
        assert [p.bone for p in a.axis] == [p.bone for p in b.axis]
        assert np.max(np.abs(np.array([p.at for p in a.axis]) - np.array([p.at for p in b.axis]))) < 1e-9
        assert np.max(np.abs(flat_sizes(a) - flat_sizes(b))) < 1e-9
        assert (a.color, a.tendons, a.resolution, a.volume, a.group, a.twist, a.strength, a.tension) == \
               (b.color, b.tendons, b.resolution, b.volume, b.group, b.twist, b.strength, b.tension)
        assert [s.t for s in a.sections] == [s.t for s in b.sections]
        assert [s.angle for s in a.sections] == [s.angle for s in b.sections]
    report = json.loads((out / "transfer_report.json").read_text())
    assert report["skipped"] == [] and all(abs(r["length_ratio"] - 1) < 1e-9 for r in report["muscles"])


def test_scaled_skeleton_scales_points_lengths_and_radii(tmp_path):
    b = scaled_skeleton(tmp_path / "big.yaml", 1.3)
    m = write_map(tmp_path / "id.yaml", {x: x for x in HUMAN_BONES})
    rc, out = transfer(tmp_path, b, m)
    assert rc == 0
    src, got = load_specs(DEMO), load_specs(out)
    for name, a in src.items():
        pa = np.array([p.at for p in a.axis])
        pb = np.array([p.at for p in got[name].axis])
        assert np.max(np.abs(pb - 1.3 * pa)) < 1e-9
        assert np.max(np.abs(flat_sizes(got[name]) - 1.3 * flat_sizes(a))) < 1e-9
    report = json.loads((out / "transfer_report.json").read_text())
    assert len(report["muscles"]) == 7
    for r in report["muscles"]:
        assert abs(r["length_ratio"] - 1.3) < 1e-9, r
        assert abs(r["radius_scale"] - 1.3) < 1e-12
        assert abs(r["rest_volume_to"] / r["rest_volume_from"] - 1.3 ** 3) < 1e-6, r


def test_t_pose_rest_rotation_keeps_bone_local_points(tmp_path):
    """B's arm is abducted 90° at rest (a T-pose): the humerus' and ulna's segments turn with it;
    the radius is a leaf bone, so the map's ``rotate`` gives its rest rotation."""
    from axdf_cli.importers.emit import rest_world
    from axdf_cli.specs import load_skeleton

    b = scaled_skeleton(tmp_path / "tpose.yaml", 1.0, humerus_orient=[0, 90, 0])
    entries = {x: x for x in HUMAN_BONES}
    entries["radius_r"] = {"to": "radius_r", "rotate": [0, 90, 0]}
    rc, out = transfer(tmp_path, b, write_map(tmp_path / "t.yaml", entries))
    assert rc == 0
    sb = load_skeleton(b)
    wb = rest_world(sb)
    elbow = wb[sb.bone_index["ulna_r"], :3, 3]
    shoulder = wb[sb.bone_index["humerus_r"], :3, 3]
    assert abs(elbow[0] - (shoulder[0] - 0.30)) < 1e-12 and abs(elbow[2] - shoulder[2]) < 1e-12  # arm along -X
    src, got = load_specs(DEMO), load_specs(out)
    for name in ("biceps_brachii", "brachioradialis", "deltoid_anterior", "deltoid_middle", "deltoid_posterior"):
        pa = np.array([p.at for p in src[name].axis])
        pb = np.array([p.at for p in got[name].axis])
        assert np.max(np.abs(pb - pa)) < 1e-9, name
    # without `rotate`, the radius (no segment) keeps its world orientation: its points move
    rc, out2 = transfer(tmp_path, b, write_map(tmp_path / "t2.yaml", {x: x for x in HUMAN_BONES}), "out2")
    assert rc == 0
    moved = load_specs(out2)["biceps_brachii"].axis[-1].at
    assert np.linalg.norm(np.subtract(moved, src["biceps_brachii"].axis[-1].at)) > 0.01


def test_bones_without_counterpart_are_skipped_and_reported(tmp_path, capsys):
    entries = {x: x for x in HUMAN_BONES if x != "foot_r"}
    rc, out = transfer(tmp_path, HUMAN, write_map(tmp_path / "nofoot.yaml", entries))
    assert rc == 0
    err = capsys.readouterr().err
    assert "gastrocnemius.yaml: muscle gastrocnemius_medial skipped: bones without a counterpart in the map: foot_r" \
           in err
    assert not (out / "gastrocnemius.yaml").exists()
    report = json.loads((out / "transfer_report.json").read_text())
    assert {s["muscle"] for s in report["skipped"]} == {"gastrocnemius_medial", "gastrocnemius_lateral"}
    assert len(report["muscles"]) == 5
    assert "gastrocnemius_lateral (gastrocnemius.yaml): foot_r" in (out / "TRANSFER.md").read_text()


@pytest.mark.parametrize("text,where,what", [
    ("transfer: m\nbones:\n  femur_r: RightHip\n  femurr: RightKnee\n", "4:3", "unknown bone 'femurr' of skeleton human_r"),
    ("transfer: m\nbones:\n  femur_r: RightHipp\n", "3:12", "unknown bone 'RightHipp' of skeleton cmu_131_01"),
    ("transfer: m\nbones:\n  femur_r: {to: RightHip, to_segment: [RightHip, Knee]}\n", "3:50",
     "unknown bone 'Knee' in to_segment"),
    ("transfer: m\nbones:\n  femur_r: {to: RightHip, segment: [femur_r, [0, 1]]}\n", "3:46",
     "segment point has 2 values"),
    ("transfer: m\nbones:\n  femur_r: {to: RightHip, scale: -1}\n", "3:34", "scale is -1"),
    ("transfer: m\nbones:\n  femur_r: {to: RightHip, rotation: [0, 0, 0]}\n", "3:27", "unknown key 'rotation'"),
    ("transfer: m\nbone:\n  femur_r: RightHip\n", "2:1",  # a misspelt key: unknown, not missing
     "unknown key 'bone' in transfer map; did you mean 'bones'?"),
    ("transfer: m\nbones: {femur_r: RightHip}\nbone: {}\n", "3:1", "unknown key 'bone' in transfer map"),
])
def test_bad_map_exit_2_at_its_position(tmp_path, capsys, text, where, what):
    (tmp_path / "bad.yaml").write_text(text)
    rc = run_cli(tmp_path, "transfer", str(DEMO), "--from", str(HUMAN), "--to", str(CMU_SKEL), "--map", "bad.yaml",
                 "--out", "out", "--allow-outside")
    err = capsys.readouterr().err
    assert rc == 2, err
    assert err.startswith(f"bad.yaml:{where}: {what}"), err
    assert not (tmp_path / "out").exists()


def test_skeletons_named_by_the_map(tmp_path, capsys):
    """``from:``/``to:`` in the map stand in for --from/--to; with neither, exit 2 naming both ways."""
    b = scaled_skeleton(tmp_path / "big.yaml", 1.3)
    m = tmp_path / "named.yaml"
    m.write_text(f"transfer: named\nfrom: {os.path.relpath(HUMAN, tmp_path)}\nto: big.yaml\n"
                 "bones: {femur_r: femur_r, tibia_r: tibia_r, foot_r: foot_r}\n")
    rc = run_cli(tmp_path, "transfer", str(DEMO / "gastrocnemius.yaml"), "--map", "named.yaml", "--out", "o", "-q",
                 "--allow-outside")
    assert rc == 0
    pa = np.array([p.at for p in load_specs(DEMO)["gastrocnemius_medial"].axis])
    pb = np.array([p.at for p in load_specs(tmp_path / "o")["gastrocnemius_medial"].axis])
    assert np.max(np.abs(pb - 1.3 * pa)) < 1e-9
    write_map(tmp_path / "bare.yaml", {"femur_r": "femur_r"})
    rc = run_cli(tmp_path, "transfer", str(DEMO), "--map", "bare.yaml", "--out", "o2", "--allow-outside")
    assert rc == 2
    assert capsys.readouterr().err.startswith("bare.yaml:1:1: transfer map names no 'from' skeleton; give --from")
    assert not (tmp_path / "o2").exists()


# ----------------------------------------------------------------------------- the shipped CMU library


needs_cmu = pytest.mark.skipif(not CMU_BVH.is_file(), reason=f"CMU BVH not found at {CMU_BVH}")


def _numbers(doc):
    """Every number of a YAML document, in order, and the document with numbers blanked."""
    nums = []

    def walk(x):
        if isinstance(x, bool) or x is None or isinstance(x, str):
            return x
        if isinstance(x, (int, float)):
            nums.append(float(x))
            return 0
        if isinstance(x, dict):
            return {k: walk(v) for k, v in x.items()}
        return [walk(v) for v in x]

    return walk(doc), np.array(nums)


def assert_same_yaml(a: Path, b: Path, atol: float):
    sa, na = _numbers(yaml.safe_load(a.read_text()))
    sb, nb = _numbers(yaml.safe_load(b.read_text()))
    assert sa == sb, (a, b)
    assert len(na) == len(nb) and (len(na) == 0 or np.max(np.abs(na - nb)) <= atol), (a, b)


@needs_cmu
def test_shipped_cmu_library_is_what_make_import_writes(tmp_path):
    assert run_cli(tmp_path, "import", "bvh", str(CMU_BVH), "--out", "imp", "--name", "cmu_131_01",
                   "--pose-name", "cmu_131_01_walk", "--step", "4", "-q") == 0
    assert_same_yaml(tmp_path / "imp" / "skeletons" / "cmu_131_01.yaml", CMU_SKEL, 1e-12)
    assert_same_yaml(tmp_path / "imp" / "cmu_131_01_walk.yaml", REPO / "poses" / "cmu_131_01_walk.yaml", 1e-12)
    rc = run_cli(tmp_path, "transfer", str(DEMO), "--from", str(HUMAN), "--to", str(CMU_SKEL), "--map", str(CMU_MAP),
                 "--out", "cmu", "-q", "--allow-outside")
    assert rc == 0
    shipped = sorted(p.name for p in (REPO / "muscles" / "cmu").iterdir())
    assert shipped == sorted(p.name for p in (tmp_path / "cmu").iterdir())
    for name in shipped:
        if name.endswith(".yaml"):
            # positions are written to 0.1 µm: a value on a rounding boundary may flip by one step
            assert_same_yaml(tmp_path / "cmu" / name, REPO / "muscles" / "cmu" / name, 1.5e-7)
    report = json.loads((tmp_path / "cmu" / "transfer_report.json").read_text())
    assert report["skipped"] == []


def test_cmu_job_runs(tmp_path):
    """The shipped job on a few frames of the walk: finite, closed meshes; plausible lengths."""
    import csv

    from axdf_cli.formats import read_mesh

    rc = run_cli(REPO, "run", "poses/jobs/cmu_walk.yaml", "--out", str(tmp_path / "run"), "--frames", "0:248:62",
                 "--no-render", "-q", "--allow-outside")
    assert rc == 0
    rows = list(csv.DictReader((tmp_path / "run" / "stats.csv").open()))
    assert len(rows) == 7 * 5 and all(r["warning"] == "" for r in rows)
    src = load_specs(DEMO)
    from axdf_cli.importers.emit import rest_world
    from axdf_cli.specs import load_skeleton
    from axdf_cli.model.muscle import MuscleModel

    skel = load_skeleton(HUMAN)
    w = rest_world(skel)
    for r in rows:
        l_src = MuscleModel(src[r["muscle"]], skel.bone_index, w).l0
        assert 0.5 < float(r["length"]) / l_src < 1.2, r  # the CMU body is smaller; the walk bends joints
        assert abs(float(r["volume_ratio"]) - 1) < 5e-3
    for f in sorted((tmp_path / "run" / "meshes").rglob("*.ply")):
        v = read_mesh(f.read_bytes(), ".ply").vertices
        assert np.all(np.isfinite(v)) and np.ptp(v, axis=0).max() < 1.0
