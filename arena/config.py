"""``RaceConfig``: a frozen, serialisable description of a race (a ruleset plus its cars).

The league stores a config verbatim with every result; its :meth:`RaceConfig.ruleset_hash`
identifies the ruleset, so two races with the same hash ran under the same rules.
"""

from __future__ import annotations

import hashlib
import json
from typing import Literal, get_args

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from arena.actions import (
    MAX_SPEED,
    MIN_SPEED,
    ActionSpace,
    DiscreteActionSpace,
    default_discrete_space,
)
from arena.sensors_spec import MAX_STACK_SIZE, LidarConfig, check_sensors
from tracks.catalog import Direction, get_track
from tracks.track import Track, TrackError

RaceType = Literal["time_trial", "object_avoidance", "head_to_bot", "head_to_model"]
"""The four DeepRacer race types; the one place they are listed."""
RACE_TYPES: tuple[str, ...] = get_args(RaceType)
Mode = Literal["training", "race"]
Lane = Literal["inner", "outer"]
MAX_CARS = 8


class ConfigError(ValueError):
    """A race configuration is invalid; the message says which field and why."""


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class CarConfig(_Frozen):
    """One controlled car: its name, sensors and action space."""

    name: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.\-]+$")
    sensors: tuple[str, ...] = ("lidar",)
    action_space: ActionSpace = Field(default_factory=default_discrete_space)
    lidar_config: LidarConfig = LidarConfig()
    stack_size: int = Field(default=1, ge=1, le=MAX_STACK_SIZE)
    """Frames of each sensor in an observation, stacked along its last axis (DeepRacer's)."""

    @field_validator("sensors")
    @classmethod
    def _valid_sensors(cls, value: tuple[str, ...]) -> tuple[str, ...]:
        return check_sensors(value)


class Penalties(_Frozen):
    """Seconds a car is frozen (race mode) after each kind of incident."""

    off_track_s: float = Field(default=3.0, ge=0.0, le=60.0)
    crash_s: float = Field(default=5.0, ge=0.0, le=60.0)
    reset_s: float = Field(default=3.0, ge=0.0, le=60.0)


class ObstacleConfig(_Frozen):
    """Boxes for object avoidance: fixed ``(progress %, lane)`` places or random ones."""

    count: int = Field(default=6, ge=1, le=20)
    positions: tuple[tuple[float, Lane], ...] | None = None
    min_gap_m: float = Field(default=2.0, gt=0.0)
    size: tuple[float, float, float] = (0.4, 0.5, 0.3)

    @model_validator(mode="after")
    def _positions_match_count(self) -> ObstacleConfig:
        if self.positions is not None:
            if len(self.positions) != self.count:
                raise ValueError(f"{len(self.positions)} positions given for {self.count} boxes")
            for progress, _ in self.positions:
                if not 0.0 <= progress < 100.0:
                    raise ValueError(f"box progress {progress} must be in [0, 100)")
        return self


class BotConfig(_Frozen):
    """Bot cars for head-to-bot races: lane followers that change lanes now and then."""

    count: int = Field(default=3, ge=1, le=6)
    speed: float = Field(default=0.8, ge=MIN_SPEED, le=MAX_SPEED)
    lane_change_min_s: float = Field(default=1.0, gt=0.0)
    lane_change_max_s: float = Field(default=5.0, gt=0.0)
    min_gap_m: float = Field(default=2.0, gt=0.0)

    @model_validator(mode="after")
    def _ordered(self) -> BotConfig:
        if self.lane_change_min_s > self.lane_change_max_s:
            raise ValueError("lane_change_min_s must not exceed lane_change_max_s")
        return self


class PhysicsConfig(_Frozen):
    """Control and physics rates (simulated time)."""

    control_hz: float = Field(default=15.0, gt=0.0, le=120.0)
    physics_hz: float = Field(default=60.0, gt=0.0, le=1000.0)

    @model_validator(mode="after")
    def _whole_substeps(self) -> PhysicsConfig:
        ratio = self.physics_hz / self.control_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError("physics_hz must be a whole multiple of control_hz")
        return self


class SeedVariation(_Frozen):
    """What a race's seed varies, and by how much: what a real start varies.

    Races only: a training episode starts on its grid slot as DeepRacer's training does,
    with commands applied as given. Jitter is uniform within the bounds; noise is
    Gaussian, drawn afresh every step from each car's own stream.
    """

    start_jitter_m: float = Field(default=0.05, ge=0.0, le=0.2)
    """Largest shift of a car's start position, along and across the track."""
    start_jitter_deg: float = Field(default=3.0, ge=0.0, le=10.0)
    """Largest turn of a car's start heading."""
    shuffle_grid: bool = True
    """Head-to-model: cars take the slots in an order drawn by name; the front lane is drawn."""
    steering_noise_deg: float = Field(default=1.0, ge=0.0, le=10.0)
    """Standard deviation of the noise added to each commanded steering angle."""
    speed_noise_frac: float = Field(default=0.02, ge=0.0, le=0.5)
    """Standard deviation of the noise on each commanded speed, as a fraction of it."""

    @property
    def has_actuation_noise(self) -> bool:
        """Whether commands are perturbed at all."""
        return self.steering_noise_deg > 0.0 or self.speed_noise_frac > 0.0


NO_VARIATION = SeedVariation(
    start_jitter_m=0.0,
    start_jitter_deg=0.0,
    shuffle_grid=False,
    steering_noise_deg=0.0,
    speed_noise_frac=0.0,
)


class RaceConfig(_Frozen):
    """Everything that decides a race: track, rules, cars and seed."""

    track: str = "beginner_loop"
    direction: Direction | None = None
    """``ccw`` or ``cw``; ``None`` drives the track the way its file runs (waypoint order)."""
    race_type: RaceType = "time_trial"
    mode: Mode = "race"
    cars: tuple[CarConfig, ...] = (CarConfig(name="car0"),)
    laps: int = Field(default=3, ge=1, le=100)
    penalties: Penalties = Penalties()
    max_resets: int | None = Field(default=None, ge=0)
    time_limit_s: float = Field(default=180.0, gt=0.0)
    obstacles: ObstacleConfig | None = None
    bots: BotConfig | None = None
    physics: PhysicsConfig = PhysicsConfig()
    start_offset_pct: float = Field(default=0.0, ge=0.0, lt=100.0)
    training_start_step_pct: float = Field(default=5.0, ge=0.0, lt=100.0)
    variation: SeedVariation = SeedVariation()
    seed: int = Field(default=0, ge=0, lt=2**63)

    @model_validator(mode="after")
    def _consistent(self) -> RaceConfig:
        if not 1 <= len(self.cars) <= MAX_CARS:
            raise ValueError(f"a race needs 1 to {MAX_CARS} controlled cars, got {len(self.cars)}")
        names = [c.name for c in self.cars]
        if len(set(names)) != len(names):
            raise ValueError(f"car names must be unique, got {names}")
        if self.race_type == "object_avoidance" and self.obstacles is None:
            raise ValueError("object_avoidance races need an 'obstacles' section")
        if self.race_type != "object_avoidance" and self.obstacles is not None:
            raise ValueError(f"{self.race_type} races have no obstacles; drop 'obstacles'")
        if self.race_type == "head_to_bot" and self.bots is None:
            raise ValueError("head_to_bot races need a 'bots' section")
        if self.race_type != "head_to_bot" and self.bots is not None:
            raise ValueError(f"{self.race_type} races have no bots; drop 'bots'")
        if self.race_type == "head_to_model" and len(self.cars) < 2:
            raise ValueError("head_to_model races need at least 2 controlled cars")
        if self.race_type in ("time_trial", "object_avoidance") and len(self.cars) > 1:
            raise ValueError(f"{self.race_type} races have exactly one controlled car")
        return self

    # ------------------------------------------------------------ serialising
    def to_json(self) -> str:
        """Canonical JSON (sorted keys, no whitespace): the stored form of a race."""
        return json.dumps(self.model_dump(mode="json"), sort_keys=True, separators=(",", ":"))

    @classmethod
    def from_json(cls, text: str | bytes) -> RaceConfig:
        """Parse a config stored with :meth:`to_json` (raises :class:`ConfigError`)."""
        try:
            return cls.model_validate_json(text)
        except ValidationError as exc:
            raise ConfigError(describe_validation_error(exc)) from None

    @classmethod
    def build(cls, **fields: object) -> RaceConfig:
        """Validate keyword fields into a config, raising one readable :class:`ConfigError`."""
        try:
            return cls.model_validate(fields)
        except ValidationError as exc:
            raise ConfigError(describe_validation_error(exc)) from None

    def ruleset(self) -> dict[str, object]:
        """The rules without the cars and the seed: what an event freezes."""
        return self.model_dump(mode="json", exclude={"cars", "seed", "mode"})

    def ruleset_hash(self) -> str:
        """sha256 of the canonical JSON of :meth:`ruleset`."""
        text = json.dumps(self.ruleset(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()

    @property
    def active_variation(self) -> SeedVariation:
        """What the seed varies in this config's mode: ``variation`` in races, none in training."""
        return self.variation if self.mode == "race" else NO_VARIATION

    @property
    def control_dt(self) -> float:
        """Seconds of simulated time per control step."""
        return 1.0 / self.physics.control_hz


def resolve_track(config: RaceConfig) -> tuple[Track, bool]:
    """The config's track in its race direction, and whether that reverses the file.

    A track file is driven in its waypoint order unless ``config.direction`` asks for the
    other way round (DeepRacer's ``_cw`` files run clockwise, ``is_reversed`` false).
    An unknown or unreadable track is a :class:`ConfigError`.
    """
    try:
        native = get_track(config.track)
    except TrackError as exc:
        raise ConfigError(f"invalid race config: track: {exc}") from None
    track = native if config.direction is None else native.with_direction(config.direction)
    return track, track is not native


def describe_validation_error(exc: ValidationError) -> str:
    """``invalid race config:`` and the problems, as :func:`validation_problems` gives them."""
    return "invalid race config: " + validation_problems(exc)


def validation_problems(exc: ValidationError) -> str:
    """One readable ``field.path: message`` per problem, joined with ``; ``."""
    lines = []
    errors = exc.errors()
    failing = [e["loc"] for e in errors if e["type"] != "too_short"]
    for err in errors:
        if err["type"] == "too_short" and any(
            loc[: len(err["loc"])] == err["loc"] for loc in failing
        ):
            continue  # pydantic's echo of an invalid item, not a separate problem
        where = ".".join(str(p) for p in err["loc"] if not str(p).startswith(("discrete", "cont")))
        msg = err["msg"].removeprefix("Value error, ")
        lines.append(f"{where or 'config'}: {msg}")
    return "; ".join(dict.fromkeys(lines))


__all__ = [
    "MAX_CARS",
    "NO_VARIATION",
    "BotConfig",
    "CarConfig",
    "ConfigError",
    "DiscreteActionSpace",
    "ObstacleConfig",
    "Penalties",
    "PhysicsConfig",
    "RaceConfig",
    "SeedVariation",
    "resolve_track",
]
