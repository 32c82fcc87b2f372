"""RacingEnv against PettingZoo's API tests and DeepRacer's rules, with real PyBullet."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pettingzoo.test import parallel_api_test, parallel_seed_test

import arena
from arena import world
from arena.config import NO_VARIATION, resolve_track
from arena.drivers import LaneFollowerPolicy
from arena.env import RacingEnv
from arena.lidar import clip_lidar
from arena.race import run_race
from arena.sensors_spec import LIDAR_CLIP
from arena.spawn import GRID_GAP_M

PARAM_KEYS = {
    "all_wheels_on_track",
    "x",
    "y",
    "heading",
    "speed",
    "steering_angle",
    "progress",
    "steps",
    "distance_from_center",
    "track_width",
    "track_length",
    "waypoints",
    "closest_waypoints",
    "is_left_of_center",
    "is_reversed",
    "is_offtrack",
    "is_crashed",
    "projection_distance",
}
OBJECT_KEYS = {
    "closest_objects",
    "objects_location",
    "objects_left_of_center",
    "objects_distance",
    "objects_distance_from_center",
    "objects_heading",
    "objects_speed",
    "object_in_camera",
}
SENSOR_SETS = [
    (1, ("camera", "lidar")),
    (1, ("stereo", "discretized_sector_lidar")),
    (4, ("camera", "sector_lidar")),
    (4, ("stereo", "lidar")),
]


def _env(num_cars: int, sensors: tuple[str, ...], **kwargs) -> RacingEnv:
    race_type = "head_to_model" if num_cars > 1 else "time_trial"
    return arena.parallel_env(race_type=race_type, num_cars=num_cars, sensors=sensors, **kwargs)


@pytest.mark.slow
@pytest.mark.parametrize(("num_cars", "sensors"), SENSOR_SETS)
def test_pettingzoo_parallel_api(num_cars: int, sensors: tuple[str, ...]) -> None:
    parallel_api_test(_env(num_cars, sensors), num_cycles=300)


@pytest.mark.slow
@pytest.mark.parametrize(("num_cars", "sensors"), [SENSOR_SETS[0], SENSOR_SETS[3]])
def test_pettingzoo_seed_test(num_cars: int, sensors: tuple[str, ...]) -> None:
    parallel_seed_test(lambda: _env(num_cars, sensors), num_cycles=50)


def test_observations_match_the_declared_spaces() -> None:
    env = _env(2, ("stereo", "lidar"))
    obs, _ = env.reset(seed=3)
    for agent in env.agents:
        space = env.observation_space(agent)
        assert space.contains(obs[agent])
        assert obs[agent]["stereo"].shape == (120, 160, 2)
        assert obs[agent]["lidar"].dtype == np.float32
        assert obs[agent]["lidar"].min() >= 0.15 and obs[agent]["lidar"].max() <= 1.0
    env.close()


def test_params_carry_every_deepracer_key() -> None:
    env = arena.parallel_env(race_type="time_trial")
    env.reset(seed=0)
    _, _, _, _, infos = env.step({"car0": 4})
    params = infos["car0"]["params"]
    assert set(params) >= PARAM_KEYS | OBJECT_KEYS | {"sim_time"}  # DeepRacer: every key
    assert params["objects_location"] == [] and params["closest_objects"] == [0, 0]
    assert params["steps"] == 1
    assert params["track_length"] == pytest.approx(env.track.length)
    assert params["closest_waypoints"][1] == params["closest_waypoints"][0] + 1
    assert -180 < params["heading"] <= 180
    assert params["all_wheels_on_track"] and not params["is_offtrack"]
    assert params["speed"] == 0.4 and params["steering_angle"] == 0.0  # commanded action 4
    assert set(infos["car0"]) >= {"episode_status", "laps", "lap_times", "penalty_seconds"}
    env.close()


def test_object_keys_appear_with_obstacles() -> None:
    env = arena.parallel_env(race_type="object_avoidance", seed=5)
    _, infos = env.reset()
    params = infos["car0"]["params"]
    assert set(params) >= OBJECT_KEYS
    assert len(params["objects_location"]) == 6
    _, ahead = params["closest_objects"]
    distances = params["objects_distance"]
    mine = params["projection_distance"]
    gaps = [(d - mine) % env.track.length for d in distances]
    assert ahead == int(np.argmin(gaps))
    lanes = params["objects_left_of_center"]
    order = np.argsort(distances)
    assert all(lanes[order[i]] != lanes[order[i + 1]] for i in range(5))  # alternating
    env.close()


def test_reversed_direction_flags_params() -> None:
    env = arena.parallel_env(direction="cw")
    _, infos = env.reset()
    assert infos["car0"]["params"]["is_reversed"]
    assert env.track.direction == "cw"
    env.close()


def test_bad_reward_is_refused_naming_car_and_step() -> None:
    env = arena.parallel_env(reward_function=lambda params: math.nan)
    env.reset()
    with pytest.raises(ValueError, match=r"car 'car0'.*step 1"):
        env.step({"car0": 4})
    env.close()


def test_bot_driver_completes_laps_with_plausible_times() -> None:
    config = arena.make_config(laps=2, time_limit_s=120.0)
    track, _ = resolve_track(config)
    policy = LaneFollowerPolicy(track, config.cars[0].action_space, speed=0.8)
    result = run_race(config, {"car0": policy})
    car = result.car("car0")
    assert car.status == "finished" and car.laps == 2
    assert car.off_track_count == 0 and car.reset_count == 0
    ideal = track.length / 0.8
    assert ideal * 0.95 < car.lap_times[1] < ideal * 1.25
    assert car.total_time == pytest.approx(sum(car.lap_times))


def test_off_track_in_race_mode_costs_the_penalty_and_respawns() -> None:
    class FullLock:
        def reset(self) -> None: ...

        def act(self, observation):
            return 1  # -30 deg at 0.8 m/s: drives off the track to the right

    config = arena.make_config(laps=1, time_limit_s=12.0)
    result = run_race(config, {"car0": FullLock()})
    car = result.car("car0")
    statuses = result.trace["car0"]["status"]
    assert car.off_track_count >= 1
    assert "pause" in statuses
    first = statuses.index("off_track")
    pause_steps = round(config.penalties.off_track_s * config.physics.control_hz)
    assert statuses[first + 1 : first + pause_steps] == ["pause"] * (pause_steps - 1)
    assert car.penalty_seconds >= config.penalties.off_track_s
    assert car.status == "time_up"


def test_object_avoidance_crash_respawns_behind_the_box_in_the_other_lane() -> None:
    config = arena.make_config(
        race_type="object_avoidance",
        obstacles={"count": 1, "positions": [[15.0, "inner"]]},
        laps=1,
        time_limit_s=25.0,
    )
    track, _ = resolve_track(config)
    inner = LaneFollowerPolicy(track, config.cars[0].action_space, speed=0.8)
    inner.follower.lane = "inner"
    result = run_race(config, {"car0": inner})
    car = result.car("car0")
    assert car.crash_count >= 1
    statuses = result.trace["car0"]["status"]
    i = statuses.index("crashed")
    x, y = result.trace["car0"]["x"][i + 1], result.trace["car0"]["y"][i + 1]
    box_arc = 0.15 * track.length
    proj = track.project(np.array([[x, y]]))
    assert proj.arc_length[0] == pytest.approx(box_arc - 1.0 - 0.0, abs=0.35)
    assert not proj.is_left_of_center[0]  # inner = left on a ccw loop; respawned outer


def test_head_to_model_rear_car_is_at_fault() -> None:
    config = arena.make_config(
        race_type="head_to_model",
        num_cars=2,
        laps=1,
        time_limit_s=15.0,
        variation=NO_VARIATION,  # car1 starts right behind car0, commands as given
    )
    track, _ = resolve_track(config)
    space = config.cars[0].action_space
    slow = LaneFollowerPolicy(track, space, speed=0.4)
    fast = LaneFollowerPolicy(track, space, speed=0.8)
    slow.follower.lane = fast.follower.lane = "inner"  # one line: car1 runs into car0
    result = run_race(config, {"car0": slow, "car1": fast})  # car1 starts behind
    assert result.car("car1").crash_count >= 1
    assert result.car("car0").crash_count == 0


def test_top_down_render_shows_the_cars() -> None:
    env = arena.parallel_env(race_type="head_to_bot", render_mode="rgb_array")
    env.reset()
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    red = (frame[..., 0] > 180) & (frame[..., 1] < 60) & (frame[..., 2] < 60)
    assert red.sum() > 10  # car0 is red
    env.close()


def bot_race_hash() -> str:
    """sha256 of a head-to-bot race's canonical JSON (camera and lidar on)."""
    import hashlib

    config = arena.make_config(
        race_type="head_to_bot", laps=1, time_limit_s=10.0, seed=11, sensors=("camera", "lidar")
    )
    track, _ = resolve_track(config)
    policy = LaneFollowerPolicy(track, config.cars[0].action_space, speed=1.0)
    return hashlib.sha256(run_race(config, {"car0": policy}).to_json().encode()).hexdigest()


@pytest.mark.slow
def test_race_is_bit_identical_in_a_fresh_process() -> None:
    import subprocess
    import sys
    from pathlib import Path

    code = "from tests.arena.test_env import bot_race_hash; print(bot_race_hash())"
    root = Path(__file__).resolve().parents[2]
    fresh = [
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root
        ).stdout.split()[-1]
        for _ in range(2)
    ]
    assert fresh[0] == fresh[1] == bot_race_hash()


def _episodes_of_random_driving(race_type: str, episodes: int) -> list[tuple]:
    """Each step's observations (bytes) and rewards over ``episodes`` seeded resets of a
    race on random actions that meets bots or boxes (the episodes end off the road)."""
    env = arena.parallel_env(
        race_type=race_type, mode="training", sensors=("camera", "lidar"), seed=5
    )
    rng = np.random.default_rng(0)
    trace = []
    for _ in range(episodes):
        obs, _ = env.reset()
        for _ in range(60):
            actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
            obs, rewards, *_ = env.step(actions)
            trace.append(([o.tobytes() for ob in obs.values() for o in ob.values()], rewards))
            if not env.agents:
                break
    env.close()
    return trace


@pytest.mark.parametrize("race_type", ["head_to_bot", "object_avoidance"])
def test_episodes_in_a_reused_world_repeat_those_in_fresh_worlds(
    race_type: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    reused = _episodes_of_random_driving(race_type, 3)
    build = world.create_world

    def fresh_world(settings: world.PhysicsSettings, client: int | None = None) -> int:
        if client is not None:
            world.close(client)
        return build(settings)

    monkeypatch.setattr(world, "create_world", fresh_world)
    assert reused == _episodes_of_random_driving(race_type, 3)


def test_training_restart_car_starts_a_new_episode_for_one_car() -> None:
    env = arena.parallel_env(race_type="head_to_model", num_cars=2, mode="training")
    _, infos = env.reset(seed=0)
    driver = LaneFollowerPolicy(env.track, env.config.cars[1].action_space, speed=0.8)
    for _ in range(200):
        actions = {"car0": 1, "car1": driver.act({}, params=infos["car1"]["params"])}
        _, _, _, _, step_infos = env.step(actions)  # car0 circles at full lock
        infos.update(step_infos)
        if "car0" not in env.agents:
            break
    assert "car0" not in env.agents and "car1" in env.agents
    # Its full-lock circle (about 0.8 m across: the wheels scrub) leaves the 0.76 m road.
    assert env.record("car0").status == "off_track"
    obs, info = env.restart_car("car0")
    assert env.agents == ["car0", "car1"]
    assert env.observation_space("car0").contains(obs)
    assert info["episode_status"] == "prepare" and info["params"]["all_wheels_on_track"]
    _, _, terms, _, step_infos = env.step({"car0": 4, "car1": 4})
    assert step_infos["car0"]["params"]["steps"] == 1 and not terms["car0"]
    env.close()


def _car0_off_while_car1_races() -> tuple[RacingEnv, dict]:
    """A two-car training race stepped until car0, circling at full lock, ends its episode
    (off the road) while car1 follows its lane at 0.8 m/s; returns the env and each car's last
    info."""
    env = arena.parallel_env(race_type="head_to_model", num_cars=2, mode="training")
    _, infos = env.reset(seed=0)
    driver = LaneFollowerPolicy(env.track, env.config.cars[1].action_space, speed=0.8)
    while "car0" in env.agents:
        _, _, _, _, step_infos = env.step(
            {"car0": 1, "car1": driver.act({}, params=infos["car1"]["params"])}
        )
        infos.update(step_infos)
    return env, infos


def test_a_car_restarted_near_a_rival_starts_behind_it_in_the_other_lane() -> None:
    env, infos = _car0_off_while_car1_races()
    _, info = env.restart_car("car0", near=("car1", -1.0))
    me, rival = info["params"], infos["car1"]["params"]
    behind = (rival["projection_distance"] - me["projection_distance"]) % me["track_length"]
    assert behind == pytest.approx(1.0, abs=0.1)
    assert me["is_left_of_center"] != rival["is_left_of_center"]
    assert me["all_wheels_on_track"] and info["episode_status"] == "prepare"
    env.close()


def test_cars_restarted_on_a_grid_stand_in_its_slots_in_the_order_given() -> None:
    env, infos = _car0_off_while_car1_races()
    assert infos["car1"]["params"]["speed"] > 0.3
    starts = env.restart_on_grid(["car1", "car0"])  # car1 in front, though it was racing
    assert env.agents == ["car0", "car1"]
    front, back = starts["car1"][1]["params"], starts["car0"][1]["params"]
    behind = (front["projection_distance"] - back["projection_distance"]) % back["track_length"]
    assert behind == pytest.approx(GRID_GAP_M, abs=0.1)
    assert front["is_left_of_center"] != back["is_left_of_center"]
    for car, (first, info) in starts.items():
        assert env.observation_space(car).contains(first)
        assert info["episode_status"] == "prepare" and info["params"]["speed"] == 0.0
        assert info["params"]["all_wheels_on_track"] and info["params"]["progress"] == 0.0
    _, _, _, _, step_infos = env.step({"car0": 4, "car1": 4})
    assert step_infos["car0"]["params"]["steps"] == step_infos["car1"]["params"]["steps"] == 1
    with pytest.raises(ValueError, match="distinct cars"):
        env.restart_on_grid(["car1", "car1"])
    env.close()


def test_races_are_never_restarted_on_a_grid() -> None:
    env = arena.parallel_env(race_type="head_to_model", num_cars=2, mode="race")
    env.reset(seed=0)
    with pytest.raises(RuntimeError, match="training mode"):
        env.restart_on_grid(["car0", "car1"])
    env.close()


def test_a_lone_training_car_meets_a_new_box_layout_each_episode() -> None:
    """Random boxes are redrawn ahead of each new start, in the physics as in the params."""
    import pybullet as p

    from arena.spawn import START_CLEAR_M

    env = arena.parallel_env(race_type="object_avoidance", mode="training", seed=3)
    _, infos = env.reset()
    layouts = [infos["car0"]["params"]["objects_location"]]
    for _ in range(3):
        while "car0" in env.agents:
            env.step({"car0": 1})  # full lock: off the road within a few metres
        _, info = env.restart_car("car0")
        params = info["params"]
        layouts.append(params["objects_location"])
        ahead = [(d - params["projection_distance"]) % params["track_length"]
                 for d in params["objects_distance"]]  # fmt: skip
        assert min(ahead) >= START_CLEAR_M - 0.3  # the new start is clear
        for box, location in zip(env._obstacles, params["objects_location"], strict=True):
            position, _ = p.getBasePositionAndOrientation(box.body, physicsClientId=env._client)
            assert position[:2] == pytest.approx(location, abs=1e-6)  # what the car can hit
    assert len({tuple(map(tuple, layout)) for layout in layouts}) == len(layouts)
    env.close()


def test_sensors_see_the_car_ahead() -> None:
    env = arena.parallel_env(
        race_type="head_to_model", num_cars=2, sensors=["camera", "lidar"], variation=NO_VARIATION
    )
    obs, _ = env.reset(seed=0)
    lidar = obs["car1"]["lidar"]  # car1 starts 0.8 m behind car0, one lane to the right
    angles = env._lidar.beam_angles
    left_front = (angles > 0) & (angles < 0.6)
    assert lidar[left_front].min() < 0.95
    assert lidar[np.abs(angles) > 1.5].min() == pytest.approx(1.0)  # nothing beside or behind
    alone = arena.parallel_env(race_type="time_trial", sensors=["camera", "lidar"])
    alone_obs, _ = alone.reset(seed=0)
    assert alone_obs["car0"]["lidar"].min() == pytest.approx(1.0)
    state = env._cars["car1"].car.state()
    empty_road = env._camera.render(state.x, state.y, state.yaw, boxes=())
    differs = obs["car1"]["camera"][..., 0] != empty_road
    assert differs.sum() > 100  # car0 covers part of car1's picture
    assert differs[:, :80].sum() > differs[:, 80:].sum()  # ... on the left
    env.close()
    alone.close()


@pytest.mark.parametrize(
    ("race_type", "num_cars"), [("head_to_model", 4), ("head_to_bot", 2), ("object_avoidance", 1)]
)
def test_lidar_culling_in_races_changes_no_view(race_type: str, num_cars: int) -> None:
    """Scanning all cars at once, only towards nearby objects, sees what full scans see."""
    sensors = ["lidar"]
    env = arena.parallel_env(race_type=race_type, num_cars=num_cars, sensors=sensors)
    _, infos = env.reset(seed=3)
    space = env.config.cars[0].action_space
    followers = {a: LaneFollowerPolicy(env.track, space) for a in env.agents}
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(120):
        actions = {  # half random, half lane following: the cars meet, bump and spread
            a: followers[a].act({}, infos[a]["params"])
            if rng.random() < 0.5
            else int(rng.integers(env.action_space(a).n))
            for a in env.agents
        }
        _, _, _, _, infos = env.step(actions)
        noise_state = env.rng.bit_generator.state
        seen = env._scan_lidars(env.agents)  # what the cars' observations are made of
        env.rng.bit_generator.state = noise_state
        for agent in sorted(env.agents, key=env._order.index):  # the batch's (noise) order
            car = env._cars[agent].car
            state = car.state()
            full = env._lidar.scan(state.x, state.y, state.yaw, [car.body_id], rng=env.rng)
            assert np.array_equal(clip_lidar(full), clip_lidar(seen[agent]))
            hits += int((full < LIDAR_CLIP).sum())
        if not env.agents:
            break
    assert hits > 200
    env.close()
