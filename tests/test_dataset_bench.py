"""The data-set rows of `make bench` run on a tiny share of their data set (no speed assertions)."""
from __future__ import annotations

from benchmarks import common
from benchmarks.sections import dataset


def test_dataset_rows(tmp_path, repo_root):
    table = common.Table()
    dataset.dataset_rows(table, 2, tmp_path)
    rows = {r[0]: r for r in table.rows if len(r) == 5}
    assert rows["dataset, 1 worker"][1].endswith("samples/s")
    assert rows["dataset, 2 workers (process pool)"][3].endswith("x")
    ev, wr, rd = (float(x) for x in rows["per sample, 1 worker: evaluation / writing / rendering"][1][:-3].split(" / "))
    assert ev > 0 and wr > 0 and rd > 0
    assert not any(tmp_path.iterdir())  # the data sets are removed after timing
