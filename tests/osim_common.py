"""Shared helpers for the OpenSim importer tests: where the real data lives, and imports."""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
OSIM = DATA / "opensim"

needs_data = pytest.mark.skipif(not OSIM.is_dir(), reason=f"OpenSim test data not found at {OSIM} "
                                                           "(../shared/data relative to the repository)")

ARM = OSIM / "arm26" / "arm26.osim"
ARM_Q = OSIM / "arm26" / "arm26_Kinematics_q.sto"
ARM_CTRL = OSIM / "arm26" / "arm26_controls.sto"
GAIT = OSIM / "gait2392" / "gait2392_thelen2003muscle.osim"
GAIT_Q = OSIM / "gait2392" / "subject01_walk1_ik.mot"
GAIT_CTRL = OSIM / "gait2392" / "subject01_walk1_controls.sto"
FK = OSIM / "gait2354_fk_check"
FK_MODEL = FK / "subject01_simbody_adjusted.osim"
FK_Q = FK / "subject01_walk1_Kinematics_q.sto"
FK_POS = FK / "subject01_walk1_BodyKinematics_pos_global.sto"


def run_import(tmp_path: Path, model: Path, *extra: str, out: str = "imp") -> tuple[int, Path]:
    """``axdf import osim MODEL --out tmp/out ...`` in-process, from ``tmp_path`` (paths stay inside)."""
    import os

    from axdf_cli.cli.main import main

    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        rc = main(["import", "osim", str(model), "--out", out, "-q", *extra])
    finally:
        os.chdir(cwd)
    return rc, tmp_path / out
