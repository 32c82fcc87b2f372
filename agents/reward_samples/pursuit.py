"""Pursuit: reward progress per step plus speed, the usual recipe for fast laps.

``progress / steps`` is the average share of a lap made per step so far: it grows when
the car covers the lap in fewer steps, i.e. drives a shorter line faster. The speed term
keeps the car pushing on straights. Off the road it pays almost nothing.

At 15 steps a second, a lap of L metres at v m/s makes ``100 v / (15 L)`` percent per
step: about 1.3 on a 20 m track at 4 m/s; PROGRESS_SCALE brings that near 1.

Params used: all_wheels_on_track, progress, steps, speed.
"""

PROGRESS_SCALE = 0.75
MAX_SPEED = 4.0


def reward_function(params):
    if not params["all_wheels_on_track"]:
        return 1e-3
    steps = max(params["steps"], 1)
    pace = PROGRESS_SCALE * params["progress"] / steps
    speed = (params["speed"] / MAX_SPEED) ** 2
    return pace + speed
