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


def bar(quiet: bool, unit: str, **options) -> Bar | None:
    """A :class:`Bar` when one is :func:`wanted`, else None."""
    return Bar(unit, **options) if wanted(quiet) else None
