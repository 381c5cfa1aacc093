"""``axdf run``: muscles × pose → mesh sequence, stats, bones (and frames), plus a manifest.

Data flow: YAML → frozen specs (:mod:`axdf_cli.specs`) → :mod:`.plan` (every input checked,
a :class:`~axdf_cli.model.muscle.MuscleModel` per muscle: basis matrices and binding, once; the
stages, :mod:`.stages`) → :mod:`.evaluate` (the one evaluation path: chunks of frames, batch
dimension first, through the model's two steps and the stages) → :mod:`.execute`
(every check first, then the mesh pass, in this process or forked workers; the tables,
:mod:`.tables`; rendering; the manifest, :mod:`.manifest`) → the run folder
(:mod:`axdf_cli.fileio.runfolder`: layout, manifest, writer, staging and swap; the lock,
:mod:`axdf_cli.fileio.lock`). Every file is written atomically; the manifest is valid JSON
at every moment and a killed run can be resumed (``--resume`` skips files whose bytes
already match the manifest, and refuses other inputs, settings or model: the run's identity).
"""
from axdf_cli.pipeline.evaluate import (CHUNK_FRAMES, Prepass, batch_of, chunk_frames, evaluate_plan,
                                        evaluate_chunks, prepare, twist_references)
from axdf_cli.pipeline.execute import check_output, execute, mesh_pass
from axdf_cli.pipeline.plan import RunPlan, job_render_settings, plan_run
from axdf_cli.pipeline.stages import STAGES, Chunk, Scope, Stage, build_stages

__all__ = ["CHUNK_FRAMES", "Chunk", "Prepass", "RunPlan", "STAGES", "Scope", "Stage", "batch_of",
           "build_stages", "check_output", "chunk_frames", "evaluate_chunks", "evaluate_plan", "execute",
           "job_render_settings", "mesh_pass", "plan_run", "prepare", "twist_references"]
