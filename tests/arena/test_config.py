"""RaceConfig: exact JSON round trips, ruleset hashes, and one clear error per bad config."""

from __future__ import annotations

import json

import pytest

import arena
from arena.config import NO_VARIATION, ConfigError, RaceConfig, SeedVariation, resolve_track
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


def test_ruleset_hash_covers_what_the_seed_varies() -> None:
    base = arena.make_config(race_type="head_to_model")
    calmer = arena.make_config(race_type="head_to_model", variation={"steering_noise_deg": 0.5})
    fixed_grid = arena.make_config(race_type="head_to_model", variation={"shuffle_grid": False})
    hashes = {base.ruleset_hash(), calmer.ruleset_hash(), fixed_grid.ruleset_hash()}
    assert len(hashes) == 3
    assert base.variation.has_actuation_noise and base.variation.start_jitter_m > 0


def test_configs_stored_before_seed_variation_load_with_its_defaults() -> None:
    stored = json.loads(arena.make_config(race_type="head_to_model", seed=3).to_json())
    del stored["variation"]
    loaded = RaceConfig.from_json(json.dumps(stored))
    assert loaded.variation == SeedVariation()
    ruleset = {k: v for k, v in loaded.ruleset().items() if k != "variation"}
    rebuilt = RaceConfig.build(**ruleset, cars=stored["cars"], seed=3)  # as the league does
    assert rebuilt == loaded


def test_seed_variation_is_for_races_only() -> None:
    varied = {"steering_noise_deg": 2.0}
    race = arena.make_config(variation=varied)
    training = arena.make_config(variation=varied, mode="training")
    assert race.active_variation == race.variation
    assert training.active_variation == NO_VARIATION
    assert race.ruleset_hash() == training.ruleset_hash()


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
        ({"variation": {"start_jitter_m": 0.5}}, "variation.start_jitter_m"),
        ({"variation": {"speed_noise_frac": -0.1}}, "variation.speed_noise_frac"),
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
