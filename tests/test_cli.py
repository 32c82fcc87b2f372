"""The root ``slipstream`` command's race, through Typer's runner (demo: test_demo.py)."""

from __future__ import annotations

import json
from pathlib import Path

import imageio.v2 as imageio
import pytest
from typer.testing import CliRunner

from league.cli import app

runner = CliRunner()


@pytest.mark.slow
def test_race_writes_result_and_replay(tmp_path: Path) -> None:
    args = ["race", "--race-type", "head_to_bot", "--laps", "1", "--time-limit", "12"]
    result = runner.invoke(app, [*args, "--out", str(tmp_path), "--seed", "3"])
    assert result.exit_code == 0, result.output
    assert "head_to_bot on beginner_loop" in result.output
    stored = json.loads((tmp_path / "result.json").read_text())
    assert stored["config"]["race_type"] == "head_to_bot"
    assert len(stored["bots"]) == len(stored["trace"]["car0"]["t"])
    frames = imageio.mimread(tmp_path / "replay.gif")
    assert len(frames) >= 10 and frames[0].ndim == 3


def test_race_json_and_bad_input() -> None:
    result = runner.invoke(app, ["race", "--laps", "1", "--time-limit", "3", "--json"])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.output)
    assert doc["cars"][0]["name"] == "car0" and "trace" not in doc
    bad = runner.invoke(app, ["race", "--race-type", "drag_race"])
    assert bad.exit_code == 1 and "race_type" in bad.output
    unknown = runner.invoke(app, ["race", "--track", "atlantis"])
    assert unknown.exit_code == 1 and "atlantis" in unknown.output
