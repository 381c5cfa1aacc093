"""Progress bars on stderr: the one bar every command shows while it works.

A bar is shown only where a person watches: stderr is a terminal and ``-q`` was not given
(:func:`bar` returns None otherwise, so a command's output never depends on it). tqdm is
imported when a bar is shown, not before.
"""
from __future__ import annotations

import sys


def wanted(quiet: bool) -> bool:
    """Whether a bar is shown: not ``quiet`` and stderr is a terminal."""
    return not quiet and sys.stderr.isatty()


class Bar:
    """A tqdm bar on stderr counting ``unit``s (``total``: None when unknown). ``lazy``: the
    bar appears at the first update, not before (a step that may not come)."""

    def __init__(self, unit: str, *, total: int | None = None, desc: str | None = None, leave: bool = True,
                 smoothing: float | None = None, lazy: bool = False):
        self._options = dict(total=total, unit=unit, desc=desc, file=sys.stderr, leave=leave)
        if smoothing is not None:
            self._options["smoothing"] = smoothing
        self.bar = None
        if not lazy:
            self._open()

    def _open(self):
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(**self._options)
        return self.bar

    def update(self, n: int = 1) -> None:
        """``n`` more units done."""
        self._open().update(n)

    __call__ = update

    def tick(self, step: str) -> None:
        """One more step done, named beside the bar."""
        b = self._open()
        b.set_postfix_str(step)
        b.update(1)

    def show(self, done: int, total: int) -> None:
        """``done`` of ``total`` (a total learnt while working)."""
        b = self._open()
        b.total = total
        b.n = done
        b.refresh()

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


#: In a log (stderr not a terminal), ``AXDF_LOG_PROGRESS=SECONDS`` asks for a progress line at
#: most every SECONDS instead of no bar (``make demo`` sets 20, so that a job is never silent for
#: long in its log); unset, a log gets none, and a command's stderr is only its messages.
LOG_PROGRESS_VAR = "AXDF_LOG_PROGRESS"


class LogLines:
    """A bar's counts as a line on stderr at most every ``every`` seconds (a log's progress)."""

    def __init__(self, unit: str, every: float, *, total: int | None = None, desc: str | None = None, **_):
        import time

        self.units = unit + ("es" if unit.endswith(("s", "sh", "x")) else "s")
        self.every, self.total, self.desc, self.n = every, total, desc or self.units, 0
        self.t0 = self.last = time.perf_counter()

    def _say(self) -> None:
        import time

        now = time.perf_counter()
        if now - self.last >= self.every:
            self.last = now
            of = f" of {self.total}" if self.total else ""
            print(f"axdf: {self.desc}: {self.n}{of} {self.units} ({now - self.t0:.0f} s)", file=sys.stderr, flush=True)

    def update(self, n: int = 1) -> None:
        self.n += n
        self._say()

    __call__ = update

    def tick(self, step: str) -> None:
        self.update(1)

    def show(self, done: int, total: int) -> None:
        self.n, self.total = done, total
        self._say()

    def close(self) -> None:
        pass


def bar(quiet: bool, unit: str, **options) -> Bar | LogLines | None:
    """A :class:`Bar` when one is :func:`wanted`; in a log that asks for it
    (:data:`LOG_PROGRESS_VAR`, not ``quiet``), :class:`LogLines`; else None."""
    import os

    if wanted(quiet):
        return Bar(unit, **options)
    every = os.environ.get(LOG_PROGRESS_VAR, "")
    if quiet or not every:
        return None
    try:
        return LogLines(unit, max(1.0, float(every)), **options)
    except ValueError:
        return None


class Phases:
    """Progress of a long command in phases and steps, on stderr unless ``quiet``: on a
    terminal one bar of ``total`` steps whose label is the current phase; in a log (stderr not
    a terminal) a line per phase and per step, flushed at once, so a log never stays silent for
    long."""

    def __init__(self, quiet: bool, name: str, unit: str, total: int, at_most: bool = False):
        self.quiet, self.name, self.unit, self.total = quiet, name, unit, total
        self.of = f"of at most {total}" if at_most else f"of {total}"  # at_most: the work may end early
        self.bar = Bar(unit, total=total, desc=name) if wanted(quiet) else None
        self.done = 0

    def phase(self, text: str) -> None:
        """A new phase starts (``text`` says what it does)."""
        if self.bar is not None:
            self.bar.bar.set_description_str(f"{self.name}: {text}")
        elif not self.quiet:
            print(f"{self.name}: {text}", file=sys.stderr, flush=True)

    def step(self, text: str) -> None:
        """One more step done (``text``: its result, in a few words)."""
        self.done += 1
        if self.bar is not None:
            self.bar.tick(text)
        elif not self.quiet:
            print(f"{self.name}: {self.unit} {self.done} {self.of} done: {text}", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
