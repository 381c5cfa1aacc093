"""One worker's share of a data set: the per-process context, and one sequence made whole.

The context (dataset spec, skeleton, muscle models, bone meshes, scene topology) is built once
per process: the models depend only on the skeleton's rest pose, so every sequence reuses
them. A sequence is a run of ``axdf run``'s own code (:mod:`axdf_cli.dataset.door`) into
``OUT/<sequence>/`` (meshes, stats.csv, bones.csv, manifest.json), then its views are
rendered into ``OUT/<sequence>/views/<view>/<frame>.png|.exr``, its labels written to
``labels.npz``, and last ``sequence.json``, whose presence marks the sequence complete.
"""
from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from axdf_cli import __version__
from axdf_cli import tolerances as tol
from axdf_cli.fileio import atomic, lock, runfolder
from axdf_cli.fileio.yamlio import FileRefused, read_regular
from axdf_cli.dataset import amodal as coco
from axdf_cli.dataset.folder import DATASET_JSON, INDEX, RECORD  # noqa: F401  (RECORD: written last)
from axdf_cli.dataset import labels as lab
from axdf_cli.dataset import door
from axdf_cli.geometry.bones import load_bone_mesh
from axdf_cli.pipeline.plan import display_path, load_muscle_specs
from axdf_cli.pipeline.stages import build_stages, stages_record
from axdf_cli.render.framing import ground_bones, placed_plates, skeleton_points, skin_anchors, skin_points
from axdf_cli.render.renderer import id_map
from axdf_cli.specs.render import settings_to_dict
from axdf_cli.errors import InputError
from axdf_cli.dataset.sampling import sample_pose, with_activation
from axdf_cli.dataset.spec import (DatasetSpec, Sequence, expand_sequences, load_dataset, load_motion,
                                   motion_frames)
from axdf_cli.specs import load_skeleton
from axdf_cli.model.keypoints import skeleton_keypoints
from axdf_cli.model.pose import sample_activation, sample_coordinates
from axdf_cli.model.skeleton import forward_kinematics

AMODAL = "amodal.json"  # with the amodal pass: COCO annotations of each muscle's full extent
LABELS = "labels.npz"


@dataclass
class Context:
    spec: DatasetSpec
    sequences: list[Sequence]
    skeleton: object  # with bone meshes (rendering)
    plan_skeleton: object  # without: runs do not copy bone meshes
    muscles: list
    models: list
    bone_meshes: dict  # bone index -> (vertices, faces, bytes)
    keypoints: object  # axdf_cli.model.keypoints.Keypoints: the labelled joints and end points
    inputs: dict  # display path -> sha256 (dataset file, skeleton, muscles, bone meshes)
    motion_inputs: dict  # motion name -> {display path: sha256}
    scene: object
    scene_bones: list  # bone indices of the scene's bones
    dataset_json: bytes
    digest: str
    timing: dict = field(default_factory=dict)
    stages: tuple = ()  # the run's stages (axdf_cli.pipeline.stages), applied to every sequence
    skin: object = None  # the skin every sequence wears (axdf_cli.specs.skin.Skin), or None
    face_part: object = None  # (F,) each skin triangle's body part (index into skin.bones)
    skin_anchors: list = field(default_factory=list)  # render.framing.skin_anchors of the skin, for the cameras

    @property
    def names(self) -> list[str]:
        return [m.name for m in self.muscles]


def build_context(path: Path | str, seed: int | None = None, policy=None, listed: bool = True,
                  fit: bool = True) -> Context:
    """Load and check everything (InputError on bad input); build the muscle models once.
    ``policy``: the command's :class:`~axdf_cli.specs.RefPolicy` (where referenced files may
    lie). ``listed`` False: the sequences are not listed and dataset.json not made (``--dry-run``:
    memory and time independent of the number of sequences; :func:`spec.count` counts them);
    ``fit`` False: motion-capture takes are read, not fitted (:func:`spec.load_dataset`)."""
    from axdf_cli.render.scene import Scene, SceneBone, SceneLayer, SceneMuscle

    spec = load_dataset(path, seed, policy, fit=fit)
    skel = load_skeleton(spec.skeleton_path, spec.policy)
    muscles = load_muscle_specs(spec.muscle_files)
    models = door.build_models(muscles, skel)
    bone_meshes = {i: load_bone_mesh(b.mesh, spec.skeleton_path) for i, b in enumerate(skel.bones) if b.mesh}
    srcs = [spec.source, spec.skeleton_path, *spec.muscle_files, *sorted({b.mesh for b in skel.bones if b.mesh})]
    skin = face_part = None
    if spec.skin is not None:
        from axdf_cli.render.under import face_parts
        from axdf_cli.specs.skin import load_skin

        skin = load_skin(spec.skin, skel, spec.policy)
        srcs += list(skin.files)
        face_part = face_parts(skin.faces, skin.weights)
    stages = build_stages(dict(spec.stages), muscles=muscles, skin=skin)
    layers = tuple(p for s in stages for p in s.parts(_Models(muscles, models, _Rest(skel), bone_meshes)))
    inputs = {display_path(Path(s)): atomic.sha256_file(s) for s in srcs}
    motion_inputs = {m.name: {display_path(Path(p)): atomic.sha256_file(p) for p in (m.path, m.map) if p}
                     for m in spec.motions.values()}
    scene_bones = sorted(bone_meshes) if spec.render.bones else []
    scene = Scene(muscles=tuple(SceneMuscle(s.name, s.color, m.faces) for s, m in zip(muscles, models)),
                  bones=tuple(SceneBone(skel.bones[i].name, bone_meshes[i][0], bone_meshes[i][1]) for i in scene_bones),
                  bounds=np.zeros((2, 3)), frames=(),
                  layers=tuple(SceneLayer(p.name, p.kind, p.faces, p.color) for p in layers))
    sequences = expand_sequences(spec) if listed else []
    keypoints = skeleton_keypoints(skel, {i: m[0] for i, m in bone_meshes.items()})
    ctx = Context(spec, sequences, skel, door.without_meshes(skel), muscles, models, bone_meshes, keypoints,
                  inputs, motion_inputs, scene, scene_bones, b"", "",
                  stages=stages, skin=skin, face_part=face_part,
                  skin_anchors=skin_anchors(skel, skin) if skin is not None else [])
    if not listed:
        return ctx
    ctx.dataset_json = (json.dumps(dataset_dict(ctx), indent=1) + "\n").encode()
    ctx.digest = hashlib.sha256(ctx.dataset_json).hexdigest()
    return ctx


@dataclass(frozen=True)
class _Models:
    """What a stage's ``parts`` reads of a run (its muscles, models, skeleton and bone meshes),
    for the data set's scene."""

    muscles: list
    models: list
    pose: object  # .skeleton, as a run's pose has it
    contact_meshes: dict  # {bone index: (vertices, faces, bytes)}, as a run's


@dataclass(frozen=True)
class _Rest:
    """The skeleton a stage reads as ``plan.pose.skeleton``."""

    skeleton: object


def sequence_plates(ctx: Context, subject: np.ndarray):
    """The scene with its ground plates (a run's rule: render.framing.placed_plates) under the
    sequence's subject (``subject`` (F, P, 3): its points at each frame), or None when the
    data set draws no plate."""
    names = set(ground_bones(ctx.skeleton))
    if not ctx.scene_bones or not names & {b.name for b in ctx.scene.bones}:
        return None
    xy = subject[..., :2].reshape(-1, 2)
    return replace(ctx.scene, ground=tuple(sorted(names)), footprint=np.stack([xy.min(0), xy.max(0)]))


def dataset_dict(ctx: Context) -> dict:
    """``dataset.json``: names, conventions, settings and the list of sequences."""
    from axdf_cli.render.views import VIEW_PNG_NOTES

    spec, skel = ctx.spec, ctx.skeleton
    W, H = spec.render.size
    return {
        "tool": "axdf", "version": __version__, "dataset": spec.name, "seed": spec.seed,
        "inputs": dict(sorted(ctx.inputs.items())),
        "motions": {k: v for m in sorted(ctx.motion_inputs) for k, v in ctx.motion_inputs[m].items()},
        "skeleton": skel.name,
        "coordinates": [{"name": c.name, "type": c.type, "unit": "deg" if c.type == "rotation" else "m"}
                        for c in skel.coordinates],
        "joints": list(ctx.keypoints.names),
        "joint_parents": ctx.keypoints.parents.tolist(),
        "joint_bones": [skel.bones[b].name for b in ctx.keypoints.bones],
        "joint_kinds": list(ctx.keypoints.kinds),
        "bone_names": [b.name for b in skel.bones],
        "bone_parents": [b.parent for b in skel.bones],
        "muscles": ctx.names,
        "views": list(spec.views),
        "image": {"width": W, "height": H, "passes": list(spec.passes)},
        "render": settings_to_dict(spec.render),
        "ids": id_map(ctx.scene, spec.render.bones, spec.render.skin if ctx.skin is not None else "off"),
        **({"skin": skin_dict(ctx)} if ctx.skin is not None else {}),
        "format": spec.format,
        "shards": spec.shards,
        "bones": {skel.bones[i].name: f"bones/{skel.bones[i].name}.ply" for i in sorted(ctx.bone_meshes)},
        "convention": ("world Z up, metres, degrees; cameras OpenCV (x right, y down, z forward), "
                       "world_to_camera maps world to camera, K in pixels with pixel (0,0)'s centre at (0.5,0.5) "
                       "(OpenCV's is at (0,0): for cv2.projectPoints use K with cx - 0.5, cy - 0.5); "
                       "joints are named anatomical keypoints fixed in bones: a joint where a bone with DOFs "
                       "attaches to its parent (the origin of its joint frame), or an end point (head top, "
                       "fingertips, toe tips)"),
        "labels": {
            "frames": "(F,) frame numbers", "coords": "(F, C) coordinate values (deg, m)",
            "bone_world": "(F, B, 4, 4) bone frames in the world", "joints3d": "(F, J, 3) world keypoints",
            "joints2d": "(F, V, J, 2) pixels", "joints_depth": "(F, V, J) camera z (m)",
            "visible": "(F, V, J) bool", "muscle_length": "(F, M) m", "muscle_volume": "(F, M) m^3",
            "muscle_activation": "(F, M) 0..1", "K": "(V, 3, 3)", "world_to_camera": "(F, V, 4, 4)",
        },
        "visibility_tolerance": spec.visibility_tolerance,
        **({"amodal": f"<sequence>/{AMODAL}: COCO annotations per view and frame, each muscle's full extent "
                      "(occluders ignored) as uncompressed RLE, category id = the muscle's EXR id"}
           if "amodal" in spec.passes else {}),
        **({"stages": stages_record(ctx.stages)} if ctx.stages else {}),
        **{p: VIEW_PNG_NOTES[p] for p in VIEW_PNG_NOTES if p in spec.passes},
        "sequences": [{"name": s.name, "source": spec.entries[s.entry].label, "frames": s.n_frames}
                      for s in ctx.sequences],
    }


def skin_dict(ctx: Context) -> dict:
    """``dataset.json``'s ``skin``: what the skin adds to each sequence and image."""
    opaque = ctx.spec.render.skin == "opaque"
    return {
        "name": ctx.skin.name, "drawn": ctx.spec.render.skin,
        "meshes": "<sequence>/meshes/skin/skin_<frame>.<format>: the skin worn over the muscles (docs/SKIN.md)",
        "parts": list(ctx.skin.bones),
        **({"passes": {
            "under.id": "EXR channel: for each skin pixel the muscle nearest beneath it (the muscle's id; 0: none "
                        "within the cap, or not skin)",
            "under.Z": "EXR channel: the depth of that muscle's surface under the skin (m; 0: none)",
            "part.id": "EXR channel: for each skin pixel 1 + its body part's index in parts (the bone that carries "
                       "the skin there most, by its skinning weights); 0: not skin"}} if opaque else {}),
    }


# ----------------------------------------------------------------------------- one sequence


def read_record(folder: Path, digest: str) -> dict | None:
    """The sequence's record when it is complete (same data set, every listed file present)."""
    return record_state(folder, digest)[0]


def record_state(folder: Path, digest: str) -> tuple[dict | None, str]:
    """(the record, "") when the sequence is complete; else (None, why not)."""
    try:
        rec = json.loads(read_regular(folder / RECORD, tol.INPUT_MAX_BYTES))  # (a FIFO there: refused, no hang)
    except FileNotFoundError:
        return None, "not made yet (no sequence.json)"
    except FileRefused as e:
        return None, f"its sequence.json is refused ({e.problem})"
    except (OSError, ValueError, RecursionError) as e:
        return None, f"its sequence.json is unreadable ({type(e).__name__})"
    if not isinstance(rec, dict):
        return None, "its sequence.json is not an object"
    if rec.get("dataset") != digest:
        return None, ("made for another data set (its sequence.json names another dataset.json: other seed, "
                      "inputs or settings)")
    files = rec.get("files")
    if not isinstance(files, dict):
        return None, "its sequence.json lists no files"
    gone = [rel for rel in files if not (isinstance(rel, str) and runfolder.plain_relpath(rel)
                                         and (folder / rel).is_file())]
    if gone:
        return None, f"{gone[0]} is missing"
    return rec, ""


def sequence_pose(ctx: Context, seq: Sequence):
    """(pose, output frames) of a sequence: a motion as it is, or sampled."""
    spec = ctx.spec
    entry = spec.entries[seq.entry]
    if entry.kind == "uniform":
        frames = np.arange(entry.frames)
        pose = sample_pose(spec, seq, ctx.plan_skeleton, None, frames)
    else:
        base = load_motion(spec, entry.motion)
        frames = motion_frames(spec, entry.motion)
        if entry.kind == "motion":
            pose = replace(base, name=seq.name, skeleton=ctx.plan_skeleton)
        else:
            pose = sample_pose(spec, seq, ctx.plan_skeleton, base, frames)
    return with_activation(spec, seq, pose, ctx.names, frames), frames


RENDERERS: dict = {}  # pid -> ViewRenderer (a GL context never crosses a fork)


def view_renderer(ctx: Context):
    from axdf_cli.render.views import ViewRenderer

    vr = RENDERERS.get(os.getpid())
    if vr is None:
        vr = RENDERERS[os.getpid()] = ViewRenderer(ctx.scene, ctx.spec.render)
    return vr


def release_renderer() -> None:
    vr = RENDERERS.pop(os.getpid(), None)
    if vr is not None:
        vr.release()


def build_sequence(ctx: Context, index: int, out: Path, resume: bool) -> tuple[dict, dict]:
    """Make sequence ``index`` whole in ``out``; return (its record, seconds per stage; with
    contact, ``"overlap"``: (share of its vertices inside another muscle, frames), its run's
    :func:`~axdf_cli.pipeline.overlap.overlap_share`).
    With ``resume`` a complete sequence is kept as it is and a partial one finished;
    otherwise it is made again: the files its earlier record lists and the new one lacks
    are deleted once the new record is written, nothing else (dataset/folder.py). The
    sequence folder is locked while it is made (another writer: exit 3)."""
    seq = ctx.sequences[index]
    folder = Path(out) / seq.name
    timing = {"run": 0.0, "read": 0.0, "render": 0.0, "write": 0.0, "cpu": 0.0, "skipped": 0}
    if resume:
        rec = read_record(folder, ctx.digest)
        if rec is not None:
            timing["skipped"] = 1
            return rec, timing
    runfolder.check_dirs(Path(out), [seq.name])
    atomic.ensure_dir(folder)
    fd = lock.lock_folder(folder, what=str(folder))
    try:
        lock.remove_stale_lock(folder / runfolder.LOCK)
        return _make_sequence(ctx, seq, folder, resume, timing)
    finally:
        lock.unlock_folder(fd)


def _make_sequence(ctx: Context, seq: Sequence, folder: Path, resume: bool, timing: dict) -> tuple[dict, dict]:
    from axdf_cli.render.views import view_camera, write_view_images

    spec = ctx.spec
    old = _json_file(folder / RECORD)
    old_files = [r for r in (old.get("files") or {}) if runfolder.plain_relpath(r)] \
        if isinstance(old, dict) and isinstance(old.get("files"), dict) else []
    if os.path.lexists(folder / RECORD):  # made again: incomplete until the new record is written
        runfolder.remove_listed(runfolder.Root(folder), RECORD)
    t0, c0 = time.perf_counter(), time.process_time()
    pose, frames = sequence_pose(ctx, seq)
    entry = spec.entries[seq.entry]
    inputs = dict(ctx.inputs)
    if entry.motion is not None:
        inputs.update(ctx.motion_inputs[entry.motion])
    plan = door.sequence_plan(pose, frames, ctx.muscles, ctx.models, spec.format, folder, inputs, ctx.stages,
                              ctx.bone_meshes)
    summary = door.run_sequence(plan, resume)
    t1 = time.perf_counter()
    timing["run"] = t1 - t0
    if summary.get("overlap") is not None:  # (contact ran: the share inside another muscle, and over how many frames)
        timing["overlap"] = (summary["overlap"], len(frames))

    coords = sample_coordinates(pose, frames)
    world = forward_kinematics(ctx.skeleton, coords)
    joints = ctx.keypoints.positions(world)
    subject = skeleton_points(ctx.skeleton, world, ctx.bone_meshes)
    if ctx.skin is not None:  # the body worn: its hands and head stay in view too
        subject = np.concatenate([subject, skin_points(ctx.skin_anchors, world)], axis=1)
    K, w2c, clip = lab.view_cameras(spec, seq, frames, subject, world, ctx.skeleton)
    uv, z = lab.project(K, w2c, joints)
    _check_finite(seq.name, K=K, world_to_camera=w2c, joints3d=joints, joints2d=uv, joints_depth=z)
    views = spec.views
    nf, nv = len(frames), len(views)
    W, H = spec.render.size
    visible = np.zeros((nf, nv, joints.shape[1]), bool)
    files: dict = {}
    amodal = "amodal" in spec.passes
    coco_images: list[dict] = []
    coco_anns: list[dict] = []
    t_read = t_render = 0.0
    t_write = time.perf_counter() - t1  # labels so far
    vr = view_renderer(ctx)  # once per process
    plates = sequence_plates(ctx, subject)
    root = runfolder.Root(folder)  # never through a link (views, views/<view>)
    for fi, frame in enumerate(frames):
        ta = time.perf_counter()
        pos, nrm = door.written_meshes(plan, int(frame))
        layers = door.written_layers(plan, int(frame))
        skin = layers[ctx.scene.skin_index] if ctx.scene.skin is not None else None
        cams = [view_camera(views[v], K[v], w2c[fi, v], clip[fi, v, 0], clip[fi, v, 1], spec.render.size)
                for v in range(nv)]
        bw = world[fi, ctx.scene_bones] if ctx.scene_bones else None
        if plates is not None:
            bw = placed_plates(plates, bw)
        tb = time.perf_counter()
        imgs = vr.render(int(frame), pos, nrm, bw, cams, layers)
        if skin is not None and spec.render.skin == "opaque":
            meshes = [(p, m.faces) for p, m in zip(pos, ctx.models)]
            imgs = [replace(im, under=vr.renderer.under(im, meshes),
                            parts=vr.renderer.parts(im, skin[0], ctx.skin.faces, ctx.face_part)) for im in imgs]
        masks = [vr.renderer.amodal(c) for c in cams] if amodal else []
        tc = time.perf_counter()
        depth = np.stack([im.depth for im in imgs])[None]  # (1, V, H, W)
        visible[fi] = lab.visibility(uv[fi:fi + 1], z[fi:fi + 1], depth, spec.visibility_tolerance)[0]
        for v, im in enumerate(imgs):
            rel = f"views/{views[v]}"
            files.update(write_view_images(root.path(f"{rel}/{int(frame):04d}").parent, rel, im, spec.passes,
                                           vr.labels))
            if amodal:
                image_id = len(coco_images)
                coco_images.append({"id": image_id, "file_name": f"{rel}/{int(frame):04d}.png", "width": W,
                                    "height": H, "frame": int(frame), "view": views[v]})
                coco_anns += coco.annotations(masks[v], im.ids, image_id, len(coco_anns))
        t_read += tb - ta
        t_render += tc - tb
        t_write += time.perf_counter() - tc
    t2 = time.perf_counter()
    stats = summary["stats"]
    act = np.nan_to_num(sample_activation(pose, ctx.names, frames), nan=0.0)
    arrays = {
        "frames": np.asarray(frames, np.int64), "coords": coords, "bone_world": world, "joints3d": joints,
        "joints2d": uv, "joints_depth": z, "visible": visible,
        "muscle_length": stats[..., 0], "muscle_volume": stats[..., 1], "muscle_activation": act,
        "K": K, "world_to_camera": w2c,
        "coord_names": np.array([c.name for c in ctx.skeleton.coordinates]),
        "joint_names": np.array(list(ctx.keypoints.names)), "joint_parents": ctx.keypoints.parents,
        "joint_bones": ctx.keypoints.bones, "bone_names": np.array([b.name for b in ctx.skeleton.bones]),
        "muscle_names": np.array(ctx.names), "view_names": np.array(list(views)),
    }
    if ctx.skin is not None:
        arrays["skin_part_names"] = np.array(list(ctx.skin.bones))
    files[LABELS] = atomic.write_bytes(root.path(LABELS), lab.npz_bytes(arrays))
    if amodal:
        files[AMODAL] = atomic.write_text(root.path(AMODAL), json.dumps(
            coco.coco_dict(ctx.names, coco_images, coco_anns), separators=(",", ":")) + "\n")
    manifest = json.loads((folder / "manifest.json").read_text())
    files.update(manifest.get("files", {}))
    files["manifest.json"] = atomic.sha256_file(folder / "manifest.json")
    rec = {"dataset": ctx.digest, "sequence": seq.name, "index": seq.index, "source": entry.label,
           "frames": [int(f) for f in frames], "views": list(views),
           "visible_keypoints": visible.sum(axis=-1).astype(int).tolist(),  # (F, V): 0 marks a sample showing none
           **({"parts": [{"name": p.name, "kind": p.kind.value} for p in plan.layers]} if plan.layers else {}),
           **({"skin_passes": ["under.id", "under.Z", "part.id"]}
              if ctx.skin is not None and spec.render.skin == "opaque" else {}),
           "files": dict(sorted(files.items()))}
    atomic.write_text(root.path(RECORD), json.dumps(rec, indent=1) + "\n")
    for rel in old_files:  # what the earlier record listed and this one does not (never anything else)
        if rel not in files and rel != RECORD:
            runfolder.remove_listed(root, rel)
    t_write += time.perf_counter() - t2
    timing.update(read=t_read, render=t_render, write=t_write, cpu=time.process_time() - c0)
    return rec, timing


def _check_finite(name: str, **arrays) -> None:
    """Labels are finite numbers, or the sequence is refused before its views are written."""
    for key, a in arrays.items():
        if not np.all(np.isfinite(a)):
            raise InputError(None, f"{name}: its labels' {key} are not finite numbers (a camera at the subject's "
                             "centre, or a degenerate view)", "cameras at a distance from the subject "
                             "(cameras: sphere distance, or rig positions away from their targets)")


def _json_file(path: Path):
    try:
        return json.loads(read_regular(path, tol.INPUT_MAX_BYTES)) if not os.path.islink(path) else None
    except (OSError, ValueError, RecursionError, FileRefused):
        return None
