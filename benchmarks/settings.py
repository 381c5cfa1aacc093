"""A bench run's settings (:class:`Run`), handed to every section's ``rows``."""
from __future__ import annotations

import dataclasses
import sys
import tempfile
from pathlib import Path

from benchmarks.case import load_case
from benchmarks.common import DEMO_JOB, GAIT_JOB, MUSCLE_COUNTS, gait_shipped


@dataclasses.dataclass
class Run:
    """One bench run's settings, handed to every section's ``rows``; ``results`` holds what one
    section measured that a later one of the same run reads (writers' PLY row for packed,
    rendering's for rendering over processes), so that each section also runs alone."""

    quick: bool = False
    profile: bool = False
    tmp: Path = Path(tempfile.gettempdir())  # the run's folder for written files
    dataset_samples: int | None = None  # None: DATASET_SAMPLES, 100 with --quick
    alone: bool = False  # the sections were picked with --only
    results: dict = dataclasses.field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return 200 if self.quick else 1000

    @property
    def reps(self) -> int:
        return 2 if self.quick else 3

    @property
    def counts(self) -> tuple[int, ...]:
        return (1, 10) if self.quick else MUSCLE_COUNTS

    @property
    def job(self) -> Path:
        """The job of the end-to-end and packed rows: the walk's when gait2392 is shipped."""
        return GAIT_JOB if gait_shipped() and GAIT_JOB.is_file() else DEMO_JOB

    def case(self):
        """The evaluation case (:func:`benchmarks.case.load_case` over ``n_frames`` and the most
        muscles counted), loaded once per run."""
        if "case" not in self.results:
            case = load_case(self.n_frames, max(self.counts))
            print(f"axdf bench: {case.name} muscles ({len(case.specs)}), {self.n_frames} frames, median of "
                  f"{self.reps} runs (one run for 92 muscles); shared machine: figures are noisy, ratios are "
                  "taken in the same run", file=sys.stderr)
            self.results["case"] = case
        return self.results["case"]
