"""RaceConfig: exact JSON round trips, ruleset hashes, and one clear error per bad config."""

from __future__ import annotations

import pytest

import arena
from arena.config import ConfigError, RaceConfig, resolve_track
from tracks.catalog import get_track


def test_json_round_trip_is_exact() -> None:
    config = arena.make_config(
        race_type="object_avoidance", sensors=("camera", "lidar"), seed=7, laps=2
    )
    text = config.to_json()
    again = RaceConfig.from_json(text)
    assert again == config
    assert again.to_json() == text


def test_ruleset_hash_ignores_cars_and_seed_but_not_rules() -> None:
    base = arena.make_config(seed=1)
    assert base.ruleset_hash() == arena.make_config(seed=2, sensors=("camera",)).ruleset_hash()
    assert base.ruleset_hash() != arena.make_config(seed=1, laps=5).ruleset_hash()
    assert base.ruleset_hash() != arena.make_config(seed=1, direction="cw").ruleset_hash()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"sensors": ("radar",)}, "unknown sensor"),
        ({"race_type": "head_to_model", "num_cars": 9}, "1 to 8"),
        ({"num_cars": 0}, "1 to 8"),
        ({"sensors": ("camera", "stereo")}, "camera"),
        (
            {"action_space": {"type": "discrete", "actions": [{"steering_angle": 0, "speed": 7}]}},
            "less than or equal to 4",
        ),
        (
            {"action_space": {"type": "continuous", "speed": {"low": 2, "high": 1}}},
            "must be below high",
        ),
        ({"race_type": "drag_race"}, "race_type"),
        ({"race_type": "time_trial", "num_cars": 2}, "exactly one"),
        ({"physics": {"control_hz": 15, "physics_hz": 50}}, "whole multiple"),
    ],
)
def test_bad_configs_raise_one_clear_error(kwargs: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message) as err:
        arena.make_config(**kwargs)
    assert "invalid race config" in str(err.value)
    assert "\n" not in str(err.value)


def test_obstacles_that_do_not_fit_are_refused_before_the_race() -> None:
    with pytest.raises(ConfigError, match="boxes"):
        arena.parallel_env(race_type="object_avoidance", obstacles={"count": 20, "min_gap_m": 3.0})


def test_unknown_track_is_refused() -> None:
    with pytest.raises(ConfigError, match="no_such_track"):
        arena.parallel_env(track="no_such_track")


def test_resolve_track_turns_the_track_to_the_race_direction() -> None:
    native = get_track("beginner_loop")
    other = "cw" if native.direction == "ccw" else "ccw"
    track, reversed_ = resolve_track(RaceConfig(track="beginner_loop", direction=other))
    assert track.direction == other and reversed_
    same, reversed_ = resolve_track(RaceConfig(track="beginner_loop", direction=native.direction))
    assert same.direction == native.direction and not reversed_
    with pytest.raises(ConfigError, match="no_such_track"):
        resolve_track(RaceConfig(track="no_such_track"))
