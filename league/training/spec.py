"""A training job's request checked up front: its settings in the API process (no racer
code runs there), then its reward function in a sandboxed child, as ``slipstream train``
checks it before training (a broken reward is refused naming its line)."""

from __future__ import annotations

import json
import shutil
import subprocess
import uuid
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from agents.hyperparameters import Hyperparameters
from agents.recipes import get_recipe
from agents.settings import RACE_SECTIONS, TrainSettings
from agents.train_job import JOB_FILE, REWARD_FILE, job_settings, read_record
from league.settings import Settings
from league.training.launch import CHECK_CPU_SECONDS, limits_of, start_child, stop_child

CHECK_WALL_SECONDS = 30.0
MAX_CHECK_OUTPUT = 64 * 1024


class JobRefused(ValueError):
    """The request cannot train: the message says why (422)."""


def trains_on(spec: dict[str, Any]) -> dict[str, Any]:
    """The track, direction (None: the track file's), race type and the race type's own
    settings that differ from the league's defaults (boxes, bots) a job's spec trains on:
    its options over its recipe's over ``slipstream train``'s defaults."""
    recipe = spec.get("recipe")
    options = {**(get_recipe(recipe).options if recipe else {}), **spec.get("options", {})}
    fields = TrainSettings.model_fields
    race_type = options.get("race_type", fields["race_type"].default)
    section = RACE_SECTIONS.get(race_type)
    own = section.options.values() if section else ()
    return {
        "track": options.get("track", fields["track"].default),
        "direction": options.get("direction"),
        "race_type": race_type,
        "race_settings": {option: options[option] for option in own if option in options},
    }


def job_fields(
    options: dict[str, Any], recipe: str | None, hyperparameters: dict | None, minutes: float
) -> dict[str, Any]:
    """What a job stores in ``spec`` and a trainer writes to ``job.json`` (with workers)."""
    return {
        "options": options,
        "recipe": recipe,
        "hyperparameters": hyperparameters,
        "minutes": minutes,
    }


def check_settings(fields: dict[str, Any], cloned: bool) -> None:
    """Raise :class:`JobRefused` unless the options, recipe and hyperparameters make valid
    training settings (nothing of the racer's is run)."""
    try:
        recipe = get_recipe(fields["recipe"]) if fields["recipe"] else None
        if recipe is not None and recipe.parent is not None and not cloned:
            raise ValueError(
                f"the {recipe.name} recipe starts from a {recipe.parent} run: give clone_of, "
                f"one of your jobs trained with the {recipe.parent} recipe"
            )
        job_settings(fields["options"], fields["recipe"], Path(REWARD_FILE), fields["minutes"])
        if fields["hyperparameters"] is not None:
            Hyperparameters(**fields["hyperparameters"])
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first.get("loc", ()))
        raise JobRefused(f"{where}: {first.get('msg')}") from None
    except (ValueError, KeyError, TypeError) as exc:
        raise JobRefused(str(exc).strip("'\"")) from None


def write_workdir(workdir: Path, fields: dict[str, Any], reward_source: str) -> None:
    """Lay out a child's working folder: ``job.json`` and ``reward.py``."""
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / JOB_FILE).write_text(json.dumps(fields))
    (workdir / REWARD_FILE).write_text(reward_source, encoding="utf-8")


def check_reward(settings: Settings, fields: dict[str, Any], reward_source: str) -> None:
    """Pre-check the reward function in a sandboxed child (blocking: call it in a thread);
    raise :class:`JobRefused` with the child's message (``reward.py: ... at line N``)."""
    workdir = settings.data_dir / "training" / "checks" / uuid.uuid4().hex
    try:
        write_workdir(workdir, fields, reward_source)
        limits = limits_of(settings, CHECK_CPU_SECONDS)
        child = start_child(["--check"], workdir, settings, limits)
        try:
            out, _ = child.communicate(timeout=CHECK_WALL_SECONDS)
        except subprocess.TimeoutExpired:
            raise JobRefused(
                f"reward.py: checking the reward function took over {CHECK_WALL_SECONDS:g} s"
            ) from None
        finally:
            stop_child(child)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    verdict = last_json(out[-MAX_CHECK_OUTPUT:])
    if verdict.get("ok") is True:
        return
    if "error" in verdict:
        raise JobRefused(str(verdict["error"]))
    tail = out[-600:].decode("utf-8", "replace").strip()
    raise JobRefused(
        f"reward.py: the check ended without an answer (exit code {child.returncode}): {tail}"
    )


def last_json(out: bytes) -> dict[str, Any]:
    """The last JSON object a sandboxed child printed (its verdict), or ``{}``."""
    for line in reversed(out.decode("utf-8", "replace").splitlines()):
        record = read_record(line)
        if record is not None:
            return record
    return {}
