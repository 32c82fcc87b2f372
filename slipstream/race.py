"""``slipstream race``: race built-in drivers, or model files head to head with bots, under
the league's rules; print the results (or win rates over several seeds) and write replays.

Model files are validated as the league validates an upload (never unpickled or imported),
then each drives a car with the sensors and action space it declares; a model that faults
in the race (NaN or inf, onnxruntime failing on a real frame) is out of that race with the
reason, as in the league. ``--bots N`` adds N of the league's ``racer`` bots
(:mod:`league.bots`: the passing pursuit driver, the imitation teacher, with continuous
actions up to 4 m/s). With ``--seeds K`` the cars
race K seeded races, the grid rotating one slot a race (so with two cars each starts in
front half the time).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape

from arena.cli import DRIVERS, RandomPolicy, print_results, win_rates_table
from arena.config import ConfigError, RaceConfig, SeedVariation, resolve_track

if TYPE_CHECKING:
    from arena.race import RaceResult

RaceRunner = Callable[..., "RaceResult"]


def _fail(err: Console, message: str) -> typer.Exit:
    err.print(f"[red]error:[/] {escape(message)}")
    return typer.Exit(1)


def _model_cars(paths: list[Path], err: Console) -> list[tuple[str, Any]]:
    """``(car name, policy)`` per model file, each validated; names from the file stems."""
    from submissions import InvalidSubmission, load_policy

    cars: list[tuple[str, Any]] = []
    taken: set[str] = set()
    for path in paths:
        name, n = path.stem, 2
        while name in taken:
            name, n = f"{path.stem}-{n}", n + 1
        taken.add(name)
        try:
            policy = load_policy(path, non_finite="raise", name=f"car {name}")
        except InvalidSubmission as exc:
            problems = "; ".join(p.message for p in exc.report.problems)
            raise _fail(err, f"{path} is not a valid model file: {problems}") from None
        except OSError as exc:
            raise _fail(err, f"cannot read {path}: {exc.strerror or exc}") from None
        cars.append((name, policy))
    return cars


def _model_race(
    models: list[tuple[str, Any]], bots: int, rules: dict[str, Any]
) -> tuple[RaceConfig, RaceRunner]:
    """The first race's config and a function that races any rotation of it."""
    from arena.config import BotConfig, ObstacleConfig
    from arena.race import StepGuard, run_race
    from league.bots import bot_car, bot_driver
    from league.jobs.evaluation import model_car
    from submissions import ModelFault

    cars = [model_car(name, policy.info.model_dump(mode="json")) for name, policy in models]
    cars += [bot_car(f"bot{i}", "racer") for i in range(bots)]
    defaults = {
        "object_avoidance": ("obstacles", ObstacleConfig),
        "head_to_bot": ("bots", BotConfig),
    }
    if rules["race_type"] in defaults:
        field, section = defaults[rules["race_type"]]
        rules = {field: section(), **rules}
    config = RaceConfig.build(cars=cars, **rules)
    track, _ = resolve_track(config)
    drivers = dict(models)
    drivers.update(
        {c.name: bot_driver("racer", track, c.action_space) for c in config.cars[len(models) :]}
    )
    guard = StepGuard(faults=(ModelFault,), cars=frozenset(name for name, _ in models))

    def race(config: RaceConfig, on_step=None) -> RaceResult:
        return run_race(config, drivers, on_step=on_step, guard=guard)

    return config, race


def race_command(
    model: Annotated[
        list[Path] | None,
        typer.Option(help="A model file (.zip) to race; repeat for several, head to head."),
    ] = None,
    bots: Annotated[
        int,
        typer.Option(
            help="Cars driven by the league's racer bot (the passing pursuit driver), beside "
            "the models.",
            min=0,
        ),
    ] = 0,
    track: Annotated[
        str | None,
        typer.Option(help="Track name (default: beginner_loop; slipstream_speedway with models)."),
    ] = None,
    race_type: Annotated[
        str | None,
        typer.Option(
            help="time_trial | object_avoidance | head_to_bot | head_to_model "
            "(default: time_trial; head_to_model for two or more cars with models)."
        ),
    ] = None,
    direction: Annotated[
        str | None, typer.Option(help="ccw or cw (default: the way the track's file runs).")
    ] = None,
    cars: Annotated[
        int | None,
        typer.Option(help="Built-in drivers' cars (default 1; 2 for head_to_model)."),
    ] = None,
    driver: Annotated[
        str, typer.Option(help="Built-in driver for every car: bot | random.")
    ] = "bot",
    speed: Annotated[float, typer.Option(help="Target speed of the bot driver, m/s.")] = 1.5,
    laps: Annotated[int, typer.Option(help="Laps to race.")] = 3,
    sensors: Annotated[
        str, typer.Option(help="Comma-separated sensors of the built-in drivers' cars.")
    ] = "lidar",
    time_limit: Annotated[float, typer.Option(help="Race time limit, simulated seconds.")] = 180.0,
    seed: Annotated[int, typer.Option(help="Race seed (the first, with --seeds).")] = 0,
    seeds: Annotated[
        int, typer.Option(help="Races to run, seeds SEED, SEED+1, ...; prints win rates.", min=1)
    ] = 1,
    out: Annotated[
        Path | None, typer.Option(help="Folder for result.json and replay.gif (one per race).")
    ] = None,
    gif: Annotated[bool, typer.Option(help="Write a GIF replay into --out.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Race built-in drivers, or model files against each other and bots, and print the
    results table (with --seeds, win rates)."""
    from arena import make_config

    err = Console(stderr=True)
    paths = list(model or [])
    if not paths and bots:
        raise _fail(err, "--bots races bots beside model files: give --model as well")
    if driver not in DRIVERS:
        choices = ", ".join(DRIVERS)
        raise _fail(err, f"unknown driver {driver!r}; choose from {choices}")
    rules: dict[str, Any] = {"direction": direction, "laps": laps, "time_limit_s": time_limit}
    if seeds > 1:  # the grid rotates instead of being drawn
        rules["variation"] = SeedVariation(shuffle_grid=False)
    try:
        if paths:
            models = _model_cars(paths, err)
            head_to_head = len(paths) + bots > 1
            rules["race_type"] = race_type or ("head_to_model" if head_to_head else "time_trial")
            rules["track"] = track or "slipstream_speedway"
            config, race = _model_race(models, bots, {**rules, "seed": seed})
        else:
            config = make_config(
                track=track or "beginner_loop",
                race_type=race_type or "time_trial",
                num_cars=cars,
                sensors=tuple(s.strip() for s in sensors.split(",") if s.strip()),
                seed=seed,
                **rules,
            )
            race = _builtin_race(config, driver, speed, seed)
    except (ConfigError, ValueError, KeyError) as exc:
        raise _fail(err, str(exc)) from None
    try:
        results = [
            _race_once(rotated(config, seed + k, k), race, _folder(out, seeds, seed + k), gif,
                       err, quiet=as_json, label=f"race {k + 1}/{seeds}")
            for k in range(seeds)
        ]  # fmt: skip
    except (ConfigError, ValueError) as exc:
        raise _fail(err, str(exc)) from None
    if as_json:
        docs = [{k: v for k, v in r.to_dict().items() if k != "trace"} for r in results]
        typer.echo(json.dumps(docs[0] if seeds == 1 else docs))
        return
    if seeds == 1:
        print_results(results[0])
    else:
        Console().print(win_rates_table(results))


def _builtin_race(config: RaceConfig, driver: str, speed: float, seed: int) -> RaceRunner:
    """Races of ``config``'s cars, each driven by the built-in ``driver``."""
    from arena.drivers import LaneFollowerPolicy
    from arena.race import run_race

    track, _ = resolve_track(config)
    policies: dict[str, Any] = {}
    for i, car in enumerate(config.cars):
        if driver == "bot":
            policies[car.name] = LaneFollowerPolicy(track, car.action_space, speed)
        else:
            policies[car.name] = RandomPolicy(car.action_space.gym_space(), seed + i)

    def race(config: RaceConfig, on_step=None) -> RaceResult:
        return run_race(config, policies, on_step=on_step)

    return race


def rotated(config: RaceConfig, seed: int, turn: int) -> RaceConfig:
    """``config`` with ``seed`` and its cars rotated ``turn`` slots along the grid."""
    shift = turn % len(config.cars)
    cars = (*config.cars[shift:], *config.cars[:shift])
    return config.model_copy(update={"seed": seed, "cars": cars})


def _folder(out: Path | None, seeds: int, seed: int) -> Path | None:
    """Where one race's files go: ``out`` itself for one race, ``out/seed-N`` for several."""
    if out is None or seeds == 1:
        return out
    return out / f"seed-{seed}"


def _race_once(
    config: RaceConfig,
    race: RaceRunner,
    out: Path | None,
    gif: bool,
    err: Console,
    *,
    quiet: bool,
    label: str,
) -> RaceResult:
    """One race with a progress bar; its result and replay written to ``out``."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from arena.replay import ReplayWriter

    track, _ = resolve_track(config)
    writer = ReplayWriter(track) if (out is not None and gif) else None
    with Progress(
        TextColumn(label),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
        TimeElapsedColumn(),
        console=err,
        disable=quiet,
    ) as progress:
        task = progress.add_task("race", total=config.time_limit_s)

        def on_step(env) -> None:
            progress.update(task, completed=env.time)
            if writer is not None:
                writer.add(env)

        result = race(config, on_step=on_step)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "result.json").write_text(result.to_json())
        if writer is not None:
            writer.save(out / "replay.gif")
        if not quiet:
            replay = f" and {out / 'replay.gif'}" if writer else ""
            err.print(f"wrote {out / 'result.json'}{replay}")
    return result
