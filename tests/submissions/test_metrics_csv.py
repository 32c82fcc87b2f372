"""``metrics.csv`` bounded in every dimension at validation, and read small by construction."""

from __future__ import annotations

import numpy as np
import pytest

from agents.metrics import METRICS_COLUMNS
from arena.actions import default_discrete_space
from submissions import pack, validate
from submissions.format import Limits
from submissions.metrics_csv import check_metrics, read_metrics
from tests.league.conftest import CREATED_AT, policy_onnx

LIMITS = Limits()


def _digits(rows: int, columns: int, seed: int = 0) -> str:
    values = np.random.default_rng(seed).integers(0, 10, size=(rows, columns)).tolist()
    header = ",".join(f"c{i}" for i in range(columns))
    return header + "\n" + "".join(",".join(map(str, row)) + "\n" for row in values)


HOSTILE = {
    "1.5 million columns": (",".join(["x"] * 1_500_000) + "\n", "line 1 of more"),
    "500 columns": (_digits(50, 500), "too many columns"),
    "a wide row under a narrow header": ("a,b\n1,2\n" + ",".join(["1"] * 65) + "\n", "line 3"),
    "a long column name": ("a," + "n" * 65 + "\n1,2\n", "column name"),
    "too many rows": ("a\n" + "1\n" * 100_001, "too many rows"),
    "too many cells": (_digits(16_000, 64), "too many cells"),
    "blank lines past the row cap": ("a\n" + "\n" * 100_001, "too many rows"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_metrics_file_over_any_bound_is_refused(case: str) -> None:
    text, words = HOSTILE[case]
    problems = check_metrics(text.encode(), LIMITS)
    assert len(problems) == 1, problems
    assert problems[0].field == "archive:metrics.csv"
    assert words in str(problems[0])


def test_the_validator_refuses_a_wide_metrics_file_with_a_clear_problem(tmp_path) -> None:
    archive = pack(
        tmp_path / "wide.zip",
        policy_onnx(3),
        default_discrete_space(),
        ["lidar"],
        metrics_csv=_digits(100, 500),
        created_at=CREATED_AT,
    )
    report = validate(archive, run_policy=False)
    assert not report.ok
    (problem,) = report.problems
    assert problem.message == "The metrics file has too many columns."
    assert problem.expected == f"at most {LIMITS.max_metrics_columns} columns"


def test_a_training_runs_metrics_file_is_within_every_bound() -> None:
    header = ",".join(METRICS_COLUMNS)
    row = ",".join(["-1234.5678901234567"] * len(METRICS_COLUMNS))
    text = header + "\n" + (row + "\n") * 50_000
    assert check_metrics(text.encode(), LIMITS) == []


def test_a_read_is_downsampled_and_keeps_sparse_columns() -> None:
    """10,000 rows with an evaluation every 7th: 500 points, the evaluations still there."""
    lines = ["iteration,mean_reward,eval_progress"]
    lines += [f"{i},{i / 2},{i if i % 7 == 0 else ''}" for i in range(10_000)]
    series = read_metrics(("\n".join(lines) + "\n").encode(), LIMITS, max_points=500)
    assert series.rows == 10_000 and series.columns == ["iteration", "mean_reward", "eval_progress"]
    assert [len(v) for v in series.values.values()] == [500, 500, 500]
    assert series.values["iteration"][-1] == 9_999
    assert all(v is not None for v in series.values["eval_progress"])


def test_a_short_read_keeps_every_row_and_blank_cells() -> None:
    series = read_metrics(b"a,b,,a\n1,x,5,9\n2,,6,8\n", LIMITS)
    assert series.columns == ["a", "b"]
    assert series.values == {"a": [1.0, 2.0], "b": [None, None]}
