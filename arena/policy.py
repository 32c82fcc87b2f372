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


def policy_action(policy: Policy, observation: dict[str, Any], info: dict[str, Any]) -> Any:
    """``policy``'s action for a car's ``observation``; a policy that sets ``needs_params``
    (the scripted drivers, which read the track's geometry) also gets ``info["params"]``."""
    if getattr(policy, "needs_params", False):
        return policy.act(observation, params=info["params"])
    return policy.act(observation)
