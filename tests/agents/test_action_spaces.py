"""Action-space builders, the CLI spec grammar and model_metadata.json round trips."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents.action_spaces import (
    ActionSpaceError,
    console_action_space,
    continuous_action_space,
    custom_action_space,
    parse_action_space_spec,
)
from agents.model_metadata import (
    DeepRacerMetadata,
    ModelMetadataError,
    metadata_from_dict,
    metadata_to_dict,
    read_model_metadata,
    write_model_metadata,
)
from arena.actions import ContinuousActionSpace, DiscreteActionSpace, default_discrete_space
from arena.sensors_spec import LidarConfig


def _pairs(space: DiscreteActionSpace) -> list[tuple[float, float]]:
    return [(a.steering_angle, a.speed) for a in space.actions]


def test_console_defaults_are_deepracers_default_space() -> None:
    assert console_action_space() == default_discrete_space()
    assert console_action_space(30, 5, 0.8, 2) == default_discrete_space()


def test_console_builder_spreads_values_like_the_console() -> None:
    space = console_action_space(30, 3, 1.0, 3)
    assert _pairs(space) == [(s, v) for s in (-30.0, 0.0, 30.0) for v in (0.33, 0.67, 1.0)]
    seven = console_action_space(25, 7, 4.0, 1)
    assert [a.steering_angle for a in seven.actions] == [
        -25.0,
        -16.67,
        -8.33,
        0.0,
        8.33,
        16.67,
        25.0,
    ]
    assert {a.speed for a in seven.actions} == {4.0}


@pytest.mark.parametrize("steer_g", [3, 5, 7])
@pytest.mark.parametrize("speed_g", [1, 2, 3])
@pytest.mark.parametrize(("max_steer", "max_speed"), [(1, 0.3), (17.5, 2.2), (30, 4.0)])
def test_console_builder_covers_every_combination(
    steer_g: int, speed_g: int, max_steer: float, max_speed: float
) -> None:
    space = console_action_space(max_steer, steer_g, max_speed, speed_g)
    steers = sorted({a.steering_angle for a in space.actions})
    speeds = sorted({a.speed for a in space.actions})
    assert space.n == steer_g * speed_g
    assert len(steers) == steer_g and len(speeds) == speed_g
    assert steers[0] == -max_steer and steers[-1] == max_steer and 0.0 in steers
    assert speeds[-1] == max_speed


@pytest.mark.parametrize(
    ("call", "named"),
    [
        (lambda: console_action_space(30, 5, 4.5, 2), "4.5"),
        (lambda: console_action_space(30, 4, 1.0, 2), "4"),
        (lambda: console_action_space(31, 5, 1.0, 2), "31"),
        (lambda: console_action_space(0.5, 5, 1.0, 2), "0.5"),
        (lambda: console_action_space(30, 5, 1.0, 4), "speed granularity"),
        (lambda: console_action_space(30, 5, 0.1, 3), "0.03"),
        (lambda: console_action_space(30, 5, float("nan"), 2), "nan"),
        (lambda: custom_action_space([]), "at least one action"),
        (lambda: custom_action_space([(0, 4.2)]), "4.2"),
        (lambda: custom_action_space([(-45, 1.0)]), "-45"),
        (lambda: custom_action_space([(0, 1.0), (0, 1.0)]), "twice"),
        (lambda: custom_action_space([(0, 1.0, 2.0)]), "pair"),
        (lambda: continuous_action_space(-30, 30, 2.0, 2.0), "speed low (2)"),
        (lambda: continuous_action_space(10, -10, 0.5, 4), "steering low (10)"),
        (lambda: continuous_action_space(-30, 30, 0.5, 5), "5"),
        (lambda: continuous_action_space(-30, 30, 0.0, 4), "speed low"),
    ],
)
def test_invalid_spaces_raise_naming_the_bad_value(call, named: str) -> None:
    with pytest.raises(ActionSpaceError) as info:
        call()
    assert isinstance(info.value, ValueError)
    assert named in str(info.value)


def test_custom_and_continuous_builders() -> None:
    custom = custom_action_space([(-20, 1.0), (0, 2.5), (20, 1.0)])
    assert _pairs(custom) == [(-20.0, 1.0), (0.0, 2.5), (20.0, 1.0)]
    cont = continuous_action_space(-20, 25, 0.5, 3.5)
    assert (cont.steering_angle.low, cont.steering_angle.high) == (-20.0, 25.0)
    assert (cont.speed.low, cont.speed.high) == (0.5, 3.5)


def test_spec_grammar() -> None:
    assert parse_action_space_spec("default") == default_discrete_space()
    assert parse_action_space_spec("console:30:5:0.8:2") == default_discrete_space()
    assert parse_action_space_spec("5x2@0.8") == default_discrete_space()
    beginner = parse_action_space_spec("3x3@1.0")
    assert beginner == console_action_space(30, 3, 1.0, 3)
    assert parse_action_space_spec("3X1@2/20") == console_action_space(20, 3, 2.0, 1)
    assert _pairs(parse_action_space_spec("list:-20/1,0/2,20/1")) == [
        (-20.0, 1.0),
        (0.0, 2.0),
        (20.0, 1.0),
    ]
    cont = parse_action_space_spec("continuous:-30:30:0.5:4")
    assert cont == continuous_action_space(-30, 30, 0.5, 4)


@pytest.mark.parametrize(
    ("spec", "named"),
    [
        ("console:30:5:0.8", "console:MAX_STEER"),
        ("console:30:x:0.8:2", "'x'"),
        ("4x2@1.0", "[3, 5, 7]"),
        ("3x3@5", "5"),
        ("list:-20/1,0", "'0'"),
        ("continuous:-30:30:4:0.5", "speed low (4)"),
        ("continuous:-30:30:a:4", "'a'"),
        ("warp-speed", "unknown action space spec"),
        ("missing.json", "cannot read"),
    ],
)
def test_bad_specs_raise_clear_errors(spec: str, named: str) -> None:
    with pytest.raises(ActionSpaceError) as info:
        parse_action_space_spec(spec)
    assert named in str(info.value)


def test_spec_reads_json_files(tmp_path: Path) -> None:
    bare_list = tmp_path / "actions.json"
    bare_list.write_text(
        json.dumps([{"steering_angle": -10, "speed": 1}, {"steering_angle": 10, "speed": 1}])
    )
    assert _pairs(parse_action_space_spec(str(bare_list))) == [(-10.0, 1.0), (10.0, 1.0)]
    bare_range = tmp_path / "range.json"
    bare_range.write_text(
        json.dumps({"steering_angle": {"low": -20, "high": 20}, "speed": {"low": 1, "high": 3}})
    )
    assert parse_action_space_spec(str(bare_range)) == continuous_action_space(-20, 20, 1, 3)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps([{"steering_angle": 0, "speed": 9}]))
    with pytest.raises(ActionSpaceError, match="speed"):
        parse_action_space_spec(str(bad))


# A model_metadata.json as the DeepRacer console writes it (values typed in for this test).
DEEPRACER_FILE = {
    "action_space": [
        {"steering_angle": -30, "speed": 0.6, "index": 0},
        {"steering_angle": -30, "speed": 1.2, "index": 1},
        {"steering_angle": 0, "speed": 0.6, "index": 2},
        {"steering_angle": 0, "speed": 1.2, "index": 3},
        {"steering_angle": 30, "speed": 0.6, "index": 4},
        {"steering_angle": 30, "speed": 1.2, "index": 5},
    ],
    "sensor": ["FRONT_FACING_CAMERA"],
    "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    "training_algorithm": "clipped_ppo",
    "action_space_type": "discrete",
    "version": "5",
    "preprocess_type": "GREY_SCALE",
    "regional_parameters": [0, 0, 0, 0],
}


def test_reads_a_deepracer_console_file(tmp_path: Path) -> None:
    path = tmp_path / "model_metadata.json"
    path.write_text(json.dumps(DEEPRACER_FILE, indent=4))
    meta = read_model_metadata(path)
    assert meta.sensors == ("camera",)
    assert meta.neural_network == "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"
    assert meta.training_algorithm == "clipped_ppo" and meta.version == "5"
    assert meta.action_space == console_action_space(30, 3, 1.2, 2)
    written = metadata_to_dict(meta)
    for key in ("action_space", "sensor", "neural_network", "training_algorithm", "version"):
        assert written[key] == DEEPRACER_FILE[key]


def test_legacy_file_defaults() -> None:
    meta = metadata_from_dict({"action_space": DEEPRACER_FILE["action_space"], "version": 3})
    assert meta.sensors == ("camera",) and meta.version == "3"
    assert isinstance(meta.action_space, DiscreteActionSpace)


@pytest.mark.parametrize(
    "meta",
    [
        DeepRacerMetadata(
            action_space=console_action_space(30, 7, 3.0, 3), sensors=("stereo", "lidar")
        ),
        DeepRacerMetadata(
            action_space=continuous_action_space(-25, 25, 0.8, 3.6),
            sensors=("camera", "discretized_sector_lidar"),
            neural_network="DEEP_CONVOLUTIONAL_NETWORK",
            lidar_config=LidarConfig(num_sectors=4, num_values_per_sector=6, clipping_dist=1.5),
            training_algorithm="sac",
        ),
    ],
)
def test_write_read_round_trip(tmp_path: Path, meta: DeepRacerMetadata) -> None:
    path = write_model_metadata(tmp_path / "model_metadata.json", meta)
    assert read_model_metadata(path) == meta
    data = json.loads(path.read_text())
    assert data["version"] == "5"
    assert all(s.isupper() for s in data["sensor"])
    if isinstance(meta.action_space, ContinuousActionSpace):
        assert data["action_space_type"] == "continuous"
        assert data["lidar_config"] == {
            "num_sectors": 4,
            "num_values_per_sector": 6,
            "clipping_dist": 1.5,
        }
    else:
        assert [a["index"] for a in data["action_space"]] == list(range(meta.action_space.n))


@pytest.mark.parametrize(
    ("change", "named"),
    [
        ({"sensor": ["FRONT_FACING_CAMERA", "RADAR"]}, "RADAR"),
        ({"sensor": ["FRONT_FACING_CAMERA", "STEREO_CAMERAS"]}, "camera"),
        ({"training_algorithm": "sac"}, "continuous"),
        ({"training_algorithm": "dqn"}, "dqn"),
        ({"action_space_type": "hybrid"}, "hybrid"),
        ({"action_space": [{"steering_angle": 40, "speed": 1}]}, "steering_angle"),
        ({"lidar_config": {"num_sectors": 0}}, "num_sectors"),
    ],
)
def test_bad_metadata_raises(change: dict, named: str) -> None:
    with pytest.raises(ModelMetadataError) as info:
        metadata_from_dict({**DEEPRACER_FILE, **change})
    assert named in str(info.value)


def test_unreadable_metadata_file(tmp_path: Path) -> None:
    with pytest.raises(ModelMetadataError, match="cannot read"):
        read_model_metadata(tmp_path / "nope.json")
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    with pytest.raises(ModelMetadataError, match="not valid JSON"):
        read_model_metadata(broken)
