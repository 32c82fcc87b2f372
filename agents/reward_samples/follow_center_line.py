"""Follow the centre line: the higher the reward, the closer the car drives to the middle.

Three bands across the track (10 %, 25 % and 50 % of its width from the centre) pay
1.0, 0.5 and 0.1; anything further out, or any wheel off the road, pays almost nothing.
A good first reward: it teaches staying on track, not speed.

Params used: all_wheels_on_track, distance_from_center, track_width.
"""


def reward_function(params):
    if not params["all_wheels_on_track"]:
        return 1e-3
    offset = params["distance_from_center"] / params["track_width"]
    if offset <= 0.1:
        return 1.0
    if offset <= 0.25:
        return 0.5
    if offset <= 0.5:
        return 0.1
    return 1e-3
