"""Issue 17's fresh hostile round: new variations of its cases (output rule, links, signals,
damaged inputs and packed files), each a regression test of a defect the round found.

Where a command must leave things alone, the test snapshots the tree (test_safety.snapshot).
"""
from __future__ import annotations

import json
import os

import pytest

from conftest import run_main
from test_outputs import Importer, imp, proj  # noqa: F401  (fixtures)
from test_safety import own_leftovers, snapshot


def test_overwrite_checks_the_way_to_every_file_it_deletes_before_the_first_byte(imp, proj, capsys, tmp_path):
    """A manifest edited to list a file below a link (OUT/evil -> elsewhere): --overwrite,
    which deletes the old output's listed files, once found the link in the middle of the
    swap, with exit 2 after it had rewritten the manifest as incomplete."""
    assert run_main(imp.args("--out", "imp", "-q"), capsys)[0] == 0
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "x.yaml").write_text("mine\n")
    (proj / "imp" / "evil").symlink_to(elsewhere)
    m = json.loads((proj / "imp" / "manifest.json").read_text())
    m["files"]["evil/x.yaml"] = "0" * 64
    (proj / "imp" / "manifest.json").write_text(json.dumps(m, indent=1))
    before = snapshot(tmp_path)
    rc, _, err = run_main(imp.args("--out", "imp", "--overwrite"), capsys)
    assert rc == 2 and "imp/evil is a symbolic link" in err, err
    assert snapshot(tmp_path) == before and own_leftovers(proj / "imp") == []
