"""The arena: DeepRacer-style multi-car racing in PyBullet, as a PettingZoo env.

Quick start::

    import arena
    env = arena.parallel_env(track="beginner_loop", num_cars=2, race_type="head_to_model")
    observations, infos = env.reset(seed=42)
    actions = {agent: env.action_space(agent).sample() for agent in env.agents}
    observations, rewards, terminations, truncations, infos = env.step(actions)
"""

from __future__ import annotations

from typing import Any

from arena.config import (
    BotConfig,
    CarConfig,
    ConfigError,
    ObstacleConfig,
    Penalties,
    PhysicsConfig,
    RaceConfig,
)


def make_config(
    track: str = "beginner_loop",
    race_type: str = "time_trial",
    num_cars: int | None = None,
    sensors: tuple[str, ...] | list[str] = ("lidar",),
    action_space: Any = None,
    mode: str = "race",
    seed: int = 0,
    direction: str | None = None,
    stack_size: int = 1,
    **rules: Any,
) -> RaceConfig:
    """Build a :class:`RaceConfig` from the common keyword settings.

    Every car stacks ``stack_size`` frames of each sensor in its observations.
    ``num_cars`` defaults to 1 (2 for head-to-model); obstacles and bots get their
    default sections for object-avoidance and head-to-bot races unless given in
    ``rules`` (any other :class:`RaceConfig` field: ``laps``, ``penalties``, ...).
    """
    if num_cars is None:
        num_cars = 2 if race_type == "head_to_model" else 1
    if not isinstance(num_cars, int) or isinstance(num_cars, bool):
        raise ConfigError(f"num_cars must be a whole number, got {num_cars!r}")
    car: dict[str, Any] = {"sensors": tuple(sensors), "stack_size": stack_size}
    if action_space is not None:
        car["action_space"] = action_space
    cars = [{"name": f"car{i}", **car} for i in range(num_cars)]
    if race_type == "object_avoidance":
        rules.setdefault("obstacles", ObstacleConfig())
    if race_type == "head_to_bot":
        rules.setdefault("bots", BotConfig())
    return RaceConfig.build(
        track=track,
        direction=direction,
        race_type=race_type,
        mode=mode,
        cars=cars,
        seed=seed,
        **rules,
    )


def parallel_env(
    track: str = "beginner_loop",
    race_type: str = "time_trial",
    num_cars: int | None = None,
    sensors: tuple[str, ...] | list[str] = ("lidar",),
    action_space: Any = None,
    reward_function: Any = None,
    mode: str = "race",
    render_mode: str | None = None,
    seed: int = 0,
    config: RaceConfig | None = None,
    **rules: Any,
):
    """PettingZoo's parallel env for a race built from keyword settings (or a config)."""
    from arena.env import RacingEnv

    if config is None:
        config = make_config(track, race_type, num_cars, sensors, action_space, mode, seed, **rules)
    return RacingEnv(config, reward_functions=reward_function, render_mode=render_mode)


def env(**kwargs: Any):
    """The same race as an AEC env (PettingZoo's turn-based API)."""
    from pettingzoo.utils.conversions import parallel_to_aec

    return parallel_to_aec(parallel_env(**kwargs))


__all__ = [
    "BotConfig",
    "CarConfig",
    "ConfigError",
    "ObstacleConfig",
    "Penalties",
    "PhysicsConfig",
    "RaceConfig",
    "env",
    "make_config",
    "parallel_env",
]
