"""Data sets (``axdf dataset``): many sequences from seeded pose sampling, pose files and
OpenSim motions, rendered from several cameras, with labels for learning and one index.

Rooms: :mod:`~axdf_cli.dataset.spec` (the dataset file), :mod:`~axdf_cli.dataset.sampling`
(seeded draws), :mod:`~axdf_cli.dataset.labels` (joints, cameras, projections, visibility,
npz), :mod:`~axdf_cli.dataset.index` (the Parquet index), :mod:`~axdf_cli.dataset.worker`
(one sequence), :mod:`~axdf_cli.dataset.engine` (shards, process pool, Ray) and
:mod:`~axdf_cli.dataset.door` (the one door into the run machinery). This room drives
runs; it does not repeat them.
"""
from axdf_cli.dataset.engine import build, merge  # noqa: F401
from axdf_cli.dataset.spec import load_dataset  # noqa: F401
