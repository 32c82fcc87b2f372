"""Who caused a contact (docs/arena.md, "Contacts and fault"), with scripted cars in PyBullet.

Each test puts two cars of a race-mode head-to-model race where a contact will happen,
drives them with fixed commands and reads who the env blamed: only that car is penalised.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import arena
from agents.action_spaces import continuous_action_space
from arena.config import resolve_track
from arena.env import RacingEnv
from arena.rules import ContactParty, RuleBook
from arena.spawn import place

SPACE = continuous_action_space(speed_low=0.5, speed_high=3.0)
STRAIGHT = (0.3, 1.9)  # metres of beginner_loop's start straight


def _env(**rules) -> RacingEnv:
    config = arena.make_config(
        race_type="head_to_model", num_cars=2, action_space=SPACE, laps=1, **rules
    )
    env = arena.parallel_env(config=config)
    env.reset(seed=0)
    return env


def _put(env: RacingEnv, agent: str, arc: float, offset: float, turn_deg: float = 0.0) -> None:
    """Teleport a car to ``(arc, offset)`` facing the track (plus ``turn_deg``), at rest,
    and restart its record there."""
    spot = place(env.track, arc, offset)
    live = env._cars[agent]
    live.car.teleport(spot.x, spot.y, spot.yaw + math.radians(turn_deg))
    env._forget_poses()
    live.last_point = live.car.model_point()
    live.record = env._rules.start(env._arc_of(live.last_point), env.time)


def _action(steer_deg: float, speed: float) -> np.ndarray:
    steer, pace = SPACE.steering_angle, SPACE.speed
    return np.array(
        [
            2.0 * (steer_deg - steer.low) / (steer.high - steer.low) - 1.0,
            2.0 * (speed - pace.low) / (pace.high - pace.low) - 1.0,
        ]
    )


def _drive_to_contact(env: RacingEnv, commands: dict[str, tuple[float, float]], steps: int = 30):
    """Step with fixed ``(steering, speed)`` commands until a contact; that step's infos."""
    for _ in range(steps):
        _, _, _, _, infos = env.step({a: _action(*commands[a]) for a in env.agents})
        if any(info["contacts"] for info in infos.values()):
            return infos
    raise AssertionError("the cars never touched")


def _blame(infos: dict) -> dict[str, list[tuple[str, bool]]]:
    return {a: [(c["other"], c["at_fault"]) for c in i["contacts"]] for a, i in infos.items()}


def test_rear_end_the_car_behind_is_at_fault() -> None:
    env = _env()
    _put(env, "car0", 1.2, 0.0)
    _put(env, "car1", 0.8, 0.0)  # 0.08 m of air between car1's nose and car0's tail
    infos = _drive_to_contact(env, {"car0": (0.0, 0.5), "car1": (0.0, 2.5)})
    assert _blame(infos) == {"car0": [("car1", False)], "car1": [("car0", True)]}
    assert infos["car1"]["episode_status"] == "crashed" and infos["car1"]["params"]["is_crashed"]
    assert infos["car0"]["episode_status"] == "in_progress"
    assert (env.record("car0").crash_count, env.record("car1").crash_count) == (0, 1)
    env.close()


@pytest.mark.parametrize("swerver", ["car0", "car1"])
def test_side_by_side_the_car_that_steered_into_the_other_is_at_fault(swerver: str) -> None:
    env = _env()
    _put(env, "car0", 0.8, 0.13)  # left, level with car1: 0.06 m apart
    _put(env, "car1", 0.8, -0.13)
    steer = -20.0 if swerver == "car0" else 20.0  # towards the other car
    commands = {a: (steer if a == swerver else 0.0, 1.0) for a in ("car0", "car1")}
    infos = _drive_to_contact(env, commands)
    other = "car1" if swerver == "car0" else "car0"
    assert _blame(infos) == {swerver: [(other, True)], other: [(swerver, False)]}
    assert env.record(swerver).crash_count == 1 and env.record(other).crash_count == 0
    env.close()


def test_side_by_side_both_steering_together_neither_is_at_fault() -> None:
    env = _env()
    _put(env, "car0", 0.8, 0.13)
    _put(env, "car1", 0.8, -0.13)
    infos = _drive_to_contact(env, {"car0": (-20.0, 1.0), "car1": (20.0, 1.0)})
    assert _blame(infos) == {"car0": [("car1", False)], "car1": [("car0", False)]}
    assert env.record("car0").crash_count == env.record("car1").crash_count == 0
    env.close()


def _serve_off_track_penalty(env: RacingEnv, agent: str, other: str) -> dict:
    """Drive ``agent`` off the track at full lock (``other`` drives slowly on); return the
    infos of the step its penalty began (from the next step it is held on the track)."""
    for _ in range(60):
        _, _, _, _, infos = env.step({agent: _action(-30.0, 1.5), other: _action(0.0, 0.5)})
        if infos[agent]["episode_status"] == "off_track":
            return infos
    raise AssertionError(f"{agent} never left the track")


def test_a_car_rejoining_after_a_respawn_is_at_fault_against_one_already_racing() -> None:
    env = _env(penalties={"off_track_s": 1.0})
    _serve_off_track_penalty(env, "car1", "car0")
    for _ in range(30):  # until car1 is released
        _, _, _, _, infos = env.step({"car0": _action(0.0, 0.5), "car1": _action(0.0, 0.5)})
        if infos["car1"]["episode_status"] == "in_progress":
            break
    assert env._cars["car1"].hold is None
    state = env._cars["car1"].car.state()
    arc = float(env.track.project(np.array([[state.x, state.y]])).arc_length[0])
    offset = float(env.track.project(np.array([[state.x, state.y]])).offset[0])
    # car0 comes up right behind the rejoining car1 and runs into it: behind, yet not at fault
    _put(env, "car0", arc - env._cars["car1"].car.spec.length - 0.003, offset)  # origin to origin
    infos = _drive_to_contact(env, {"car0": (0.0, 2.5), "car1": (0.0, 0.5)}, steps=5)
    assert _blame(infos) == {"car0": [("car1", False)], "car1": [("car0", True)]}
    assert env.record("car0").crash_count == 0 and env.record("car1").crash_count == 1
    env.close()


def test_a_moving_car_touching_a_held_car_is_at_fault_even_from_ahead() -> None:
    env = _env(penalties={"off_track_s": 5.0})
    _serve_off_track_penalty(env, "car1", "car0")
    env.step({"car0": _action(0.0, 0.5), "car1": _action(0.0, 0.5)})
    held = env._cars["car1"]
    assert held.hold is not None and env.record("car1").frozen
    # car0 stands 0.45 m ahead of the held car in the other lane and drives back into it
    across = 0.12 if held.hold.offset < 0 else -0.12
    _put(env, "car0", held.hold.arc + 0.45, held.hold.offset + across, turn_deg=180.0 - 25.0)
    turn = 20.0 if across > 0 else -20.0
    infos = _drive_to_contact(env, {"car0": (turn, 1.0), "car1": (0.0, 0.5)}, steps=20)
    assert _blame(infos) == {"car0": [("car1", True)], "car1": [("car0", False)]}
    assert infos["car1"]["episode_status"] == "pause"
    assert env.record("car0").crash_count == 1 and env.record("car1").crash_count == 0
    env.close()


def test_fault_rules_never_blame_both_parties() -> None:
    config = arena.make_config(race_type="head_to_model", num_cars=2)
    rules = RuleBook(resolve_track(config)[0], "race", 1, config.penalties, None, 60.0)
    rng = np.random.default_rng(0)
    kinds = ["car", "car", "car", "bot", "box"]
    for _ in range(2000):
        a, b = (
            ContactParty(
                kinds[int(rng.integers(len(kinds)))],
                float(rng.uniform(0.0, 1.0)),
                float(rng.normal(0.0, 0.02)),
                held=bool(rng.random() < 0.2),
                rejoining=bool(rng.random() < 0.2),
            )
            for _ in range(2)
        )
        assert not (rules.at_fault(a, b) and rules.at_fault(b, a)), (a, b)
