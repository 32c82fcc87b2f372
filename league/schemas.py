"""Request and response bodies of the league API (pydantic), as shown at ``/docs``.

Times of races are whole milliseconds (``*_ms``); timestamps are ISO 8601 UTC.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    model_validator,
)

from agents.train_job import MAX_REWARD_SOURCE
from arena.config import BotConfig, ObstacleConfig, Penalties, RaceType, SeedVariation
from league.bots import DEFAULT_BOT, BotLevel
from submissions import Problem

MAX_ID = 2**31 - 1
Metric = Literal["total", "best", "average"]


def clean_name(value: str) -> str:
    """The one rule for a name a person chooses (racer alias, model name, event name): no
    control or other invisible characters (newlines, tabs, NUL, bidi overrides...), spaces
    around it trimmed, not blank. Returns the trimmed name; ``ValueError`` says what is wrong.
    """
    if any(not ch.isprintable() for ch in value):
        raise ValueError("must not contain control or invisible characters (newline, tab, NUL...)")
    value = value.strip(" ")
    if not value:
        raise ValueError("must not be blank")
    return value


def _name_input(value: object) -> object:
    return clean_name(value) if isinstance(value, str) else value


def _utc(value: datetime) -> datetime:
    try:
        return value.replace(tzinfo=UTC) if value.tzinfo is None else value.astimezone(UTC)
    except (OverflowError, ValueError):
        raise ValueError("is out of range once converted to UTC") from None


UtcTime = Annotated[datetime, AfterValidator(_utc)]
# Chosen names: clean_name runs first, then the limits apply to the trimmed name.
Alias = Annotated[
    str,
    Field(min_length=2, max_length=32, pattern=r"^[A-Za-z0-9_.\-]+$"),
    BeforeValidator(_name_input),
]
ModelName = Annotated[str, Field(min_length=1, max_length=64), BeforeValidator(_name_input)]
EventName = Annotated[str, Field(min_length=1, max_length=100), BeforeValidator(_name_input)]


class ErrorOut(BaseModel):
    """Every error answer: a sentence for a person, plus details where there are any."""

    detail: str
    errors: list[dict[str, Any]] | None = None
    problems: list[Problem] | None = None


class _Out(BaseModel):
    model_config = ConfigDict(from_attributes=True)


# ------------------------------------------------------------------ racers
class RacerCreate(BaseModel):
    """A new racer (admins only)."""

    model_config = ConfigDict(extra="forbid")

    alias: Alias
    admin: bool = False


class RacerOut(_Out):
    """A racer as others may see them."""

    id: int
    alias: str
    role: str
    created_at: datetime


class RacerCreated(RacerOut):
    """A racer with their new API token (at creation or rotation): shown once, never stored
    in clear."""

    token: str


# ------------------------------------------------------------------ models
class ModelSuspension(BaseModel):
    """An event the model was suspended from for breaking its races, and why."""

    event_id: int
    event_name: str
    entry_id: int
    suspended_at: datetime
    message: str


class ModelOut(BaseModel):
    """A model. Owners and admins see everything; others only the public fields of a model
    entered in an event (``sha256``, ``size`` and ``info`` are then null, ``suspensions``
    empty)."""

    id: int
    name: str
    owner: str
    visibility: Literal["owner", "public"]
    action_space_type: str
    sensors: list[str]
    created_at: datetime
    sha256: str | None = None
    size: int | None = None
    info: dict[str, Any] | None = None
    suspensions: list[ModelSuspension] = []


# ------------------------------------------------------------------ events
class EventCreate(BaseModel):
    """An event's ruleset and schedule; frozen once created."""

    model_config = ConfigDict(extra="forbid")

    name: EventName
    race_type: RaceType = "time_trial"
    track: Annotated[str, Field(min_length=1, max_length=64)] = "beginner_loop"
    direction: Literal["ccw", "cw"] | None = Field(
        default=None, description="ccw or cw; default: the way the track's file runs"
    )
    laps: int = Field(default=3, ge=1, le=100)
    ranking_metric: Metric = "total"
    penalties: Penalties = Penalties()
    max_resets: int | None = Field(default=None, ge=0, le=1000)
    time_limit_s: float = Field(default=180.0, gt=0.0, le=3600.0, allow_inf_nan=False)
    obstacles: ObstacleConfig | None = None
    bots: BotConfig | None = None
    variation: SeedVariation = SeedVariation()
    seeds: list[Annotated[int, Field(ge=0, le=MAX_ID)]] = Field(
        default_factory=lambda: [0], min_length=1, max_length=20
    )
    opens_at: UtcTime | None = None
    closes_at: UtcTime | None = None
    round_interval_s: int | None = Field(default=None, ge=60, le=30 * 86400)
    round_bot: BotLevel = Field(
        default=DEFAULT_BOT,
        description="head_to_model only: the bot a model entered alone races (pursuit: the "
        "console's default car at 0.4-0.8 m/s on the racing line, blind to other cars; racer: "
        "the passing pursuit driver at the racing line's pace, 0.5-4 m/s)",
    )


class EventOut(_Out):
    """An event with its frozen ruleset."""

    id: int
    name: str
    race_type: str
    track: str
    direction: str
    ranking_metric: str
    ruleset: dict[str, Any]
    ruleset_hash: str
    seeds: list[int]
    opens_at: datetime
    closes_at: datetime | None
    round_interval_s: int | None
    round_bot: str
    status: Literal["upcoming", "open", "closed"]
    created_at: datetime


class EntryCreate(BaseModel):
    """Enter one of your models."""

    model_config = ConfigDict(extra="forbid")

    model_id: int = Field(ge=1, le=MAX_ID)


class EntryAccepted(BaseModel):
    """An accepted entry and the evaluation jobs queued for it."""

    entry_id: int
    event_id: int
    model_id: int
    job_ids: list[int]


class JobOut(_Out):
    """One queued, running, finished or failed job."""

    id: int
    kind: str
    event_id: int
    entry_id: int | None
    round: int | None
    seed: int
    status: str
    attempts: int
    error: str | None
    race_id: int | None = None
    created_at: datetime
    updated_at: datetime


# ------------------------------------------------------------------ evaluations
EvaluationRaceType = Literal["time_trial", "object_avoidance", "head_to_bot"]
EvaluationStatus = Literal["queued", "running", "done", "failed"]


class EvaluationCreate(BaseModel):
    """Evaluate one of your models alone on a track, under the league's default ruleset
    (with the race type's own settings given)."""

    model_config = ConfigDict(extra="forbid")

    track: Annotated[str, Field(min_length=1, max_length=64)]
    direction: Literal["ccw", "cw"] | None = Field(
        default=None, description="ccw or cw; default: the way the track's file runs"
    )
    race_type: EvaluationRaceType = "time_trial"
    race_settings: dict[str, float | int] = Field(
        default_factory=dict,
        max_length=8,
        description="The race type's own settings over the league's defaults, as training "
        'takes them: {"boxes": 3} for object avoidance; bots, bot_speed, '
        "bot_lane_change_min_s, bot_lane_change_max_s for head-to-bot.",
    )
    laps: int = Field(default=3, ge=1, le=5)
    races: int = Field(default=1, ge=1, le=3, description="Races, on seeds 0 .. races-1.")


class EvaluationAccepted(BaseModel):
    """A created evaluation: its unlisted event, the model's entry and the queued jobs."""

    event_id: int
    entry_id: int
    jobs: list[JobOut]
    track: str
    direction: str
    race_type: str


class EvaluationRace(BaseModel):
    """One race of an evaluation: the model's laps (times in ms) and incidents."""

    race_id: int
    status: str
    laps: int
    lap_times_ms: list[int]
    best_lap_ms: int | None
    total_ms: int | None
    off_track: int
    crashes: int
    resets: int


class EvaluationOut(BaseModel):
    """An evaluation of a model: where its jobs stand (``failed`` once every job has
    settled and one failed, with that job's ``error``) and the races run so far."""

    event_id: int
    name: str
    track: str
    direction: str
    race_type: str
    laps: int
    created_at: datetime
    status: EvaluationStatus
    error: str | None
    races: list[EvaluationRace]


# ------------------------------------------------------------------ leaderboards
class LeaderboardRow(BaseModel):
    """DeepRacer's leaderboard columns; times in ms; ratings for head-to-head events.

    The racing metrics (overtakes, times overtaken, at-fault collisions, laps led, gap to
    the winner in ms) are the counting race's, like every other figure of the row.
    """

    rank: int
    alias: str
    model_id: int
    model_name: str
    race_id: int | None
    status: str | None
    lap_count: int
    best_lap_ms: int | None
    average_lap_ms: int | None
    total_time_ms: int | None
    off_track_count: int
    collision_count: int
    reset_count: int
    overtakes: int
    times_overtaken: int
    at_fault_collisions: int
    laps_led: int
    gap_to_winner_ms: int | None
    ranking_score_ms: int | None
    submission_count: int
    mu: float | None = None
    sigma: float | None = None
    ordinal: float | None = None


class Leaderboard(BaseModel):
    """An event's standings: one row per racer, their best result counting."""

    event_id: int
    race_type: str
    ranking_metric: str
    rows: list[LeaderboardRow]


# ------------------------------------------------------------------ races
class RaceCarOut(_Out):
    """One car's result with lap splits and racing metrics (``gap_to_winner_ms``: 0 for the
    winner, null for a car that did not finish; ``dnf_reason``: why a model fault took the
    car out of the race, null otherwise)."""

    car_name: str
    alias: str | None = None
    model_id: int | None
    entry_id: int | None
    status: str
    laps: int
    lap_times_ms: list[int]
    best_ms: int | None
    average_ms: int | None
    total_ms: int | None
    penalty_ms: int
    off_track_count: int
    crash_count: int
    reset_count: int
    distance_m: float
    finish_position: int
    overtakes: int
    times_overtaken: int
    at_fault_collisions: int
    laps_led: int
    gap_to_winner_ms: int | None
    dnf_reason: str | None = None


class RaceBrief(_Out):
    """A race in a list."""

    id: int
    event_id: int
    seed: int
    ruleset_hash: str
    created_at: datetime
    has_trace: bool
    cars: list[RaceCarOut]


class RaceOut(RaceBrief):
    """A race with the config it ran under and its summary (duration, steps, order)."""

    config: dict[str, Any]
    summary: dict[str, Any]


# ------------------------------------------------------------------ training jobs
OptionValue = str | int | float | bool | None


class TrainingJobCreate(BaseModel):
    """A training job: what ``slipstream train`` takes, the reward function as source."""

    model_config = ConfigDict(extra="forbid")

    name: ModelName = Field(description="The model's name once trained.")
    description: str | None = Field(
        default=None, max_length=255, description="What the model tries (shown in the garage)."
    )
    reward_source: str | None = Field(
        default=None,
        min_length=1,
        max_length=64 * 1024,
        description="The reward function's Python source (DeepRacer's reward_function(params)); "
        "a resumed run keeps its own when this is left out.",
    )
    options: dict[str, OptionValue] = Field(
        default_factory=dict,
        max_length=32,
        description="`slipstream train` options in their command-line forms, e.g. "
        '{"track": "slipstream_speedway", "sensors": "camera", "action_space": "default"}.',
    )
    recipe: str | None = Field(default=None, max_length=64, description="A training recipe.")
    hyperparameters: dict[str, OptionValue] | None = Field(
        default=None, max_length=32, description="DeepRacer hyperparameters (hyperparameters.json)."
    )
    minutes: float = Field(gt=0, le=24 * 60, description="Training budget in minutes.")
    clone_of: int | None = Field(
        default=None, ge=1, le=MAX_ID, description="Start from the run of one of your jobs."
    )
    resume_of: int | None = Field(
        default=None,
        ge=1,
        le=MAX_ID,
        description="Continue the run of one of your jobs for ``minutes`` more, with its "
        "settings and hyperparameters (no options, recipe or hyperparameters here).",
    )


class TrainingJobUpdate(BaseModel):
    """What an admin may change on a training job."""

    model_config = ConfigDict(extra="forbid")

    priority: int = Field(ge=-1000, le=1000, description="Higher runs first.")


class TrainingJobOut(_Out):
    """A training job: its request, where it stands and what it made."""

    id: int
    owner: str
    name: str
    description: str | None
    status: str
    priority: int
    options: dict[str, Any]
    recipe: str | None
    hyperparameters: dict[str, Any] | None
    reward_source: str
    track: str = Field(description="The track it trains on (its options over its recipe's)")
    direction: Literal["ccw", "cw"] | None = Field(description="None: the track file's")
    race_type: str
    race_settings: dict[str, OptionValue] = Field(
        description="The race type's own settings the job sets (boxes, bots, bot_speed, ...)"
    )
    minutes: float
    clone_of: int | None
    resume_of: int | None
    attempts: int
    error: str | None
    stop_requested: bool
    compute_minutes: float
    best_lap_ms: int | None
    model_id: int | None
    has_run: bool
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None


class TrainingQuota(BaseModel):
    """A racer's training quotas and what they used this month."""

    max_minutes_per_job: float
    jobs_queued_or_running: int
    minutes_per_month: float
    minutes_used: float
    resets_at: datetime


class RescoreCreate(BaseModel):
    """A logged run to re-score with an edited reward function: one car of a race, or an
    episode (``null``: the last evaluation) of one of your training jobs."""

    model_config = ConfigDict(extra="forbid")

    reward_source: str = Field(
        min_length=1,
        max_length=MAX_REWARD_SOURCE,
        description="The reward function's Python source (DeepRacer's reward_function(params)).",
    )
    race_id: int | None = Field(default=None, ge=1, le=MAX_ID, description="A race (any).")
    car: str | None = Field(
        default=None, min_length=1, max_length=64, description="The car of ``race_id``."
    )
    training_job_id: int | None = Field(
        default=None, ge=1, le=MAX_ID, description="One of your training jobs (admins: any)."
    )
    episode: int | None = Field(
        default=None,
        ge=0,
        le=MAX_ID,
        description="A training episode of ``training_job_id``'s simtrace; null: its last "
        "evaluation (one lap per episode).",
    )

    @model_validator(mode="after")
    def _one_run(self) -> RescoreCreate:
        if (self.race_id is None) == (self.training_job_id is None):
            raise ValueError("give either race_id and car, or training_job_id")
        if self.race_id is not None and (self.car is None or self.episode is not None):
            raise ValueError("a race is re-scored for one car: give car (and no episode)")
        if self.training_job_id is not None and self.car is not None:
            raise ValueError("a training job has one car: give episode, not car")
        return self


class RescoreLap(BaseModel):
    """One lap's (a training episode's) summed rewards."""

    lap: int
    reward: float
    original: float | None


class RescoreOut(BaseModel):
    """The re-scored run: per control step, its position, progress, lap (from 0), the new
    reward and the original one (``null`` when unknown), and their sums per lap and in all."""

    steps: int
    x: list[float]
    y: list[float]
    progress: list[float]
    lap: list[int]
    reward: list[float]
    original: list[float] | None
    laps: list[RescoreLap]
    total: float
    original_total: float | None
