"""A track is driven the way its file runs; ``direction`` asks for the other way.

DeepRacer drives a ``_cw`` world in file order with ``is_reversed`` false; a run asked
to go against the file's order reverses the waypoints and sets ``is_reversed``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import arena
from arena.config import RaceConfig, resolve_track
from league.rulesets import event_config
from league.schemas import EventCreate
from slipstream.cli import app
from tracks.catalog import get_track, import_track, user_track_dir
from tracks.io import write_document


@pytest.fixture
def clockwise_track(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A user track whose file runs clockwise (the built-in loop, reversed)."""
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    track = get_track("beginner_loop").reversed()
    assert track.direction == "cw"
    user_track_dir().mkdir(parents=True)
    write_document(track, user_track_dir() / "loop_cw.json")
    return "loop_cw"


def _first_params(**config: object) -> dict:
    env = arena.parallel_env(**config)
    _, infos = env.reset()
    env.close()
    return infos["car0"]["params"]


def test_a_clockwise_file_is_driven_clockwise_in_file_order(clockwise_track: str) -> None:
    native = get_track(clockwise_track)
    track, reversed_ = resolve_track(RaceConfig(track=clockwise_track))
    assert track.direction == "cw" and not reversed_
    params = _first_params(track=clockwise_track)
    assert params["is_reversed"] is False
    assert np.allclose(params["waypoints"], native.waypoints, atol=1e-6)


def test_asking_for_the_other_direction_reverses_the_file(clockwise_track: str) -> None:
    native = get_track(clockwise_track)
    track, reversed_ = resolve_track(RaceConfig(track=clockwise_track, direction="ccw"))
    assert track.direction == "ccw" and reversed_
    params = _first_params(track=clockwise_track, direction="ccw")
    assert params["is_reversed"] is True
    first = np.asarray(params["waypoints"][0])
    assert np.allclose(first, native.waypoints[-1], atol=1e-6)  # file order, backwards


def test_the_files_own_direction_named_explicitly_is_not_reversed(clockwise_track: str) -> None:
    assert _first_params(track=clockwise_track, direction="cw")["is_reversed"] is False


def test_an_event_without_direction_freezes_the_files_direction(clockwise_track: str) -> None:
    config = event_config(EventCreate(name="cw cup", track=clockwise_track))
    assert config.direction == "cw"
    assert config.ruleset()["direction"] == "cw"
    other_way = EventCreate(name="ccw cup", track=clockwise_track, direction="ccw")
    assert resolve_track(event_config(other_way))[1]


def test_train_and_evaluate_take_a_direction() -> None:
    runner = CliRunner()
    for command in ("train", "evaluate", "race"):
        result = runner.invoke(app, [command, "--help"], terminal_width=200)
        assert result.exit_code == 0
        assert "--direction" in result.output, command


def test_race_refuses_a_bad_direction() -> None:
    result = CliRunner().invoke(app, ["race", "--direction", "sideways"])
    assert result.exit_code != 0
    assert "direction" in result.output


@pytest.mark.realdata
def test_the_real_reinvent2019_wide_cw_runs_clockwise_unreversed(
    shared_tracks: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The measured bug: this file was driven counter-clockwise with is_reversed True."""
    monkeypatch.setenv("SLIPSTREAM_HOME", str(tmp_path / "home"))
    track = import_track(shared_tracks / "reInvent2019_wide_cw.npy")
    file_rows = np.load(shared_tracks / "reInvent2019_wide_cw.npy")
    params = _first_params(track=track.name)
    assert resolve_track(RaceConfig(track=track.name))[0].direction == "cw"
    assert params["is_reversed"] is False
    assert np.allclose(params["waypoints"][1], file_rows[1, :2], atol=1e-3)
