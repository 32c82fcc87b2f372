"""Race quality per race type: train each for a fixed budget, then measure how it drives.

For every race type (``time_trial``, ``object_avoidance``, ``head_to_bot``,
``head_to_model``) it trains its recipe (``agents/recipes.py``) for ``--minutes`` on a
built-in track and prints one table: sensors, training minutes, samples/s, minutes to
the first clean evaluation (3 laps, every lap done, no off-track; from ``metrics.csv``),
the best evaluation lap and its ratio to the track's physical-limit lap (the racing line
of the simulated car, ``arena.pursuit.car_limits`` + ``tracks.raceline``, as
``slipstream tracks raceline`` reports it), and the off-tracks and collisions of the
evaluation of the packed model (the run's best evaluation, whose weights ``model.zip``
holds). ``head_to_model`` starts from the time-trial run (``clone``; trained on
``head_to_model``'s track when both run), trains against a pool of its own snapshots plus
the time-trial model, and then races the time-trial parent :data:`H2M_RACES` seeded
times: win rate (and the wins of the races it started in front and behind, and its mean
margin at the finish in those it started behind), overtakes and at-fault collisions per
race (the learner's, ``arena.racing_metrics``).

Run::

    .venv/bin/python benchmarks/race_quality.py --minutes 30 --out runs/race_quality
    .venv/bin/python benchmarks/race_quality.py --only time_trial,head_to_model --minutes 10

``head_to_model`` without ``time_trial`` in ``--only`` needs ``OUT/time_trial`` from an
earlier run.
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import get_args

from harness import ResultTable, add_record_option, write

from agents.evaluate import EvalSummary
from agents.privileged import CriticInput
from agents.recipes import RECIPES, Recipe
from agents.run import Run
from agents.selfplay import opponent_policy, read_policy_graph
from agents.settings import TrainSettings
from agents.train import Trainer, TrainResult
from arena.pursuit import car_limits
from arena.race import RaceResult, run_race
from tracks.catalog import get_track
from tracks.raceline import compute_racing_line

# The race types in training order (a parent before the recipe that clones it).
RACE_TYPES = ("time_trial", "object_avoidance", "head_to_bot", "head_to_model")
H2M_RACES = 20  # seeded races of the head-to-model learner against its parent
H2M_LAPS = 3


# --------------------------------------------------------------------------- training
def settings_of(recipe: Recipe, args: argparse.Namespace, opponent: Path | None) -> TrainSettings:
    """The run's settings: the recipe, with the command line's budget and choices."""
    given: dict[str, object] = {
        "critic": args.critic,
        "device": args.device,
        "minutes": args.minutes,
        "eval_every": args.eval_every,
    }
    if args.workers is not None:
        given["workers"] = args.workers
    children = [RECIPES[n] for n in args.only if RECIPES[n].parent == recipe.name]
    if children:  # a parent trains where its child races it
        given["track"] = children[0].options["track"]
    if opponent is not None:
        given["opponent"] = [opponent]
    return recipe.settings(given)


def train(name: str, args: argparse.Namespace) -> tuple[Path, TrainResult]:
    """Train recipe ``name`` into ``OUT/name``; returns the run folder and the result."""
    recipe = RECIPES[name]
    run_dir = args.out / name
    if run_dir.exists():
        raise SystemExit(f"{run_dir} exists: give another --out (runs are not appended to)")
    clone = opponent = None
    if recipe.parent is not None:
        clone = args.out / recipe.parent
        opponent = parent_zip(clone)
    settings = settings_of(recipe, args, opponent)
    print(f"training {name} for {args.minutes:g} min -> {run_dir}", flush=True)
    result = Trainer(settings, run_dir, recipe.hyperparameters_model(), clone=clone).run()
    if result.model_zip is None:
        raise SystemExit(f"{name}: no iteration finished, so no model was written")
    return run_dir, result


def parent_zip(parent_dir: Path) -> Path:
    """The parent run's packed model (it must have been trained first)."""
    path = parent_dir / "model" / "model.zip"
    if not path.is_file():
        raise SystemExit(f"head_to_model needs the time-trial run's {path}: train time_trial first")
    return path


# ------------------------------------------------------------------------- measuring
def read_metrics(run_dir: Path) -> list[dict[str, str]]:
    """``RUN/metrics.csv`` as rows of strings (empty cell: no value)."""
    with (run_dir / "metrics.csv").open(newline="") as handle:
        return list(csv.DictReader(handle))


def first_clean_minutes(rows: list[dict[str, str]], laps: int) -> float | None:
    """Minutes of training to the first evaluation with ``laps`` laps and no off-track."""
    for row in rows:
        if row["eval_laps"] and int(row["eval_laps"]) >= laps and row["eval_off_track"] == "0":
            return float(row["elapsed_s"]) / 60.0
    return None


def model_evaluation(name: str, result: TrainResult) -> EvalSummary:
    """The evaluation of the packed model's weights: the run's best (``checkpoints/best.pt``
    keeps the first evaluation of the highest score)."""
    evaluations = [s.eval for s in result.evaluations if s.eval is not None]
    if not evaluations:
        raise SystemExit(f"{name}: training ended before its first evaluation")
    return max(evaluations, key=lambda e: e.score)


def physical_limit_lap(track: str) -> float:
    """The track's physical-limit lap: the racing line at the simulated car's limits."""
    return compute_racing_line(get_track(track), car_limits()).lap_time


def races_against_parent(run_dir: Path, parent_dir: Path, races: int) -> dict[str, float]:
    """Race the learner's and the parent's greedy policies ``races`` seeded times.

    Both drive their packed ``model.zip`` graphs (what a league race would run). The
    learner drives ``car0`` on even seeds and ``car1`` on odd ones; the seed draws which
    grid slot each car takes. A win is finishing ahead (``RaceResult.finish_order``);
    ``ahead_wins`` and ``behind_wins`` (``"won/raced"``) split the races by which car
    started in front: laps are timed from each car's own slot, so a car that does not
    get past wins from behind only by ending the race closer to the leader than it
    started. ``behind_margin`` is the learner's mean total time minus the parent's in
    the races it started behind (negative: it won them on average).
    """
    learner = Run.load(run_dir)
    s, parent = learner.settings, Run.load(parent_dir).settings
    learner_graph = read_policy_graph(run_dir / "model" / "model.zip")
    parent_graph = read_policy_graph(parent_zip(parent_dir))
    wins = overtakes = at_fault = 0
    split = StartSplit()
    for seed in range(races):
        config = learner.evaluation_config(laps=H2M_LAPS, seed=seed, num_cars=2)
        learner_car, parent_car = ("car0", "car1") if seed % 2 == 0 else ("car1", "car0")
        policies = {
            learner_car: opponent_policy(learner_graph, s.discrete, name="learner"),
            parent_car: opponent_policy(parent_graph, parent.discrete, name="parent"),
        }
        race: RaceResult = run_race(config, policies, record_trace=False)
        learner = race.car(learner_car)
        wins += split.add(race, learner_car, parent_car)
        overtakes += learner.overtakes
        at_fault += learner.at_fault_collisions
    return {
        "win_rate": wins / races,
        "ahead_wins": split.cell(ahead=True),
        "behind_wins": split.cell(ahead=False),
        "behind_margin": split.behind_margin(),
        "overtakes": overtakes / races,
        "at_fault": at_fault / races,
    }


@dataclass
class StartSplit:
    """One car's two-car races against another, ``[wins, races]`` by who started in front,
    and by how much it finished ahead or behind in the races it started behind."""

    tallies: dict[bool, list[int]] = field(default_factory=lambda: {True: [0, 0], False: [0, 0]})
    behind_margins: list[float] = field(default_factory=list)

    def add(self, race: RaceResult, car: str, other: str) -> bool:
        """Count ``race``; whether ``car`` finished ahead of ``other``."""
        me, rival = race.car(car), race.car(other)
        won = race.finish_order.index(car) < race.finish_order.index(other)
        ahead = me.grid_offset > rival.grid_offset
        tally = self.tallies[ahead]
        tally[0] += won
        tally[1] += 1
        if not ahead and me.total_time is not None and rival.total_time is not None:
            self.behind_margins.append(me.total_time - rival.total_time)
        return won

    def cell(self, ahead: bool) -> str:
        """``"won/raced"`` of the races ``car`` started in front (``ahead``) or behind."""
        return "{}/{}".format(*self.tallies[ahead])

    def behind_margin(self) -> float | None:
        """Mean seconds ``car`` finished behind ``other`` (negative: ahead of it) in the
        races it started behind and both finished; None if there were none."""
        margins = self.behind_margins
        return sum(margins) / len(margins) if margins else None


def measure(name: str, run_dir: Path, result: TrainResult, args: argparse.Namespace) -> dict:
    """One table row's numbers for a trained run."""
    s = Run.load(run_dir).settings
    rows = read_metrics(run_dir)
    elapsed = float(rows[-1]["elapsed_s"])
    steps = sum(int(r["steps"]) for r in rows)
    model = model_evaluation(name, result)
    best = min((float(r["eval_best_lap"]) for r in rows if r["eval_best_lap"]), default=None)
    row = {
        "race_type": name,
        "sensors": "+".join(s.sensors),
        "minutes": elapsed / 60.0,
        "samples_s": steps / elapsed if elapsed > 0 else 0.0,
        "clean_min": first_clean_minutes(rows, s.eval_laps),
        "best_lap": best,
        "limit_ratio": best / physical_limit_lap(s.track) if best is not None else None,
        "off_track": model.off_track,
        "collisions": model.crashes,
    }
    parent = RECIPES[name].parent
    if parent is not None:
        print(f"racing {name} against {parent} ({args.races} races)", flush=True)
        row |= races_against_parent(run_dir, args.out / parent, args.races)
    return row


# ---------------------------------------------------------------------------- output
COLUMNS = (
    ("race type", "race_type", "{}"),
    ("sensors", "sensors", "{}"),
    ("minutes", "minutes", "{:.1f}"),
    ("samples/s", "samples_s", "{:.0f}"),
    ("min to clean 3 laps", "clean_min", "{:.1f}"),
    ("best lap (s)", "best_lap", "{:.2f}"),
    ("best / limit", "limit_ratio", "{:.2f}"),
    ("model eval off-tracks", "off_track", "{}"),
    ("model eval collisions", "collisions", "{}"),
    ("win rate vs parent", "win_rate", "{:.0%}"),
    ("wins from ahead", "ahead_wins", "{}"),
    ("wins from behind", "behind_wins", "{}"),
    ("margin from behind (s)", "behind_margin", "{:+.2f}"),
    ("overtakes / race", "overtakes", "{:.2f}"),
    ("at-fault collisions / race", "at_fault", "{:.2f}"),
)


def cells(row: dict) -> list[str]:
    """A row's formatted cells ("-": no value)."""
    return [fmt.format(row[key]) if row.get(key) is not None else "-" for _, key, fmt in COLUMNS]


def title(args: argparse.Namespace) -> str:
    """The table's title."""
    tracks = sorted({settings_of(RECIPES[n], args, None).track for n in args.only})
    limits = ", ".join(f"{t} {physical_limit_lap(t):.2f} s" for t in tracks)
    return (
        f"race quality after {args.minutes:g} min per race type, {args.critic} critic "
        f"(physical-limit lap: {limits})"
    )


def parse_args() -> argparse.Namespace:
    """The command line."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=30.0, help="training budget per type")
    parser.add_argument(
        "--only",
        default=",".join(RACE_TYPES),
        help=f"comma-separated race types (default: all: {','.join(RACE_TYPES)})",
    )
    parser.add_argument("--out", type=Path, help="keep the runs here (default: a temp dir)")
    parser.add_argument("--workers", type=int, help="worker processes (default: the recipe's)")
    parser.add_argument("--eval-every", type=int, default=5, help="evaluate every N iterations")
    parser.add_argument("--races", type=int, default=H2M_RACES, help="head_to_model races")
    parser.add_argument("--device", default="cpu", help="where PPO trains: cpu, cuda or cuda:N")
    parser.add_argument(
        "--critic",
        choices=get_args(CriticInput),
        default=TrainSettings.model_fields["critic"].default,
        help="what PPO's critic reads (default: train's)",
    )
    add_record_option(parser)
    args = parser.parse_args()
    args.only = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in args.only if n not in RACE_TYPES]
    if unknown:
        parser.error(f"unknown race type(s) {unknown}; choose from {', '.join(RACE_TYPES)}")
    return args


def main() -> None:
    """Train the selected race types in recipe order, measure them, write the table."""
    args = parse_args()
    with tempfile.TemporaryDirectory(prefix="race_quality-") as temp:
        keep = args.out is not None
        args.out = args.out or Path(temp)
        args.out.mkdir(parents=True, exist_ok=True)
        rows = []
        for name in (n for n in RACE_TYPES if n in args.only):  # parents before children
            run_dir, result = train(name, args)
            rows.append(measure(name, run_dir, result, args))
        align = "ll" + "r" * (len(COLUMNS) - 2)
        table = ResultTable(title(args), [c for c, _, _ in COLUMNS], align)
        for row in rows:
            table.add_row(*cells(row))
        write(table, args.record)
        if keep:
            print(f"runs kept in {args.out}")


if __name__ == "__main__":
    main()
