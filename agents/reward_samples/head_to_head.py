"""Head to head: go fast, keep a safe gap to the car ahead, and get past it.

On the road the car is paid for speed. When the nearest car ahead is closer than
SAFE_GAP metres along the track, the reward shrinks with the gap if both share a lane
(following too close invites a crash, which counts against the car behind) and grows
if the car is in the other lane, where it can pass. A car close behind means this car
has just got past it (or is holding it off): that earns a bonus. Crashes pay almost
nothing. Without other cars it simply rewards speed on the road.

Params used: all_wheels_on_track, is_crashed, speed, is_left_of_center,
projection_distance, track_length, closest_objects, objects_distance,
objects_left_of_center.
"""

SAFE_GAP = 1.0  # metres along the track to the car ahead
PASS_WINDOW = 1.0  # metres behind in which a car counts as just overtaken
MAX_SPEED = 4.0


def reward_function(params):
    if not params["all_wheels_on_track"] or params["is_crashed"]:
        return 1e-3
    reward = 0.5 + 0.5 * params["speed"] / MAX_SPEED
    if not params.get("objects_distance"):
        return reward
    here = params["projection_distance"]
    length = params["track_length"]
    behind, ahead = params["closest_objects"]
    gap_ahead = (params["objects_distance"][ahead] - here) % length
    if gap_ahead < SAFE_GAP:
        same_lane = params["is_left_of_center"] == params["objects_left_of_center"][ahead]
        reward *= gap_ahead / SAFE_GAP if same_lane else 1.5
    gap_behind = (here - params["objects_distance"][behind]) % length
    if gap_behind < PASS_WINDOW:
        reward += 0.5
    return reward
