"""The settings of a training run: one declaration, one description per field.

Each setting ``slipstream train`` takes is the option of the field's name, with the field's
description as its help (``agents/options.py`` says which, and their command-line forms);
the rest are for Python callers. A run stores its settings as
``RUN/training_settings.json``. This module imports no torch, so the CLI can read it at
start-up.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from agents.privileged import CriticInput
from arena.actions import ActionSpace, DiscreteActionSpace
from arena.config import RACE_TYPES, BotConfig, ObstacleConfig, RaceType
from tracks.catalog import Direction

# Fields a ``--resume`` takes from the command line; every other one comes from the run.
RESUME_OVERRIDES = (
    "iterations",
    "minutes",
    "workers",
    "device",
    "threads",
    "sync",
    "background_eval",
)
# Learner cars per worker process (or in-process) when ``races`` is not given. Each step of
# a worker carries fixed costs (the pipe, waking it, the learner's forward pass and
# bookkeeping per call) that its cars share; at DeepRacer's default iteration (1,280
# samples on 2 workers) each of a worker's four cars still collects 160 steps, about a lap
# (benchmarks/RESULTS.md, "Races per worker").
SLOTS_PER_WORKER = 4
_BOXES, _BOTS = ObstacleConfig(), BotConfig()  # the league's defaults, named in the help


class TrainSettings(BaseModel):
    """Everything that defines a training run (stored as ``RUN/training_settings.json``)."""

    model_config = ConfigDict(extra="forbid")

    track: str = Field("beginner_loop", description="Track name.")
    direction: Direction | None = Field(
        None, description="ccw or cw (default: the way the track's file runs)."
    )
    also_tracks: tuple[str, ...] = Field(
        (),
        description="Further tracks the training races run on (comma-separated): the races "
        "take --track and these in turn, at least one race each; evaluations stay on --track "
        "unless --eval-also-tracks.",
    )
    race_type: RaceType = Field("time_trial", description=" | ".join(RACE_TYPES))
    boxes: int | None = Field(
        None, description=f"object_avoidance: boxes on the track (default {_BOXES.count})."
    )
    bots: int | None = Field(
        None, description=f"head_to_bot: bot cars on the track (default {_BOTS.count})."
    )
    bot_speed: float | None = Field(
        None, description=f"head_to_bot: the bots' speed in m/s (default {_BOTS.speed:g})."
    )
    bot_lane_change_min_s: float | None = Field(
        None,
        description="head_to_bot: fewest seconds between a bot's lane changes "
        f"(default {_BOTS.lane_change_min_s:g}).",
    )
    bot_lane_change_max_s: float | None = Field(
        None,
        description="head_to_bot: most seconds between a bot's lane changes "
        f"(default {_BOTS.lane_change_max_s:g}).",
    )
    sensors: tuple[str, ...] = Field(
        ("camera",),
        description="Sensors; on the command line comma-separated, e.g. camera,lidar "
        "(default: the sensors of a model_metadata.json action space, else camera).",
    )
    action_space: ActionSpace = Field(
        description="Action space; on the command line a spec, e.g. 3x3@1.0 or default."
    )
    reward_fn: str = Field(
        "follow_center_line", description="Reward-function file or bundled sample name."
    )
    network: str | None = Field(None, description="Network preset (default: by sensors).")
    critic: CriticInput = Field(
        "privileged",
        description="What PPO's critic reads: privileged (an MLP on track-relative state; "
        "only the actor is exported) or sensors (the actor's network).",
    )
    teacher: Literal["pursuit"] | None = Field(
        None,
        description="Train the actor by imitating this driver instead of by PPO: pursuit "
        "(pure pursuit on the racing line, steering around boxes and cars; "
        "agents.imitation). Clone the run to go on with PPO and the reward function.",
    )
    teacher_drives: float = Field(
        0.0,
        ge=0.0,
        le=1.0,
        description="With --teacher: the share of episodes the teacher drives (each "
        "episode's chance), the student learning from their states too; 0: the student "
        "drives every episode.",
    )
    anchor: Literal["pursuit"] | None = Field(
        None,
        description="PPO held near this driver: PPO's loss gains the distance of the "
        "actor's action to the driver's, weighted --anchor-weight (agents.anchor). For PPO "
        "after imitation (--clone of a --teacher run).",
    )
    anchor_weight: float = Field(
        1.0, ge=0.0, description="The anchor's weight (at the first update, if it decays)."
    )
    anchor_iterations: int | None = Field(
        None,
        ge=1,
        description="Iterations over which the anchor's weight decays linearly to 0 "
        "(default: it holds).",
    )
    min_std: float | None = Field(
        None,
        gt=0.0,
        description="The lowest standard deviation of a continuous policy's action noise "
        "(rsl-rl's std_range); PPO after imitation otherwise shrinks it (0.1 to 0.02 in "
        "one run). Default: no floor.",
    )
    critic_warmup: int | None = Field(
        None,
        ge=0,
        description="Iterations at the start in which only PPO's critic learns, the actor "
        "held. Default: 5 for a clone whose critic is not reused (an imitation run has "
        "none), else 0.",
    )
    seed: int = Field(0, description="Random seed.")
    workers: int | None = Field(
        None, description="Worker processes (default: CPU cores; 0: in-process)."
    )
    races: int | None = Field(
        None,
        description=f"Parallel races (default: {SLOTS_PER_WORKER} learner cars per worker, "
        f"or in-process: {SLOTS_PER_WORKER} one-car races, {SLOTS_PER_WORKER // 2} with two "
        "learner cars).",
    )
    iterations: int | None = Field(None, description="Iteration budget.")
    minutes: float | None = Field(None, description="Wall-clock budget in minutes.")
    steps_per_env: int | None = Field(
        None,
        description="Rollout steps per slot and iteration "
        "(default: from num_episodes_between_training).",
    )
    eval_every: int = Field(
        5, description="Evaluate every N iterations (and after the iteration that ends the budget)."
    )
    eval_laps: int = Field(3, description="Laps of each evaluation race.")
    eval_also_tracks: bool = Field(
        False,
        description="Each evaluation also races every --also-tracks track, and the run's "
        "best model is the best over all of its races (metrics.csv's evaluation columns "
        "stay --track's).",
    )
    eval_time_limit: float = Field(120.0, description="Simulated seconds an evaluation may take.")
    stop_on_clean_eval: bool = Field(
        False, description="Stop at the first evaluation with every lap and no off-track."
    )
    selfplay: Literal["shared", "pool"] = Field(
        "shared", description="head_to_model: shared | pool."
    )
    opponent: tuple[str, ...] = Field(
        (), description="ONNX / model.zip opponent for head_to_model (repeatable)."
    )
    snapshot_every: int = Field(
        10, description="Pool self-play: snapshot the learner into the pool every N iterations."
    )
    paced_rivals: tuple[float, ...] = Field(
        (0.6, 0.8, 0.9, 1.0),
        description="Pool self-play: the pure-pursuit driver races in the pool at these "
        "shares of the learner's pace, from its first evaluation that finishes a lap "
        "(comma-separated; 'none': no paced rivals).",
    )
    device: str = Field("cpu", description="cpu, cuda or cuda:N.")
    threads: int | None = Field(
        None,
        description="Torch CPU threads (default: every core for the update, the cores the "
        "env workers leave free while collecting).",
        ge=1,
    )
    sync: bool | None = Field(
        None,
        description="Collect, then update, in turn (--sync), or update while the next "
        "rollout is collected, one update behind (--no-sync). Default: overlapped on a "
        "GPU, in turn on a CPU.",
    )
    background_eval: bool = Field(
        False,
        description="Race each evaluation in a process of its own while the next "
        "iterations train (for a machine with a core the trainer and its env workers "
        "leave free; on 2 cores it gained nothing).",
    )
    grow_batch: bool | None = Field(
        None,
        description="Grow the iteration and the minibatch with the number of races "
        "(the same gradient steps per update). Default: on a GPU, unless "
        "--hyperparameters or --steps-per-env fixes them.",
    )
    recipe: str | None = Field(
        None, description="The recipe the settings were made from (agents/recipes.py)."
    )

    @model_validator(mode="after")
    def _race_settings_fit(self) -> TrainSettings:
        self.race_rules()
        return self

    @field_validator("paced_rivals")
    @classmethod
    def _shares_of_pace(cls, shares: tuple[float, ...]) -> tuple[float, ...]:
        outside = [share for share in shares if not 0.0 < share <= 1.0]
        if outside:
            raise ValueError(f"a share of the learner's pace is in (0, 1], got {outside[0]}")
        return shares

    @model_validator(mode="after")
    def _a_race_on_every_track(self) -> TrainSettings:
        tracks = [self.track, *self.also_tracks]
        if len(set(tracks)) < len(tracks):
            raise ValueError(f"a track is named twice in --track and --also-tracks: {tracks}")
        if self.races is not None and self.races < len(tracks):
            raise ValueError(
                f"{len(tracks)} tracks need at least {len(tracks)} races, one on each: "
                f"give --races {len(tracks)} or more"
            )
        return self

    @model_validator(mode="after")
    def _anchor_needs_ppo(self) -> TrainSettings:
        if self.anchor is not None and self.teacher is not None:
            raise ValueError(
                "--anchor holds PPO near a driver, and --teacher trains by imitation "
                "without PPO: give one (clone a --teacher run to anchor its PPO)"
            )
        return self

    @model_validator(mode="after")
    def _teacher_drives_needs_a_teacher(self) -> TrainSettings:
        if self.teacher_drives and self.teacher is None:
            raise ValueError("--teacher-drives needs --teacher: it is a share of imitation")
        return self

    @model_validator(mode="after")
    def _min_std_needs_a_gaussian(self) -> TrainSettings:
        if self.min_std is not None and self.discrete:
            raise ValueError(
                "--min-std floors a continuous policy's action noise; a discrete action "
                "space draws from its action probabilities: leave --min-std out"
            )
        return self

    def race_rules(self) -> dict[str, ObstacleConfig | BotConfig]:
        """The race type's boxes or bots: these settings over the league's defaults
        (:func:`race_rules`)."""
        options = {o for section in RACE_SECTIONS.values() for o in section.options.values()}
        given = {o: getattr(self, o) for o in options if getattr(self, o) is not None}
        return race_rules(self.race_type, given)

    @property
    def preset(self) -> str:
        """The network preset (default by sensors)."""
        from agents.networks import default_preset  # torch: not at CLI start-up

        return self.network or default_preset(self.sensors)

    @property
    def overlapped(self) -> bool:
        """Whether the update runs during the next rollout (:func:`overlapped`)."""
        return overlapped(self.sync, self.device)

    @property
    def grows_batch(self) -> bool:
        """Whether the iteration and minibatch grow with the races (:func:`grows_batch`)."""
        return grows_batch(self.grow_batch, self.device, self.steps_per_env)

    @property
    def discrete(self) -> bool:
        """Whether the action space is a discrete list."""
        return isinstance(self.action_space, DiscreteActionSpace)


@dataclass(frozen=True)
class RaceSection:
    """A race type's section of :class:`~arena.config.RaceConfig` (``key``) and the
    settings that set its fields (``options``: field -> setting)."""

    key: str
    kind: type[ObstacleConfig] | type[BotConfig]
    options: dict[str, str]

    def build(self, given: dict[str, Any]) -> ObstacleConfig | BotConfig:
        """The section from ``given`` fields, its errors naming the settings."""
        try:
            return self.kind(**given)
        except ValidationError as exc:
            first = exc.errors()[0]
            field = str(first["loc"][0]) if first["loc"] else ""
            where = self.options.get(field, ", ".join(self.options[k] for k in given))
            message = first["msg"].removeprefix("Value error, ")
            for name, option in self.options.items():
                message = message.replace(name, option) if "_" in name else message
            raise ValueError(f"{where}: {message}") from None


RACE_SECTIONS = {
    "object_avoidance": RaceSection("obstacles", ObstacleConfig, {"count": "boxes"}),
    "head_to_bot": RaceSection(
        "bots",
        BotConfig,
        {
            "count": "bots",
            "speed": "bot_speed",
            "lane_change_min_s": "bot_lane_change_min_s",
            "lane_change_max_s": "bot_lane_change_max_s",
        },
    ),
}
"""The race types with settings of their own (boxes, bots), by race type."""


def race_rules(race_type: str, given: Mapping[str, Any]) -> dict[str, ObstacleConfig | BotConfig]:
    """The :class:`~arena.config.RaceConfig` section of ``race_type`` (``obstacles`` or
    ``bots``; none for the others) from ``given`` settings (``boxes``, ``bots``,
    ``bot_speed``, ...) over the league's defaults. ValueError, naming the settings, for
    settings of another race type, unknown ones, or values out of range."""
    rules: dict[str, ObstacleConfig | BotConfig] = {}
    known: set[str] = set()
    for kind, section in RACE_SECTIONS.items():
        known |= set(section.options.values())
        fields = {f: given[o] for f, o in section.options.items() if o in given}
        if kind == race_type:
            rules[section.key] = section.build(fields)
        elif fields:
            names = ", ".join(section.options[f] for f in fields)
            raise ValueError(f"{names}: only {kind} races have {section.key}")
    unknown = sorted(set(given) - known)
    if unknown:
        raise ValueError(f"{', '.join(unknown)}: not a race-type setting")
    return rules


def overlapped(sync: bool | None, device: str) -> bool:
    """``not sync`` when given; else (auto) on a GPU only. On CPU cores the update and the
    races compete for the same cores: overlapping gained nothing on 2 cores and lost with
    14 workers on 16 (benchmarks/RESULTS.md, "Overlapped collection")."""
    if sync is not None:
        return not sync
    return device.startswith("cuda")


def grows_batch(grow_batch: bool | None, device: str, steps_per_env: int | None) -> bool:
    """``grow_batch`` when given; else (auto) on a GPU, unless ``steps_per_env`` fixes the
    rollout. The CLI sets ``grow_batch`` off for an explicit ``hyperparameters.json``."""
    if grow_batch is not None:
        return grow_batch
    return device.startswith("cuda") and steps_per_env is None


def settings_path(run_dir: str | Path) -> Path:
    """Where a run keeps its settings."""
    return Path(run_dir) / "training_settings.json"


def save_settings(run_dir: str | Path, settings: TrainSettings) -> Path:
    """Write ``RUN/training_settings.json``."""
    path = settings_path(run_dir)
    path.write_text(settings.model_dump_json(indent=2))
    return path


def load_settings(run_dir: str | Path) -> TrainSettings:
    """The settings a run was started with (``RUN/training_settings.json``)."""
    return TrainSettings.model_validate_json(settings_path(run_dir).read_text())
