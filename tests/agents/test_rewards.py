"""Reward-function loading, its error messages, and the bundled samples on real env params."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import arena
from agents.rewards import (
    CHECK_STEPS,
    RewardFunctionError,
    bundled_samples,
    check_reward_episode,
    check_reward_function,
    load_reward_function,
    load_sample,
    resolve_reward,
    sample_episode,
    sample_params,
)

RACE_TYPES = ("time_trial", "object_avoidance", "head_to_model")
SAMPLES = (
    "follow_center_line",
    "stay_inside_borders",
    "prevent_zigzag",
    "object_avoidance",
    "head_to_head",
    "pursuit",
    "progress_rate",
)


def _env_params(race_type: str, steps: int = 6) -> list[dict]:
    """Params of every car after each of a few random steps of a real env."""
    env = arena.parallel_env(race_type=race_type, sensors=("sector_lidar",), seed=7)
    try:
        env.reset(seed=7)
        rng = np.random.default_rng(7)
        collected = []
        for _ in range(steps):
            actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
            _, _, _, _, infos = env.step(actions)
            collected += [info["params"] for info in infos.values()]
        return collected
    finally:
        env.close()


@pytest.fixture(scope="module")
def env_params() -> dict[str, list[dict]]:
    return {race_type: _env_params(race_type) for race_type in RACE_TYPES}


def test_every_sample_is_bundled_and_standalone() -> None:
    samples = bundled_samples()
    assert set(SAMPLES) <= set(samples)
    for path in samples.values():
        imports = [ln for ln in path.read_text().splitlines() if ln.startswith(("import", "from"))]
        assert imports in ([], ["import math"]), f"{path.name} imports {imports}"


@pytest.mark.parametrize("race_type", RACE_TYPES)
@pytest.mark.parametrize("name", SAMPLES)
def test_samples_run_on_real_env_params(env_params, name: str, race_type: str) -> None:
    fn = load_sample(name, race_type)
    for params in env_params[race_type]:
        reward = fn(params)
        assert isinstance(reward, float | int) and math.isfinite(reward)
        assert abs(reward) <= 1e5


def test_progress_rate_pays_the_metres_of_centre_line_a_lap_is_made_of() -> None:
    """In a left turn of radius 2 m, 0.5 m inside the centre line is a third more of the
    lap for each metre driven, 0.5 m outside a fifth less (paid squared); a car pointing
    off the track's direction makes less; off the road, nothing."""
    rate = load_sample("progress_rate")
    angles = np.linspace(0.0, 2.0 * math.pi, 64)[:-1]
    points = [(2.0 * math.cos(a), 2.0 * math.sin(a)) for a in angles]
    circle = [*points, points[0]]  # a closed loop, as track files are

    def beside(k: int, **changes: object) -> dict:
        """On the centre line beside segment k -> k + 1 at 2 m/s, heading along it."""
        a, b = circle[k], circle[k + 1]
        heading = math.degrees(math.atan2(b[1] - a[1], b[0] - a[0]))
        params = {
            "all_wheels_on_track": True,
            "speed": 2.0,
            "heading": heading,
            "waypoints": circle,
            "closest_waypoints": [k, k + 1],
            "distance_from_center": 0.0,
            "is_left_of_center": True,
        }
        return {**params, **changes}

    centre_pay = rate(beside(10))
    assert centre_pay == pytest.approx(0.25, rel=0.01)  # (2 m/s of a 4 m/s car) squared
    inside = beside(10, distance_from_center=0.5)
    assert rate(inside) == pytest.approx(centre_pay / 0.75**2, rel=0.02)
    outside = beside(10, distance_from_center=0.5, is_left_of_center=False)
    assert rate(outside) == pytest.approx(centre_pay / 1.25**2, rel=0.02)
    askew = beside(10, heading=beside(10)["heading"] + 40.0)
    assert rate(askew) == pytest.approx(centre_pay * math.cos(math.radians(40.0)) ** 2, rel=0.02)
    assert rate(beside(10, all_wheels_on_track=False)) < 0.01
    assert rate(beside(len(circle) - 2)) == pytest.approx(centre_pay, rel=0.01)  # the seam


def test_sample_params_have_the_env_keys(env_params) -> None:
    for race_type in RACE_TYPES:
        assert set(sample_params(race_type)) == set(env_params[race_type][0])


def test_samples_prefer_what_they_document() -> None:
    centre = sample_params()
    wide = {**centre, "distance_from_center": 0.45 * centre["track_width"]}
    follow = load_sample("follow_center_line")
    assert follow(centre) > follow(wide)
    zigzag = load_sample("prevent_zigzag")
    assert zigzag(centre) > zigzag({**centre, "steering_angle": 25.0})
    borders = load_sample("stay_inside_borders")
    assert borders({**centre, "all_wheels_on_track": False}) < borders(centre)
    pursuit = load_sample("pursuit")
    assert pursuit({**centre, "speed": 3.0}) > pursuit(centre)

    rate = load_sample("progress_rate")
    assert rate({**centre, "speed": 3.0}) > rate(centre)

    boxes = sample_params("object_avoidance")  # next box 1.5 m ahead in the inner lane
    avoid = load_sample("object_avoidance", "object_avoidance")
    ahead = boxes["closest_objects"][1]
    box_lane = boxes["objects_left_of_center"][ahead]
    boxes["objects_distance"][ahead] = boxes["projection_distance"] + 0.5
    assert avoid({**boxes, "is_left_of_center": not box_lane}) > avoid(
        {**boxes, "is_left_of_center": box_lane}
    )
    passing = {**boxes, "is_left_of_center": not box_lane}
    assert avoid({**passing, "speed": 3.0}) > avoid({**passing, "speed": 1.0})  # racing pays
    cars = sample_params("head_to_model")
    h2h = load_sample("head_to_head", "head_to_model")
    assert h2h({**cars, "is_crashed": True}) < h2h(cars)
    racing = {**cars, "steps": 40, "progress": 10.0}
    assert h2h(racing) > h2h({**racing, "progress": 5.0})  # a lap made faster pays more
    ahead = cars["closest_objects"][1]
    tailing = {**racing, "is_left_of_center": cars["objects_left_of_center"][ahead]}
    tailing["objects_distance"] = list(cars["objects_distance"])
    tailing["objects_distance"][ahead] = (cars["projection_distance"] + 0.3) % cars[
        "track_length"
    ]
    beside = {**tailing, "is_left_of_center": not tailing["is_left_of_center"]}
    assert h2h(beside) > h2h(tailing)  # the other lane, where it can pass, pays more


CLASSIC_EXAMPLES = {
    "centre_bands": """
def reward_function(params):
    width = params["track_width"]
    off_centre = params["distance_from_center"]
    near, mid, far = 0.1 * width, 0.25 * width, 0.5 * width
    if off_centre <= near:
        return 1.0
    elif off_centre <= mid:
        return 0.5
    elif off_centre <= far:
        return 0.1
    return 1e-3
""",
    "wheels_and_speed": """
def reward_function(params):
    SLOW = 0.5
    reward = 1e-3
    if params["all_wheels_on_track"] and params["speed"] >= SLOW:
        reward = 1.0
    return float(reward)
""",
    "steering_penalty": """
def reward_function(params):
    width = params["track_width"]
    reward = 1.0 if params["distance_from_center"] <= 0.25 * width else 0.2
    if abs(params["steering_angle"]) > 15:
        reward *= 0.8
    return float(reward)
""",
    "waypoint_heading": """
import math

def reward_function(params):
    points = params["waypoints"]
    behind, ahead = params["closest_waypoints"]
    dx = points[ahead][0] - points[behind][0]
    dy = points[ahead][1] - points[behind][1]
    track_heading = math.degrees(math.atan2(dy, dx))
    error = abs(track_heading - params["heading"])
    if error > 180:
        error = 360 - error
    reward = 1.0
    if error > 10.0:
        reward *= 0.5
    return float(reward)
""",
}


@pytest.mark.parametrize("name", sorted(CLASSIC_EXAMPLES))
def test_classic_deepracer_examples_run_unchanged(env_params, tmp_path: Path, name: str) -> None:
    path = tmp_path / f"{name}.py"
    path.write_text(CLASSIC_EXAMPLES[name])
    fn = load_reward_function(path)
    for race_type in RACE_TYPES:
        for params in env_params[race_type]:
            assert 0.0 < fn(params) <= 1.0


BROKEN = {
    "syntax": ("def reward_function(params)\n    return 1.0\n", "syntax error at line 1"),
    "missing_function": ("def reward(params):\n    return 1.0\n", "does not define"),
    "not_callable": ("reward_function = 1.0\n", "must be a function, got float"),
    "no_argument": ("def reward_function():\n    return 1.0\n", "exactly one argument"),
    "two_arguments": ("def reward_function(params, more):\n    return 1.0\n", "exactly one"),
    "raises": (
        "def reward_function(params):\n    return params['lap_time'] * 2\n",
        "raised KeyError: 'lap_time' at line 2",
    ),
    "import_fails": ("import not_a_module_here\n", "ModuleNotFoundError"),
    "returns_text": ("def reward_function(params):\n    return 'fast'\n", "must return a number"),
    "returns_none": ("def reward_function(params):\n    pass\n", "got NoneType"),
    "returns_nan": ("def reward_function(params):\n    return float('nan')\n", "finite"),
    "returns_huge": ("def reward_function(params):\n    return 1e6\n", "within +-100000"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_files_give_clear_errors(tmp_path: Path, case: str) -> None:
    source, expected = BROKEN[case]
    path = tmp_path / "reward.py"
    path.write_text(source)
    with pytest.raises(RewardFunctionError) as info:
        load_reward_function(path)
    assert expected in str(info.value)
    assert str(path) in str(info.value)


def test_missing_file_and_unknown_sample(tmp_path: Path) -> None:
    with pytest.raises(RewardFunctionError, match="does not exist"):
        load_reward_function(tmp_path / "nowhere.py")
    with pytest.raises(RewardFunctionError, match="follow_center_line"):
        load_sample("warp_drive")


def test_object_race_smoke_test_catches_object_only_functions(tmp_path: Path) -> None:
    path = tmp_path / "boxes.py"
    path.write_text(
        "def reward_function(params):\n    return params['objects_distance'][1] > 0\n"
    )
    with pytest.raises(RewardFunctionError, match="at line 2"):
        load_reward_function(path)
    assert load_reward_function(path, "object_avoidance")(sample_params("object_avoidance"))


def test_check_does_not_let_the_function_mutate_params() -> None:
    def greedy(params: dict) -> float:
        params["waypoints"].clear()
        params["speed"] = 99.0
        return 1.0

    params = sample_params()
    waypoints = len(params["waypoints"])
    assert check_reward_function(greedy, params) == 1.0
    assert len(params["waypoints"]) == waypoints and params["speed"] == 1.5


def test_resolve_reward_takes_a_file_path_or_a_sample_name(tmp_path: Path) -> None:
    path = tmp_path / "mine.py"
    path.write_text("def reward_function(params):\n    return 0.5\n")
    assert resolve_reward(str(path))(sample_params()) == 0.5
    sample = resolve_reward("follow_center_line", "object_avoidance")
    assert sample(sample_params()) == load_sample("follow_center_line")(sample_params())
    with pytest.raises(RewardFunctionError, match="no sample reward function"):
        resolve_reward("no_such_sample")


STATEFUL = """
STATE = {}

def reward_function(params):
    if params["steps"] == 1:
        STATE.clear()
        STATE["start"] = params["progress"]
        STATE["last_steps"] = 0
    assert params["steps"] == STATE["last_steps"] + 1
    STATE["last_steps"] = params["steps"]
    gained = params["progress"] - STATE["start"]
    return 1.0 + 0.01 * gained
"""


def test_state_set_on_the_first_step_is_accepted_and_runs_in_the_env(tmp_path: Path) -> None:
    path = tmp_path / "stateful.py"
    path.write_text(STATEFUL)
    fn = load_reward_function(path)
    env = arena.parallel_env(sensors=("sector_lidar",), reward_function=fn, seed=3)
    try:
        env.reset(seed=3)
        for _ in range(12):
            actions = {a: 0 for a in env.agents}
            _, rewards, _, _, _ = env.step(actions)
            assert all(math.isfinite(r) and r >= 1.0 for r in rewards.values())
    finally:
        env.close()


def test_sample_episode_is_the_start_of_an_episode() -> None:
    for race_type in RACE_TYPES:
        episode = sample_episode(race_type)
        assert [p["steps"] for p in episode] == list(range(1, CHECK_STEPS + 1))
        progress = [p["progress"] for p in episode]
        assert 0.0 < progress[0] < 5.0 and progress == sorted(set(progress))
        assert {p["track_length"] for p in episode} == {episode[0]["track_length"]}
        assert set(episode[0]) == set(sample_params(race_type))


def test_a_function_that_raises_later_in_the_episode_is_refused_with_its_line(
    tmp_path: Path,
) -> None:
    path = tmp_path / "late.py"
    path.write_text(
        "def reward_function(params):\n"
        "    if params['steps'] == 3:\n"
        "        raise RuntimeError('third step')\n"
        "    return 1.0\n"
    )
    with pytest.raises(RewardFunctionError) as info:
        load_reward_function(path)
    message = str(info.value)
    assert "raised RuntimeError: third step at line 3" in message
    assert "steps=3" in message and str(path) in message


def test_numpy_scipy_and_shapely_are_available_to_reward_functions(tmp_path: Path) -> None:
    path = tmp_path / "libs.py"
    path.write_text(
        "import numpy as np\n"
        "from scipy.spatial import distance\n"
        "from shapely.geometry import LineString, Point\n\n"
        "def reward_function(params):\n"
        "    line = LineString(params['waypoints'])\n"
        "    car = Point(params['x'], params['y'])\n"
        "    car_xy = np.array([params['x'], params['y']])\n"
        "    gap = distance.euclidean(car_xy, params['waypoints'][0])\n"
        "    return float(1.0 / (1.0 + line.distance(car) + 0.0 * gap))\n"
    )
    fn = load_reward_function(path)
    assert 0.0 < fn(sample_params()) <= 1.0


@pytest.mark.parametrize(
    ("returned", "accepted"),
    [
        ("float('nan')", False),
        ("float('-inf')", False),
        ("[1.0]", False),
        ("True", True),
        ("__import__('numpy').float32(0.5)", True),
        ("3", True),
    ],
)
def test_return_values_are_judged_as_deepracer_judges_them(
    tmp_path: Path, returned: str, accepted: bool
) -> None:
    path = tmp_path / "value.py"
    path.write_text(f"def reward_function(params):\n    return {returned}\n")
    if accepted:
        load_reward_function(path)
    else:
        with pytest.raises(RewardFunctionError, match=r"finite|must return a number"):
            load_reward_function(path)


def test_training_starts_with_module_state_untouched_by_the_check(tmp_path: Path) -> None:
    path = tmp_path / "counter.py"
    path.write_text(
        "CALLS = []\n\ndef reward_function(params):\n"
        "    CALLS.append(params['steps'])\n    return float(len(CALLS))\n"
    )
    fn = load_reward_function(path)
    assert fn(sample_params()) == 1.0
    assert check_reward_episode(fn, sample_episode()) == [2.0, 3.0, 4.0, 5.0, 6.0]
