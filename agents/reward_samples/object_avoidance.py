"""Object avoidance: stay on the road and be in the other lane when a box comes up.

Far from any object the car is paid for staying on track. Within LOOK_AHEAD metres of
the next object ahead, being in the object's lane is paid less the closer it gets, and
being in the other lane earns a bonus. Without objects (a time trial) it reduces to
"stay on the road".

Params used: all_wheels_on_track, is_left_of_center, projection_distance, track_length,
closest_objects, objects_distance, objects_left_of_center (without objects the lists are
empty, as in DeepRacer).
"""

LOOK_AHEAD = 1.5  # metres along the track at which an object starts to matter


def reward_function(params):
    if not params["all_wheels_on_track"]:
        return 1e-3
    reward = 1.0
    if not params.get("objects_distance"):
        return reward
    ahead = params["closest_objects"][1]
    gap = (params["objects_distance"][ahead] - params["projection_distance"]) % params[
        "track_length"
    ]
    if gap < LOOK_AHEAD:
        same_lane = params["is_left_of_center"] == params["objects_left_of_center"][ahead]
        if same_lane:
            reward *= max(gap / LOOK_AHEAD, 0.05)
        else:
            reward += 1.0
    return reward
