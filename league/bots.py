"""The league's bots: the scripted cars that fill head-to-model grids.

A head-to-model round gives a model entered alone a bot to race, and a bot takes the place
of an entry suspended from the event when that leaves fewer than two cars. Which bot is
the event's ``round_bot``, chosen when it is created (default ``racer``):

- ``pursuit``: pure pursuit on the racing line in the DeepRacer console's default car
  (five steering angles at 0.4 or 0.8 m/s), blind to other cars: a slow car to get past.
- ``racer``: the passing pursuit driver (the teacher that imitation copies) in the racing
  car (continuous, 0.5-4 m/s): it laps at the racing line's pace, passes a slower car where
  the pass completes and follows one it cannot pass.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Literal, get_args

from arena.actions import ContinuousActionSpace
from arena.config import CarConfig

if TYPE_CHECKING:
    from arena.actions import ActionSpace
    from arena.policy import Policy
    from tracks.track import Track

BotLevel = Literal["pursuit", "racer"]
BOT_LEVELS: tuple[str, ...] = get_args(BotLevel)
DEFAULT_BOT: BotLevel = "racer"
"""A new event's bot. Events created before events had a ``round_bot`` keep ``pursuit``."""


def _known(level: str) -> str:
    """``level`` itself, or ``ValueError`` naming the league's bots."""
    if level not in BOT_LEVELS:
        raise ValueError(f"unknown bot {level!r}: the league's bots are {', '.join(BOT_LEVELS)}")
    return level


def bot_car(name: str, level: str) -> CarConfig:
    """The car of a ``level`` bot named ``name`` (``ValueError`` for an unknown level): the
    racing car for ``racer``, the console's default action space for ``pursuit``."""
    if _known(level) == "racer":
        return CarConfig(name=name, action_space=ContinuousActionSpace())
    return CarConfig(name=name)


def bot_driver(level: str, track: Track, action_space: ActionSpace) -> Policy:
    """The driver of a ``level`` bot on ``track`` in its car's ``action_space``."""
    from arena.pursuit import PassingPursuitPolicy, PurePursuitPolicy

    driver = PassingPursuitPolicy if _known(level) == "racer" else PurePursuitPolicy
    return driver(track, action_space)
