"""The arena's pieces of ``slipstream race`` (:mod:`slipstream.race`): the built-in drivers
and the results tables."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rich.table import Table

    from arena.race import RaceResult

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


def print_results(result: RaceResult) -> None:
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


def win_rates_table(results: Sequence[RaceResult]) -> Table:
    """Per car over several races of the same cars: wins (and wins from a slot behind the
    front of the grid), mean finishing position, and overtakes, overtaken, at-fault
    collisions, off-tracks and DNFs per race."""
    from rich.table import Table

    races = len(results)
    first = results[0].config
    table = Table(title=f"{races} races, {first.race_type} on {first.track}")
    columns = ("car", "wins", "win %", "wins from behind", "mean pos", "overtakes/race",
               "overtaken/race", "at-fault/race", "off-track/race", "DNF")  # fmt: skip
    for column in columns:
        table.add_column(column, justify="left" if column == "car" else "right")
    names = [c.name for c in first.cars]
    for name in sorted(names):
        cars = [r.car(name) for r in results]
        wins = [c for c in cars if c.finish_position == 1 and c.status == "finished"]
        behind = [c for c in wins if c.grid_offset is not None and c.grid_offset < 0]
        started_behind = sum(1 for c in cars if c.grid_offset is not None and c.grid_offset < 0)

        def per_race(field: str, cars: list = cars) -> str:
            return f"{sum(getattr(c, field) for c in cars) / races:.2f}"

        table.add_row(
            name,
            str(len(wins)),
            f"{100 * len(wins) / races:.0f}",
            f"{len(behind)}/{started_behind}",
            f"{sum(c.finish_position for c in cars) / races:.2f}",
            per_race("overtakes"),
            per_race("times_overtaken"),
            per_race("at_fault_collisions"),
            per_race("off_track_count"),
            str(sum(1 for c in cars if c.status == "dnf")),
        )
    return table
