"""Property test: the shipped YAML files mutated at random never crash axdf.

Whatever the mutation, ``axdf run`` exits 0 or 2, prints no traceback, and writes nothing
outside its output folder. Seeded (``derandomize``) and bounded (``max_examples``)."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from axdf_cli.cli.main import main

ROOT = Path(__file__).resolve().parents[1]
FILES = ["poses/jobs/demo.yaml", "poses/demo.yaml", "poses/skeletons/human_r.yaml",
         "muscles/demo/biceps_brachii.yaml", "muscles/demo/deltoid.yaml", "muscles/demo/gastrocnemius.yaml"]
TOKENS = ["", "-1", "0", "0.5", "1e308", "-1e308", ".nan", ".inf", "-.inf", "null", "[]", "{}", "'..'",
          "/etc/passwd", "../../../x", "*a", "&a [1]", "!!python/object/apply:os.system ['touch pwned']",
          "'a/b'", "'a\\\\b'", "\u00fc", "99999999999999999999999", "true", "[1, 2]", "[[[[", "}", ":", "- ",
          "'#'", "~", "2001-01-01", "0x10", "1_000", "!!binary aGVsbG8=", "&b", "<<: *b"]


@pytest.fixture(scope="module")
def template(tmp_path_factory):
    base = tmp_path_factory.mktemp("fuzz-template")
    shutil.copytree(ROOT / "muscles" / "demo", base / "muscles" / "demo")
    (base / "poses" / "jobs").mkdir(parents=True)
    shutil.copy(ROOT / "poses" / "demo.yaml", base / "poses" / "demo.yaml")
    shutil.copy(ROOT / "poses" / "jobs" / "demo.yaml", base / "poses" / "jobs" / "demo.yaml")
    shutil.copytree(ROOT / "poses" / "skeletons" / "human_r_meshes", base / "poses" / "skeletons" / "human_r_meshes")
    shutil.copy(ROOT / "poses" / "skeletons" / "human_r.yaml", base / "poses" / "skeletons" / "human_r.yaml")
    return base


def _mutate(text: str, data) -> str:
    lines = text.splitlines(keepends=True)
    op = data.draw(st.sampled_from(["value", "value", "value", "delete", "duplicate", "insert", "truncate", "swap"]))
    i = data.draw(st.integers(0, max(0, len(lines) - 1)))
    if op == "value" and lines:
        line = lines[i]
        if ":" in line:
            head, _, _ = line.partition(":")
            lines[i] = f"{head}: {data.draw(st.sampled_from(TOKENS))}\n"
        else:
            lines[i] = data.draw(st.sampled_from(TOKENS)) + "\n"
    elif op == "delete" and lines:
        del lines[i]
    elif op == "duplicate" and lines:
        lines.insert(i, lines[i])
    elif op == "insert":
        pos = data.draw(st.integers(0, len(text)))
        junk = data.draw(st.text(alphabet=st.sampled_from(list("[]{}:,-&*!|>'\"#% \n\t0.9ax\u00e9")), max_size=6))
        return text[:pos] + junk + text[pos:]
    elif op == "truncate":
        return text[: data.draw(st.integers(0, len(text)))]
    elif op == "swap" and len(lines) > 1:
        j = data.draw(st.integers(0, len(lines) - 1))
        lines[i], lines[j] = lines[j], lines[i]
    return "".join(lines)


def _snapshot(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.stat().st_size for p in folder.rglob("*") if p.is_file()}


@settings(max_examples=60, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_mutated_inputs_exit_0_or_2_and_write_only_into_out(template, tmp_path_factory, capsys, monkeypatch, data):
    work = tmp_path_factory.mktemp("fuzz")
    project = work / "p"
    shutil.copytree(template, project)
    n_mut = data.draw(st.integers(1, 3))
    for _ in range(n_mut):
        rel = data.draw(st.sampled_from(FILES))
        path = project / rel
        path.write_text(_mutate(path.read_text(), data))
    before = _snapshot(project)
    monkeypatch.chdir(project)
    rc = main(["run", "poses/jobs/demo.yaml", "--no-render", "--frames", "0:1", "--out", "out"])
    err = capsys.readouterr().err
    monkeypatch.undo()
    event(f"exit {rc}")
    assert rc in (0, 2), err
    assert "Traceback" not in err
    after = {k: v for k, v in _snapshot(project).items() if not k.startswith("out/")}
    assert after == before
    assert not (project / "pwned").exists()
    if rc == 2:
        first = err.strip().splitlines()[0]
        assert first.startswith("axdf:") or ":" in first
