"""Read an axdf run folder into Blender (``bpy``) and write what Blender evaluates.

Run with the side environment's interpreter (``.venv-blender/bin/python``: bpy needs numpy<2,
axdf numpy 2), by ``tests/test_blender.py``::

    python tests/blender_check.py RUN_DIR OUT.npz FRAME [FRAME ...]

What it does, as a user would in Blender:

- ``scene.usda`` through Blender's USD importer (``bpy.ops.wm.usd_import``): every muscle
  becomes a mesh object with a Mesh Sequence Cache modifier;
- each point cache (``pc2/<m>.pc2``, ``mdd/<m>.mdd``): its rest mesh ``<fmt>/<m>.ply``
  imported (``bpy.ops.wm.ply_import``) and a Mesh Cache modifier added. MDD in time mode
  "seconds": Blender finds the sample by the file's times. PC2 in time mode "frame" with
  Frame Start = startFrame / sampleRate and Frame Scale = 1 / sampleRate from the file's
  header (sample = scale·frame − start); Blender's "seconds" mode for PC2 divides the time
  by the fps twice (``meshcache_read_pc2_range_from_time``), so it is not usable;

then for each FRAME: ``scene.frame_set(FRAME)``, the depsgraph evaluated, and every object's
evaluated mesh (``evaluated_get(depsgraph).to_mesh()``) in world coordinates saved as
``<fmt>/<muscle>/<frame>`` (V, 3) float32 in OUT.npz (the bones from the stage as
``usd_bone/<bone>/<frame>``), with ``scene_fps`` (what the USD import left) and the frame
range Blender took from the stage.
"""
from __future__ import annotations

import json
import struct
import sys
from pathlib import Path

import bpy
import numpy as np


def world_vertices(obj, depsgraph) -> np.ndarray:
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, np.float64)
    me.vertices.foreach_get("co", co)
    ev.to_mesh_clear()
    M = np.array(ev.matrix_world, np.float64)
    # p_world[v] = M[:3, :3] @ p[v] + M[:3, 3]
    return (co.reshape(-1, 3) @ M[:3, :3].T + M[:3, 3]).astype(np.float32)


def import_usd(run: Path) -> dict:
    before = set(bpy.data.objects)
    res = bpy.ops.wm.usd_import(filepath=str(run / "scene.usda"))
    if res != {"FINISHED"}:
        raise SystemExit(f"usd_import: {res}")
    muscles, bones = {}, {}
    for o in set(bpy.data.objects) - before:
        parent = o.parent.name if o.parent else ""
        if o.type == "MESH" and parent == "muscles":  # /axdf/muscles/<m>
            muscles[o.name] = o
        elif o.type == "MESH" and o.name.endswith("_mesh"):  # /axdf/bones/<b>/<b>_mesh (Blender merges the Xform)
            bones[o.name[:-len("_mesh")]] = o
    return muscles, bones


def import_cache(run: Path, fmt: str, muscle: str):
    before = set(bpy.data.objects)
    res = bpy.ops.wm.ply_import(filepath=str(run / fmt / f"{muscle}.ply"))
    if res != {"FINISHED"}:
        raise SystemExit(f"ply_import: {res}")
    (obj,) = set(bpy.data.objects) - before
    mod = obj.modifiers.new("axdf cache", "MESH_CACHE")
    mod.cache_format = fmt.upper()
    mod.filepath = str(run / fmt / f"{muscle}.{fmt}")
    mod.play_mode = "SCENE"
    if fmt == "mdd":
        mod.time_mode = "TIME"  # seconds: the sample whose time is frame / fps
    else:
        mod.time_mode = "FRAME"  # sample k = frame_scale * frame - frame_start
        _, _, _, start, rate, _ = struct.unpack("<12siiffi", (run / fmt / f"{muscle}.{fmt}").read_bytes()[:32])
        mod.frame_start = start / rate
        mod.frame_scale = 1.0 / rate
    return obj


def main(argv) -> int:
    run, out, frames = Path(argv[0]), Path(argv[1]), [int(f) for f in argv[2:]]
    manifest = json.loads((run / "manifest.json").read_text())
    fps = manifest["settings"]["fps"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    objects = {}
    fmts = manifest["settings"]["format"].split(",")
    if "usd" in fmts:
        objects["usd"], objects["usd_bone"] = import_usd(run)
    scene_fps = scene.render.fps / scene.render.fps_base  # what the USD import left (or the default)
    scene.render.fps = round(fps)  # as a user sets the scene to the animation's rate
    scene.render.fps_base = round(fps) / fps
    for fmt in ("pc2", "mdd"):
        if fmt in fmts:
            objects[fmt] = {m["name"]: import_cache(run, fmt, m["name"]) for m in manifest["muscles"]}
    result = {"scene_fps": np.float64(scene_fps), "pose_fps": np.float64(fps),
              "frame_range": np.array([scene.frame_start, scene.frame_end])}
    for f in frames:
        scene.frame_set(f)
        dg = bpy.context.evaluated_depsgraph_get()
        for fmt, objs in objects.items():
            for name, obj in objs.items():
                result[f"{fmt}/{name}/{f}"] = world_vertices(obj, dg)
    np.savez(out, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]))
