"""``slipstream train`` and ``slipstream evaluate`` (a Typer app with those two commands)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

if TYPE_CHECKING:
    from agents.train import TrainSettings

app = typer.Typer(help="Train and evaluate racing policies.", no_args_is_help=True)
console = Console()


def _fail(message: str) -> None:
    console.print(f"[red]error:[/red] {message}")
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


def _settings(**options: Any) -> TrainSettings:
    from agents.action_spaces import parse_action_space_spec
    from agents.train import TrainSettings, load_settings

    out, resume = options.pop("out"), options.pop("resume")
    keep = {k: options[k] for k in ("iterations", "minutes", "workers", "device", "threads")}
    if resume:
        return load_settings(out).model_copy(update=keep)
    space = parse_action_space_spec(options.pop("action_space"))
    reward = options.pop("reward_fn")
    if reward.endswith(".py") or Path(reward).exists():
        reward = str(Path(reward).resolve())
    sensors = tuple(s.strip() for s in options.pop("sensors").split(",") if s.strip())
    opponents = tuple(str(Path(p).resolve()) for p in options.pop("opponent") or ())
    return TrainSettings(
        action_space=space, reward=reward, sensors=sensors, opponents=opponents, **options
    )


@app.command()
def train(
    out: Annotated[Path, typer.Option(help="Run folder, e.g. runs/NAME.")],
    track: Annotated[str, typer.Option(help="Track name.")] = "beginner_loop",
    race_type: Annotated[
        str, typer.Option(help="time_trial | object_avoidance | head_to_bot | head_to_model")
    ] = "time_trial",
    sensors: Annotated[str, typer.Option(help="Comma-separated, e.g. camera,lidar.")] = "camera",
    action_space: Annotated[
        str, typer.Option(help="Action-space spec, e.g. 3x3@1.0 or default.")
    ] = "default",
    reward_fn: Annotated[
        str, typer.Option(help="Reward-function file or sample name.")
    ] = "follow_center_line",
    minutes: Annotated[float | None, typer.Option(help="Wall-clock budget.")] = None,
    iterations: Annotated[int | None, typer.Option(help="Iteration budget.")] = None,
    clone: Annotated[Path | None, typer.Option(help="Start from another run's weights.")] = None,
    resume: Annotated[bool, typer.Option(help="Continue the run in --out.")] = False,
    workers: Annotated[int | None, typer.Option(help="Worker processes (default: cores).")] = None,
    races: Annotated[int | None, typer.Option(help="Parallel races (default: workers).")] = None,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    network: Annotated[str | None, typer.Option(help="Network preset.")] = None,
    hyperparameters: Annotated[
        Path | None, typer.Option(help="DeepRacer hyperparameters.json.")
    ] = None,
    eval_every: Annotated[int, typer.Option(help="Evaluate every N iterations.")] = 5,
    eval_time_limit: Annotated[
        float, typer.Option(help="Simulated seconds an evaluation may take.")
    ] = 120.0,
    selfplay: Annotated[str, typer.Option(help="head_to_model: shared | pool.")] = "shared",
    opponent: Annotated[
        list[Path] | None, typer.Option(help="ONNX / model.zip opponent (repeatable).")
    ] = None,
    device: Annotated[str, typer.Option(help="cpu, cuda or cuda:N.")] = "cpu",
    threads: Annotated[int, typer.Option(help="Torch CPU threads.")] = 1,
) -> None:
    """Train a policy with PPO (rsl-rl); Ctrl-C stops cleanly keeping the last checkpoint."""
    from pydantic import ValidationError

    from agents.hyperparameters import Hyperparameters
    from agents.train import Trainer

    if minutes is None and iterations is None and not resume:
        _fail("give --minutes or --iterations")
    try:
        settings = _settings(
            out=out,
            resume=resume,
            track=track,
            race_type=race_type,
            sensors=sensors,
            action_space=action_space,
            reward_fn=reward_fn,
            minutes=minutes,
            iterations=iterations,
            workers=workers,
            races=races,
            seed=seed,
            network=network,
            eval_every=eval_every,
            eval_time_limit_s=eval_time_limit,
            selfplay=selfplay,
            opponent=opponent,
            device=_device(device),
            threads=threads,
        )
        hp = Hyperparameters.load(hyperparameters) if hyperparameters else None
        if resume and hp is None and (out / "ip" / "hyperparameters.json").exists():
            hp = Hyperparameters.load(out / "ip" / "hyperparameters.json")
        trainer = Trainer(settings, out, hp, clone=clone, resume=resume)
    except (ValueError, ValidationError, FileNotFoundError) as exc:
        _fail(str(exc))
    if settings.race_type == "time_trial" and not {"camera", "stereo"} & set(settings.sensors):
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

        def on_iteration(row: dict[str, Any]) -> None:
            status = f"it {row['iteration']}  reward {row['mean_reward']:.1f}  "
            status += f"progress {row['mean_progress']:.0f}%"
            if row.get("eval_progress") != "":
                status += f"  eval {row['eval_progress']:.0f}%"
            if settings.iterations:
                progress.update(task, advance=1, status=status)
            else:
                progress.update(task, completed=row["elapsed_s"], status=status)

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
    laps: Annotated[int, typer.Option(help="Laps.")] = 3,
    race_type: Annotated[str | None, typer.Option(help="Race type (default: the run's).")] = None,
    seed: Annotated[int, typer.Option(help="Race seed.")] = 0,
    time_limit: Annotated[float, typer.Option(help="Simulated seconds before time-up.")] = 180.0,
) -> None:
    """Race a trained run, print the results table and write a replay GIF."""
    from agents import evaluate
    from agents.train import load_actor

    try:
        actor, settings = load_actor(run)
    except (FileNotFoundError, ValueError) as exc:
        _fail(f"cannot load {run}: {exc}")
    config = evaluate.evaluation_config(
        track or settings.track,
        race_type or settings.race_type,
        settings.sensors,
        settings.action_space,
        laps=laps,
        seed=seed,
        time_limit_s=time_limit,
    )
    folder = evaluate.evaluation_dir(run)
    race = evaluate.evaluate_policy(
        config, evaluate.TorchPolicy(actor, settings.discrete), folder / "replay.gif"
    )
    evaluate.write_evaluation(run, race, folder)
    console.print(evaluate.results_table(race))
    console.print(f"replay: {folder / 'replay.gif'}")
