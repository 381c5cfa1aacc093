"""What a new user meets in the first hour (issue 37): the compare header, the hint for a
motion file given as a pose, range warnings for path muscles, a data set's frame ranges
checked before the work, the compile notice and pack's progress."""
from __future__ import annotations

import shutil

from compare_helpers import make_run
from conftest import REPO_ROOT, run_main


def test_the_compare_header_names_each_folder_once(tmp_path, capsys):
    golden = make_run(tmp_path / "golden")
    actual = tmp_path / "actual"
    shutil.copytree(golden, actual)
    rc, out, _ = run_main(["compare", actual, golden], capsys)
    header = out.splitlines()[0]
    assert rc == 0, out
    assert "golden golden" not in header
    assert header == f"axdf compare: {actual} (actual) against {golden} (golden)"
