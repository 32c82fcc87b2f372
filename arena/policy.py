"""The ``Policy`` protocol: anything that can drive a car in a race."""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable


@runtime_checkable
class Policy(Protocol):
    """Drives one car. Bots, ONNX submissions and live torch policies all satisfy this.

    ``reset()`` is called before each race (or episode); ``act(observation)`` receives the
    car's observation dict (one entry per sensor, shapes from
    :func:`arena.sensors_spec.observation_space`) and returns an action of the car's
    action space: an ``int`` index for a discrete space, two floats in ``[-1, 1]`` for a
    continuous one.
    """

    def reset(self) -> None:
        """Forget any state from a previous race."""

    def act(self, observation: dict[str, Any]) -> Any:
        """Choose the next action."""
