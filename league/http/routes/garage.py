"""``/api/garage/catalogue``: what the "create a model" page offers, from where each fact lives.

Tracks (built-in only: a training job races those) with their physical-limit lap, race
types with the obstacles and bots their races get, the sensor combinations
``arena.sensors_spec.check_sensors`` accepts, the action-space builder's limits, DeepRacer's
hyperparameters with their defaults and ranges, the recipes, the bundled reward samples,
the training defaults and the league's budget limit. Built once per server process (the
racing lines take about half a second) and answered with an ETag.
"""

from __future__ import annotations

import json
from itertools import combinations
from typing import Any, get_args

from fastapi import APIRouter, Request, Response
from pydantic.fields import FieldInfo

from agents import action_spaces
from agents.hyperparameters import Hyperparameters
from agents.recipes import RECIPES
from agents.rewards import bundled_samples
from agents.settings import RACE_SECTIONS, TrainSettings
from arena import actions
from arena.config import RACE_TYPES
from arena.sensors_spec import SENSOR_NAMES, check_sensors
from league.http.read_cache import Prepared, answer, prepared
from tracks.catalog import builtin_names, get_track
from tracks.raceline import compute_racing_line

router = APIRouter(prefix="/api/garage", tags=["garage"])

RACE_TYPE_TEXT = {
    "time_trial": ("Time trial", "Fastest laps alone on the track."),
    "object_avoidance": ("Object avoidance", "Laps around boxes placed on the track."),
    "head_to_bot": ("Head-to-bot", "Laps among bot cars that change lanes."),
    "head_to_model": ("Head-to-model", "Racing other racers' models, car against car."),
}
"""The race types' names and one-line descriptions as the page shows them."""


def _tracks() -> list[dict[str, Any]]:
    rows = []
    for name in builtin_names():
        track = get_track(name)
        rows.append(
            {
                "name": name,
                "display_name": track.display_name,
                "direction": track.direction,
                "length": round(track.length, 3),
                "width": round(track.width, 3),
                "is_loop": track.is_loop,
                "physical_limit_lap_s": round(compute_racing_line(track).lap_time, 3),
                "thumbnail_url": f"/api/tracks/{name}/thumbnail.svg",
            }
        )
    return rows


def _race_types() -> list[dict[str, Any]]:
    return [
        {
            "name": name,
            "label": RACE_TYPE_TEXT[name][0],
            "description": RACE_TYPE_TEXT[name][1],
            "settings": _race_settings(name),
        }
        for name in RACE_TYPES
    ]


def _race_settings(race_type: str) -> list[dict[str, Any]]:
    """The race type's own settings (``agents.settings.RACE_SECTIONS``): each training
    option with its help, the league's default and its range."""
    section = RACE_SECTIONS.get(race_type)
    if section is None:
        return []
    rows = []
    for field, option in section.options.items():
        info = section.kind.model_fields[field]
        help_text = TrainSettings.model_fields[option].description or ""
        # "head_to_bot: the bots' speed in m/s (default 0.8)." -> "the bots' speed in m/s"
        label = help_text.split(": ", 1)[-1].split(" (default")[0]
        row = {"option": option, "help": label, "default": info.default}
        rows.append({**row, **_bounds(info)})
    return rows


def _sensors() -> dict[str, Any]:
    allowed = []
    for size in range(1, len(SENSOR_NAMES) + 1):
        for group in combinations(SENSOR_NAMES, size):
            try:
                allowed.append(list(check_sensors(group)))
            except ValueError:
                continue
    return {
        "choices": list(SENSOR_NAMES),
        "combinations": allowed,
        "rules": "At most one camera (camera or stereo) and at most one lidar kind.",
    }


def _action_space() -> dict[str, Any]:
    default = action_spaces.console_action_space.__defaults__
    assert default is not None
    return {
        "max_steering_deg": actions.MAX_STEERING_DEG,
        "min_max_steering_deg": action_spaces.MIN_MAX_STEERING_DEG,
        "min_speed": actions.MIN_SPEED,
        "max_speed": actions.MAX_SPEED,
        "steering_granularities": list(action_spaces.STEERING_GRANULARITIES),
        "speed_granularities": list(action_spaces.SPEED_GRANULARITIES),
        "max_discrete_actions": actions.MAX_DISCRETE_ACTIONS,
        "console_default": dict(
            zip(
                ("max_steering_deg", "steering_granularity", "max_speed", "speed_granularity"),
                default,
                strict=True,
            )
        ),
        "spec_forms": [
            "console:MAX_STEER:STEER_GRANULARITY:MAX_SPEED:SPEED_GRANULARITY",
            "list:STEER/SPEED,STEER/SPEED,...",
            "continuous:STEER_LOW:STEER_HIGH:SPEED_LOW:SPEED_HIGH",
        ],
    }


def _bounds(info: FieldInfo) -> dict[str, Any]:
    found: dict[str, Any] = {}
    for rule in info.metadata:
        for key, name in (("ge", "min"), ("gt", "min"), ("le", "max"), ("lt", "max")):
            if getattr(rule, key, None) is not None:
                found[name] = getattr(rule, key)
    return found


def _hyperparameters() -> list[dict[str, Any]]:
    rows = []
    for name, info in Hyperparameters.model_fields.items():
        row: dict[str, Any] = {"name": name, "default": info.default, "help": info.description}
        choices = get_args(info.annotation)
        if choices:
            row["choices"] = list(choices)
        else:
            row.update(_bounds(info))
        rows.append(row)
    return rows


def _defaults() -> dict[str, Any]:
    fields = TrainSettings.model_fields
    return {
        "track": fields["track"].default,
        "direction": None,
        "race_type": fields["race_type"].default,
        "sensors": ",".join(fields["sensors"].default),
        "action_space": "default",
        "eval_every": fields["eval_every"].default,
        "minutes": 10,
    }


def catalogue(max_minutes: float) -> dict[str, Any]:
    """Everything the create page offers (see the module's docstring)."""
    return {
        "tracks": _tracks(),
        "race_types": _race_types(),
        "sensors": _sensors(),
        "action_space": _action_space(),
        "hyperparameters": _hyperparameters(),
        "recipes": [
            {"name": r.name, "summary": r.summary, "needs_parent": r.parent is not None}
            for r in RECIPES.values()
        ],
        "reward_samples": [
            {"name": name, "title": name.replace("_", " ").capitalize(), "source": path.read_text()}
            for name, path in bundled_samples().items()
        ],
        "defaults": _defaults(),
        "limits": {"max_minutes": max_minutes},
    }


@router.get("/catalogue")
async def read_catalogue(request: Request) -> Response:
    """Tracks, race types, sensors, action-space limits, hyperparameters, recipes, reward
    samples, defaults and limits for creating a model (public; ETag)."""
    max_minutes = request.app.state.settings.training_max_minutes
    build = lambda: Prepared.of(  # noqa: E731
        json.dumps(catalogue(max_minutes)).encode(), "application/json"
    )
    item = await prepared(request, ("garage-catalogue", max_minutes), build)
    assert item is not None
    return answer(request, item)
