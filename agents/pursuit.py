"""Pure pursuit on the racing line: the strong non-learning baseline driver.

The car steers, from its rear axle, towards the point ``lookahead`` metres ahead along
the track's minimum-curvature racing line, and asks for the speed profile's speed there
(the lowest on the way, so it never speeds up before a bend is over), capped by the
action space. It reads DeepRacer's params (not the sensors), so it races with any sensors.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.drivers import nearest_action, pursuit_steering
from tracks.raceline import CarLimits, RacingLine, compute_racing_line
from tracks.track import Track


def car_limits(car: CarSpec = DEFAULT_CAR) -> CarLimits:
    """The racing-line limits of ``car``: its top speed and width.

    Grip, acceleration and braking keep :class:`CarLimits`' defaults (figures for the
    line's speed profile, not settings of the simulated car).
    """
    return CarLimits(max_speed=car.max_speed, car_width=car.width)


DEFAULT_LIMITS = car_limits()

_LINES: dict[tuple[Any, ...], RacingLine] = {}


def racing_line_for(track: Track, limits: CarLimits = DEFAULT_LIMITS) -> RacingLine:
    """``compute_racing_line(track, limits)``, computed once per track geometry and limits."""
    key = (track.name, track.direction, track.waypoints.tobytes(), limits)
    if key not in _LINES:
        _LINES[key] = compute_racing_line(track, limits)
    return _LINES[key]


class PurePursuitPolicy:
    """A ``Policy`` that follows the racing line with its speed profile (needs the params).

    Args:
        track: the race's track, in its driving direction.
        action_space: the car's action space; commands snap to its nearest action.
        limits: the car limits the racing line and its speed profile are computed for.
        lookahead: pursuit distance in metres at standstill.
        lookahead_per_speed: extra pursuit distance per m/s of commanded speed (seconds).
    """

    needs_params = True

    def __init__(
        self,
        track: Track,
        action_space: DiscreteActionSpace | ContinuousActionSpace,
        limits: CarLimits = DEFAULT_LIMITS,
        lookahead: float = 0.5,
        lookahead_per_speed: float = 0.2,
    ) -> None:
        if lookahead <= 0 or lookahead_per_speed < 0:
            raise ValueError("lookahead must be positive and lookahead_per_speed not negative")
        self.space = action_space
        self.line = racing_line_for(track, limits)
        self.lookahead = lookahead
        self.lookahead_per_speed = lookahead_per_speed
        self.max_speed = action_space.max_speed
        self._carry = 0.0

    def reset(self) -> None:
        """Forget the steering carried over between steps (start of a race)."""
        self._carry = 0.0

    def act(self, observation: Any, params: dict[str, Any] | None = None) -> Any:
        """The action towards the racing-line point ahead, at its profile speed.

        In a discrete space the speed is rounded down to one the space offers, and the
        steering its few angles miss is carried into the next step (error diffusion), so
        that over a few steps the chosen angles average out to the wanted one.
        """
        if params is None:
            raise ValueError("PurePursuitPolicy needs the race params")
        steer, speed = self.command(params["x"], params["y"], params["heading"], params["speed"])
        if not isinstance(self.space, DiscreteActionSpace):
            return nearest_action(self.space, steer, speed)
        wanted = steer + self._carry
        action = nearest_action(self.space, wanted, self._speed_at_most(speed))
        chosen = self.space.actions[action].steering_angle
        lock = DEFAULT_CAR.max_steering_deg
        self._carry = float(np.clip(wanted - chosen, -lock, lock))
        return action

    def _speed_at_most(self, speed: float) -> float:
        """The discrete space's fastest speed not above ``speed`` (else its slowest)."""
        speeds = sorted({a.speed for a in self.space.actions})
        below = [v for v in speeds if v <= speed + 1e-9]
        return below[-1] if below else speeds[0]

    def command(self, x: float, y: float, heading_deg: float, speed: float) -> tuple[float, float]:
        """``(steering_deg, speed)`` for a car whose model point is at ``(x, y)``."""
        yaw = math.radians(heading_deg)
        rear = np.array(DEFAULT_CAR.rear_axle(x, y, yaw))
        distance = self.lookahead + self.lookahead_per_speed * max(speed, 0.0)
        target, target_speed = self._ahead(rear, distance)
        steer = pursuit_steering(DEFAULT_CAR, rear[0], rear[1], yaw, target)
        return steer, float(min(target_speed, self.max_speed))

    def _ahead(self, point: np.ndarray, distance: float) -> tuple[np.ndarray, float]:
        """The racing-line point ``distance`` metres past the line point nearest ``point``."""
        line = self.line
        nearest = int(np.argmin(np.sum((line.points - point) ** 2, axis=1)))
        s = line.arc_length[nearest] + distance
        s = s % line.length if line.is_loop else min(s, line.length)
        x = np.interp(s, line.arc_length, line.points[:, 0])
        y = np.interp(s, line.arc_length, line.points[:, 1])
        return np.array([x, y]), self._slowest(nearest, s)

    def _slowest(self, start: int, s_end: float) -> float:
        """The lowest profile speed from line point ``start`` to arc length ``s_end``."""
        line = self.line
        end_speed = float(np.interp(s_end, line.arc_length, line.speed))
        end = int(np.searchsorted(line.arc_length, s_end))
        window = (
            line.speed[start:end] if end >= start else np.r_[line.speed[start:], line.speed[:end]]
        )
        return min(end_speed, float(window.min())) if window.size else end_speed
