"""``axdf run``: muscles × pose → mesh sequence, stats, bones (and frames), plus a manifest.

Data flow: YAML → frozen specs (:mod:`axdf_cli.specs`) → :mod:`.plan` (every input checked,
a :class:`~axdf_cli.model.muscle.MuscleModel` per muscle: basis matrices and binding, once) →
:mod:`.evaluate` (batched over chunks of frames, batch dimension first) → :mod:`.execute`
(every check first, then the mesh pass, in this process or :mod:`.pool`'s forked workers;
the tables; rendering; the manifest) → the run folder (:mod:`axdf_cli.fileio.runfolder`: layout,
manifest, writer, lock, staging and swap). Every file is written atomically; the manifest
is valid JSON at every moment and a killed run can be resumed (``--resume`` skips files
whose bytes already match the manifest, and refuses other inputs or settings).
"""
from axdf_cli.pipeline.evaluate import (CHUNK_FRAMES, batched_axis_frames, chunk_frames, evaluate_chunks,
                                   twist_references)
from axdf_cli.pipeline.execute import check_output, execute, mesh_pass
from axdf_cli.pipeline.plan import RunPlan, job_render_settings, load_bone_mesh, plan_run

__all__ = ["CHUNK_FRAMES", "RunPlan", "batched_axis_frames", "check_output", "chunk_frames", "evaluate_chunks",
           "execute", "job_render_settings", "load_bone_mesh", "mesh_pass", "plan_run", "twist_references"]
