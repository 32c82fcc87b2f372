"""Build DeepRacer action spaces: the console builder, custom lists, ranges and CLI specs.

The spaces themselves are ``arena.actions``'s; this module only builds and checks them,
raising :class:`ActionSpaceError` with a message that names the bad value.

Action-space spec grammar (``parse_action_space_spec``), case-insensitive keywords::

    default                                   the console default (5 x 2, 30 deg, 0.8 m/s)
    console:MAX_STEER:STEER_GRAN:MAX_SPEED:SPEED_GRAN
                                              the console builder, e.g. console:30:5:0.8:2
    SxV@MAX_SPEED[/MAX_STEER]                 short console form: S steering x V speed values,
                                              e.g. 3x3@1.0 (max steering 30 unless /MAX_STEER)
    list:STEER/SPEED,STEER/SPEED,...          custom discrete list, e.g. list:-20/1,0/2,20/1
    continuous:STEER_LOW:STEER_HIGH:SPEED_LOW:SPEED_HIGH
                                              e.g. continuous:-30:30:0.5:4
    PATH.json                                 a model_metadata.json, or a bare action_space
                                              value (a list of actions or a {low, high} object)
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from arena.actions import (
    MAX_DISCRETE_ACTIONS,
    MAX_SPEED,
    MAX_STEERING_DEG,
    MIN_SPEED,
    ContinuousActionSpace,
    DiscreteAction,
    DiscreteActionSpace,
    Range,
    from_deepracer_metadata,
)

ActionSpace = DiscreteActionSpace | ContinuousActionSpace

STEERING_GRANULARITIES = (3, 5, 7)
SPEED_GRANULARITIES = (1, 2, 3)
MIN_MAX_STEERING_DEG = 1.0
CONSOLE_DECIMALS = 2
"""The console shows (and stores) action values to two decimals."""

_SHORT_CONSOLE = re.compile(
    r"^(?P<steer_g>\d+)x(?P<speed_g>\d+)@(?P<speed>[^/]+)(?:/(?P<steer>.+))?$", re.IGNORECASE
)


class ActionSpaceError(ValueError):
    """An action space (or its spec) that DeepRacer's rules do not allow."""


def _number(value: Any, name: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ActionSpaceError(f"{name} must be a number, got {value!r}") from None
    if isinstance(value, bool) or not math.isfinite(number):
        raise ActionSpaceError(f"{name} must be a finite number, got {value!r}")
    return number


def _within(value: float, low: float, high: float, name: str, unit: str) -> float:
    if not low <= value <= high:
        raise ActionSpaceError(f"{name} must be within {low:g}..{high:g} {unit}, got {value:g}")
    return value


def _granularity(value: Any, allowed: tuple[int, ...], name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value not in allowed:
        raise ActionSpaceError(f"{name} must be one of {list(allowed)}, got {value!r}")
    return value


def console_action_space(
    max_steering_deg: float = 30.0,
    steering_granularity: int = 5,
    max_speed: float = 0.8,
    speed_granularity: int = 2,
) -> DiscreteActionSpace:
    """The DeepRacer console's discrete builder.

    Steering takes ``steering_granularity`` values evenly from ``-max`` to ``+max``; speed
    takes ``speed_granularity`` values ``max/g, 2 max/g, ..., max``; every combination,
    ordered by steering then speed (the console's numbering). The defaults give the
    console default space.
    """
    max_steer = _within(
        _number(max_steering_deg, "max steering angle"),
        MIN_MAX_STEERING_DEG,
        MAX_STEERING_DEG,
        "max steering angle",
        "degrees",
    )
    steer_g = _granularity(steering_granularity, STEERING_GRANULARITIES, "steering granularity")
    top = _within(_number(max_speed, "max speed"), MIN_SPEED, MAX_SPEED, "max speed", "m/s")
    speed_g = _granularity(speed_granularity, SPEED_GRANULARITIES, "speed granularity")
    half = (steer_g - 1) // 2
    steers = [round(max_steer * k / half, CONSOLE_DECIMALS) for k in range(-half, half + 1)]
    speeds = [round(top * k / speed_g, CONSOLE_DECIMALS) for k in range(1, speed_g + 1)]
    if speeds[0] < MIN_SPEED:
        raise ActionSpaceError(
            f"speed granularity {speed_g} at max speed {top:g} m/s gives a lowest speed of "
            f"{speeds[0]:g} m/s, below the {MIN_SPEED:g} m/s minimum"
        )
    return custom_action_space((s, v) for s in steers for v in speeds)


def custom_action_space(actions: Iterable[tuple[float, float]]) -> DiscreteActionSpace:
    """A discrete space from ``(steering_deg, speed_mps)`` pairs, kept in the given order."""
    pairs = []
    for i, pair in enumerate(actions):
        try:
            steer_raw, speed_raw = pair
        except (TypeError, ValueError):
            raise ActionSpaceError(
                f"action {i} must be a (steering, speed) pair, got {pair!r}"
            ) from None
        steer = _number(steer_raw, f"action {i} steering angle")
        speed = _number(speed_raw, f"action {i} speed")
        _within(steer, -MAX_STEERING_DEG, MAX_STEERING_DEG, f"action {i} steering angle", "degrees")
        _within(speed, MIN_SPEED, MAX_SPEED, f"action {i} speed", "m/s")
        if (steer, speed) in pairs:
            raise ActionSpaceError(f"action {i} ({steer:g} deg, {speed:g} m/s) is listed twice")
        pairs.append((steer, speed))
    if not pairs:
        raise ActionSpaceError("a discrete action space needs at least one action")
    if len(pairs) > MAX_DISCRETE_ACTIONS:
        raise ActionSpaceError(
            f"a discrete action space holds at most {MAX_DISCRETE_ACTIONS} actions, "
            f"got {len(pairs)}"
        )
    return DiscreteActionSpace(
        actions=tuple(DiscreteAction(steering_angle=s, speed=v) for s, v in pairs)
    )


def continuous_action_space(
    steer_low: float = -MAX_STEERING_DEG,
    steer_high: float = MAX_STEERING_DEG,
    speed_low: float = 0.5,
    speed_high: float = MAX_SPEED,
) -> ContinuousActionSpace:
    """A continuous space: steering in ``[steer_low, steer_high]`` deg, speed in m/s."""
    s_low = _within(
        _number(steer_low, "steering low"),
        -MAX_STEERING_DEG,
        MAX_STEERING_DEG,
        "steering low",
        "degrees",
    )
    s_high = _within(
        _number(steer_high, "steering high"),
        -MAX_STEERING_DEG,
        MAX_STEERING_DEG,
        "steering high",
        "degrees",
    )
    v_low = _within(_number(speed_low, "speed low"), MIN_SPEED, MAX_SPEED, "speed low", "m/s")
    v_high = _within(_number(speed_high, "speed high"), MIN_SPEED, MAX_SPEED, "speed high", "m/s")
    if s_low >= s_high:
        raise ActionSpaceError(f"steering low ({s_low:g}) must be below steering high ({s_high:g})")
    if v_low >= v_high:
        raise ActionSpaceError(f"speed low ({v_low:g}) must be below speed high ({v_high:g})")
    return ContinuousActionSpace(
        steering_angle=Range(low=s_low, high=s_high), speed=Range(low=v_low, high=v_high)
    )


def action_space_from_json(data: Any) -> ActionSpace:
    """An action space from decoded JSON: a whole ``model_metadata.json`` or a bare
    ``action_space`` value (a list of actions, or a ``{steering_angle, speed}`` range object).
    """
    if isinstance(data, dict) and "action_space" in data:
        metadata = data
    elif isinstance(data, list):
        metadata = {"action_space": data, "action_space_type": "discrete"}
    elif isinstance(data, dict):
        metadata = {"action_space": data, "action_space_type": "continuous"}
    else:
        raise ActionSpaceError(f"expected an action space object or list, got {data!r:.80}")
    try:
        return from_deepracer_metadata(metadata)
    except ValidationError as exc:
        errors = exc.errors()
        # a bad entry also empties the validated tuple: report the entry, not the length
        errors = [e for e in errors if e["type"] != "too_short"] or errors
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc'][1:]) or 'action_space'}: {e['msg']}"
            for e in errors
        )
        raise ActionSpaceError(f"invalid action space: {problems}") from None
    except ValueError as exc:
        raise ActionSpaceError(str(exc)) from None


def _fields(text: str, count: int, form: str) -> list[str]:
    parts = text.split(":")[1:]
    if len(parts) != count:
        raise ActionSpaceError(f"{text!r} does not match {form}")
    return parts


def _int(text: str, name: str) -> int:
    if not text.strip().isdigit():
        raise ActionSpaceError(f"{name} must be a whole number, got {text!r}")
    return int(text)


def _from_file(path: Path) -> ActionSpace:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ActionSpaceError(f"cannot read action space file {path}: {exc.strerror}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ActionSpaceError(f"{path} is not valid JSON: {exc}") from None
    return action_space_from_json(data)


def parse_action_space_spec(text: str) -> ActionSpace:
    """Parse a CLI action-space spec (grammar in this module's docstring)."""
    spec = text.strip()
    keyword = spec.split(":", 1)[0].lower()
    if keyword == "default":
        return console_action_space()
    if keyword == "console":
        form = "console:MAX_STEER:STEER_GRAN:MAX_SPEED:SPEED_GRAN"
        steer, steer_g, speed, speed_g = _fields(spec, 4, form)
        return console_action_space(
            _number(steer, "max steering angle"),
            _int(steer_g, "steering granularity"),
            _number(speed, "max speed"),
            _int(speed_g, "speed granularity"),
        )
    if keyword == "continuous":
        form = "continuous:STEER_LOW:STEER_HIGH:SPEED_LOW:SPEED_HIGH"
        return continuous_action_space(*_fields(spec, 4, form))
    if keyword == "list":
        items = spec.split(":", 1)[1].split(",")
        pairs = []
        for item in items:
            steer, sep, speed = item.partition("/")
            if not sep:
                raise ActionSpaceError(f"list entry {item!r} must be STEER/SPEED, e.g. -15/1.2")
            pairs.append((steer, speed))
        return custom_action_space(pairs)
    short = _SHORT_CONSOLE.match(spec)
    if short:
        return console_action_space(
            _number(short["steer"] or MAX_STEERING_DEG, "max steering angle"),
            int(short["steer_g"]),
            _number(short["speed"], "max speed"),
            int(short["speed_g"]),
        )
    if spec.lower().endswith(".json") or Path(spec).is_file():
        return _from_file(Path(spec))
    raise ActionSpaceError(
        f"unknown action space spec {text!r}; use 'default', 'console:30:5:0.8:2', '3x3@1.0', "
        "'list:-20/1,0/2,20/1', 'continuous:-30:30:0.5:4' or a path to a .json file"
    )
