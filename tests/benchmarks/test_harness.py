"""The benchmarks' harness: the table writer's records, the statistics, the server's errors.

``benchmarks/`` is a folder of scripts, not a package, so the harness is loaded from its file.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
from pathlib import Path
from types import ModuleType

import pytest

HARNESS = Path(__file__).resolve().parents[2] / "benchmarks" / "harness.py"


@pytest.fixture(scope="module")
def harness() -> ModuleType:
    """``benchmarks/harness.py`` as a module."""
    spec = importlib.util.spec_from_file_location("benchmarks_harness", HARNESS)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _table(harness: ModuleType, title: str) -> object:
    table = harness.ResultTable(title, ("case", "median ms", "where"), "lrl")
    table.add_row("mono", "0.10", "child")
    table.add_row("a | b", 2, "worker")
    table.notes.append("200 frames per case")
    return table


def test_write_appends_markdown_and_one_json_line_per_table(
    harness: ModuleType, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for title in ("first run", "second run"):
        harness.write(_table(harness, title), name="demo", results=tmp_path)
    printed = capsys.readouterr().out
    assert "second run" in printed and "200 frames per case" in printed
    assert "1-min load average" in printed

    entries = [json.loads(line) for line in (tmp_path / "demo.jsonl").read_text().splitlines()]
    assert [e["title"] for e in entries] == ["first run", "second run"]
    entry = entries[0]
    assert entry["columns"] == ["case", "median ms", "where"]
    assert entry["rows"] == [["mono", "0.10", "child"], ["a | b", "2", "worker"]]
    assert entry["notes"] == ["200 frames per case"]
    assert entry["date"].endswith("Z") and entry["command"]
    assert entry["machine"]["cores"] == os.cpu_count()
    assert {"cpu", "memory_gib", "gpu"} <= set(entry["machine"])

    text = (tmp_path / "demo.md").read_text()
    assert text.startswith("# Results of `demo.py`") and text.count("\n# ") == 0
    assert text.count("## first run") == 1 and text.count("## second run") == 1
    assert "| case | median ms | where |\n|---|---:|---|\n| mono | 0.10 | child |" in text
    assert "| a \\| b | 2 | worker |" in text  # a pipe in a cell does not split it
    assert f"- command: `{entry['command']}`" in text


def test_write_without_record_appends_nothing(harness: ModuleType, tmp_path: Path) -> None:
    harness.write(_table(harness, "dry run"), record=False, name="demo", results=tmp_path)
    assert not list(tmp_path.iterdir())


def test_record_option_defaults_to_recording(harness: ModuleType) -> None:
    parser = argparse.ArgumentParser()
    harness.add_record_option(parser)
    assert parser.parse_args([]).record is True
    assert parser.parse_args(["--no-record"]).record is False


def test_a_row_needs_one_cell_per_column(harness: ModuleType) -> None:
    table = harness.ResultTable("t", ("a", "b"))
    assert table.align == "lr"
    with pytest.raises(ValueError):
        table.add_row("only one")
    with pytest.raises(ValueError):
        harness.ResultTable("t", ("a", "b"), "lx")


def test_summary_statistics(harness: ModuleType) -> None:
    stats = harness.summary([float(v) for v in range(1, 101)])
    assert stats.n == 100
    assert stats.mean == pytest.approx(50.5)
    assert stats.median == pytest.approx(50.5)
    assert stats.p95 == pytest.approx(95.05)
    assert stats.p99 == pytest.approx(99.01)
    assert stats.max == 100.0
    with pytest.raises(ValueError):
        harness.summary([])


def test_time_calls_times_runs_after_the_warm_up(harness: ModuleType) -> None:
    calls = []
    times = harness.time_calls(lambda: calls.append(1), runs=3, warmup=2)
    assert len(calls) == 5
    assert len(times) == 3 and all(t >= 0.0 for t in times)


def test_a_server_that_exits_is_reported_with_its_output(
    harness: ModuleType, tmp_path: Path
) -> None:
    env = {**os.environ, "SLIPSTREAM_DATA_DIR": str(tmp_path)}
    with pytest.raises(harness.ServerNotReady, match="exited with code 2") as raised:
        harness.start_league("--no-such-option", env=env, cwd=tmp_path)
    assert "--no-such-option" in str(raised.value).split("\n", 1)[1]  # the server's own words
