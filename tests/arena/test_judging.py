"""Every car of a step is judged on one world state, whatever order the cars are listed in."""

from __future__ import annotations

import math

import numpy as np
import pytest

import arena
import arena.env as env_module
from arena.env import RacingEnv

NAMES = ("ann", "bob", "cat")


def _race(order: tuple[str, ...], steps: int = 300) -> tuple[list[dict], RacingEnv]:
    """A 3-car race-mode race with seeded random actions (one stream per car name);
    every step's ``{car: (params, reward, info)}`` and the env at the end."""
    config = arena.make_config(
        race_type="head_to_model", num_cars=3, laps=2, time_limit_s=60.0, seed=5
    )
    cars = [
        car.model_copy(update={"name": name})
        for car, name in zip(config.cars, order, strict=True)
    ]
    env = arena.parallel_env(config=config.model_copy(update={"cars": tuple(cars)}))
    env.reset(seed=5)
    streams = {name: np.random.default_rng(NAMES.index(name)) for name in order}
    steps_seen = []
    for _ in range(steps):
        actions = {a: int(streams[a].integers(env.action_space(a).n)) for a in env.agents}
        _, rewards, _, _, infos = env.step(actions)
        steps_seen.append({a: (infos[a]["params"], rewards[a], infos[a]) for a in infos})
        if not env.agents:
            break
    return steps_seen, env


@pytest.fixture
def grid_by_name(monkeypatch: pytest.MonkeyPatch) -> None:
    """Each car starts on the grid slot of its name, whatever its place in the list (the
    grid itself follows the list order; what is tested here is the judging)."""
    real = env_module.car_grid

    def by_name(config, *args, **kwargs):
        listed = [car.name for car in config.cars]
        canonical = config.model_copy(
            update={"cars": tuple(sorted(config.cars, key=lambda c: NAMES.index(c.name)))}
        )
        slots = real(canonical, *args, **kwargs)
        return [slots[NAMES.index(name)] for name in listed]

    monkeypatch.setattr(env_module, "car_grid", by_name)


def test_listing_order_changes_no_params_reward_or_result(grid_by_name: None) -> None:
    first, env_a = _race(NAMES)
    second, env_b = _race(("cat", "ann", "bob"))
    assert len(first) == len(second)
    contacts = 0
    for step_a, step_b in zip(first, second, strict=True):
        assert step_a.keys() == step_b.keys()
        for name in step_a:
            assert step_a[name] == step_b[name], name
            contacts += len(step_a[name][2]["contacts"])
    assert contacts > 0  # the cars did meet
    for name in NAMES:
        assert env_a.record(name) == env_b.record(name)
    env_a.close()
    env_b.close()


def test_every_observer_sees_every_object_where_it_was_judged() -> None:
    """Within a step each car's own (x, y) and the objects_location it sees of the others
    are one scene, penalised cars included; and no lidar sees an object nearer than that."""
    config = arena.make_config(race_type="head_to_model", num_cars=4, laps=2, time_limit_s=40.0)
    env = arena.parallel_env(config=config)
    env.reset(seed=1)
    rng = np.random.default_rng(1)
    respawns = 0
    for _ in range(400):
        actions = {a: int(rng.integers(env.action_space(a).n)) for a in env.agents}
        obs, _, _, _, infos = env.step(actions)
        scenes = {
            a: sorted([(i["params"]["x"], i["params"]["y"]), *i["params"]["objects_location"]])
            for a, i in infos.items()
        }
        assert all(scene == next(iter(scenes.values())) for scene in scenes.values())
        for agent, info in infos.items():
            params = info["params"]
            yaw = math.radians(params["heading"])
            origin = np.array(env._cars[agent].car.spec.rear_axle(params["x"], params["y"], yaw))
            nearest = min(math.dist(origin, loc) for loc in params["objects_location"])
            # the lidar cannot see a car nearer than its model point less its reach (0.25 m)
            assert obs[agent]["lidar"].min() >= min(nearest - 0.25 - 0.05, 1.0) - 1e-6
        respawns += sum(i["episode_status"] in ("crashed", "off_track") for i in infos.values())
        if not env.agents:
            break
    assert respawns >= 3
    env.close()
