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

import bisect
import math
from collections import deque
from typing import Any

import numpy as np

from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.car_spec import DEFAULT_CAR, CarSpec
from arena.drivers import SteeringLead, nearest_action, pursuit_steering
from tracks.raceline import CarLimits, RacingLine, compute_racing_line, profile_path
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
        pace: the share of the speed profile it drives at (0-1]: a slower racer on the
            same line, braking for the same corners.
    """

    needs_params = True

    def __init__(
        self,
        track: Track,
        action_space: DiscreteActionSpace | ContinuousActionSpace,
        limits: CarLimits = DEFAULT_LIMITS,
        lookahead: float = 0.7,
        lookahead_per_speed: float = 0.25,
        pace: float = 1.0,
    ) -> None:
        if lookahead <= 0 or lookahead_per_speed < 0:
            raise ValueError("lookahead must be positive and lookahead_per_speed not negative")
        if not 0.0 < pace <= 1.0:
            raise ValueError(f"pace must be in (0, 1], got {pace}")
        self.pace = pace
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
        steer, speed = self.command(params["x"], params["y"], params["heading"], params["speed"])
        return steer, self.pace * speed

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
        return yaw, rear, self._lookahead_at(speed)

    def _lookahead_at(self, speed: float) -> float:
        """The pursuit distance (m) at ``speed``."""
        return self.lookahead + self.lookahead_per_speed * max(speed, 0.0)

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
# Closer than this across the track (centre to centre), a standing object is in the car's
# path: half a box's width (0.25 m) and half the car's (0.1 m).
ON_COURSE_M = 0.35
# The shortest pursuit distance when aiming beside such an object close ahead (about a car
# length: shorter, the pursuit steers at full lock for any error).
MIN_AIM_M = 0.3
# The highest speed asked for while steering around a box (a tighter, steadier line).
PASS_SPEED = 2.0
# Off the racing line by more than this after passing a box, the car rejoins it at
# PASS_SPEED (the lagging steering strays up to about 0.2 m from the line with nothing to
# pass); after a car it rejoins at the speed it holds on the arc it steers (slowing to
# PASS_SPEED handed the place back to the car just passed).
REJOIN_M = 0.25
# A car ahead is passed on the far side only when it is at least this far ahead (else the
# pass would cut across its nose): closer, the car passes on its own side or follows.
CROSS_GAP_M = 1.5
FOLLOW_MIN_SPEED = 0.5  # DeepRacer's lowest speed
CONTROL_DT = 1.0 / 15.0  # DeepRacer's control step (s)

# Whether to pass a car is decided from closing speed, gap and room (_pass_completes): the
# car plays the pass forward, itself at its profile's speed (PASS_LINE_SHARE of it: off
# the line it drives a longer, tighter path) and the rival at what it has shown it drives,
# and passes only when it gets PASS_CLEAR_M ahead (centre to centre: a car length and a
# quarter metre, room to cut back in front) within PASS_PLAN_S, before the next corner
# where the rival is the faster car hands the place back (a straight of the speedway is
# about 2 s at full speed). The rival's speed there is the larger of its speed now and its
# pace share times the profile's speed where it will be; its pace share is the lowest
# ratio of its measured speed to the profile's over the last PACE_MEMORY_STEPS (1.5 s: a
# corner and its exit), so a car of equal pace that brakes for a corner or accelerates out
# of one is not taken for a slow one (that took a pass leaving every corner and lost 2 s
# a race; RESULTS.md, "The gauntlet on real-width tracks"). In the first
# START_FOLLOW_STEPS control steps (2 s: from a standing start both cars accelerate alike
# and the pace share is not yet known) every car is followed.
PASS_LINE_SHARE = 0.95
PASS_CLEAR_M = 0.6
PASS_PLAN_S = 3.0
PACE_MEMORY_STEPS = 22
START_FOLLOW_STEPS = 30
# A pass under way goes on while it still gets ABORT_CLEAR_M ahead in the plan (less than
# PASS_CLEAR_M, so that the decision does not flicker from step to step); once the car is
# level with the rival it goes on regardless and holds its side.
ABORT_CLEAR_M = 0.4
# A car ahead crossing the track at more than HAZARD_ANGLE_DEG to it, fast enough to have
# no wheel on the road within HAZARD_S, will be held for a penalty on its lane: it is
# followed as a car that is about to stop (0.3 s and 25 deg: the paced follower swung off
# the road at the start at 35 deg, and was rear-ended while held in half the races at 90%
# pace; a racing car on the 0.76 m loop cuts from edge to edge, and taken for one leaving
# the road it was followed 0.2 s a race slower).
HAZARD_S = 0.3
HAZARD_ANGLE_DEG = 25.0
# A car whose lateral offset stayed within ON_LINE_M of the racing line's (mean over the
# memory) races the line: it brakes for the corners, takes their apexes and drives a
# steady share of the profile's speed (the LINE_SHARE_QUANTILE of its shares: a lagging
# car's share swings 0.55-0.8 round a corner at 80% pace, and the lowest of them took it
# for a 55% car and started passes into every corner). Such a car is passed along a lane
# CAR_CLEARANCE_M beside the line (:class:`_Lane`), at that lane's own speed profile, and
# only where the lane stays on the road while the cars overlap (the line runs along the
# edges, so one side of it has no room at every apex and straight end). 0.15 m: the
# pursuit drivers stray up to about 0.1 m from their line. Only on a track where a car
# fits beside one on the centre line (room >= CAR_CLEARANCE_M: DeepRacer's 1.07 m, not the
# 0.76 m loop, where the loop's lane-following bots stay within ON_LINE_M of the line and
# this rule ran into them 16 times in 5 races against 10 before).
ON_LINE_M = 0.15
# The median share still read the 80% racer as a 68% one leaving the speedway's hairpin
# (pursuit cuts the apex and exits slower than its profile), and started a pass there each
# lap that was given up on the straight; the upper quartile reads it at 0.78-0.88, and
# following it instead lost 1.43 s a lap to it, not 1.58 (h2h_gauntlet.py, 6 races).
LINE_SHARE_QUANTILE = 0.75
# Beside such a car the car aims this much wider than CAR_CLEARANCE_M: pursuit cuts a
# corner's inside by about 0.1 m, and on the outside of the speedway's first corner at 60%
# it closed to 0.2 m from the rival (centre to centre, the cars 0.196 m wide) and hit it.
PURSUIT_CUT_M = 0.1
# A pass along a lane is planned this far ahead (longer than PASS_PLAN_S: the lane's
# speed gains 0.5-0.8 m/s on an 80% racer, so the 1.4 m a pass needs takes 2-3 s after
# the swing out; planned over 3 s the teacher never passed it on grand_tour). While it
# passes, the car aims at the lane where its pursuit point is, not beside the rival now,
# and until the lane has room where the car is it follows on the line: where the line
# crosses the track the rival, a metre ahead, is already across, and aiming beside it, or
# at the lane pressed against the road's edge, steered the car into the corner's inside
# and halved its speed (RESULTS.md, "The teacher passes the 80% racer on grand_tour").
LANE_PASS_PLAN_S = 4.5
# Following (a car that cannot be passed): closing to FOLLOW_GAP_M (centre to centre along
# the track) at FOLLOW_GAIN m/s per metre of gap error, and never faster than lets the car
# brake at its braking limit, after FOLLOW_REACTION_S (three control steps: with one, the
# follower ran into the leader once a race on the lagging car), to the leader's speed
# before the gap falls to FOLLOW_MIN_GAP_M (the car's length and a few centimetres;
# Gipps' rule). Head-to-head laps are timed from each car's own grid slot, so a car that
# ends the race closer behind than it started wins: following a racing car wins more races
# than a pass that cannot complete, and the braking cap keeps the follower off a leader
# that brakes hard (benchmarks/RESULTS.md, "Following instead of passing").
FOLLOW_GAP_M = 0.55
FOLLOW_GAIN = 3.0
FOLLOW_MIN_GAP_M = 0.35
FOLLOW_REACTION_S = 0.2
# A car that races the racing line brakes where its profile brakes, so behind one the
# follower plays the next RACER_FOLLOW_PLAN_S forward (the rival at its usual share of
# the profile, never faster than now, both on the line) and keeps only the speed from
# which, after RACER_REACTION_STEPS, braking at its limit keeps it RACER_MIN_GAP_M behind
# the rival along the line all the while (:meth:`PassingPursuitPolicy._racer_follow_speed`).
# Two control steps (0.13 s) rather than FOLLOW_REACTION_S, which stands in for not
# knowing when a car brakes: at 3 m/s it follows about 0.55 m behind, not 0.95 m, and
# starts its passes that much closer (behind the speedway's 70% racer it passed in 10 of
# 10 races, not 5). 0.45 m of line, not FOLLOW_MIN_GAP_M: the cars cut a hairpin's apex
# off the line, and at 0.35 m the teacher touched the 90% racer on grand_tour's tightest
# corner once in 10 races (RESULTS.md, "Following a racer closely").
RACER_FOLLOW_PLAN_S = 1.5
RACER_REACTION_STEPS = 2
RACER_MIN_GAP_M = 0.45
# A car swinging out to pass such a car, still less than the cars' width and this much
# across from it, is still in its wake and closes on it no faster than following allows
# (it ran into the 60% racer braking for the speedway's first corner before it was out).
SWING_OUT_M = 0.05


class _Interpolated:
    """``np.interp`` of one function of the centre line's arc length at one point at a time
    (as fast in pure Python as a pass plan calling it 90 times a step needs): samples
    ``values`` at arc lengths ``arcs`` (sorted), periodic on a loop of length ``period``
    (a value that grows by ``rise`` a lap, as another path's arc length, unwrapped)."""

    def __init__(
        self, arcs: np.ndarray, values: np.ndarray, period: float | None, rise: float = 0.0
    ) -> None:
        xs, ys = arcs.tolist(), values.tolist()
        if period is not None:  # np.interp's padding: one sample each side, wrapped
            xs = [xs[-1] - period, *xs, xs[0] + period]
            ys = [ys[-1] - rise, *ys, ys[0] + rise]
        self._xs, self._ys, self._period = xs, ys, period

    def __call__(self, arc: float) -> float:
        """The interpolated value at ``arc``."""
        xs, ys = self._xs, self._ys
        x = arc % self._period if self._period is not None else arc
        if x <= xs[0]:
            return ys[0]
        if x >= xs[-1]:
            return ys[-1]
        j = bisect.bisect_right(xs, x) - 1
        slope = (ys[j + 1] - ys[j]) / (xs[j + 1] - xs[j])
        return slope * (x - xs[j]) + ys[j]


def _stretch(track: Track, arcs: np.ndarray, path_arcs: np.ndarray) -> np.ndarray:
    """Centre-line metres per metre driven along a path, at each of its points (forward
    differences; ``arcs``: the points' centre-line arc lengths, ``path_arcs``: their arc
    lengths along the path): above 1 on a corner's inside, below on its outside."""
    along = np.atleast_1d(track.arc_delta(arcs[:-1], arcs[1:]))
    ratio = along / np.maximum(np.diff(path_arcs), 1e-9)
    return np.append(ratio, ratio[0] if track.is_loop else ratio[-1])


class _Lane:
    """The way past a car racing the racing line on one side of it (``side`` 1 left, -1
    right): the line moved :data:`CAR_CLEARANCE_M` to that side, with its own speed
    profile, on the road where it stays within ``room`` of the centre line. Functions of
    the centre line's arc length (``arcs``, ``offsets``: the line's points projected onto
    it, in line order)."""

    def __init__(
        self,
        track: Track,
        line: RacingLine,
        arcs: np.ndarray,
        offsets: np.ndarray,
        side: float,
        room: float,
    ) -> None:
        wanted = offsets + side * CAR_CLEARANCE_M
        centre, heading = track.pose_at(arcs)
        normal = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
        points = centre + wanted[:, None] * normal  # unclipped: where it leaves the road
        # the pass may not be alongside (``fits``), and clipping would kink the path
        path = profile_path(points, line.limits, is_loop=line.is_loop)
        order = np.argsort(arcs)
        period = track.length if track.is_loop else None
        stretch = _stretch(track, arcs, path.arc_length)
        self.speed = _Interpolated(arcs[order], path.speed[order], period)
        self.stretch = _Interpolated(arcs[order], stretch[order], period)
        self._overflow = _Interpolated(arcs[order], np.abs(wanted[order]) - room, period)

    def fits(self, arc: float) -> bool:
        """Whether the lane beside the line is on the road at ``arc``."""
        return self._overflow(arc) <= 0.0


class _Seen:
    """What the car saw of one other car over its last :data:`PACE_MEMORY_STEPS` steps:
    its measured speed, its lateral offset (m, left positive) and its speed as a share of
    the racing line's profile speed where it was."""

    def __init__(self) -> None:
        self.speeds: deque[float] = deque(maxlen=PACE_MEMORY_STEPS)
        self.offsets: deque[float] = deque(maxlen=PACE_MEMORY_STEPS)
        self.shares: deque[float] = deque(maxlen=PACE_MEMORY_STEPS)
        self.off_line: deque[float] = deque(maxlen=PACE_MEMORY_STEPS)
        self.is_car = False  # it was seen moving: a car, held for a penalty when it stands

    def add(self, speed: float, offset: float, profile_speed: float, line_offset: float) -> None:
        """Record one step (``line_offset``: the racing line's offset where the car is)."""
        self.speeds.append(speed)
        self.is_car = self.is_car or speed > MOVING_MPS
        self.offsets.append(offset)
        self.off_line.append(abs(offset - line_offset))
        self.shares.append(speed / max(profile_speed, FOLLOW_MIN_SPEED))

    @property
    def speed(self) -> float:
        """Its speed now (m/s)."""
        return self.speeds[-1]

    @property
    def pace_share(self) -> float:
        """The lowest share of the profile's speed it drove at over the memory; 1.0 (as
        fast as this car) until the memory is full."""
        return min(self.shares) if len(self.shares) == self.shares.maxlen else 1.0

    @property
    def on_line(self) -> bool:
        """Whether it races the racing line (:data:`ON_LINE_M`), over a full memory."""
        full = len(self.off_line) == self.off_line.maxlen
        return full and sum(self.off_line) / len(self.off_line) < ON_LINE_M

    @property
    def line_share(self) -> float:
        """The :data:`LINE_SHARE_QUANTILE` of the shares of the profile's speed it drove
        at over the memory."""
        return float(np.quantile(self.shares, LINE_SHARE_QUANTILE))

    def lateral_speed(self) -> float:
        """Its speed across the track over the last two steps (m/s, left positive)."""
        if len(self.offsets) < 3:
            return 0.0
        return (self.offsets[-1] - self.offsets[-3]) / (2.0 * CONTROL_DT)


class PassingPursuitPolicy(PurePursuitPolicy):
    """Pure pursuit on the racing line that steers around the objects ahead of it.

    Boxes, bots and other cars come from the params (``objects_*``). When one lies within
    :data:`PASS_HORIZON_S` seconds (at least :data:`PASS_HORIZON_M` metres) ahead, or
    still beside the car, and the car's way from where it is to the racing line would pass
    it closer than the clearance, the car aims beside it instead: past a box at most at
    :data:`PASS_SPEED` on the side it is on when the track has room there, else on the far
    side. A car is passed, at the profile's speed, only when the pass completes
    (:meth:`_pass_completes`: closing speed, gap and room), on the side with room at the
    rival (:meth:`_pass_side`); a pass once begun is kept, on its side, until it no longer
    completes while the car is still behind. A car racing the racing line itself is
    passed along a lane beside that line, only where the lane has room while the cars
    overlap (:meth:`_lane_pass_completes`). Any other car is followed
    (:meth:`_follow_speed`): on the racing line from behind, on its own side when level.
    Off the line by more than :data:`REJOIN_M`, it rejoins the line at most at
    :data:`PASS_SPEED`. On the line with no object near it drives as
    :class:`PurePursuitPolicy`. It is the teacher that ``slipstream train --teacher
    pursuit`` imitates.
    """

    def __init__(self, track: Track, *args: Any, **kwargs: Any) -> None:
        super().__init__(track, *args, **kwargs)
        self.track = track
        where = track.project(self.line.points)
        order = np.argsort(where.arc_length)
        arcs = where.arc_length[order]
        period = track.length if track.is_loop else None
        # The racing line's profile speed and lateral offset where the centre line is
        # ``arc`` metres long.
        self._profile_at = _Interpolated(arcs, self.line.speed[order], period)
        self._line_offset_at = _Interpolated(arcs, where.offset[order], period)
        stretch = _stretch(track, where.arc_length, self.line.arc_length)
        self._line_stretch = _Interpolated(arcs, stretch[order], period)
        # The racing line's own arc length where the centre line is ``arc`` metres long
        # (unwrapped), and its profile speed by its own arc length: the gap between two
        # cars on the line in metres of line (round a hairpin's apex a metre of centre
        # line is about half a metre of line).
        line = self.line
        own = len(line.points) - 1 if line.is_loop else len(line.points)  # loops repeat
        by_arc = np.argsort(where.arc_length[:own])
        line_arcs = line.arc_length[:own][by_arc]
        if line.is_loop:
            line_arcs = np.unwrap(line_arcs, period=line.length)
        self._line_arc_at = _Interpolated(
            where.arc_length[:own][by_arc], line_arcs, period, rise=line.length
        )
        line_period = line.length if line.is_loop else None
        self._speed_on_line = _Interpolated(line.arc_length[:own], line.speed[:own], line_period)
        self._room = 0.5 * track.width - 0.5 * DEFAULT_CAR.width - PASS_EDGE_MARGIN_M
        self._lanes = {
            side: _Lane(track, self.line, where.arc_length, where.offset, side, self._room)
            for side in (1.0, -1.0)
        }
        self.reset()

    def reset(self) -> None:
        """Start of a race: forget the steps, the cars seen and any pass under way."""
        super().reset()
        self._steps = 0
        self._seen: dict[int, _Seen] = {}
        self._last_arc: float | None = None
        self._my_speed = 0.0
        self._passing: int | None = None  # the object being passed
        self._side = 0.0  # which side of it: 1 left, -1 right
        self._after_box = False  # rejoining the line after a box (at PASS_SPEED)

    @property
    def is_passing(self) -> bool:
        """Whether a pass of a car is under way (as of the last command)."""
        return self._passing is not None

    @property
    def pass_side(self) -> float | None:
        """The side of the car being passed that this car goes by (1 left, -1 right), None
        when no pass is under way (as of the last command)."""
        return self._side if self._passing is not None else None

    def command_for(self, params: dict[str, Any]) -> tuple[float, float]:
        """The racing-line command, or one aimed beside an object in the way.

        Aimed beside a car that races the line, the car asks for the profile's speed
        capped by the arc it steers there, not by the arc it would steer back to the line
        (that halved its speed beside the line leaving the speedway's hairpin; behind
        the 60% racer there it lost 0.63 s a lap, not 2.11).
        """
        steer, speed = super().command_for(params)
        self._steps += 1
        self._aim_within = math.inf
        self._lane_aim = False  # aiming beside a car that races the line (_past_car)
        self._observe(params)
        way = self._way_past(params, speed)
        if way is None:
            self._passing = None
            off_line = abs(car_offset(params) - self._line_offset_at(params["projection_distance"]))
            slow = self._after_box and off_line > REJOIN_M
            self._after_box = slow
            return steer, min(speed, PASS_SPEED) if slow else speed
        offset, most = way
        if offset is None:  # following a racing car, on the racing line
            return steer, min(speed, most)
        yaw, rear, distance = self._pursuit_geometry(
            params["x"], params["y"], params["heading"], min(params["speed"], most)
        )
        arc = float(self.track.project(rear[None]).arc_length[0]) + min(distance, self._aim_within)
        if self._lane_aim:  # the lane it planned, where it aims (not beside the rival now)
            offset = self._lane_offset(arc)
        target, _ = self.track.pose_at(self.track.wrap_arc_length(arc), offset)
        wheelbase = self.limits.wheelbase_at(params["speed"])
        steer = pursuit_steering(DEFAULT_CAR, rear[0], rear[1], yaw, target, wheelbase)
        if self._lane_aim:  # the profile's speed, not capped by the arc back to the line
            profile = self._ahead(rear, self._lookahead_at(params["speed"]))[1]
            speed = self.pace * min(profile, self.max_speed)
        return steer, min(speed, most, self.arc_speed(steer, params["speed"]))

    def _observe(self, params: dict[str, Any]) -> None:
        """Update this car's measured speed (along the centre line) and what it saw of the
        moving objects; forget them all when the list of objects changes (a car parked
        or back from a penalty)."""
        arc = float(params["projection_distance"])
        if self._last_arc is not None:
            self._my_speed = max(0.0, self.track.arc_delta(self._last_arc, arc) / CONTROL_DT)
        self._last_arc = arc
        count = len(params["objects_distance"])
        if len(self._seen) != count or count == 0:
            self._seen = {i: _Seen() for i in range(count)}
            self._passing = None
        for i, seen in self._seen.items():
            their_arc = float(params["objects_distance"][i])
            profile = self._profile_at(their_arc)
            seen.add(
                float(params["objects_speed"][i]),
                object_offset(params, i),
                profile,
                self._line_offset_at(their_arc),
            )

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
        here = car_offset(params)
        for i in np.argsort(gaps):
            if not -PASS_BESIDE_M <= gaps[i] <= horizon:
                continue
            obstacle = self._seen[int(i)].offsets[-1]
            moving = float(params["objects_speed"][i]) > MOVING_MPS
            clearance = CAR_CLEARANCE_M if moving else BOX_CLEARANCE_M
            # From where the car is to the line's offset at the object, all the way clear?
            low, high = sorted((here, self._line_offset_at(arc + gaps[i])))
            if max(low - obstacle, obstacle - high) >= clearance:
                if self._passing == i and gaps[i] > 0.0:
                    return here, line_speed  # beside it already: hold the side
                continue
            if moving:
                return self._past_car(int(i), float(gaps[i]), here, arc, line_speed)
            clearance = CAR_CLEARANCE_M if self._seen[int(i)].is_car else BOX_CLEARANCE_M
            return self._past_box(float(gaps[i]), obstacle, clearance, here, (low, high))
        return None

    def _past_box(
        self, gap: float, obstacle: float, clearance: float, here: float, way: tuple
    ) -> tuple[float, float]:
        """The way past a standing object (a box, or a car held for a penalty) ``gap``
        metres ahead at lateral offset ``obstacle``, kept ``clearance`` from, the car's
        way to the line spanning offsets ``way`` (low, high): beside it on the near side
        when the track has room, else on the far side, at most at :data:`PASS_SPEED`.
        While still in its path (:data:`ON_COURSE_M`) the car goes no faster than lets it
        stop short of it, and aims beside it no further ahead than it is (the lookahead
        at a crawl would steer too gently to get round it)."""
        lean = 1.0 if sum(way) >= 2.0 * obstacle else -1.0
        self._after_box = clearance == BOX_CLEARANCE_M
        most = PASS_SPEED
        if gap > 0.0 and abs(here - obstacle) < ON_COURSE_M:
            most = min(most, self._follow_speed(gap, 0.0, self._my_speed))
            self._aim_within = max(gap - MIN_AIM_M, MIN_AIM_M)
        for side in (obstacle + lean * clearance, obstacle - lean * clearance):
            if abs(side) <= self._room:
                return side, most
        near_side = obstacle + lean * clearance
        return float(np.clip(near_side, -self._room, self._room)), FOLLOW_MIN_SPEED

    def _past_car(
        self, i: int, gap: float, here: float, arc: float, line_speed: float
    ) -> tuple[float | None, float]:
        """The way past car ``i``, ``gap`` metres ahead (negative: beside, behind the
        car's centre) of this car at lateral offset ``here`` and arc length ``arc``: pass
        it when the pass completes and there is room, else follow it."""
        seen = self._seen[i]
        if gap > 0.0 and self._leaving_road(seen):
            self._passing = None
            return None, self._follow_speed(gap, 0.0, self._my_speed)
        if seen.on_line and self._room >= CAR_CLEARANCE_M:
            side = self._racer_side(i, gap, here, arc, seen)
            if side is not None:
                self._passing, self._side = i, side
                if gap > DEFAULT_CAR.length and not self._lanes[side].fits(arc):
                    # no room for the lane here yet: behind the rival on the line
                    return None, min(line_speed, self._racer_follow_speed(arc, gap, seen))
                self._lane_aim = True
                speed = self._lanes[side].speed(arc)
                if gap > 0.0 and abs(here - seen.offsets[-1]) < DEFAULT_CAR.width + SWING_OUT_M:
                    # still in its wake: close no faster than following allows
                    speed = min(speed, self._racer_follow_speed(arc, gap, seen))
                return self._lane_offset(arc), speed
        else:
            side = self._pass_side(seen.offsets[-1], here, gap)
            if side is not None and self._keeps_passing(i, gap, arc, seen):
                self._passing, self._side = i, side
                return seen.offsets[-1] + side * CAR_CLEARANCE_M, line_speed
        self._passing = None
        if seen.on_line and self._room >= CAR_CLEARANCE_M and gap > 0.0:
            follow = self._racer_follow_speed(arc, gap, seen)
        else:
            follow = self._follow_speed(max(gap, 0.0), seen.speed, self._my_speed)
        if abs(here - seen.offsets[-1]) >= CAR_CLEARANCE_M and gap < DEFAULT_CAR.length:
            # level with it (a pass given up): hold this side and drop back behind it
            clear_side = 1.0 if here > seen.offsets[-1] else -1.0
            aside = seen.offsets[-1] + clear_side * CAR_CLEARANCE_M
            return float(np.clip(aside, -self._room, self._room)), min(line_speed, follow)
        return None, follow

    def _keeps_passing(self, i: int, gap: float, arc: float, seen: _Seen) -> bool:
        """Whether to pass car ``i`` now: a pass under way goes on while it completes
        with :data:`ABORT_CLEAR_M` (and always once level); a new one starts after the
        start's :data:`START_FOLLOW_STEPS` when it completes with :data:`PASS_CLEAR_M`."""
        if self._passing == i:
            return gap <= 0.0 or self._pass_completes(arc, gap, seen, ABORT_CLEAR_M)
        if self._steps <= START_FOLLOW_STEPS:
            return False
        return self._pass_completes(arc, gap, seen, PASS_CLEAR_M)

    def _pass_completes(self, arc: float, gap: float, seen: _Seen, clear: float) -> bool:
        """Whether this car, at arc length ``arc`` and ``gap`` metres behind a car it has
        ``seen``, gets ``clear`` metres ahead of it within :data:`PASS_PLAN_S`.

        Played forward a control step at a time along the centre line: this car at
        :data:`PASS_LINE_SHARE` of its profile's speed, reached at its acceleration and
        braking limits from its measured speed; the rival at the larger of its speed now
        and its pace share of the profile's speed where it will be. A pass that reaches
        a stretch where the rival is the faster car (the next corner: beside it, this
        car is off its line and slower still) before it is clear does not complete.
        """
        limits = self.line.limits
        mine, theirs = arc, arc + gap
        speed, share, now = self._my_speed, seen.pace_share, seen.speed
        for _ in range(round(PASS_PLAN_S / CONTROL_DT)):
            wanted = PASS_LINE_SHARE * self._profile_at(mine)
            rival_speed = max(now, share * self._profile_at(theirs))
            if wanted < rival_speed:
                return False  # a corner where the rival is the faster car comes first
            change = wanted - speed
            speed += min(max(change, -limits.max_brake * CONTROL_DT), limits.max_accel * CONTROL_DT)
            mine += speed * CONTROL_DT
            theirs += rival_speed * CONTROL_DT
            if mine - theirs >= clear:
                return True
        return False

    def _racer_side(self, i: int, gap: float, here: float, arc: float, seen: _Seen) -> float | None:
        """The side (1 left, -1 right) to pass car ``i``, which races the racing line, or
        None to follow it: a pass under way goes on, on its side, while it completes with
        :data:`ABORT_CLEAR_M`; a new one starts after the start's :data:`START_FOLLOW_STEPS`
        on a side where it completes with :data:`PASS_CLEAR_M`: this car's own side of the
        rival, or either side from straight behind it (or :data:`CROSS_GAP_M` back)."""
        if self._passing == i:
            sides, clear = [self._side], ABORT_CLEAR_M
        elif self._steps <= START_FOLLOW_STEPS:
            return None
        else:
            own = 1.0 if here >= seen.offsets[-1] else -1.0
            behind = abs(here - seen.offsets[-1]) < DEFAULT_CAR.width or gap >= CROSS_GAP_M
            sides, clear = ([own, -own] if behind else [own]), PASS_CLEAR_M
        for side in sides:
            if self._lane_pass_completes(arc, gap, seen, self._lanes[side], clear):
                return side
        return None

    def _lane_offset(self, arc: float) -> float:
        """The lateral offset of the pass under way along a lane at arc length ``arc``: the
        racing line's there, moved :data:`CAR_CLEARANCE_M` and :data:`PURSUIT_CUT_M` to the
        pass's side, on the road."""
        wide = self._side * (CAR_CLEARANCE_M + PURSUIT_CUT_M)
        return float(np.clip(self._line_offset_at(arc) + wide, -self._room, self._room))

    def _lane_pass_completes(
        self, arc: float, gap: float, seen: _Seen, lane: _Lane, clear: float
    ) -> bool:
        """Whether this car, at arc length ``arc`` and ``gap`` metres behind a car it has
        ``seen`` racing the racing line, gets ``clear`` metres ahead of it along ``lane``
        within :data:`LANE_PASS_PLAN_S`, the lane staying on the road while the cars
        overlap.

        Played forward a control step at a time: this car at :data:`PASS_LINE_SHARE` of
        the lane's profile speed, reached at its acceleration and braking limits from its
        measured speed; the rival on the line at its usual share of the line's profile
        speed (:attr:`_Seen.line_share`). Each moves along the centre line at its speed
        times its path's stretch (a corner's inside is shorter than its outside).
        """
        limits = self.line.limits
        mine, theirs = arc, arc + gap
        speed, share = self._my_speed, seen.line_share
        for _ in range(round(LANE_PASS_PLAN_S / CONTROL_DT)):
            if mine - theirs > -DEFAULT_CAR.length and not lane.fits(theirs):
                return False  # alongside where the lane beside the rival leaves the road
            change = PASS_LINE_SHARE * lane.speed(mine) - speed
            speed += min(max(change, -limits.max_brake * CONTROL_DT), limits.max_accel * CONTROL_DT)
            mine += speed * lane.stretch(mine) * CONTROL_DT
            theirs += share * self._profile_at(theirs) * self._line_stretch(theirs) * CONTROL_DT
            if mine - theirs >= clear:
                return True
        return False

    def _pass_side(self, rival: float, here: float, gap: float) -> float | None:
        """The side (1 left, -1 right) to pass a car at lateral offset ``rival``: the one
        under way if it still has room, else this car's own side when it has room, else
        the far side when the car is far enough ahead to cross in front of
        (:data:`CROSS_GAP_M`); None when neither has room."""

        def fits(side: float) -> bool:
            return abs(rival + side * CAR_CLEARANCE_M) <= self._room

        if self._passing is not None and fits(self._side):
            return self._side
        own = 1.0 if here >= rival else -1.0
        if fits(own):
            return own
        if fits(-own) and gap >= CROSS_GAP_M:
            return -own
        return None

    def _leaving_road(self, seen: _Seen) -> bool:
        """Whether the car ``seen`` is leaving the road: crossing the track at more than
        :data:`HAZARD_ANGLE_DEG` to it, fast enough that within :data:`HAZARD_S` no wheel
        will be on the road."""
        lateral = seen.lateral_speed()
        ahead = seen.offsets[-1] + HAZARD_S * lateral
        steep = abs(lateral) > math.tan(math.radians(HAZARD_ANGLE_DEG)) * max(seen.speed, 0.1)
        return steep and abs(ahead) > 0.5 * (self.track.width + DEFAULT_CAR.width)

    def _racer_follow_speed(self, arc: float, gap: float, seen: _Seen) -> float:
        """The speed to follow car ``seen``, which races the racing line, ``gap`` metres
        ahead of this car at arc length ``arc``: closing to :data:`FOLLOW_GAP_M` as
        :meth:`_follow_speed` does, capped by the fastest speed from which this car,
        braking at its limit after :data:`RACER_REACTION_STEPS`, stays
        :data:`RACER_MIN_GAP_M` behind the rival played forward
        :data:`RACER_FOLLOW_PLAN_S` (at its usual share of the line's profile speed,
        never faster than it is now). Both are taken on the racing line and their gaps
        measured along it."""
        line = self.line
        mine = self._line_arc_at(arc)
        ahead = self._line_arc_at(arc + gap) - mine
        if line.is_loop:
            ahead %= line.length
        share, now, start_gap = seen.line_share, seen.speed, ahead
        rival = []  # metres of line the rival is ahead of this car's start, per step
        for _ in range(round(RACER_FOLLOW_PLAN_S / CONTROL_DT)):
            rival_speed = min(now, share * self._speed_on_line(mine + ahead))
            ahead += rival_speed * CONTROL_DT
            rival.append((ahead, rival_speed))
        brake = line.limits.max_brake * CONTROL_DT

        def keeps_clear(speed: float) -> bool:
            driven = 0.0
            for k, (their_lead, rival_speed) in enumerate(rival):
                if k >= RACER_REACTION_STEPS and speed > rival_speed:
                    speed = max(speed - brake, rival_speed)
                driven += speed * CONTROL_DT
                if their_lead - driven < RACER_MIN_GAP_M:
                    return False
            return True

        low, high = 0.0, self.max_speed
        if keeps_clear(high):
            low = high
        while high - low > 0.01:
            mid = 0.5 * (low + high)
            low, high = (mid, high) if keeps_clear(mid) else (low, mid)
        closing = now + FOLLOW_GAIN * (start_gap - FOLLOW_GAP_M)
        return max(FOLLOW_MIN_SPEED, min(closing, low))

    def _follow_speed(self, gap: float, leader_speed: float, speed: float) -> float:
        """The speed to follow a car ``gap`` metres ahead (centre to centre along the
        track) that moves at ``leader_speed``; ``speed`` is this car's speed."""
        closing = leader_speed + FOLLOW_GAIN * (gap - FOLLOW_GAP_M)
        room = gap - FOLLOW_MIN_GAP_M - FOLLOW_REACTION_S * speed
        braking = math.sqrt(max(0.0, leader_speed**2 + 2.0 * self.line.limits.max_brake * room))
        return max(FOLLOW_MIN_SPEED, min(closing, braking))


def car_offset(params: dict[str, Any]) -> float:
    """The car's signed lateral offset from the centre line (m, left positive)."""
    return (1.0 if params["is_left_of_center"] else -1.0) * float(params["distance_from_center"])


def object_offset(params: dict[str, Any], i: int) -> float:
    """Object ``i``'s signed lateral offset from the centre line (m, left positive)."""
    side = 1.0 if params["objects_left_of_center"][i] else -1.0
    return side * float(params["objects_distance_from_center"][i])
