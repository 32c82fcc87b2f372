"""A training job as the league's trainers run it: its spec, and the confined child that runs it.

A job is what ``slipstream train`` takes, minus what the server decides: ``options`` in
their command-line forms (only :data:`JOB_OPTIONS`), a recipe, DeepRacer hyperparameters,
a budget in minutes and the reward function's source. :func:`job_settings` turns a spec
into :class:`~agents.settings.TrainSettings` the same way in the API process (which checks
the spec without running any of the racer's code) and in the child.

The child, ``python -m agents.train_job WORKDIR [--check]``, runs inside the trainer's
sandbox (``league.training.sandbox``). ``WORKDIR`` holds ``job.json`` (the spec plus the
trainer's ``workers`` and ``threads``), ``reward.py`` and, for a clone, the parent run in
``parent/``. With ``--check`` it loads and pre-checks the reward function and prints one
JSON line, ``{"ok": true}`` or ``{"error": message}``; otherwise it trains into
``WORKDIR/run`` (each checkpoint packed in ``run/models/``) and prints one JSON line per
iteration (``{"type": "iteration", ...}``) and a last one (``{"type": "done", ...}``);
anything else it prints is a log line. A ``STOP`` file in ``WORKDIR`` (or SIGTERM) stops it
as Ctrl-C stops ``slipstream train``: finished work is kept and packed.
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

from agents.options import comma_separated, settings_from_options
from agents.recipes import get_recipe
from agents.settings import TrainSettings
from tracks.catalog import builtin_names

JOB_OPTIONS = (
    "track",
    "also_tracks",
    "direction",
    "race_type",
    "boxes",
    "bots",
    "bot_speed",
    "bot_lane_change_min_s",
    "bot_lane_change_max_s",
    "sensors",
    "action_space",
    "network",
    "critic",
    "teacher",
    "anchor",
    "anchor_weight",
    "anchor_iterations",
    "min_std",
    "critic_warmup",
    "seed",
    "eval_every",
    "eval_time_limit",
    "eval_also_tracks",
    "selfplay",
)
"""The ``train`` options a job may set; the trainer decides workers, threads and device,
the reward is the job's source, and files on the server are never named."""
JOB_FILE, REWARD_FILE, RUN_DIR, PARENT_DIR = "job.json", "reward.py", "run", "parent"
CHECKPOINT_MODELS_DIR = "models"
"""Under ``RUN_DIR``: each checkpoint packed as a submission, for the racer to choose from
(:meth:`agents.run.Run.pack_checkpoints`)."""
STOP_FILE = "STOP"
"""Created by the trainer to stop the job (signals do not cross the sandbox's init)."""
MAX_REWARD_SOURCE = 64 * 1024


def check_options(options: Mapping[str, Any]) -> None:
    """Refuse options a job may not set, tracks that are not built in, and action spaces
    given as file paths: a job never names a file on the server."""
    unknown = sorted(set(options) - set(JOB_OPTIONS))
    if unknown:
        raise ValueError(
            f"a training job cannot set {', '.join(unknown)}; it may set {', '.join(JOB_OPTIONS)}"
        )
    also = options.get("also_tracks", "")
    if not isinstance(also, str):
        raise ValueError("also_tracks: give the track names comma-separated in one string")
    named = [options.get("track"), *comma_separated(also)]
    for track in named:
        if track is not None and track not in builtin_names():
            raise ValueError(
                f"track {track!r}: a training job races built-in tracks, "
                f"{', '.join(builtin_names())}"
            )
    space = str(options.get("action_space") or "default")
    if "/" in space.split(":", 1)[0] or space.endswith(".json"):
        raise ValueError(
            f"action_space {space!r}: give a spec (default, console:..., continuous:..., "
            "list:...), not a file"
        )


def job_settings(
    options: Mapping[str, Any],
    recipe: str | None,
    reward_path: Path,
    minutes: float,
    workers: int | None = None,
    threads: int | None = None,
    opponent: Path | None = None,
    explicit_hyperparameters: bool = False,
) -> TrainSettings:
    """The settings a job trains with: its ``options`` over its recipe's over the defaults,
    with the job's reward file, budget and (a clone of a parent run) opponent. Explicit
    hyperparameters are honoured as written, as by ``slipstream train``."""
    check_options(options)
    given: dict[str, Any] = {**options, "reward_fn": str(reward_path), "minutes": minutes}
    if explicit_hyperparameters:
        given["grow_batch"] = False
    if workers is not None:
        given["workers"] = workers
    if threads is not None:
        given["threads"] = threads
    if opponent is not None:
        given["opponent"] = [opponent]
    if recipe is None:
        return settings_from_options(given)
    return get_recipe(recipe).settings(given)


def read_record(line: str) -> dict[str, Any] | None:
    """The JSON object a line of the child's output holds, or None (a log line)."""
    if not line.startswith("{"):
        return None
    try:
        value = json.loads(line)
    except ValueError:
        return None
    return value if isinstance(value, dict) else None


def _emit(record: dict[str, Any]) -> None:
    print(json.dumps(record, separators=(",", ":"), default=str), flush=True)


def _check(workdir: Path, job: dict[str, Any]) -> int:
    from agents.rewards import RewardFunctionError, load_reward_function

    try:
        settings = job_settings(job["options"], job.get("recipe"), workdir / REWARD_FILE, 1.0)
        load_reward_function(settings.reward_fn, settings.race_type)
    except (RewardFunctionError, ValueError) as exc:
        _emit({"error": str(exc).replace(f"{workdir}/", "")})
        return 0
    _emit({"ok": True})
    return 0


def _resumed(workdir: Path, job: dict[str, Any]) -> Any:
    """The trainer that continues the run in ``WORKDIR/run`` with its own settings, for
    the job's budget, on this trainer's machine share and with the job's reward file."""
    from agents.settings import load_settings
    from agents.train import Trainer

    run = workdir / RUN_DIR
    changes = {
        "reward_fn": str(workdir / REWARD_FILE),
        "minutes": job["minutes"],
        "iterations": None,
        "workers": job.get("workers"),
        "threads": job.get("threads"),
    }
    return Trainer(load_settings(run).model_copy(update=changes), run, resume=True)


def _train(workdir: Path, job: dict[str, Any]) -> int:
    from agents.hyperparameters import Hyperparameters
    from agents.recipes import parent_model
    from agents.train import Trainer

    if job.get("resume"):
        return _run(_resumed(workdir, job))

    parent = workdir / PARENT_DIR
    clone = parent if parent.is_dir() else None
    recipe = get_recipe(job["recipe"]) if job.get("recipe") else None
    opponent = parent_model(parent) if recipe and recipe.parent and clone else None
    settings = job_settings(
        job["options"],
        job.get("recipe"),
        workdir / REWARD_FILE,
        job["minutes"],
        workers=job.get("workers"),
        threads=job.get("threads"),
        opponent=opponent,
        explicit_hyperparameters=job.get("hyperparameters") is not None,
    )
    if job.get("hyperparameters") is not None:
        hp = Hyperparameters(**job["hyperparameters"])
    else:
        hp = recipe.hyperparameters_model() if recipe else None
    return _run(Trainer(settings, workdir / RUN_DIR, hp, clone=clone))


def _run(trainer: Any) -> int:
    """Train, printing each iteration and how it ended as JSON lines."""
    _stop_when_asked(trainer.run_dir.parent / STOP_FILE)

    def on_iteration(stats: Any) -> None:
        record = asdict(stats)
        _emit({"type": "iteration", **record})

    result = trainer.run(on_iteration)
    if result.model_zip is not None:
        trainer.target.pack_checkpoints(trainer.run_dir / CHECKPOINT_MODELS_DIR)
    _emit(
        {
            "type": "done",
            "iterations": result.iterations,
            "elapsed_s": result.elapsed_s,
            "interrupted": result.interrupted,
            "best_lap": result.best_lap,
            "model": result.model_zip is not None,
        }
    )
    return 0


def _stop_when_asked(stop_file: Path) -> None:
    """Once ``stop_file`` exists, SIGTERM this process (the trainer's graceful stop)."""

    def watch() -> None:
        while not stop_file.exists():
            time.sleep(0.5)
        os.kill(os.getpid(), signal.SIGTERM)

    threading.Thread(target=watch, daemon=True, name="stop-file").start()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the confined child (see the module docstring)."""
    args = sys.argv[1:] if argv is None else argv
    workdir = Path(args[0])
    job = json.loads((workdir / JOB_FILE).read_text())
    return _check(workdir, job) if "--check" in args else _train(workdir, job)


if __name__ == "__main__":
    sys.exit(main())
