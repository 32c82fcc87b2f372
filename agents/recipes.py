"""Named training recipes: how each race type is trained (``slipstream train --recipe``).

A recipe is a set of ``train`` options in their command-line forms (``agents/options.py``)
and DeepRacer hyperparameters. Options given on the command line win over the recipe's,
and an explicit ``hyperparameters.json`` replaces the recipe's hyperparameters. How well
each recipe drives after a fixed budget: ``benchmarks/race_quality.py`` and
``benchmarks/time_to_lap.py`` (results in ``benchmarks/RESULTS.md``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from agents.hyperparameters import Hyperparameters
from agents.options import settings_from_options
from agents.settings import TrainSettings

# Continuous steering of +-30 degrees at 0.5 to 4 m/s: room to learn the racing line.
RACING_ACTIONS = "continuous:-30:30:0.5:4"
# The camera-only recipes' network reads the last two camera frames (DeepRacer's defaults
# otherwise): it sees how fast the road and the cars ahead move, and with DeepRacer's
# lagging steering it laps at its teacher's pace where one frame left it 1.5-2.3 times
# slower (benchmarks/RESULTS.md, "The self-play sample: two tracks, then two camera frames").
TWO_FRAMES = {"stack_size": 2}


@dataclass(frozen=True)
class Recipe:
    """One way of training: ``train`` options (command-line forms) and hyperparameters."""

    name: str
    summary: str  # one line, for ``--list-recipes``
    options: Mapping[str, Any]
    hyperparameters: Mapping[str, Any] = field(default_factory=dict)
    # The recipe of the run this one clones (``--clone``); that run's model is the opponent.
    parent: str | None = None

    def hyperparameters_model(self) -> Hyperparameters:
        """The recipe's hyperparameters (DeepRacer's defaults for those it does not set)."""
        return Hyperparameters(**self.hyperparameters)

    def settings(
        self, explicit: Mapping[str, Any] | None = None, **python_only: Any
    ) -> TrainSettings:
        """The settings this recipe trains with, ``explicit`` options (command-line forms)
        winning; the recipe's name is recorded in them."""
        options = {**self.options, **(explicit or {})}
        return settings_from_options(options, recipe=self.name, **python_only)


def parent_model(parent_run: Path) -> Path:
    """The packed model of the run a recipe with a ``parent`` clones (its opponent)."""
    path = parent_run / "model" / "model.zip"
    if not path.is_file():
        raise ValueError(f"{parent_run} has no model/model.zip to race against: train it first")
    return path


# Evaluations of the race-type recipes stop after 60 simulated seconds: 3 laps of a car worth
# measuring take well under that, and a car stuck behind a box costs no training minutes.
_RACE_TYPE_EVALS = {"workers": 2, "eval_time_limit": 60.0}

RECIPES: dict[str, Recipe] = {
    recipe.name: recipe
    for recipe in (
        Recipe(
            name="time_trial",
            summary="beginner_loop, camera (two frames), continuous 0.5-4 m/s; imitates the "
            "pursuit driver",
            options={
                "race_type": "time_trial",
                "track": "beginner_loop",
                "sensors": "camera",
                "action_space": RACING_ACTIONS,
                "reward_fn": "pursuit",
                "teacher": "pursuit",
                **_RACE_TYPE_EVALS,
            },
            hyperparameters=TWO_FRAMES,
        ),
        Recipe(
            name="object_avoidance",
            summary="slipstream_speedway (room beside a box), camera + lidar; imitates the "
            "pursuit driver around 6 random boxes",
            options={
                "race_type": "object_avoidance",
                "track": "slipstream_speedway",
                "sensors": "camera,lidar",  # the lidar sees boxes and cars, never the road
                "action_space": RACING_ACTIONS,
                "reward_fn": "object_avoidance",
                "teacher": "pursuit",
                **_RACE_TYPE_EVALS,
            },
        ),
        Recipe(
            name="head_to_bot",
            summary="slipstream_speedway (DeepRacer's width, room to pass), camera + lidar, "
            "continuous 0.5-3 m/s; imitates the pursuit driver among bot cars",
            options={
                "race_type": "head_to_bot",
                "track": "slipstream_speedway",
                "sensors": "camera,lidar",
                "action_space": "continuous:-30:30:0.5:3",
                "reward_fn": "head_to_head",
                "teacher": "pursuit",
                **_RACE_TYPE_EVALS,
            },
        ),
        Recipe(
            name="head_to_model",
            summary="slipstream_speedway (DeepRacer's width, room to pass); needs --clone of a "
            "time_trial run; races a pool of its own snapshots, pursuit racers at 60-75% of "
            "its pace and that run's model, imitating the passing pursuit driver",
            options={
                "race_type": "head_to_model",
                "track": "slipstream_speedway",  # beginner_loop (0.76 m) leaves no room to pass
                "sensors": "camera",  # the parent's: a clone needs its sensors and preset
                "action_space": RACING_ACTIONS,  # and its number of actions
                "reward_fn": "head_to_head",
                "teacher": "pursuit",
                "selfplay": "pool",
                # racers the teacher passes, so more of its labels behind a car are passes
                # (benchmarks/RESULTS.md, "Slower paced racers in the imitation pool")
                "paced_rivals": "0.6,0.65,0.7,0.75",
                **_RACE_TYPE_EVALS,
            },
            hyperparameters=TWO_FRAMES,  # the parent's: a clone needs its network
            parent="time_trial",
        ),
        Recipe(
            name="head_to_model_ppo",
            summary="PPO on the head_to_head reward after head_to_model imitation; needs "
            "--clone of a head_to_model run; held near the passing pursuit driver, racing "
            "its snapshots, paced pursuit racers and that run's model",
            options={
                "race_type": "head_to_model",
                "track": "slipstream_speedway",
                "sensors": "camera",  # the head_to_model run's
                "action_space": RACING_ACTIONS,
                "reward_fn": "head_to_head",
                "anchor": "pursuit",  # PPO alone loses what imitation gave in minutes
                "anchor_weight": 4.0,  # at 1 it lost the teacher's pace (RESULTS.md)
                "selfplay": "pool",
                **_RACE_TYPE_EVALS,
            },
            hyperparameters=TWO_FRAMES,
            parent="head_to_model",
        ),
        Recipe(
            name="first_laps",
            summary="fast start: PPO from scratch, camera, 3x3 discrete at 1 m/s, "
            "follow_center_line, cheap updates; clean laps in about a minute",
            options={
                "race_type": "time_trial",
                "track": "beginner_loop",
                "sensors": "camera",
                "action_space": "3x3@1.0",
                "reward_fn": "follow_center_line",
                "workers": 0,
                "races": 1,
                "eval_every": 4,
                "eval_time_limit": 240.0,  # 3 laps at the slowest speed (1/3 m/s) fit
            },
            # 512 steps an iteration, 2 epochs of batch 64: cheap updates on a 2-core CPU.
            hyperparameters={
                "num_episodes_between_training": 8,
                "batch_size": 64,
                "num_epochs": 2,
                "discount_factor": 0.99,
                "lr": 5e-4,
            },
        ),
    )
}


def get_recipe(name: str) -> Recipe:
    """The recipe called ``name``; a ValueError listing the recipes otherwise."""
    try:
        return RECIPES[name]
    except KeyError:
        raise ValueError(f"no recipe {name!r}; recipes: {', '.join(RECIPES)}") from None
