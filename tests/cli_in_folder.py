"""Call the CLI in process from a given folder (relative paths in arguments and outputs stay there)."""
from __future__ import annotations

import os
from pathlib import Path


def run_cli(cwd: Path, *argv: str) -> int:
    from axdf_cli.cli.main import main

    old = os.getcwd()
    os.chdir(cwd)
    try:
        return main(list(argv))
    finally:
        os.chdir(old)
