"""``make bench``: one table of speed figures, every figure and every limit measured in the same run.

    python -m benchmarks.bench [--quick] [--long] [--profile] [--only ROWS] [--markdown PATH]

Rows (medians of repeated runs timed with ``time.perf_counter``; the machine may be shared,
so figures are noisy and only ratios taken in the same run are compared with targets):

1. evaluation: µs per muscle-frame of ``MuscleModel.evaluate`` at 48x24 and 96x48, over
   1000 frames in chunks of ``pipeline.CHUNK_FRAMES``, for 1, 10 and 92 muscles (the gait2392
   library and walk when shipped, else demo muscles replicated and perturbed on the demo
   skeleton with a synthetic pose);
2. the limit: numpy filling the same outputs (``np.copyto`` into preallocated (F, V, 3)
   float64 vertices and normals), and evaluation / limit;
3. a peer: the same surface tessellated by geomdl (NURBS-Python), per muscle-frame;
4. writers: PLY and OBJ (encode; encode + atomic write) in MB/s and µs per muscle-frame,
   against ``ndarray.tofile`` of the same bytes;
5. rendering: frames per second at 512x512 for a demo-sized scene (``benchmark_fps``);
6. end to end: ``axdf run`` of the largest shipped job as a subprocess (frames per second,
   peak memory), and the split of its time between evaluation and writing (cProfile);
7. data sets: ``axdf dataset build`` of poses/datasets/gait2392_random.yaml (1000 samples, 100
   with ``--quick``) at 1 and 2 workers, the scaling ratio, and a sample's split between
   evaluation, writing and rendering.
8. packed formats (npz, pc2, mdd, usd): writing all muscles x all frames as the run streams
   them against ``ndarray.tofile`` of the same bytes in one file, and ``axdf run`` of the job
   (pose stretched to the bench's frames) per format against the same run writing no meshes,
   with peak memory.
9. contact: the gait2392 walk and Rajagopal2016's running stride (muscles only) evaluated with
   and without the contact stage (µs per muscle-frame, the ratio), and the shares of vertices
   inside another muscle or a bone and the deepest penetration before and after (the
   product's own measures, stats.csv's), the volume, and the muscle-frames that pop (a
   vertex step over 1.5x the no-contact one); where the skeleton has bone meshes, the share
   inside a bone and the deepest point in one after contact by libigl's distance to the
   meshes themselves, against the fields the product reads them through;
10. rendering split over processes: ``make demo``'s first job (poses/jobs/demo.yaml, meshes and
   512x512 frames; every 2nd frame with ``--quick``) as a subprocess at ``--jobs 1`` and
   ``--jobs 2``, and their ratio.
11. retargeting: ``axdf retarget``'s fit of the CMU walk onto gait2392 (frames per second at 30
   and 120 fps; every 4th frame of the take with ``--quick``), and one Jacobian of the mapped
   points by the analytic formula against central differences batched as frames of one
   forward-kinematics call (the alternative the fit could use).
12. jiggle: ``evaluate_plan`` of the gait2392 walk (92 muscles, the whole trial; 54 jiggle)
   with and without the jiggle stage (timed in turn, medians of 5), µs per muscle-frame, and
   the stage alone; and a ``--frames`` subset's extra cost (frames not selected are advanced too).
13. skin: the skin stage (``axdf run --skin``) over the gait2392 walk and the CMU walk onto
   gait2392 (packed muscles, contact on): its ms per frame against the muscles plus contact,
   measured side by side, the skin's volume against rest, muscle vertices outside it.
14. whole_body: a frame of myobody's 416 atlas muscles (contact, skins/myobody) beside one of
   gait2392's 92 (contact, skins/gait2392): the muscles alone, with contact, with the skin.

Each section is a module of :mod:`benchmarks.sections` (rows 1-3 and wrapping: ``evaluation``;
4: ``writers``; 5: ``render``; 6: ``end_to_end``; 7: ``dataset``; 8: ``packed``; 9: ``contact``,
with the packed library's report; 10: ``render_jobs``; 11: ``retarget``; 12: ``jiggle``; 13:
``skin``; 14: ``whole_body``; and ``compiled``: a whole run of the walk stretched to 1051 frames at 48x24 into npz
against tofile of the same bytes; 92 muscles x 1 frame; a chunk's outputs into fresh memory
against steady state; numba's first-run compile cost). ``--only NAME[,NAME...]`` measures only
those sections (``python -m benchmarks.bench --help`` lists them).

``--long`` adds the section ``long``: the memory check of 10,000 frames x 92 muscles streamed
through ``pipeline.evaluate_chunks`` in a subprocess (several minutes). Helpers are importable
for the smoke test (``tests/test_bench_smoke.py``), which runs them on a tiny case.

``--markdown PATH`` also writes the sections measured into a generated Markdown page (``make
bench`` writes docs/BENCH.md, which the docs link to instead of pasting figures): each section
between its markers, with the command, the commit and the machine it was measured on and its
own time; the page's other sections stay as they were (:mod:`benchmarks.page`). A section
that fails stops the run, and the sections measured before it are still written.
"""
from __future__ import annotations

import argparse
import importlib
import shutil
import sys
import tempfile
import time
from pathlib import Path

from benchmarks import page
from benchmarks.common import DATASET_SAMPLES, Table, machine_line
from benchmarks.sections import DEFAULT, SECTIONS
from benchmarks.settings import Run

HELP = {
    "evaluation": "MuscleModel.evaluate against numpy filling the same outputs, wrapping, geomdl",
    "contact": "the walks, arm26 and Rajagopal2016 with and without contact; the pack report",
    "writers": "PLY and OBJ against tofile",
    "render": "frames per second of a demo-sized scene",
    "end_to_end": "axdf run of the largest job, with and without contact; evaluation against writing",
    "compiled": "the compiled pass: a whole run, a data-set sample, first touch, compile cost",
    "dataset": "axdf dataset build at 1 and 2 workers",
    "packed": "npz, pc2, mdd, usd against tofile, and axdf run per format",
    "render_jobs": "the demo job at --jobs 1 and --jobs 2",
    "retarget": "the retargeting fit and its Jacobian",
    "jiggle": "the jiggle stage",
    "skin": "the skin stage over the walks",
    "whole_body": "myobody's 416 atlas muscles, contact and skin beside gait2392's frame",
    "long": "10,000 frames x all muscles: peak memory (as --long)",
}


def section(name: str):
    """The section's module (looked up when it runs: a test may stand in for its ``rows``)."""
    return importlib.import_module(f"benchmarks.sections.{name}")


def names(text: str) -> tuple[str, ...]:
    """``--only``'s value: section names, comma-separated, in the page's order."""
    picked = [n.strip() for n in text.split(",") if n.strip()]
    wrong = [n for n in picked if n not in SECTIONS]
    if wrong or not picked:
        raise argparse.ArgumentTypeError(f"unknown section {', '.join(wrong) or repr(text)}; "
                                         f"the sections: {', '.join(SECTIONS)}")
    return tuple(n for n in SECTIONS if n in picked)


def shown_args(argv: list[str]) -> list[str]:
    """The command line as the page shows it: without --markdown and its path."""
    return [a for i, a in enumerate(argv) if a != "--markdown" and not a.startswith("--markdown=")
            and not (i > 0 and argv[i - 1] == "--markdown")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.bench", description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="sections (--only), in the page's order:\n"
                                        + "\n".join(f"  {n:12s} {HELP.get(n, SECTIONS[n])}" for n in SECTIONS))
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats (about a minute)")
    ap.add_argument("--long", action="store_true",
                    help="also the section long: 10000 frames x all muscles, peak memory")
    ap.add_argument("--profile", action="store_true", help="print the top functions of the slow rows")
    ap.add_argument("--tmp", default=None, help="folder for the written files (default: a new temporary folder)")
    ap.add_argument("--only", type=names, default=None, metavar="NAME[,NAME...]",
                    help="measure only these sections (listed below); the page keeps the others")
    ap.add_argument("--dataset-samples", type=int, default=None, metavar="N",
                    help=f"samples of the data-set rows (default {DATASET_SAMPLES}, 100 with --quick; 0: skip them)")
    ap.add_argument("--markdown", default=None, metavar="PATH",
                    help="also write the sections measured into the Markdown page PATH (make bench: docs/BENCH.md)")
    args = ap.parse_args(argv)
    argv_shown = shown_args(list(sys.argv[1:] if argv is None else argv))
    command = " ".join(["python -m benchmarks.bench", *argv_shown])

    tmp = Path(tempfile.mkdtemp(prefix="axdf-bench-", dir=args.tmp))
    run = Run(quick=args.quick, profile=args.profile, tmp=tmp, dataset_samples=args.dataset_samples,
              alone=args.only is not None)
    picked = [n for n in SECTIONS if n in (args.only or DEFAULT) or (n == "long" and args.long)]
    picked = [n for n in picked if getattr(section(n), "wanted", lambda _: True)(run)]
    t_start = time.perf_counter()
    measured: list[tuple[str, Table, float]] = []
    profiles: list[str] = []
    failed: BaseException | None = None
    try:
        for name in picked:
            table, t0 = Table(), time.perf_counter()
            profiles += section(name).rows(table, run) or []
            measured.append((name, table, time.perf_counter() - t0))
    except BaseException as e:  # the sections measured before it are still printed and written
        failed = e
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    seconds = time.perf_counter() - t_start

    whole = Table()
    for _, table, _ in measured:
        whole.rows += table.rows
    unit = any(section(name).UNIT for name, _, _ in measured)
    print(whole.text())
    print(f"({'µs/mf: microseconds per muscle-frame; ' if unit else ''}total bench time {seconds:.0f} s)")
    for t in profiles:
        print()
        print(t)
    if args.markdown:
        machine = machine_line(Path(args.markdown))
        page.write(Path(args.markdown), {name: page.block(name, table.markdown(), command, machine, secs, seconds)
                                         for name, table, secs in measured})
        print(f"(sections {', '.join(n for n, _, _ in measured) or '(none)'} written to {args.markdown})",
              file=sys.stderr)
    if failed is not None:
        raise failed
    return 0


if __name__ == "__main__":
    sys.exit(main())
