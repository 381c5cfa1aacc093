"""Row 5, rendering: frames per second at 512x512 for a demo-sized scene (``benchmark_fps``)."""
from __future__ import annotations

from benchmarks.common import Table
from benchmarks.settings import Run

UNIT = False


def render_fps(size=(512, 512), frames: int = 24, n_muscles: int = 6, verts: int = 1106) -> dict:
    """Frames per second of a demo-sized scene (6 muscles of 48x24, a bone); {'error': ...}
    when no GL context can be made."""
    from axdf_cli.errors import AxdfError
    from axdf_cli.render import benchmark_fps

    try:
        return benchmark_fps(size=size, n_muscles=n_muscles, verts=verts, frames=frames)
    except (AxdfError, ImportError, OSError) as e:
        return {"error": str(e).splitlines()[0]}


def measure(run: Run) -> dict:
    """:func:`render_fps` once per run (12 frames with --quick, else 24): the rendering-over-processes
    rows run only where it rendered."""
    if "render" not in run.results:
        run.results["render"] = render_fps(frames=12 if run.quick else 24)
    return run.results["render"]


def rows(table: Table, run: Run) -> list[str]:
    table.section("rendering (benchmark_fps: 6 muscles x 1106 vertices + a bone, as the demo)")
    rf = measure(run)
    if "error" in rf:
        table.add("render 512x512", "n/a", rf["error"][:60])
    else:
        table.add("render 512x512 (+ read-back)", f"{rf['render_fps']:.1f} fps",
                  f"{rf['gl_renderer'][:40]}, supersample {rf['supersample']}")
    return []
