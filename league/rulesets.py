"""An event's ruleset: the race config an event freezes when it is created."""

from __future__ import annotations

from arena.config import RaceConfig
from league.schemas import EventCreate
from tracks.catalog import builtin_names, get_track


def event_config(spec: EventCreate) -> RaceConfig:
    """The event's ruleset as a race config with placeholder cars (``ConfigError`` if bad).

    Without a direction the event takes the one its track's file runs, written out so the
    frozen ruleset says which way the cars go.
    """
    if spec.track not in builtin_names() or spec.direction is None:
        track = get_track(spec.track)  # raises a readable error for an unknown track
        spec = spec.model_copy(update={"direction": spec.direction or track.direction})
    cars = [{"name": "car0"}, {"name": "car1"}] if spec.race_type == "head_to_model" else None
    fields = spec.model_dump(
        include={
            "track", "direction", "race_type", "laps", "penalties", "max_resets",
            "time_limit_s", "obstacles", "bots", "variation",
        },
        exclude_none=True,
    )  # fmt: skip
    return RaceConfig.build(**fields, **({"cars": cars} if cars else {}))
