"""The root ``slipstream`` command: what it mounts, and its race (demo: test_demo.py)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import pytest
from typer.testing import CliRunner

from slipstream.cli import app

runner = CliRunner()
GROUPS = {"tracks": "list", "model": "validate", "league": "serve"}
COMMANDS = ("race", "train", "evaluate", "demo")


def test_the_root_command_mounts_every_package() -> None:
    top = runner.invoke(app, ["--help"])
    assert top.exit_code == 0, top.output
    for name in (*GROUPS, *COMMANDS):
        assert name in top.output
    for group, command in GROUPS.items():
        inner = runner.invoke(app, [group, "--help"])
        assert inner.exit_code == 0 and command in inner.output, inner.output


@pytest.mark.parametrize(
    ("module", "shown"), [("slipstream", "league"), ("league", "create-racer")]
)
def test_python_dash_m_runs_the_commands(module: str, shown: str) -> None:
    done = subprocess.run(
        [sys.executable, "-m", module, "--help"], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 0, done.stderr
    assert shown in done.stdout


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


@pytest.mark.parametrize(
    "args",
    [["race", "--track", "[/bold]x"], ["race", "--driver", "[/bold]x"], ["tracks", "show", "[/]x"]],
)
def test_user_text_in_errors_is_printed_literally_not_as_markup(args: list[str]) -> None:
    result = runner.invoke(app, args)
    assert result.exit_code == 1 and isinstance(result.exception, SystemExit), result.exception
    assert args[-1] in result.output
