"""The ``slipstream model`` Typer app: validate, info and the one-lap pre-flight."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from submissions.cli import app
from tests.submissions.test_support import mlp, pack_bytes

runner = CliRunner()


@pytest.fixture
def good(tmp_path: Path) -> Path:
    path = tmp_path / "good.zip"
    path.write_bytes(pack_bytes(mlp(), training_summary={"track": "oval"}))
    return path


@pytest.fixture
def bad(tmp_path: Path) -> Path:
    path = tmp_path / "bad.zip"
    path.write_bytes(pack_bytes(mlp(n_out=3)))
    return path


def test_validate_valid(good: Path) -> None:
    result = runner.invoke(app, ["validate", str(good)])
    assert result.exit_code == 0, result.output
    assert "valid" in result.output and "lidar" in result.output


def test_validate_invalid_lists_problems(bad: Path) -> None:
    result = runner.invoke(app, ["validate", str(bad)])
    assert result.exit_code == 1
    assert "refused" in result.output and "policy.onnx:output:out" in result.output


def test_validate_json(bad: Path) -> None:
    result = runner.invoke(app, ["validate", str(bad), "--json"])
    assert result.exit_code == 1
    data = json.loads(result.output)
    assert data["ok"] is False and data["problems"][0]["field"] == "policy.onnx:output:out"


def test_info(good: Path) -> None:
    result = runner.invoke(app, ["info", str(good), "--json"])
    assert result.exit_code == 0
    info = json.loads(result.output)["info"]
    assert info["sensors"] == ["lidar"] and info["training_summary"] == {"track": "oval"}
    table = runner.invoke(app, ["info", str(good)])
    assert table.exit_code == 0 and "discrete, 10 actions" in table.output


def test_info_on_garbage(tmp_path: Path) -> None:
    path = tmp_path / "x.zip"
    path.write_bytes(b"garbage")
    result = runner.invoke(app, ["info", str(path)])
    assert result.exit_code == 1 and "archive" in result.output


def test_preflight_races_one_lap_and_reports(good: Path) -> None:
    """A valid model exits 0 whatever its pre-flight result; this one runs out of time.

    ``good`` is a random-weight lidar MLP. Alone on a track with no walls its lidar sees
    nothing, so its observation never changes and neither does its action (action 1: full
    lock at 0.8 m/s). It circles off the road again and again and is out of time (90 s)
    with no lap.
    """
    result = runner.invoke(
        app, ["validate", str(good), "--json", "--preflight", "--track", "beginner_loop"]
    )
    assert result.exit_code == 0, result.output
    flight = json.loads(result.output)["preflight"]
    assert flight["track"] == "beginner_loop" and flight["laps"] == 1
    assert flight["status"] == "time_up"
    assert flight["laps_completed"] == 0 and flight["lap_times"] == []
    assert flight["best_lap"] is None and flight["crash_count"] == 0
    assert flight["off_track_count"] >= 1 and flight["reset_count"] >= flight["off_track_count"]
    text = runner.invoke(app, ["validate", str(good), "--preflight", "--track", "beginner_loop"])
    assert text.exit_code == 0
    assert "pre-flight on beginner_loop: did NOT finish (time_up); 0/1 laps" in text.output
    unknown = runner.invoke(app, ["validate", str(good), "--preflight", "--track", "nowhere"])
    assert unknown.exit_code == 1 and "nowhere" in unknown.output
    missing_track = runner.invoke(app, ["validate", str(good), "--preflight"])
    assert missing_track.exit_code == 2


def test_preflight_of_a_refused_file_races_nothing(bad: Path) -> None:
    result = runner.invoke(
        app, ["validate", str(bad), "--json", "--preflight", "--track", "beginner_loop"]
    )
    assert result.exit_code == 1
    assert "preflight" not in json.loads(result.output)
