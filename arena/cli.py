"""``slipstream race``: run a race with built-in drivers, print results, write a replay."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from arena.config import ConfigError, resolve_track

DRIVERS = ("bot", "random")


class RandomPolicy:
    """Uniformly random actions (a yardstick, not a driver)."""

    def __init__(self, space, seed: int) -> None:
        self.space = space
        self.seed = seed

    def reset(self) -> None:
        """Re-seed so that races repeat."""
        self.space.seed(self.seed)

    def act(self, observation: dict) -> object:
        """A random action."""
        return self.space.sample()


def race_command(
    track: Annotated[
        str, typer.Option(help="Track name (see `slipstream tracks list`).")
    ] = "beginner_loop",
    race_type: Annotated[
        str, typer.Option(help="time_trial | object_avoidance | head_to_bot | head_to_model")
    ] = "time_trial",
    direction: Annotated[
        str | None, typer.Option(help="ccw or cw (default: the way the track's file runs).")
    ] = None,
    cars: Annotated[
        int | None, typer.Option(help="Controlled cars (default 1; 2 for head_to_model).")
    ] = None,
    driver: Annotated[
        str, typer.Option(help="Built-in driver for every car: bot | random.")
    ] = "bot",
    speed: Annotated[float, typer.Option(help="Target speed of the bot driver, m/s.")] = 1.5,
    laps: Annotated[int, typer.Option(help="Laps to race.")] = 3,
    sensors: Annotated[str, typer.Option(help="Comma-separated sensors.")] = "lidar",
    time_limit: Annotated[float, typer.Option(help="Race time limit, simulated seconds.")] = 180.0,
    seed: Annotated[int, typer.Option(help="Race seed.")] = 0,
    out: Annotated[Path | None, typer.Option(help="Folder for result.json and replay.gif.")] = None,
    gif: Annotated[bool, typer.Option(help="Write a GIF replay into --out.")] = True,
    as_json: Annotated[bool, typer.Option("--json", help="Print the result as JSON.")] = False,
) -> None:
    """Race built-in drivers on a track and print the results table."""
    from rich.console import Console
    from rich.markup import escape
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    from arena import make_config
    from arena.drivers import LaneFollowerPolicy
    from arena.race import run_race
    from arena.replay import ReplayWriter

    err = Console(stderr=True)
    if driver not in DRIVERS:
        choices = ", ".join(DRIVERS)
        err.print(f"[red]error:[/] unknown driver {escape(repr(driver))}; choose from {choices}")
        raise typer.Exit(1)
    try:
        config = make_config(
            track=track,
            race_type=race_type,
            num_cars=cars,
            sensors=tuple(s.strip() for s in sensors.split(",") if s.strip()),
            seed=seed,
            direction=direction,
            laps=laps,
            time_limit_s=time_limit,
        )
        race_track, _ = resolve_track(config)
    except (ConfigError, ValueError, KeyError) as exc:
        err.print(f"[red]error:[/] {escape(str(exc))}")
        raise typer.Exit(1) from None
    policies = {}
    for i, car in enumerate(config.cars):
        if driver == "bot":
            policies[car.name] = LaneFollowerPolicy(race_track, car.action_space, speed)
        else:
            policies[car.name] = RandomPolicy(car.action_space.gym_space(), seed + i)
    writer = ReplayWriter(race_track) if (out is not None and gif) else None
    with Progress(
        TextColumn("racing"),
        BarColumn(),
        TextColumn("{task.completed:.0f}/{task.total:.0f} s"),
        TimeElapsedColumn(),
        console=err,
        disable=as_json,
    ) as progress:
        task = progress.add_task("race", total=config.time_limit_s)

        def on_step(env) -> None:
            progress.update(task, completed=env.time)
            if writer is not None:
                writer.add(env)

        try:
            result = run_race(config, policies, on_step=on_step)
        except (ConfigError, ValueError) as exc:
            err.print(f"[red]error:[/] {escape(str(exc))}")
            raise typer.Exit(1) from None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "result.json").write_text(result.to_json())
        if writer is not None:
            writer.save(out / "replay.gif")
    if as_json:
        typer.echo(json.dumps({k: v for k, v in result.to_dict().items() if k != "trace"}))
        return
    print_results(result)
    if out is not None:
        err.print(f"wrote {out / 'result.json'}" + (f" and {out / 'replay.gif'}" if writer else ""))


def print_results(result) -> None:
    """A Rich table of a race result, in finishing order: times, the gap to the winner,
    incidents and racing metrics (overtakes made and suffered, at-fault collisions, laps
    led)."""
    from rich.console import Console
    from rich.table import Table

    def secs(value: float | None) -> str:
        return "-" if value is None else f"{value:.3f}"

    table = Table(title=f"{result.config.race_type} on {result.config.track}")
    for column in (
        "pos",
        "car",
        "status",
        "laps",
        "best",
        "average",
        "total",
        "gap",
        "off-track",
        "crashes",
        "resets",
        "penalty s",
        "overtakes",
        "overtaken",
        "at-fault",
        "laps led",
    ):
        table.add_column(column, justify="right" if column not in ("car", "status") else "left")
    for name in result.finish_order:
        c = result.car(name)
        table.add_row(
            str(c.finish_position),
            c.name,
            c.status,
            str(c.laps),
            secs(c.best_lap),
            secs(c.average_lap),
            secs(c.total_time),
            "-" if c.gap_to_winner is None else f"+{c.gap_to_winner:.3f}",
            str(c.off_track_count),
            str(c.crash_count),
            str(c.reset_count),
            f"{c.penalty_seconds:.0f}",
            str(c.overtakes),
            str(c.times_overtaken),
            str(c.at_fault_collisions),
            str(c.laps_led),
        )
    Console().print(table)
