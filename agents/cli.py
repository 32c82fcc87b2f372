"""``slipstream train`` and ``slipstream evaluate`` (a Typer app with those two commands).

``train`` has one option per :class:`~agents.settings.TrainSettings` field that is a
command-line setting (``agents/options.py``), generated from the field with its description
as help, besides ``--out``, ``--recipe``, ``--list-recipes``, ``--clone``, ``--resume`` and
``--hyperparameters``.
"""

from __future__ import annotations

import inspect
import os
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from agents.options import defaults, option_form, option_names, settings_from_options
from agents.recipes import RECIPES, get_recipe, parent_model
from agents.settings import RESUME_OVERRIDES, TrainSettings, load_settings
from arena.sensors_spec import IMAGE_SENSORS

if TYPE_CHECKING:
    from agents.hyperparameters import Hyperparameters
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


def _with_setting_options(command: Callable[..., None]) -> Callable[..., None]:
    """Give ``command`` (which takes ``**settings``) one option per settings field."""
    signature = inspect.signature(command, eval_str=True)
    own = [p for p in signature.parameters.values() if p.kind is not p.VAR_KEYWORD]
    generated = []
    for name in option_names():
        kind, default = option_form(name)
        info = typer.Option(help=TrainSettings.model_fields[name].description)
        annotation = Annotated[kind, info]
        generated.append(
            inspect.Parameter(
                name, inspect.Parameter.KEYWORD_ONLY, default=default, annotation=annotation
            )
        )
    parameters = [*own, *generated]
    command.__signature__ = signature.replace(parameters=parameters)  # type: ignore[attr-defined]
    command.__annotations__ = {p.name: p.annotation for p in parameters} | {"return": None}
    return command


def _list_recipes(value: bool) -> None:
    """``--list-recipes``: print the recipes, one line each, and exit."""
    if not value:
        return
    table = Table("recipe", "race type", "what it trains", box=None)
    for recipe in RECIPES.values():
        table.add_row(recipe.name, recipe.options["race_type"], recipe.summary)
    console.print(table)
    console.print("train one: slipstream train --recipe NAME --out runs/NAME --minutes 10")
    raise typer.Exit()


def _settings(
    out: Path, recipe: str | None, clone: Path | None, resume: bool, given: dict[str, Any]
) -> TrainSettings:
    """The run's settings: the options ``given`` (command-line forms) over the recipe's,
    over the defaults; ``--resume`` reads them from the run but for ``RESUME_OVERRIDES``."""
    if resume:
        if recipe is not None:
            raise ValueError("--resume continues a run with its own settings: drop --recipe")
        every = {**defaults(), **given}
        return load_settings(out).model_copy(update={k: every[k] for k in RESUME_OVERRIDES})
    if recipe is None:
        return settings_from_options(given)
    chosen = get_recipe(recipe)
    if chosen.parent is not None and "opponent" not in given:
        if clone is None:
            raise ValueError(
                f"the {recipe} recipe starts from a {chosen.parent} run: give --clone RUN "
                f"(e.g. one trained with --recipe {chosen.parent})"
            )
        given = {**given, "opponent": [parent_model(clone)]}
    return chosen.settings(given)


def _hyperparameters(path: Path | None, recipe: str | None) -> Hyperparameters | None:
    """An explicit ``hyperparameters.json`` (ignored keys warned about), else the recipe's
    (None: the run's on ``--resume``, DeepRacer's defaults otherwise)."""
    from agents.hyperparameters import Hyperparameters

    if path is None:
        return get_recipe(recipe).hyperparameters_model() if recipe else None
    hp, ignored = Hyperparameters.read(path)
    if ignored:
        console.print(
            f"[yellow]warning:[/] {escape(str(path))}: ignoring {escape(', '.join(ignored))} "
            "(not DeepRacer hyperparameters; DeepRacer ignores them too)"
        )
    return hp


@app.command()
@_with_setting_options
def train(
    ctx: typer.Context,
    out: Annotated[Path, typer.Option(help="Run folder, e.g. runs/NAME.")],
    recipe: Annotated[
        str | None,
        typer.Option(
            help="Start from a named recipe (see --list-recipes); options given here win."
        ),
    ] = None,
    list_recipes: Annotated[
        bool,
        typer.Option(
            "--list-recipes",
            help="List the recipes and exit.",
            is_eager=True,
            callback=_list_recipes,
        ),
    ] = False,
    clone: Annotated[Path | None, typer.Option(help="Start from another run's weights.")] = None,
    resume: Annotated[bool, typer.Option(help="Continue the run in --out.")] = False,
    hyperparameters: Annotated[
        Path | None, typer.Option(help="DeepRacer hyperparameters.json (wins over a recipe's).")
    ] = None,
    **settings: Any,
) -> None:
    """Train a policy with PPO (rsl-rl), or by imitation (--teacher); Ctrl-C stops cleanly,
    keeping finished work."""
    from pydantic import ValidationError

    from agents.train import Trainer

    # The options given on the command line: they win over a recipe's.
    given = {
        name: value
        for name, value in settings.items()
        if ctx.get_parameter_source(name).name != "DEFAULT"  # typer's own click enum
    }
    given["device"] = _device(settings["device"])
    if hyperparameters is not None:
        given.setdefault("grow_batch", False)  # an explicit file is honoured as written
    try:
        run_settings = _settings(out, recipe, clone, resume, given)
        if run_settings.minutes is None and run_settings.iterations is None and not resume:
            _fail("give --minutes or --iterations")
        hp = _hyperparameters(hyperparameters, recipe)
        trainer = Trainer(run_settings, out, hp, clone=clone, resume=resume)
    except ValidationError as exc:
        _fail("; ".join(_setting_error(e) for e in exc.errors()))
    except (ValueError, FileNotFoundError) as exc:
        _fail(str(exc))
    _train(trainer)


def _setting_error(error: Any) -> str:
    """One of pydantic's errors as ``--option: message``."""
    where = "--" + "-".join(str(p) for p in error.get("loc", ())).replace("_", "-")
    message = str(error.get("msg", "")).removeprefix("Value error, ")
    return message if where == "--" else f"{where}: {message}"


def _train(trainer: Any) -> None:
    """Run ``trainer`` under a progress bar and print how it ended."""
    settings = trainer.settings
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
                status += "  eval " + "/".join(f"{r.progress:.0f}%" for r in stats.eval.races)
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
    from agents.run import Run

    try:
        trained = Run.load(run)
        actor = trained.actor()
    except (FileNotFoundError, ValueError) as exc:
        _fail(f"cannot load {run}: {exc}")
    settings = trained.settings
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
        config = trained.evaluation_config(
            track=track or settings.track,
            race_type=raced.race_type,
            laps=laps,
            seed=seed,
            time_limit_s=time_limit,
            direction=direction
            or (settings.direction if track in (None, settings.track) else None),
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
