"""The ``slipstream model`` Typer app: validate, info and the honest pre-flight stub."""

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
    result = runner.invoke(
        app, ["validate", str(good), "--json", "--preflight", "--track", "beginner_loop"]
    )
    assert result.exit_code == 0, result.output
    flight = json.loads(result.output)["preflight"]
    assert flight["track"] == "beginner_loop" and flight["laps"] == 1
    assert flight["status"] in ("finished", "time_up", "dnf")
    assert flight["laps_completed"] == len(flight["lap_times"])
    text = runner.invoke(app, ["validate", str(good), "--preflight", "--track", "beginner_loop"])
    assert "pre-flight on beginner_loop" in text.output
    unknown = runner.invoke(app, ["validate", str(good), "--preflight", "--track", "nowhere"])
    assert unknown.exit_code == 1 and "nowhere" in unknown.output
    missing_track = runner.invoke(app, ["validate", str(good), "--preflight"])
    assert missing_track.exit_code == 2
