"""DeepRacer action spaces: discrete lists and continuous ranges, with their limits.

These are the only action spaces the arena accepts; ``agents`` builds them (console
builder, metadata files) and ``submissions`` validates uploaded ones against them.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

import numpy as np
from gymnasium import spaces
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, field_validator, model_validator

from arena.car_spec import DEFAULT_CAR

# An action can ask for no more than the car can be commanded.
MAX_STEERING_DEG = DEFAULT_CAR.max_steering_deg
MIN_SPEED = DEFAULT_CAR.min_speed
MAX_SPEED = DEFAULT_CAR.max_speed
MAX_DISCRETE_ACTIONS = 64


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class DiscreteAction(_Frozen):
    """One entry of a discrete action list: steering in degrees (left positive), speed m/s."""

    model_config = ConfigDict(frozen=True, extra="ignore")  # DeepRacer files carry "index"

    steering_angle: float = Field(ge=-MAX_STEERING_DEG, le=MAX_STEERING_DEG)
    speed: float = Field(ge=MIN_SPEED, le=MAX_SPEED)


class Range(_Frozen):
    """A closed interval ``[low, high]`` with ``low < high``."""

    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> Range:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


class DiscreteActionSpace(_Frozen):
    """A list of (steering, speed) pairs; the policy picks an index."""

    type: Literal["discrete"] = "discrete"
    actions: tuple[DiscreteAction, ...] = Field(min_length=1, max_length=MAX_DISCRETE_ACTIONS)

    @property
    def n(self) -> int:
        """Number of actions."""
        return len(self.actions)

    def gym_space(self) -> spaces.Discrete:
        """The PettingZoo/Gymnasium action space."""
        return spaces.Discrete(self.n)

    def to_command(self, action: Any) -> tuple[float, float]:
        """Map a policy action (an index) to ``(steering_deg, speed_mps)``."""
        if isinstance(action, int | np.integer):
            index = int(action)
        else:
            index = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= index < self.n:
            raise ValueError(f"action index {index} outside 0..{self.n - 1}")
        chosen = self.actions[index]
        return chosen.steering_angle, chosen.speed

    @property
    def max_speed(self) -> float:
        """Highest speed the space can command."""
        return max(a.speed for a in self.actions)


class ContinuousActionSpace(_Frozen):
    """Steering and speed ranges; the policy acts in ``[-1, 1]^2`` (steering, speed)."""

    type: Literal["continuous"] = "continuous"
    steering_angle: Range = Range(low=-MAX_STEERING_DEG, high=MAX_STEERING_DEG)
    speed: Range = Range(low=0.5, high=MAX_SPEED)

    @field_validator("steering_angle")
    @classmethod
    def _steering_limits(cls, value: Range) -> Range:
        if value.low < -MAX_STEERING_DEG or value.high > MAX_STEERING_DEG:
            raise ValueError(f"steering_angle must stay within +-{MAX_STEERING_DEG} degrees")
        return value

    @field_validator("speed")
    @classmethod
    def _speed_limits(cls, value: Range) -> Range:
        if value.low < MIN_SPEED or value.high > MAX_SPEED:
            raise ValueError(f"speed must stay within {MIN_SPEED}..{MAX_SPEED} m/s")
        return value

    def gym_space(self) -> spaces.Box:
        """The PettingZoo/Gymnasium action space."""
        return spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def to_command(self, action: Any) -> tuple[float, float]:
        """Rescale ``[-1, 1]^2`` (clipped) to ``(steering_deg, speed_mps)``."""
        a = np.clip(np.asarray(action, dtype=float).reshape(-1)[:2], -1.0, 1.0)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ValueError(f"continuous action must be 2 finite numbers, got {action!r}")
        steer = self.steering_angle.low + (a[0] + 1.0) * 0.5 * (
            self.steering_angle.high - self.steering_angle.low
        )
        speed = self.speed.low + (a[1] + 1.0) * 0.5 * (self.speed.high - self.speed.low)
        return float(steer), float(speed)

    @property
    def max_speed(self) -> float:
        """Highest speed the space can command."""
        return self.speed.high


ActionSpace = Annotated[DiscreteActionSpace | ContinuousActionSpace, Field(discriminator="type")]
_ACTION_SPACE = TypeAdapter(ActionSpace)


def parse_action_space(data: Any) -> DiscreteActionSpace | ContinuousActionSpace:
    """Validate an action space given as a dict or model (raises pydantic's ValidationError)."""
    return _ACTION_SPACE.validate_python(data)


def default_discrete_space() -> DiscreteActionSpace:
    """DeepRacer console default: steering {-30,-15,0,15,30} x speed {0.4, 0.8} m/s."""
    return DiscreteActionSpace(
        actions=tuple(
            DiscreteAction(steering_angle=s, speed=v)
            for s in (-30.0, -15.0, 0.0, 15.0, 30.0)
            for v in (0.4, 0.8)
        )
    )


def from_deepracer_metadata(
    metadata: dict[str, Any],
) -> DiscreteActionSpace | ContinuousActionSpace:
    """Read the action space from DeepRacer's ``model_metadata.json`` keys."""
    kind = str(metadata.get("action_space_type", "discrete")).lower()
    raw = metadata.get("action_space")
    if kind == "discrete":
        if not isinstance(raw, list):
            raise ValueError("action_space must be a list for a discrete action space")
        return parse_action_space({"type": "discrete", "actions": raw})
    if kind == "continuous":
        if not isinstance(raw, dict):
            raise ValueError("action_space must be an object for a continuous action space")
        return parse_action_space({"type": "continuous", **raw})
    raise ValueError(f"action_space_type must be 'discrete' or 'continuous', got {kind!r}")


def to_deepracer_metadata(space: DiscreteActionSpace | ContinuousActionSpace) -> dict[str, Any]:
    """DeepRacer's ``action_space`` and ``action_space_type`` keys for a space."""
    if isinstance(space, DiscreteActionSpace):
        return {
            "action_space": [
                {"steering_angle": a.steering_angle, "speed": a.speed, "index": i}
                for i, a in enumerate(space.actions)
            ],
            "action_space_type": "discrete",
        }
    return {
        "action_space": {
            "steering_angle": space.steering_angle.model_dump(),
            "speed": space.speed.model_dump(),
        },
        "action_space_type": "continuous",
    }
