"""Head to head: race the lap, keep a safe gap to the car ahead, and get past it.

On the road the car is paid as ``pursuit`` pays it, progress per step plus speed, so a
car that races earns more than one that crawls behind a rival. When the nearest car
ahead is closer than SAFE_GAP metres along the track, the pay shrinks with the gap if
both share a lane (following too close invites a crash, which counts against the car
behind) and grows by half if the car is in the other lane, where it can pass. A car
close behind means this car has just got past it (or is holding it off): that earns a
bonus. Crashes and leaving the road pay almost nothing. Without other cars it is
``pursuit``.

Params used: all_wheels_on_track, is_crashed, progress, steps, speed, is_left_of_center,
projection_distance, track_length, closest_objects, objects_distance,
objects_left_of_center.
"""

PROGRESS_SCALE = 0.75  # as in pursuit: about 1 per step at full pace on a 20 m track
MAX_SPEED = 4.0
SAFE_GAP = 1.0  # metres along the track to the car ahead
PASS_WINDOW = 1.0  # metres behind in which a car counts as just overtaken
PASS_BONUS = 0.5


def reward_function(params):
    if not params["all_wheels_on_track"] or params["is_crashed"]:
        return 1e-3
    pace = PROGRESS_SCALE * params["progress"] / max(params["steps"], 1)
    reward = pace + (params["speed"] / MAX_SPEED) ** 2
    if not params.get("objects_distance"):
        return reward
    here = params["projection_distance"]
    length = params["track_length"]
    behind, ahead = params["closest_objects"]
    gap_ahead = (params["objects_distance"][ahead] - here) % length
    if gap_ahead < SAFE_GAP:
        same_lane = params["is_left_of_center"] == params["objects_left_of_center"][ahead]
        reward *= max(gap_ahead / SAFE_GAP, 0.05) if same_lane else 1.5
    gap_behind = (here - params["objects_distance"][behind]) % length
    if gap_behind < PASS_WINDOW:
        reward += PASS_BONUS
    return reward
