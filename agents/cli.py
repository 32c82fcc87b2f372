"""``slipstream train`` and ``slipstream evaluate`` (a Typer app with those two commands).

Every ``train`` option except ``--out``, ``--clone``, ``--resume`` and ``--hyperparameters``
is the :class:`~agents.settings.TrainSettings` field of the same name, with the field's
description as its help and, where the command line takes the same form, its default.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from agents.model_metadata import training_metadata
from agents.settings import RESUME_OVERRIDES, TrainSettings, load_settings
from arena.sensors_spec import DEEPRACER_SENSOR, IMAGE_SENSORS, check_sensors

if TYPE_CHECKING:
    from agents.metrics import IterationStats

app = typer.Typer(help="Train and evaluate racing policies.", no_args_is_help=True)
console = Console()


def _fail(message: str) -> None:
    console.print(f"[red]error:[/red] {escape(message)}")
    raise typer.Exit(2)


def _device(device: str) -> str:
    """``cuda`` under torchrun becomes ``cuda:LOCAL_RANK``; torchrun needs GPUs."""
    if int(os.environ.get("WORLD_SIZE", "1")) > 1:
        if not device.startswith("cuda"):
            _fail(
                "torchrun starts one training process per GPU (rsl-rl syncs them with NCCL): "
                "add --device cuda, or run without torchrun on a CPU"
            )
        return f"cuda:{os.environ.get('LOCAL_RANK', '0')}"
    return device


def _setting(name: str) -> Any:
    """The option for the ``TrainSettings`` field ``name``, its description as help."""
    return typer.Option(help=TrainSettings.model_fields[name].description)


def _default(name: str) -> Any:
    """The default of the ``TrainSettings`` field ``name``."""
    return TrainSettings.model_fields[name].default


def _sensors(option: str | None, action_space: str) -> tuple[str, ...]:
    """``--sensors``, else those of a ``model_metadata.json`` action space, else the default.

    ``--sensors`` that disagree with the metadata file's ``sensor`` list are an error naming
    both, as are sensors no car can carry.
    """
    given = tuple(s.strip() for s in option.split(",") if s.strip()) if option else ()
    meta = training_metadata(action_space)
    if meta is None:
        return check_sensors(given or _default("sensors"))
    if given and set(check_sensors(given)) != set(meta.sensors):
        in_file = [DEEPRACER_SENSOR[s] for s in meta.sensors]
        raise ValueError(
            f"--sensors {','.join(given)} conflicts with {action_space}'s sensor {in_file} "
            f"({','.join(meta.sensors)} here): drop --sensors to train with the file's sensors, "
            "or change the file"
        )
    return meta.sensors


def _settings(out: Path, resume: bool, options: dict[str, Any]) -> TrainSettings:
    """The run's settings from the options named after its fields (command-line forms parsed).

    ``--resume`` reads them from the run, but for those in ``RESUME_OVERRIDES``.
    """
    from agents.action_spaces import parse_action_space_spec

    if resume:
        return load_settings(out).model_copy(update={k: options[k] for k in RESUME_OVERRIDES})
    reward_fn = options["reward_fn"]
    if reward_fn.endswith(".py") or Path(reward_fn).exists():
        reward_fn = str(Path(reward_fn).resolve())
    parsed = {
        "sensors": _sensors(options["sensors"], options["action_space"]),
        "action_space": parse_action_space_spec(options["action_space"]),
        "reward_fn": reward_fn,
        "opponent": tuple(str(Path(p).resolve()) for p in options["opponent"] or ()),
    }
    return TrainSettings(**{**options, **parsed})


@app.command()
def train(
    out: Annotated[Path, typer.Option(help="Run folder, e.g. runs/NAME.")],
    track: Annotated[str, _setting("track")] = _default("track"),
    direction: Annotated[str | None, _setting("direction")] = _default("direction"),
    race_type: Annotated[str, _setting("race_type")] = _default("race_type"),
    sensors: Annotated[str | None, _setting("sensors")] = None,
    action_space: Annotated[str, _setting("action_space")] = "default",
    reward_fn: Annotated[str, _setting("reward_fn")] = _default("reward_fn"),
    minutes: Annotated[float | None, _setting("minutes")] = _default("minutes"),
    iterations: Annotated[int | None, _setting("iterations")] = _default("iterations"),
    clone: Annotated[Path | None, typer.Option(help="Start from another run's weights.")] = None,
    resume: Annotated[bool, typer.Option(help="Continue the run in --out.")] = False,
    workers: Annotated[int | None, _setting("workers")] = _default("workers"),
    races: Annotated[int | None, _setting("races")] = _default("races"),
    seed: Annotated[int, _setting("seed")] = _default("seed"),
    network: Annotated[str | None, _setting("network")] = _default("network"),
    critic: Annotated[str, _setting("critic")] = _default("critic"),
    teacher: Annotated[str | None, _setting("teacher")] = _default("teacher"),
    hyperparameters: Annotated[
        Path | None, typer.Option(help="DeepRacer hyperparameters.json.")
    ] = None,
    eval_every: Annotated[int, _setting("eval_every")] = _default("eval_every"),
    eval_time_limit: Annotated[float, _setting("eval_time_limit")] = _default("eval_time_limit"),
    selfplay: Annotated[str, _setting("selfplay")] = _default("selfplay"),
    opponent: Annotated[list[Path] | None, _setting("opponent")] = None,
    device: Annotated[str, _setting("device")] = _default("device"),
    threads: Annotated[int, _setting("threads")] = _default("threads"),
) -> None:
    """Train a policy with PPO (rsl-rl), or by imitation (--teacher); Ctrl-C stops cleanly,
    keeping finished work."""
    # The parameters named after settings fields (locals() holds only parameters here).
    options = {k: v for k, v in locals().items() if k in TrainSettings.model_fields}
    from pydantic import ValidationError

    from agents.hyperparameters import Hyperparameters
    from agents.train import Trainer

    if minutes is None and iterations is None and not resume:
        _fail("give --minutes or --iterations")
    options["device"] = _device(device)
    try:
        settings = _settings(out, resume, options)
        hp = None
        if hyperparameters:
            hp, ignored = Hyperparameters.read(hyperparameters)
            if ignored:
                console.print(
                    f"[yellow]warning:[/] {escape(str(hyperparameters))}: ignoring "
                    f"{escape(', '.join(ignored))} (not DeepRacer hyperparameters; "
                    "DeepRacer ignores them too)"
                )
        trainer = Trainer(settings, out, hp, clone=clone, resume=resume)
    except (ValueError, ValidationError, FileNotFoundError) as exc:
        _fail(str(exc))
    if settings.race_type == "time_trial" and not set(IMAGE_SENSORS) & set(settings.sensors):
        console.print(
            "[yellow]warning:[/] the lidar sees only cars and boxes, and a time trial has "
            "none: a lidar-only car drives blind. Add a camera (--sensors camera,lidar)."
        )
    total = float(settings.iterations or 60.0 * (settings.minutes or 0.0))
    with Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        TextColumn("{task.fields[status]}"),
        TimeElapsedColumn(),
        console=console,
    ) as progress:
        task = progress.add_task("training", total=total, status="")

        def on_iteration(stats: IterationStats) -> None:
            status = f"it {stats.iteration}  reward {stats.mean_reward:.1f}  "
            status += f"progress {stats.mean_progress:.0f}%"
            if stats.eval is not None:
                status += f"  eval {stats.eval.progress:.0f}%"
            if settings.iterations:
                progress.update(task, advance=1, status=status)
            else:
                progress.update(task, completed=stats.elapsed_s, status=status)

        try:
            result = trainer.run(on_iteration)
        except (ValueError, RuntimeError) as exc:
            _fail(str(exc))
    state = "stopped (Ctrl-C)" if result.interrupted else "done"
    console.print(f"{state}: {result.iterations} iterations in {result.elapsed_s / 60:.1f} min")
    if result.model_zip is not None:
        console.print(f"model: {result.model_zip}")


@app.command("evaluate")
def evaluate_command(
    run: Annotated[Path, typer.Argument(help="Run folder.")],
    track: Annotated[str | None, typer.Option(help="Track (default: the run's).")] = None,
    direction: Annotated[
        str | None,
        typer.Option(help="ccw or cw (default: the run's on its track, else the file's)."),
    ] = None,
    laps: Annotated[int, typer.Option(help="Laps.")] = 3,
    race_type: Annotated[str | None, typer.Option(help="Race type (default: the run's).")] = None,
    seed: Annotated[int, typer.Option(help="Race seed.")] = 0,
    time_limit: Annotated[float, typer.Option(help="Simulated seconds before time-up.")] = 180.0,
    opponent: Annotated[
        Path | None,
        typer.Option(
            help="model.zip or .onnx driving the other cars, with the run's sensors and "
            "actions (default: a head-to-model run's first --opponent, else the run itself)."
        ),
    ] = None,
) -> None:
    """Race a trained run, print the results table and write a replay GIF."""
    from agents import evaluate
    from agents.train import load_actor, run_hyperparameters

    try:
        actor, settings = load_actor(run)
        stack_size = run_hyperparameters(run).stack_size
    except (FileNotFoundError, ValueError) as exc:
        _fail(f"cannot load {run}: {exc}")
    raced = settings.model_copy(update={"race_type": race_type or settings.race_type})
    try:
        others = (
            evaluate.model_opponent(opponent, settings)
            if opponent is not None
            else evaluate.run_opponent(raced)
        )
    except (OSError, KeyError, ValueError, zipfile.BadZipFile) as exc:
        _fail(f"cannot load the opponent: {exc}")
    try:
        config = evaluate.evaluation_config(
            track or settings.track,
            raced.race_type,
            settings.sensors,
            settings.action_space,
            laps=laps,
            seed=seed,
            time_limit_s=time_limit,
            direction=direction
            or (settings.direction if track in (None, settings.track) else None),
            stack_size=stack_size,
        )
    except ValueError as exc:
        _fail(str(exc))
    folder = evaluate.evaluation_dir(run)
    race = evaluate.evaluate_policy(
        config,
        evaluate.TorchPolicy(actor, settings.discrete),
        folder / "replay.gif",
        opponent=others,
    )
    evaluate.write_evaluation(run, race, folder)
    console.print(evaluate.results_table(race))
    console.print(f"replay: {folder / 'replay.gif'}")
