"""Pure pursuit on the racing line: the scripted drivers that race without learning.

The car steers, from its rear axle, towards the point ``lookahead`` metres ahead along
the track's minimum-curvature racing line, ahead of its lagging steering (see
:meth:`PurePursuitPolicy.act`), and asks for the speed profile's speed where it is,
capped by the action space and by what the car holds on the arc it is steering. It plans
with its car's measured limits (:func:`car_limits`) and reads DeepRacer's params (not the
sensors), so it races with any sensors.

:class:`PurePursuitPolicy` is the baseline driver and the league's bot (the car that fills
a head-to-model grid); :class:`PassingPursuitPolicy` also steers around boxes and cars,
and is the teacher that imitation learning copies.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.drivers import SteeringLead, nearest_action, pursuit_steering
from tracks.raceline import CarLimits, RacingLine, compute_racing_line
from tracks.track import Track


def car_limits(car: CarSpec = DEFAULT_CAR) -> CarLimits:
    """The racing-line limits of ``car``, measured by driving it (:mod:`arena.calibration`).

    The default car's are :class:`CarLimits`' defaults (its measurement, checked by
    ``tests/arena/test_calibration.py``), so that no process pays for a calibration to
    drive it; any other car is calibrated once per process.
    """
    if car == DEFAULT_CAR:
        return CarLimits()
    from arena.calibration import calibrate

    return calibrate(car).limits(car)


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
        lookahead: float = 0.7,
        lookahead_per_speed: float = 0.25,
    ) -> None:
        if lookahead <= 0 or lookahead_per_speed < 0:
            raise ValueError("lookahead must be positive and lookahead_per_speed not negative")
        self.space = action_space
        self.line = racing_line_for(track, limits)
        self.limits = limits
        self.lock = limits.max_steering_deg
        self.lead = SteeringLead(limits.steering_time_constant, limits.max_steering_deg)
        self.lookahead = lookahead
        self.lookahead_per_speed = lookahead_per_speed
        self.max_speed = action_space.max_speed
        self._carry = 0.0

    def reset(self) -> None:
        """Forget the steering carried over between steps (start of a race)."""
        self._carry = 0.0
        self.lead.reset()

    def act(self, observation: Any, params: dict[str, Any] | None = None) -> Any:
        """The action towards the racing-line point ahead, at its profile speed.

        The steering lags its command, so the driver leads it (:class:`SteeringLead`).
        In a discrete space the speed is rounded down to one the space offers, and the
        steering its few angles miss is carried into the next step (error diffusion), so
        that over a few steps the chosen angles average out to the wanted one.
        """
        if params is None:
            raise ValueError(f"{type(self).__name__} needs the race params")
        steer, speed = self.command_for(params)
        lead = self.lead.command(steer)
        if not isinstance(self.space, DiscreteActionSpace):
            steering = self.space.steering_angle
            chosen = float(np.clip(lead, steering.low, steering.high))
            action = nearest_action(self.space, chosen, speed)
        else:
            wanted = lead + self._carry
            action = nearest_action(self.space, wanted, self._speed_at_most(speed))
            chosen = self.space.actions[action].steering_angle
            self._carry = float(np.clip(wanted - chosen, -self.lock, self.lock))
        self.lead.sent(chosen)
        return action

    def _speed_at_most(self, speed: float) -> float:
        """The discrete space's fastest speed not above ``speed`` (else its slowest)."""
        speeds = sorted({a.speed for a in self.space.actions})
        below = [v for v in speeds if v <= speed + 1e-9]
        return below[-1] if below else speeds[0]

    def command_for(self, params: dict[str, Any]) -> tuple[float, float]:
        """``(steering_deg, speed)`` for the car that DeepRacer's ``params`` describe."""
        return self.command(params["x"], params["y"], params["heading"], params["speed"])

    def command(self, x: float, y: float, heading_deg: float, speed: float) -> tuple[float, float]:
        """``(steering_deg, speed)`` for a car whose model point is at ``(x, y)``."""
        yaw, rear, distance = self._pursuit_geometry(x, y, heading_deg, speed)
        target, target_speed = self._ahead(rear, distance)
        wheelbase = self.limits.wheelbase_at(speed)
        steer = pursuit_steering(DEFAULT_CAR, rear[0], rear[1], yaw, target, wheelbase)
        return steer, float(min(target_speed, self.max_speed, self.arc_speed(steer, speed)))

    def arc_speed(self, steer_deg: float, speed: float) -> float:
        """The highest speed the car holds on the arc that ``steer_deg`` steers at ``speed``."""
        bend = math.tan(math.radians(abs(steer_deg))) / self.limits.wheelbase_at(speed)
        return float(self.limits.corner_speed(bend)) if bend > 1e-9 else math.inf

    def _pursuit_geometry(
        self, x: float, y: float, heading_deg: float, speed: float
    ) -> tuple[float, np.ndarray, float]:
        """The car's yaw (rad), rear-axle point and lookahead distance at ``speed``."""
        yaw = math.radians(heading_deg)
        rear = np.array(DEFAULT_CAR.rear_axle(x, y, yaw))
        return yaw, rear, self.lookahead + self.lookahead_per_speed * max(speed, 0.0)

    def _ahead(self, point: np.ndarray, distance: float) -> tuple[np.ndarray, float]:
        """The racing-line point ``distance`` metres past the line point nearest ``point``
        (the rear axle), and the profile's lowest speed between there and the front axle.

        The drivetrain brakes and accelerates at the rates the profile plans with, so the
        profile's speed where the car is, is the one to ask for.
        """
        line = self.line
        nearest = int(np.argmin(np.sum((line.points - point) ** 2, axis=1)))
        here = line.arc_length[nearest]
        s, front = here + distance, here + DEFAULT_CAR.wheelbase
        if line.is_loop:
            s, front = s % line.length, front % line.length
        else:
            s, front = min(s, line.length), min(front, line.length)
        x = np.interp(s, line.arc_length, line.points[:, 0])
        y = np.interp(s, line.arc_length, line.points[:, 1])
        return np.array([x, y]), self._slowest(nearest, front)

    def _slowest(self, start: int, s_end: float) -> float:
        """The lowest profile speed from line point ``start`` to arc length ``s_end``."""
        arc, speed = self.line.arc_length, self.line.speed
        end_speed = float(np.interp(s_end, arc, speed))
        end = int(np.searchsorted(arc, s_end))
        window = speed[start:end] if end >= start else np.r_[speed[start:], speed[:end]]
        return min(end_speed, float(window.min())) if window.size else end_speed


# Passing (PassingPursuitPolicy): objects this far ahead are planned around, the larger of
# a distance and a time at the car's speed; one still this far beside or behind the car
# (centre to centre) is not yet passed. The steering lags its command by 0.5 s, so the
# car plans a pass 2 s ahead (0.8 s on a car that steered at once hit a box in every race).
PASS_HORIZON_M = 2.5
PASS_HORIZON_S = 2.0
PASS_BESIDE_M = 0.45
# Centre-to-centre lateral distance kept from an object: half its width (a box 0.25 m, a
# car 0.1 m; the params do not say which, so an object moving faster than MOVING_MPS is
# taken for a car), half the car's (0.1 m) and a margin; and the margin kept from the
# track's edge. (0.6 m from a box: the lagging steering swings wider than it aims;
# benchmarks/RESULTS.md, "The car beside DeepRacer's". 0.32 m from a car: on a 1.067 m
# track the room beside a car on the centre line is 0.375 m, so 0.4 m left none;
# "The gauntlet on real-width tracks".)
BOX_CLEARANCE_M = 0.6
CAR_CLEARANCE_M = 0.32
MOVING_MPS = 0.1
PASS_EDGE_MARGIN_M = 0.06
# The highest speed asked for while steering around an object (a tighter, steadier line).
PASS_SPEED = 2.0
# Off the racing line by more than this (after a pass), the car rejoins it at PASS_SPEED
# (the lagging steering strays up to about 0.2 m from the line with nothing to pass).
REJOIN_M = 0.25
# A car ahead is passed on the far side only when it is at least this far ahead (else the
# pass would cut across its nose): closer, the car follows it on its own side.
CROSS_GAP_M = 1.5
FOLLOW_MIN_SPEED = 0.5  # DeepRacer's lowest speed
# A moving car ahead is passed, at the speed profile's speed, when it drives slower than
# PASS_PACE of the pace its place on the line allows (the profile's lowest speed over the
# PACE_WINDOW_M of line up to it: leaving a corner, a car at full pace is still
# accelerating), so that the pass gains time; one at that pace or faster, and any car in
# the first START_FOLLOW_STEPS control steps (2 s: from a standing start both cars
# accelerate alike, and a pass crosses the leader's nose), is as fast as this one: the car
# follows it on the racing line instead, closing to FOLLOW_GAP_M (centre to centre along
# the track) at
# FOLLOW_GAIN m/s per metre of gap error, and never faster than lets it brake at the car's
# braking limit, after FOLLOW_REACTION_S (three control steps: with one, the follower
# ran into the leader once a race on the lagging car), to the leader's speed before the
# gap falls to FOLLOW_MIN_GAP_M (the car's length and a few centimetres; Gipps' rule).
# Head-to-head laps are timed from each car's own grid slot, so a car that ends the race
# closer behind than it started wins: following a racing car wins more races than passing
# it, and the braking cap keeps the follower off a leader that brakes hard
# (benchmarks/RESULTS.md, "Following instead of passing").
PASS_PACE = 0.9
PACE_WINDOW_M = 1.0
START_FOLLOW_STEPS = 30
FOLLOW_GAP_M = 0.55
FOLLOW_GAIN = 3.0
FOLLOW_MIN_GAP_M = 0.35
FOLLOW_REACTION_S = 0.2


class PassingPursuitPolicy(PurePursuitPolicy):
    """Pure pursuit on the racing line that steers around the objects ahead of it.

    Boxes, bots and other cars come from the params (``objects_*``). When one lies within
    :data:`PASS_HORIZON_S` seconds (at least :data:`PASS_HORIZON_M` metres) ahead, or
    still beside the car, and the car's way from where it is to the racing line would pass
    it closer than the clearance, the car aims beside it instead (past a box at most at
    :data:`PASS_SPEED`, past a car at the profile's speed): on the side it is already on
    when the track has room there, else on the far side. A car ahead that drives at
    :data:`PASS_PACE` of its line's pace or faster is followed on the racing line instead
    (:meth:`_follow_speed`). A car too close ahead to cross in front of (:data:`CROSS_GAP_M`) is
    followed on this side at its speed until there is room. Off the line by more than
    :data:`REJOIN_M`, it rejoins the line at most at :data:`PASS_SPEED`. On the line with
    no object near it drives as :class:`PurePursuitPolicy`. It is the teacher that
    ``slipstream train --teacher pursuit`` imitates.
    """

    def __init__(self, track: Track, *args: Any, **kwargs: Any) -> None:
        super().__init__(track, *args, **kwargs)
        self.track = track
        where = track.project(self.line.points)
        order = np.argsort(where.arc_length)
        self._line_arc = where.arc_length[order]
        self._line_offset = where.offset[order]
        self._room = 0.5 * track.width - 0.5 * DEFAULT_CAR.width - PASS_EDGE_MARGIN_M
        self._steps = 0

    def reset(self) -> None:
        """Start of a race: also restart the count of steps since the start."""
        super().reset()
        self._steps = 0

    def command_for(self, params: dict[str, Any]) -> tuple[float, float]:
        """The racing-line command, or one aimed beside an object in the way."""
        steer, speed = super().command_for(params)
        self._steps += 1
        way = self._way_past(params, speed)
        if way is None:
            off_line = abs(_offset(params) - self._line_offset_at(params["projection_distance"]))
            return steer, min(speed, PASS_SPEED) if off_line > REJOIN_M else speed
        offset, most = way
        if offset is None:  # following a racing car, on the racing line
            return steer, min(speed, most)
        yaw, rear, distance = self._pursuit_geometry(
            params["x"], params["y"], params["heading"], min(params["speed"], most)
        )
        arc = float(self.track.project(rear[None]).arc_length[0]) + distance
        target, _ = self.track.pose_at(self.track.wrap_arc_length(arc), offset)
        wheelbase = self.limits.wheelbase_at(params["speed"])
        steer = pursuit_steering(DEFAULT_CAR, rear[0], rear[1], yaw, target, wheelbase)
        return steer, min(speed, most, self.arc_speed(steer, params["speed"]))

    def _way_past(
        self, params: dict[str, Any], line_speed: float
    ) -> tuple[float | None, float] | None:
        """``(lateral offset to aim at, m left positive; speed cap)`` past the nearest
        object in the way, ``(None, speed cap)`` to follow a racing car on the racing
        line, or None to drive the racing line."""
        if not params["objects_distance"]:
            return None
        arc = float(params["projection_distance"])
        gaps = np.atleast_1d(
            self.track.arc_delta(arc, np.asarray(params["objects_distance"], dtype=float))
        )
        horizon = max(PASS_HORIZON_M, PASS_HORIZON_S * float(params["speed"]))
        here = _offset(params)
        for i in np.argsort(gaps):
            if not -PASS_BESIDE_M <= gaps[i] <= horizon:
                continue
            side = 1.0 if params["objects_left_of_center"][i] else -1.0
            obstacle = side * float(params["objects_distance_from_center"][i])
            object_speed = float(params["objects_speed"][i])
            clearance = CAR_CLEARANCE_M if object_speed > MOVING_MPS else BOX_CLEARANCE_M
            # From where the car is to the line's offset at the object, all the way clear?
            low, high = sorted((here, self._line_offset_at(arc + gaps[i])))
            if max(low - obstacle, obstacle - high) >= clearance:
                continue
            moving = object_speed > MOVING_MPS
            if gaps[i] > 0.0 and moving and self._at_pace(object_speed, params, i):
                return None, self._follow_speed(float(gaps[i]), object_speed, params["speed"])
            pass_speed = line_speed if moving else PASS_SPEED
            lean = 1.0 if low + high >= 2.0 * obstacle else -1.0
            near_side, far_side = obstacle + lean * clearance, obstacle - lean * clearance
            if abs(near_side) <= self._room:
                return near_side, pass_speed
            crossable = not moving or gaps[i] >= CROSS_GAP_M
            if abs(far_side) <= self._room and crossable:
                return far_side, pass_speed
            follow = max(object_speed, FOLLOW_MIN_SPEED)
            return float(np.clip(near_side, -self._room, self._room)), follow
        return None

    def _follow_speed(self, gap: float, leader_speed: float, speed: float) -> float:
        """The speed to follow a car ``gap`` metres ahead (centre to centre along the
        track) that moves at ``leader_speed``; ``speed`` is this car's commanded speed."""
        closing = leader_speed + FOLLOW_GAIN * (gap - FOLLOW_GAP_M)
        room = gap - FOLLOW_MIN_GAP_M - FOLLOW_REACTION_S * speed
        braking = math.sqrt(max(0.0, leader_speed**2 + 2.0 * self.line.limits.max_brake * room))
        return max(FOLLOW_MIN_SPEED, min(closing, braking))

    def _at_pace(self, speed: float, params: dict[str, Any], i: int) -> bool:
        """Whether object ``i``, a car moving at ``speed``, is too fast to pass (and to be
        followed instead): near its line's pace, or the race has just started."""
        if self._steps <= START_FOLLOW_STEPS:
            return True
        return speed >= PASS_PACE * self._line_pace_near(params["objects_location"][i])

    def _line_pace_near(self, point: Any) -> float:
        """The lowest profile speed over the :data:`PACE_WINDOW_M` of racing line up to the
        line point nearest ``point`` (x, y): what a car there at full pace drives at least
        (leaving a corner it is still accelerating to the profile's speed)."""
        line = self.line
        spot = np.asarray(point, dtype=float)
        nearest = int(np.argmin(np.sum((line.points - spot) ** 2, axis=1)))
        here = float(line.arc_length[nearest])
        back = here - PACE_WINDOW_M
        back = back % line.length if line.is_loop else max(back, 0.0)
        start = min(int(np.searchsorted(line.arc_length, back)), len(line.arc_length) - 1)
        return self._slowest(start, here)

    def _line_offset_at(self, arc: float) -> float:
        """The racing line's lateral offset where the centre line is ``arc`` metres long."""
        period = self.track.length if self.track.is_loop else None
        return float(np.interp(arc, self._line_arc, self._line_offset, period=period))


def _offset(params: dict[str, Any]) -> float:
    """The car's signed lateral offset from the centre line (m, left positive)."""
    return (1.0 if params["is_left_of_center"] else -1.0) * float(params["distance_from_center"])
