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


SAMPLES = Path(__file__).resolve().parents[1] / "league" / "demo_models"


@pytest.mark.slow
def test_race_model_files_head_to_head_with_a_bot_over_rotating_grids(tmp_path: Path) -> None:
    models = [SAMPLES / "sample-time-trial.zip", SAMPLES / "sample-self-play.zip"]
    args = ["race", "--model", str(models[0]), "--model", str(models[1]), "--bots", "1"]
    args += ["--laps", "1", "--time-limit", "15", "--seeds", "3", "--seed", "5"]
    result = runner.invoke(app, [*args, "--json", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    races = json.loads(result.output)
    assert [r["config"]["seed"] for r in races] == [5, 6, 7]
    names = {"sample-time-trial", "sample-self-play", "bot0"}
    assert all({c["name"] for c in r["cars"]} == names for r in races)
    assert all(r["config"]["race_type"] == "head_to_model" for r in races)
    assert races[0]["config"]["track"] == "slipstream_speedway"  # a real-width default
    fronts = [next(c["name"] for c in r["cars"] if c["grid_offset"] == 0.0) for r in races]
    assert sorted(fronts) == sorted(names)  # the grid rotates: each car starts in front once
    assert all(max(c["distance"] for c in r["cars"]) > 5.0 for r in races)  # they raced
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seed-5", "seed-6", "seed-7"]
    assert (tmp_path / "seed-6" / "replay.gif").is_file()

    wide = {"COLUMNS": "200"}
    table = runner.invoke(app, [*args[:-6], "--time-limit", "5", "--seeds", "2"], env=wide)
    assert table.exit_code == 0, table.output
    assert "2 races, head_to_model on slipstream_speedway" in table.output
    assert "wins from behind" in table.output
    rows = [line for line in table.output.splitlines() if "sample-" in line or "bot0" in line]
    assert len(rows) == 3


def test_a_model_that_faults_in_the_race_is_out_of_it_not_the_command(tmp_path: Path) -> None:
    from tests.league.test_race_faults import inf_on_real_frames

    hostile = tmp_path / "cliff.zip"
    hostile.write_bytes(inf_on_real_frames())
    args = ["race", "--model", str(hostile), "--bots", "1", "--laps", "1", "--time-limit", "6"]
    result = runner.invoke(app, [*args, "--json"])
    assert result.exit_code == 0, result.output
    cars = {c["name"]: c for c in json.loads(result.output)["cars"]}
    assert cars["cliff"]["status"] == "dnf"
    assert "the model output NaN or inf" in cars["cliff"]["dnf_reason"]
    assert cars["bot0"]["dnf_reason"] is None and cars["bot0"]["distance"] > 2.0


def test_race_refuses_bad_model_files_and_bots_without_models(tmp_path: Path) -> None:
    broken = tmp_path / "broken.zip"
    broken.write_bytes(b"PK\x03\x04 not really a zip")
    bad = runner.invoke(app, ["race", "--model", str(broken)])
    assert bad.exit_code == 1
    # rich wraps long lines, inside a long path too: compare without whitespace
    assert "broken.zipisnotavalidmodelfile" in "".join(bad.output.split())
    missing = runner.invoke(app, ["race", "--model", str(tmp_path / "nowhere.zip")])
    assert missing.exit_code == 1 and "nowhere.zip" in "".join(missing.output.split())
    lonely = runner.invoke(app, ["race", "--bots", "2"])
    assert lonely.exit_code == 1 and "--model" in lonely.output
