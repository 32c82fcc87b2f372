"""Prevent zig-zag: follow the centre line, but pay less for hard steering.

The centre-line bands give the base reward; steering harder than 15 degrees either way
cuts it by a fifth, so the car learns to drive straight where it can instead of
swinging from side to side.

Params used: all_wheels_on_track, distance_from_center, track_width, steering_angle.
"""

STEERING_LIMIT = 15.0  # degrees; harder steering is penalised


def reward_function(params):
    if not params["all_wheels_on_track"]:
        return 1e-3
    offset = params["distance_from_center"] / params["track_width"]
    if offset <= 0.1:
        reward = 1.0
    elif offset <= 0.25:
        reward = 0.5
    elif offset <= 0.5:
        reward = 0.1
    else:
        return 1e-3
    if abs(params["steering_angle"]) > STEERING_LIMIT:
        reward *= 0.8
    return reward
