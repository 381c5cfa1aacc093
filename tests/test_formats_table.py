"""Every entry of the format table (axdf_cli.formats.FORMATS) says what its format is, and the
tests ask the table, not a list of names: a new format is one entry, and these round trips
cover it. Each format is written by its writer and read back by its reader (points exactly;
normals and faces where the entry says it holds them); a run writes every format at once,
each file where its entry's folder says, and reading the run back (``axdf render``'s reader)
gives the PLY's points from each."""
from __future__ import annotations

import json

import numpy as np
import pytest

from axdf_cli.formats import FORMATS, of_layout, read_preference, read_sequence
from axdf_cli.formats.packed import SequenceInfo

from conftest import run_main
from test_safety import project  # noqa: F401  (the demo library in a tmp folder, as the current folder)

FPS = 24.0
FRAMES = np.arange(10, 31, 4)  # evenly spaced: every format holds them


def _mesh(rng, nf: int):
    """A small closed mesh (an octahedron) moved over ``nf`` frames: faces (8, 3), positions
    and unit normals (nf, 6, 3) float32."""
    v = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
    faces = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]],
                     np.int32)
    pos = (v[None] * rng.uniform(0.5, 2.0, (nf, 1, 3)) + rng.normal(0, 1, (nf, 1, 3))).astype(np.float32)
    nrm = v[None].repeat(nf, 0).astype(np.float32)
    return faces, pos, nrm


@pytest.mark.parametrize("name", list(FORMATS))
def test_each_format_round_trips_what_its_entry_says_it_holds(name, tmp_path):
    f = FORMATS[name]
    if f.check is not None:
        try:
            f.check()
        except Exception as e:  # (usd-core is a test dependency; say so when it is missing)
            pytest.skip(f"{name}: {e}")
    faces, pos, nrm = _mesh(np.random.default_rng(7), len(FRAMES))
    # exact float32, or within half a unit of the last decimal written (and float32's rounding of that)
    atol = 0.0 if f.decimals is None else 0.5 * 10.0 ** -f.decimals + 1e-6
    if f.layout == "frame":
        w = f.writer(faces, "m")
        for k in range(len(FRAMES)):
            mesh = f.reader(w.encode(pos[k], nrm[k]))
            np.testing.assert_allclose(np.asarray(mesh.vertices, np.float32), pos[k], rtol=0, atol=atol)
            np.testing.assert_array_equal(mesh.triangles(), faces)
            assert (mesh.normals is not None) == f.normals
            if f.normals:
                np.testing.assert_allclose(mesh.normals, nrm[k], rtol=0, atol=atol)
        return
    path = tmp_path / f"m{f.suffix}"
    w = f.writer(path, SequenceInfo(FRAMES, FPS, "m"), faces, pos.shape[1])
    w.append(pos[:2], nrm[:2])
    w.append(pos[2:], nrm[2:])
    w.finish()
    seq = read_sequence(path, FPS)
    np.testing.assert_allclose(np.asarray(seq.points), pos, rtol=0, atol=atol)
    np.testing.assert_allclose(np.asarray(seq.frames, np.float64), FRAMES, atol=1e-6)
    assert (seq.normals is not None) == f.normals
    if f.normals:
        np.testing.assert_allclose(np.asarray(seq.normals), nrm, rtol=0, atol=atol)
    assert (seq.faces is not None) == f.faces
    if f.faces:
        np.testing.assert_array_equal(seq.faces, faces)


def test_a_run_writes_every_format_where_its_entry_says(project, capsys):
    """Every --format of the table in one run; each per-sequence file in its entry's folder (a
    rest mesh beside a format without faces), read back as ``axdf render`` reads a run."""
    from axdf_cli.render.runio import muscle_frames

    for f in FORMATS.values():
        if f.check is not None:
            try:
                f.check()
            except Exception as e:
                pytest.skip(f"{f.name}: {e}")
    rc, _, err = run_main(["run", "poses/jobs/demo.yaml", "--no-render", "-q", "--out", "out",
                           "--frames", "20:30:5", "--format", ",".join(FORMATS)], capsys)
    assert rc == 0, err
    out = project / "out"
    names = [m["name"] for m in json.loads((out / "manifest.json").read_text())["muscles"]]
    frames = (20, 25, 30)
    for fmt in of_layout("sequence"):
        f = FORMATS[fmt]
        for m in names:
            assert (out / f.folder / f"{m}{f.suffix}").is_file()
            assert (out / f.folder / f"{m}.ply").is_file() == (not f.faces)
    for fmt in list(of_layout("frame")) + read_preference(FORMATS):
        atol = 0.0 if FORMATS[fmt].decimals is None else 0.5 * 10.0 ** -FORMATS[fmt].decimals + 1e-6
        for m in names[:2]:
            src = muscle_frames(out, m, (fmt,), frames, FPS)
            ref = muscle_frames(out, m, ("ply",), frames, FPS)
            for fr in frames:
                np.testing.assert_allclose(src.read(fr)[0], ref.read(fr)[0], rtol=0, atol=atol,
                                           err_msg=f"{fmt} {m} {fr}")
                np.testing.assert_array_equal(src.read(fr)[2], ref.read(fr)[2], err_msg=f"{fmt} {m} {fr}")
