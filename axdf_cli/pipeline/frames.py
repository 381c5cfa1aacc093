"""The frames sink: a run plan's frames rendered into ``OUT/frames/`` (``axdf run --render``).

The renderer (:mod:`axdf_cli.render`) takes a scene and chunks of arrays and never evaluates;
:class:`PlanFrames` is the :class:`~axdf_cli.render.framefiles.FrameSource` that evaluates the
plan's muscles again, block by block, through the same pipeline (stages included, from the
run's pre-pass), exactly as the mesh pass wrote them.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from axdf_cli.pipeline.evaluate import Prepass, evaluate_plan, finite_or_rest
from axdf_cli.pipeline.plan import camera_targets
from axdf_cli.render.framing import plan_framing, scene_framing
from axdf_cli.render.renderer import bone_layout
from axdf_cli.render.scene import FrameChunk, Scene, SceneLayer, SceneMuscle
from axdf_cli.render.framefiles import RENDER_CHUNK, render_frames_of


def render_plan(plan, out_dir: Path, bounds, prep: Prepass, progress: Callable[[int], None] | None = None,
                framing_points=None, jobs: int = 1, frames=None, on_frame: Callable[[dict], None] | None = None
                ) -> dict:
    """Render a run plan's frames into ``out_dir`` (``axdf run --render``) over ``jobs``
    processes (:func:`render_frames_of`); ``frames``: those to draw now (default all of the
    plan's; the cameras and camera.json are always the whole sequence's). ``framing_points``:
    what the automatic camera frames (a :class:`~axdf_cli.render.framing.Framing`; default
    :func:`axdf_cli.render.framing.plan_framing`); ``prep``:
    the run's pre-pass (:func:`axdf_cli.pipeline.evaluate.prepare`)."""
    skel = plan.pose.skeleton
    framing = plan_framing(plan) if framing_points is None else framing_points
    shown = skel.bones if plan.render.bones else ()
    layout = bone_layout([b.name for b in shown], skel.stick_parents() if shown else [],
                         {i: (v, f) for i, (v, f, _) in plan.bone_meshes.items() if shown},
                         float(np.ptp(framing.points, axis=0).max()))
    scene = Scene(
        muscles=tuple(SceneMuscle(s.name, s.color, m.faces) for s, m in zip(plan.muscles, plan.models)),
        bones=layout.bones, bounds=bounds, frames=tuple(int(f) for f in plan.frames),
        first_frame=int(plan.pose.first), targets=camera_targets(plan),
        layers=tuple(SceneLayer(p.name, p.kind, p.faces, p.color) for p in plan.layers),
        **scene_framing(framing, plan.pose, plan.frames))
    todo = scene.frames if frames is None else frames
    return render_frames_of(scene, PlanFrames(plan, prep, layout), todo, plan.render, out_dir, jobs,
                            progress, on_frame)


class PlanFrames:
    """A run plan's frames for the renderer (a :class:`FrameSource`): the muscles evaluated
    again, block by block (evaluation is cheap next to rendering and this keeps memory
    bounded), exactly as the mesh pass wrote them (:func:`evaluate_plan` from the run's pre-pass
    ``prep``); the bones placed by ``layout`` (:class:`~axdf_cli.render.renderer.BoneLayout`)."""

    preload = ("axdf_cli.pipeline.frames",)  # what a render worker imports before its first block

    def __init__(self, plan, prep: Prepass, layout):
        self.plan, self.prep, self.layout = plan, prep, layout

    def chunks(self, frames: list[int]) -> Iterator[FrameChunk]:
        plan = self.plan
        rows = np.searchsorted(plan.frames, np.asarray(frames, dtype=np.int64))
        if len(rows) and not np.array_equal(plan.frames[np.minimum(rows, len(plan.frames) - 1)], frames):
            raise ValueError("frames outside the plan")
        # runs of consecutive rows (a resumed render skips the frames it has)
        cuts = np.nonzero(np.diff(rows) != 1)[0] + 1
        for run in np.split(rows, cuts):
            if not len(run):
                continue
            rows_run = slice(int(run[0]), int(run[-1]) + 1)
            for chunk, results in evaluate_plan(plan, self.prep, rows_run, size=RENDER_CHUNK):
                done = [finite_or_rest(r, plan.models[j]) for j, r in results]
                layers = tuple((chunk.parts[p.name].positions, chunk.parts[p.name].normals) for p in plan.layers)
                yield FrameChunk(frames=chunk.frames, positions=tuple(d[0] for d in done),
                                 normals=tuple(d[1] for d in done), bone_world=self.layout.transforms(chunk.world),
                                 layers=layers)
