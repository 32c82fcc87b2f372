"""Stay inside the borders: a flat reward anywhere safely on the road.

Unlike following the centre line, every line that keeps all four wheels on the road
and the car's nose at least 5 cm inside the border pays the same, so the car is free to
find its own (often faster) line. Leaving the road pays almost nothing.

Params used: all_wheels_on_track, distance_from_center, track_width.
"""

MARGIN = 0.05  # metres kept between the model point and the border


def reward_function(params):
    half_width = 0.5 * params["track_width"]
    inside = params["distance_from_center"] <= half_width - MARGIN
    if params["all_wheels_on_track"] and inside:
        return 1.0
    return 1e-3
