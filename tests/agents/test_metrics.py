"""Per-iteration statistics, formatted for ``metrics.csv`` only where the file is written."""

from __future__ import annotations

import csv

import pytest

from agents.evaluate import EvalSummary
from agents.metrics import METRICS_COLUMNS, IterationStats, append_metrics, metrics_row

LOSSES = {"value": 0.5, "surrogate": -0.01, "entropy": 2.1}
EPISODES = [
    {"reward": 10.0, "progress": 40.0, "lap_complete": False},
    {"reward": 30.0, "progress": 100.0, "lap_complete": True},
]
EVAL = EvalSummary(
    laps=1,
    progress=55.0,
    best_lap=None,
    total_time=None,
    off_track=2,
    crashes=1,
    resets=3,
    status="time_up",
)


def test_statistics_average_the_ended_episodes():
    stats = IterationStats.of_iteration(3, 12.345, 500, EPISODES, LOSSES, None)
    assert (stats.episodes, stats.mean_reward, stats.mean_progress) == (2, 20.0, 70.0)
    assert stats.lap_completion == 0.5 and stats.value_loss == 0.5 and stats.eval is None
    none = IterationStats.of_iteration(0, 1.0, 10, [], LOSSES, EVAL)
    assert (none.episodes, none.mean_reward, none.lap_completion) == (0, 0.0, 0.0)
    assert none.eval is EVAL


def test_row_without_evaluation_leaves_its_cells_empty():
    row = metrics_row(IterationStats.of_iteration(3, 12.345, 500, EPISODES, LOSSES, None))
    assert tuple(row) == METRICS_COLUMNS
    assert row["elapsed_s"] == 12.35  # rounded here, not in the statistics
    assert all(row[c] == "" for c in METRICS_COLUMNS if c.startswith("eval_"))
    assert row["entropy"] == 2.1


def test_row_with_evaluation_leaves_only_absent_values_empty():
    row = metrics_row(IterationStats.of_iteration(4, 20.0, 500, EPISODES, LOSSES, EVAL))
    assert (row["eval_progress"], row["eval_laps"], row["eval_off_track"]) == (55.0, 1, 2)
    assert row["eval_crashes"] == EVAL.crashes
    assert row["eval_best_lap"] == "" and row["eval_total_time"] == ""


def test_append_writes_the_header_once(tmp_path):
    path = tmp_path / "metrics.csv"
    for it in range(3):
        append_metrics(path, IterationStats.of_iteration(it, it + 0.5, 9, EPISODES, LOSSES, None))
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["iteration"]) for r in rows] == [0, 1, 2]
    assert tuple(rows[0]) == METRICS_COLUMNS
    assert float(rows[2]["mean_reward"]) == pytest.approx(20.0)


def test_append_to_a_file_with_older_columns_keeps_its_header(tmp_path):
    """A run begun before a column existed is resumed under its own header."""
    path = tmp_path / "metrics.csv"
    older = [c for c in METRICS_COLUMNS if c != "eval_crashes"]
    path.write_text(",".join(older) + "\n")
    append_metrics(path, IterationStats.of_iteration(0, 1.0, 9, EPISODES, LOSSES, EVAL))
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == tuple(older)
    assert rows[0]["eval_off_track"] == str(EVAL.off_track)
