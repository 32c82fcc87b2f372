"""Training and evaluation simtraces agree column by column for the same steps."""

from __future__ import annotations

import torch

import arena
from agents.rewards import resolve_reward
from agents.vecenv import RacingVecEnv
from arena.actions import default_discrete_space
from arena.race import run_race
from arena.simtrace import SIMTRACE_COLUMNS, race_rows

SPACE = default_discrete_space()
HARD_LEFT = 1  # -30 deg at 0.8 m/s: off the track within a second or so


class Always:
    def __init__(self, index: int) -> None:
        self.index = index

    def reset(self) -> None: ...

    def act(self, observation) -> int:
        return self.index


def test_training_and_evaluation_rows_agree_for_the_same_steps() -> None:
    config = arena.make_config(
        track="beginner_loop", mode="training", seed=3, sensors=("lidar",), action_space=SPACE
    )
    reward = "follow_center_line"
    evaluation = run_race(
        config,
        {"car0": Always(HARD_LEFT)},
        reward_functions=resolve_reward(reward, config.race_type),
    )
    expected = race_rows(evaluation, "car0")
    assert expected[-1]["done"] and expected[-1]["episode_status"] == "off_track"

    env = RacingVecEnv(config, reward, num_races=1, num_workers=0)
    try:
        actions = torch.zeros(1, SPACE.n)
        actions[0, HARD_LEFT] = 1.0
        for _ in range(len(expected)):
            env.step(actions)
        rows = env.drain_simtrace()
    finally:
        env.close()

    assert len(rows) == len(expected)
    for training, race in zip(rows, expected, strict=True):
        for column in SIMTRACE_COLUMNS:
            if column != "wall_clock":
                assert training[column] == race[column], (column, training["steps"])
