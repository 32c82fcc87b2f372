"""Load a racer's DeepRacer reward function, smoke-test it, and find the bundled samples.

A reward function is a Python file defining ``reward_function(params) -> float``, exactly
as on DeepRacer. :func:`load_reward_function` executes that file: it is the racer's own
code, run on the racer's own machine to train their own car. It is never used on uploaded
files; the league only ever receives ONNX graphs and JSON (see ``submissions``).
"""

from __future__ import annotations

import copy
import inspect
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from arena.config import RACE_TYPES, PhysicsConfig
from arena.params import ObjectsView, build_params, deepest_line
from tracks.catalog import get_track
from tracks.track import Track

RewardFunction = Callable[[dict[str, Any]], float]
MAX_ABS_REWARD = 1e5
CHECK_STEPS = 5  # steps of the sample episode the pre-check drives the function through
SAMPLES_DIR = Path(__file__).parent / "reward_samples"


class RewardFunctionError(ValueError):
    """A reward-function file that cannot be loaded or misbehaves on sample params."""


def _where_in(path: Path, exc: BaseException) -> str:
    """``line N`` of the deepest traceback frame inside the racer's file, if any."""
    line = deepest_line(exc, str(path))
    return f" at line {line}" if line else ""


def _execute(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise RewardFunctionError(f"reward function file {path} does not exist")
    try:
        source = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RewardFunctionError(f"cannot read reward function file {path}: {exc}") from None
    try:
        code = compile(source, str(path), "exec")
    except SyntaxError as exc:
        raise RewardFunctionError(
            f"{path}: syntax error at line {exc.lineno}: {exc.msg}"
            + (f"\n    {exc.text.rstrip()}" if exc.text else "")
        ) from None
    namespace: dict[str, Any] = {"__name__": f"reward_file_{path.stem}", "__file__": str(path)}
    try:
        exec(code, namespace)  # the racer's own file on their own machine: intended
    except Exception as exc:
        raise RewardFunctionError(
            f"{path}: running the file raised {type(exc).__name__}: {exc}{_where_in(path, exc)}"
        ) from exc
    return namespace


def _checked_signature(fn: Callable[..., Any], path: Path) -> None:
    try:
        signature = inspect.signature(fn)
    except (TypeError, ValueError):
        return  # builtins and C callables: the sample call below decides
    try:
        signature.bind({})
    except TypeError:
        raise RewardFunctionError(
            f"{path}: reward_function must take exactly one argument (params), "
            f"its signature is reward_function{signature}"
        ) from None


def check_reward_function(
    fn: RewardFunction, params: dict[str, Any], source: str = "reward_function"
) -> float:
    """Call ``fn`` on a deep copy of ``params``, as DeepRacer does; return its reward.

    Refuses what DeepRacer's simapp refuses: an exception from the function, a value
    ``float()`` cannot convert, NaN or infinity, or a reward outside +-1e5. Anything else
    ``float()`` takes (ints, bools, numpy scalars) is accepted and converted, as there.
    """
    call_params = copy.deepcopy(params)
    try:
        value = fn(call_params)
    except Exception as exc:
        where = _where_in(Path(source), exc)
        raise RewardFunctionError(
            f"{source}: reward_function raised {type(exc).__name__}: {exc}{where} "
            f"on sample params (steps={params.get('steps')}, progress={params.get('progress')})"
        ) from exc
    try:
        reward = float(value)
    except (TypeError, ValueError):
        raise RewardFunctionError(
            f"{source}: reward_function must return a number, got {type(value).__name__} "
            f"({value!r:.60}) on sample params (steps={params.get('steps')})"
        ) from None
    if not math.isfinite(reward) or abs(reward) > MAX_ABS_REWARD:
        raise RewardFunctionError(
            f"{source}: reward_function returned {reward!r} on sample params "
            f"(steps={params.get('steps')}); rewards must be finite and "
            f"within +-{MAX_ABS_REWARD:g}"
        )
    return reward


def check_reward_episode(
    fn: RewardFunction, episode: list[dict[str, Any]], source: str = "reward_function"
) -> list[float]:
    """:func:`check_reward_function` on each params dict of ``episode``, in order."""
    return [check_reward_function(fn, params, source) for params in episode]


def _function_in(path: Path) -> RewardFunction:
    namespace = _execute(path)
    if "reward_function" not in namespace:
        raise RewardFunctionError(f"{path} does not define reward_function(params)")
    fn = namespace["reward_function"]
    if not callable(fn):
        raise RewardFunctionError(
            f"{path}: reward_function must be a function, got {type(fn).__name__}"
        )
    _checked_signature(fn, path)
    return fn


def load_reward_function(path: str | Path, race_type: str = "time_trial") -> RewardFunction:
    """Load ``reward_function`` from the racer's Python file and smoke-test it.

    Executes the file (intended: the racer's own code on their own machine; never used on
    uploaded files). The function is called on :func:`sample_episode` for ``race_type``:
    the first :data:`CHECK_STEPS` steps of an episode (steps 1, 2, ..., object races
    include the object keys), so state set up on ``steps == 1`` works. The check runs on
    its own execution of the file; the function returned comes from a fresh one, so
    module-level state starts clean for training, as on DeepRacer. Raises
    :class:`RewardFunctionError` for a missing file, a syntax error (with its line), no
    ``reward_function``, a non-callable one, a wrong signature, an exception on a sample
    step, or a return value that is not a finite number within +-1e5.
    """
    path = Path(path)
    check_reward_episode(_function_in(path), sample_episode(race_type), source=str(path))
    return _function_in(path)


def _objects(track: Track, race_type: str, car_arc: float, t: float = 0.0) -> ObjectsView:
    """Two boxes ahead in opposite lanes, or one car ahead and one behind, ``t`` s on."""
    if race_type == "time_trial":
        return ObjectsView.empty()
    if race_type == "object_avoidance":
        arcs, lanes, speeds = [car_arc + 1.5, car_arc + 4.0], ["inner", "outer"], [0.0, 0.0]
    else:
        arcs, lanes, speeds = [car_arc + 1.2, car_arc - 0.8], ["inner", "outer"], [1.0, 1.4]
    points, yaws = [], []
    for arc, lane, speed in zip(arcs, lanes, speeds, strict=True):
        point, yaw = track.pose_at(track.wrap_arc_length(arc + speed * t), lane)
        points.append(point)
        yaws.append(math.degrees(float(yaw)) if speed else 0.0)  # boxes report 0, as DeepRacer
    location = np.array(points, dtype=float)
    return ObjectsView.of(location, np.array(yaws), np.array(speeds), track.project(location))


def _params_at(
    track: Track,
    race_type: str,
    *,
    arc: float,
    offset: float,
    heading_off_deg: float,
    progress: float | None,
    steps: int,
    speed: float,
    steering_angle: float,
    objects_arc: float,
    t: float | None = None,
) -> dict[str, Any]:
    """Params, from the arena's own builder, for a car ``offset`` m left of the centre
    line at ``arc`` ``t`` simulated seconds into the episode (by default ``steps`` control
    steps; progress from the projection when ``progress`` is None)."""
    point, yaw = track.pose_at(track.wrap_arc_length(arc), offset)
    model_point = np.asarray(point, dtype=float)
    projection = track.project(model_point[None, :])
    return build_params(
        track=track,
        is_reversed=False,
        model_point=model_point,
        yaw=float(yaw) + math.radians(heading_off_deg),
        projection=projection,
        index=0,
        progress=float(projection.progress[0]) if progress is None else progress,
        steps=steps,
        speed=speed,
        steering_angle=steering_angle,
        all_wheels_on_track=True,
        is_offtrack=False,
        is_crashed=False,
        objects=_objects(track, race_type, objects_arc, t or 0.0),
        waypoints=[tuple(map(float, w)) for w in track.waypoints],
        sim_time=steps / PhysicsConfig().control_hz,
    )


def _resolved(race_type: str, track: str | Track) -> Track:
    if race_type not in RACE_TYPES:
        raise ValueError(f"race_type must be one of {list(RACE_TYPES)}, got {race_type!r}")
    return get_track(track) if isinstance(track, str) else track


def sample_params(race_type: str = "time_trial", track: str | Track = "beginner_loop") -> dict:
    """A realistic params dict, built by the arena's own builder, for smoke tests.

    The car is a quarter of the way round ``track``, 0.1 m left of the centre line,
    heading 5 degrees off the centre line at 1.5 m/s on step 38; object races add two
    objects (boxes ahead in both lanes; for car races one car ahead and one behind).
    """
    track = _resolved(race_type, track)
    arc = 0.25 * track.length
    return _params_at(
        track,
        race_type,
        arc=arc,
        offset=0.1,
        heading_off_deg=5.0,
        progress=None,
        steps=38,
        speed=1.5,
        steering_angle=10.0,
        objects_arc=arc,
    )


def sample_episode(
    race_type: str = "time_trial", track: str | Track = "beginner_loop", steps: int = CHECK_STEPS
) -> list[dict[str, Any]]:
    """The params of the first ``steps`` steps of an episode, as a car produces them.

    The car leaves the start line (arc 0, the env's default start) at 1.5 m/s, one
    control step (1/15 s) per call, drifting a little left of the centre line: steps
    count 1, 2, 3, ..., progress rises from just above 0, same track and waypoints
    throughout. Object races add the objects of :func:`sample_params`, the cars moving.
    """
    track = _resolved(race_type, track)
    dt = 1.0 / PhysicsConfig().control_hz  # the env's default control rate
    speed = 1.5
    episode = []
    for step in range(1, steps + 1):
        t = step * dt
        arc = speed * t
        episode.append(
            _params_at(
                track,
                race_type,
                arc=arc,
                offset=0.01 * step,
                heading_off_deg=1.0 * step,
                progress=min(100.0, 100.0 * arc / track.length),
                steps=step,
                speed=speed,
                steering_angle=2.0,
                objects_arc=0.0,
                t=t,
            )
        )
    return episode


def bundled_samples() -> dict[str, Path]:
    """The bundled sample reward functions: name -> file."""
    return {p.stem: p for p in sorted(SAMPLES_DIR.glob("*.py")) if not p.stem.startswith("_")}


def load_sample(name: str, race_type: str = "time_trial") -> RewardFunction:
    """Load a bundled sample by name (see :func:`bundled_samples`)."""
    samples = bundled_samples()
    if name not in samples:
        raise RewardFunctionError(
            f"no sample reward function {name!r}; choose from {list(samples)}"
        )
    return load_reward_function(samples[name], race_type)


def resolve_reward(spec: str, race_type: str = "time_trial") -> RewardFunction:
    """Load a reward function from a ``.py`` file path or a bundled sample's name."""
    if spec.endswith(".py") or os.sep in spec or Path(spec).exists():
        return load_reward_function(spec, race_type)
    return load_sample(spec, race_type)
