"""The error hierarchy. Only the CLI layer prints errors or exits.

- :class:`InputError`: bad input (exit 2), printed as ``FILE:LINE:COL: what is wrong; what is allowed``.
- :class:`EnvironmentProblem`: the machine cannot do the work (exit 3), with a hint.
"""
from __future__ import annotations

import difflib
from typing import Iterable, NamedTuple


class Mark(NamedTuple):
    """A position in an input file (1-based line and column). A named tuple, not a frozen
    dataclass: a large YAML pose holds a mark per value, and a frozen dataclass takes ten
    times as long to make (most of the cost of reading a 200,000-key pose's positions)."""

    file: str
    line: int = 0
    col: int = 0

    def __str__(self) -> str:
        if self.line <= 0:
            return self.file
        return f"{self.file}:{self.line}:{self.col}"


class AxdfError(Exception):
    exit_code = 1


class InputError(AxdfError):
    """Bad input: carries where (file, line, column), what is wrong, and what is allowed."""

    exit_code = 2

    def __init__(self, where: Mark | str | None, problem: str, allowed: str | None = None):
        if isinstance(where, str):
            where = Mark(where)
        self.where = where
        self.problem = problem
        self.allowed = allowed
        super().__init__(str(self))

    def __str__(self) -> str:
        text = self.problem if self.allowed is None else f"{self.problem}; {self.allowed}"
        return f"{self.where}: {text}" if self.where is not None else text

    def __reduce__(self):  # whole across processes (a worker's error reaches the parent)
        return InputError, (self.where, self.problem, self.allowed)


class InputErrors(InputError):
    """Several bad inputs found at once (a batch of files, each checked before any is used):
    printed one ``FILE: what is wrong; what is allowed`` line each, the first one's place as
    its own."""

    def __init__(self, errors):
        self.errors = list(errors)
        first = self.errors[0]
        super().__init__(first.where, first.problem, first.allowed)

    def __str__(self) -> str:
        return "\n".join(str(e) for e in self.errors)

    def __reduce__(self):
        return InputErrors, (self.errors,)


def raise_all(errors) -> None:
    """Raise the one error of ``errors``, or all of them as :class:`InputErrors`; nothing when
    there are none."""
    errors = list(errors)
    if len(errors) == 1:
        raise errors[0]
    if errors:
        raise InputErrors(errors)


class UsageError(InputError):
    """Bad command-line usage (no file position)."""

    def __init__(self, problem: str, allowed: str | None = None):
        super().__init__(None, problem, allowed)


class EnvironmentProblem(AxdfError):
    """The environment cannot do the work (no EGL, unwritable output, full disk)."""

    exit_code = 3

    def __init__(self, problem: str, hint: str | None = None):
        self.problem = problem
        self.hint = hint
        super().__init__(problem if hint is None else f"{problem}\nhint: {hint}")

    def __reduce__(self):
        return EnvironmentProblem, (self.problem, self.hint)


class Interrupted(AxdfError):
    exit_code = 130


def nearest(word, choices: Iterable[str]) -> str | None:
    """The choice closest to ``word`` (difflib), or None when none is close."""
    if not isinstance(word, str):
        return None
    hits = difflib.get_close_matches(word, [c for c in choices if isinstance(c, str)], n=1, cutoff=0.6)
    return hits[0] if hits else None


def did_you_mean(word, choices: Iterable[str]) -> str:
    """``"did you mean 'x'? "`` for the nearest choice, or ``""``."""
    near = nearest(word, choices)
    return f"did you mean {near!r}? " if near else ""
