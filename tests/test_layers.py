"""Adding a layer of the body is one stage and its part kind (axdf_cli/parts.py,
axdf_cli/pipeline/stage.py): the test stage :class:`stage_doubles.OffsetShell` declares one
part of kind fat, the first muscle's surface moved out along its normals, and makes it every
frame. Registered in the stage table and nowhere else, it comes out of every sink as a part:
its PLY meshes, its npz sequence, a mesh in the USD stage, its colour and id in the render, the
manifest's parts, and a data set's index and images."""
from __future__ import annotations

import json

import numpy as np
import pytest

import stage_doubles
from conftest import run_main
from test_safety import project  # noqa: F401  (the demo library in a tmp folder, as the current folder)
from test_stages import use_stages

RUN = ["run", "poses/jobs/demo.yaml", "-q", "--frames", "0:2", "--no-jiggle", "--format", "ply,npz,usd", "--render"]


@pytest.fixture
def shell_run(project, capsys, monkeypatch):
    """The demo job, rendered, with and without the shell stage."""
    use_stages(monkeypatch, [], block=None)
    rc, _, err = run_main(RUN + ["--out", "plain"], capsys)
    assert rc == 0, err
    use_stages(monkeypatch, ["shell"], block=None)
    rc, _, err = run_main(RUN + ["--out", "shell"], capsys)
    assert rc == 0, err
    return project


def test_the_layer_is_a_part_in_the_meshes_and_the_manifest(shell_run):
    import trimesh

    out = shell_run / "shell"
    m = json.loads((out / "manifest.json").read_text())
    first = m["muscles"][0]["name"]
    assert m["parts"] == [{"name": "shell", "kind": "fat", "color": [0.9, 0.8, 0.45],
                           "vertices": m["muscles"][0]["vertices"], "faces": m["muscles"][0]["faces"]}]
    assert {"name": "shell", "scope": "frame", "offset": stage_doubles.SHELL_OFFSET} in m["settings"]["stages"]
    for f in (0, 1, 2):
        shell = trimesh.load(out / f"meshes/shell/shell_{f:04d}.ply", process=False)
        muscle = trimesh.load(out / f"meshes/{first}/{first}_{f:04d}.ply", process=False)
        assert np.array_equal(shell.faces, muscle.faces)
        gap = np.linalg.norm(shell.vertices - muscle.vertices, axis=1)
        np.testing.assert_allclose(gap, stage_doubles.SHELL_OFFSET, atol=2e-6)
        assert f"meshes/shell/shell_{f:04d}.ply" in m["files"]
    # the muscles themselves are the same bytes as without the layer
    assert (out / f"meshes/{first}/{first}_0001.ply").read_bytes() == \
        (shell_run / "plain" / f"meshes/{first}/{first}_0001.ply").read_bytes()


def test_the_layer_has_a_sequence_and_a_mesh_in_the_usd_stage(shell_run):
    from pxr import Usd, UsdGeom

    out = shell_run / "shell"
    with np.load(out / "npz/shell.npz") as z:
        assert z["points"].shape[:2] == (3, json.loads((out / "manifest.json").read_text())["parts"][0]["vertices"])
        ply = np.asarray(__import__("trimesh").load(out / "meshes/shell/shell_0002.ply", process=False).vertices)
        np.testing.assert_allclose(z["points"][2], ply, atol=1e-6)
    stage = Usd.Stage.Open(str(out / "scene.usda"))
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh) and p.GetName() == "shell"]
    assert len(meshes) == 1
    pts = np.asarray(UsdGeom.Mesh(meshes[0]).GetPointsAttr().Get(1.0))
    assert len(pts) == json.loads((out / "manifest.json").read_text())["parts"][0]["vertices"]


def test_the_layer_is_drawn_with_its_id_and_colour(shell_run):
    from render_helpers import read_exr

    out = shell_run / "shell"
    cam = json.loads((out / "camera.json").read_text())
    ids = {int(k): v for k, v in cam["ids"].items()}
    shell_id = next(k for k, v in ids.items() if v == {"kind": "fat", "name": "shell"})
    exr = read_exr(out / "frames/0001.exr")
    assert (exr["id"].astype(int) == shell_id).sum() > 100
    plain = read_exr(shell_run / "plain/frames/0001.exr")
    assert not np.array_equal(exr["R"], plain["R"])


def test_axdf_render_draws_the_layer_from_the_run_folder(shell_run, capsys):
    rc, _, err = run_main(["render", "shell", "--out", "again", "-q"], capsys)
    assert rc == 0, err
    assert (shell_run / "again/frames/0001.png").read_bytes() == (shell_run / "shell/frames/0001.png").read_bytes()


def test_a_data_set_lists_the_layer_in_its_index(tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    from dataset_helpers import build_in, write_tiny

    write_tiny(tmp_path)
    use_stages(monkeypatch, ["shell"], block=None)
    out = build_in(tmp_path, "ds")
    index = pq.read_table(out / "index.parquet").to_pandas()
    assert index["parts"].notna().all()
    for _, row in index.iterrows():
        assert row["parts"] == f"{row['sequence']}/meshes/shell/shell_{row['frame']:04d}.ply"
        assert (out / row["parts"]).is_file()
    ids = json.loads((out / "dataset.json").read_text())["ids"]
    assert {"kind": "fat", "name": "shell"} in ids.values()


def test_a_muscle_named_as_a_part_is_refused(project, capsys, monkeypatch):
    """A stage's part and a muscle share the meshes' folder by name: the run is refused before it
    writes, naming the muscle's file."""
    first = sorted((project / "muscles/demo").glob("*.yaml"))[0]
    text = first.read_text()
    name = next(line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("muscle:"))
    first.write_text(text.replace(f"muscle: {name}", "muscle: shell", 1))
    use_stages(monkeypatch, ["shell"], block=None)
    rc, _, err = run_main(RUN + ["--out", "clash"], capsys)
    assert rc == 2 and "a muscle is named 'shell'" in err and first.name in err, err
    assert not (project / "clash").exists()
