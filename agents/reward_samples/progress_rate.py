"""Progress rate: pay how fast the car moves along the track, the quantity a lap time sums.

A car at speed ``v`` whose heading is ``psi`` off the track's direction, ``n`` metres to
the side of a centre line that turns with curvature ``k`` (1/radius, positive turning
left; ``n`` positive left), moves along the centre line at ``v cos(psi) / (1 - k n)``
metres a second: the inside of a corner is shorter, so the same speed there makes more
of the lap. Unlike a reward on speed, a longer path at the same speed earns no more.

A training episode ends after its laps, so a reward of the rate itself would sum to the
same over every lap, fast or slow: the rate is paid squared, which sums over a lap to
about ``length / step`` times the lap's mean rate, more for a faster lap. Any wheel off
the road pays almost nothing.

The direction and curvature come from the waypoints around the car; ``speed`` is the
commanded speed, as in DeepRacer.

Params used: all_wheels_on_track, speed, heading, waypoints, closest_waypoints,
distance_from_center, is_left_of_center.
"""

import math

MAX_SPEED = 4.0
MIN_STRETCH = 0.25  # at most 4x a centre-line metre for a metre driven (tight inside lines)


def _angle(a, b):
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _wrap(angle):
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def reward_function(params):
    if not params["all_wheels_on_track"]:
        return 1e-3
    points = params["waypoints"]
    count = len(points) - 1 if points[0] == points[-1] else len(points)
    here = params["closest_waypoints"][0]
    p0, p1, p2, p3 = (points[(here + k) % count] for k in (-1, 0, 1, 2))
    direction = _angle(p1, p2)
    turn = _wrap(_angle(p2, p3) - _angle(p0, p1))
    span = 0.5 * math.dist(p0, p1) + math.dist(p1, p2) + 0.5 * math.dist(p2, p3)
    curvature = turn / max(span, 1e-6)
    side = params["distance_from_center"] * (1.0 if params["is_left_of_center"] else -1.0)
    psi = math.radians(params["heading"]) - direction
    along = params["speed"] * math.cos(psi) / max(1.0 - curvature * side, MIN_STRETCH)
    return (max(along, 0.0) / MAX_SPEED) ** 2 + 1e-3
