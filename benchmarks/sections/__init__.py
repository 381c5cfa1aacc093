"""The bench's sections, in the order they run and appear in docs/BENCH.md: one module each
(``benchmarks.sections.<name>``), with ``rows(table, run)`` (the section's rows into a
:class:`benchmarks.common.Table`; returns cProfile texts for ``--profile``) and ``UNIT``
(whether its figures use µs/mf). ``--only NAME[,NAME...]`` picks some."""
from __future__ import annotations

#: name -> the section's heading in docs/BENCH.md, in the page's (and the run's) order.
SECTIONS = {
    "evaluation": "evaluation, the limit, wrapping and a peer (geomdl)",
    "contact": "contact and axdf pack",
    "writers": "writers (PLY, OBJ)",
    "render": "rendering",
    "end_to_end": "end to end (axdf run)",
    "compiled": "the compiled pass (a whole run, a data-set sample, first touch, compile cost)",
    "dataset": "data sets (axdf dataset build)",
    "packed": "packed formats (npz, pc2, mdd, usd)",
    "render_jobs": "rendering over processes (--jobs)",
    "retarget": "retargeting (axdf retarget)",
    "jiggle": "jiggle",
    "skin": "the skin stage",
    "whole_body": "a frame of the whole body beside gait2392's",
    "long": "--long: peak memory over 10,000 frames",
}
#: the sections a run measures without --only (``long``: with --long)
DEFAULT = tuple(n for n in SECTIONS if n != "long")
