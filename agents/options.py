"""The ``slipstream train`` options: :class:`~agents.settings.TrainSettings` fields in their
command-line forms, and turning those forms into settings.

Every field but :data:`PYTHON_ONLY` is the option of the same name (``reward_fn`` is
``--reward-fn``), its help the field's description; ``agents/cli.py`` generates the options
from this module and recipes (``agents/recipes.py``) are written in the same forms. This
module imports no torch, so the CLI can read it at start-up.
"""

from __future__ import annotations

import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agents.model_metadata import training_metadata
from agents.settings import TrainSettings
from arena.sensors_spec import DEEPRACER_SENSOR, check_sensors

# Fields for Python callers only, with no ``train`` option.
PYTHON_ONLY = ("steps_per_env", "eval_laps", "stop_on_clean_eval", "snapshot_every", "recipe")
# Fields whose command-line form is not the field's type: (type, default) on the command line.
_FORMS: dict[str, tuple[Any, Any]] = {
    "sensors": (str | None, None),  # comma-separated; default from an action-space file
    "also_tracks": (str, ""),  # comma-separated track names
    "action_space": (str, "default"),  # a spec (agents.action_spaces)
    "opponent": (list[Path] | None, None),  # repeatable
    "paced_rivals": (  # comma-separated shares, or "none"
        str,
        ",".join(str(share) for share in TrainSettings.model_fields["paced_rivals"].default),
    ),
}
# Types the command line takes as they are; any other (Literal, ...) is given as a string.
_PLAIN = (str, int, float, bool)


def option_names() -> tuple[str, ...]:
    """The settings fields that are ``train`` options, in declaration order."""
    return tuple(name for name in TrainSettings.model_fields if name not in PYTHON_ONLY)


def option_form(name: str) -> tuple[Any, Any]:
    """The command-line type and default of the option for the field ``name``."""
    if name in _FORMS:
        return _FORMS[name]
    field = TrainSettings.model_fields[name]
    args = typing.get_args(field.annotation)
    optional = typing.get_origin(field.annotation) in (typing.Union, types.UnionType)
    optional = optional and type(None) in args
    kind = next(a for a in args if a is not type(None)) if optional else field.annotation
    kind = kind if kind in _PLAIN else str
    return (kind | None if optional else kind), field.default


def defaults() -> dict[str, Any]:
    """Every option's default in its command-line form."""
    return {name: option_form(name)[1] for name in option_names()}


def settings_from_options(options: Mapping[str, Any], **python_only: Any) -> TrainSettings:
    """The settings of ``options`` (command-line forms; an option left out takes its
    default), plus fields of :data:`PYTHON_ONLY` as they are.

    Relative reward and opponent paths are made absolute, so the run finds them from any
    folder; ``--sensors`` must agree with an action-space file's ``sensor`` list.
    """
    from agents.action_spaces import parse_action_space_spec

    unknown = sorted(set(options) - set(option_names()))
    if unknown:
        raise ValueError(f"not train options: {', '.join(unknown)}")
    given = {**defaults(), **options}
    reward_fn = given["reward_fn"]
    if reward_fn.endswith(".py") or Path(reward_fn).exists():
        reward_fn = str(Path(reward_fn).resolve())
    parsed = {
        "sensors": _sensors(given["sensors"], given["action_space"]),
        "also_tracks": comma_separated(given["also_tracks"]),
        "action_space": parse_action_space_spec(given["action_space"]),
        "reward_fn": reward_fn,
        "opponent": tuple(str(Path(p).resolve()) for p in given["opponent"] or ()),
        "paced_rivals": _shares(given["paced_rivals"]),
    }
    return TrainSettings(**{**given, **parsed, **python_only})


def comma_separated(option: str) -> tuple[str, ...]:
    """The non-empty, stripped items of a comma-separated option (``--also-tracks``)."""
    return tuple(item.strip() for item in option.split(",") if item.strip())


def _shares(option: str) -> tuple[float, ...]:
    """``--paced-rivals``: comma-separated shares, or ``none``."""
    if option.strip().lower() == "none":
        return ()
    try:
        return tuple(float(share) for share in option.split(",") if share.strip())
    except ValueError:
        raise ValueError(
            f"--paced-rivals takes comma-separated shares such as 0.6,0.8 or 'none', got {option!r}"
        ) from None


def _sensors(option: str | None, action_space: str) -> tuple[str, ...]:
    """``--sensors``, else those of a ``model_metadata.json`` action space, else the default.

    ``--sensors`` that disagree with the metadata file's ``sensor`` list are an error naming
    both, as are sensors no car can carry.
    """
    given = tuple(s.strip() for s in option.split(",") if s.strip()) if option else ()
    meta = training_metadata(action_space)
    if meta is None:
        return check_sensors(given or TrainSettings.model_fields["sensors"].default)
    if given and set(check_sensors(given)) != set(meta.sensors):
        in_file = [DEEPRACER_SENSOR[s] for s in meta.sensors]
        raise ValueError(
            f"--sensors {','.join(given)} conflicts with {action_space}'s sensor {in_file} "
            f"({','.join(meta.sensors)} here): drop --sensors to train with the file's sensors, "
            "or change the file"
        )
    return meta.sensors
