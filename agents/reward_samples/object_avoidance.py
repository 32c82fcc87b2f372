"""Object avoidance: race the lap, and be in the other lane when a box comes up.

On the road the car is paid as ``pursuit`` pays it, progress per step plus speed, so a
car that crawls earns less than one that races. Within LOOK_AHEAD metres of the next box
ahead, the pay shrinks with the gap while the car is in the box's lane and grows by half
in the other lane. A crash or leaving the road pays almost nothing (and ends a training
episode, which costs the car every later step's pay). Without objects (a time trial) it
is ``pursuit``.

Params used: all_wheels_on_track, is_crashed, progress, steps, speed, is_left_of_center,
projection_distance, track_length, closest_objects, objects_distance,
objects_left_of_center (without objects the lists are empty, as in DeepRacer).
"""

PROGRESS_SCALE = 0.75  # as in pursuit: about 1 per step at full pace on a 20 m track
MAX_SPEED = 4.0
LOOK_AHEAD = 1.5  # metres along the track at which a box starts to matter


def reward_function(params):
    if not params["all_wheels_on_track"] or params["is_crashed"]:
        return 1e-3
    pace = PROGRESS_SCALE * params["progress"] / max(params["steps"], 1)
    reward = pace + (params["speed"] / MAX_SPEED) ** 2
    if not params.get("objects_distance"):
        return reward
    ahead = params["closest_objects"][1]
    gap = (params["objects_distance"][ahead] - params["projection_distance"]) % params[
        "track_length"
    ]
    if gap < LOOK_AHEAD:
        same_lane = params["is_left_of_center"] == params["objects_left_of_center"][ahead]
        reward *= max(gap / LOOK_AHEAD, 0.05) if same_lane else 1.5
    return reward
