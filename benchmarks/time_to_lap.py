"""Time to a clean lap: train from scratch until an evaluation drives 3 laps, 0 off-tracks.

The ``first_laps`` recipe (``agents/recipes.py``): track ``beginner_loop``,
follow-centre-line reward, 3 x 3 discrete actions at 1 m/s, cheap PPO updates. For
each sensor case (``camera``, ``camera+lidar`` — DeepRacer's lidar car, whose lidar is
added to a camera — or ``lidar`` alone, which is blind on an empty track) it reports the
wall-clock minutes to the first evaluation (race mode, 3 laps, deterministic policy) with
3 laps and no off-track, the best evaluation lap, and two references: the track's
physical-limit lap (``tracks.raceline``) and the pure-pursuit baseline driving the same
action space.

``--mode sync,overlapped`` trains each case both ways (collect then update, train's
default on a CPU, or the update during the next rollout).

Run: ``.venv/bin/python benchmarks/time_to_lap.py --case camera+lidar --max-minutes 15``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import get_args

from harness import ResultTable, add_record_option, write

import arena
from agents.action_spaces import parse_action_space_spec
from agents.privileged import CriticInput
from agents.recipes import RECIPES
from agents.settings import TrainSettings
from agents.train import Trainer
from arena.pursuit import PurePursuitPolicy
from arena.race import run_race
from tracks.catalog import get_track
from tracks.raceline import compute_racing_line

CASES = ("camera", "camera+lidar", "lidar")
DEFAULT_CASES = ("camera", "camera+lidar")
# The fast-start recipe: PPO from scratch with cheap updates (agents/recipes.py).
RECIPE = RECIPES["first_laps"]
TRACK = RECIPE.options["track"]
SPACE = RECIPE.options["action_space"]


def references() -> tuple[float, float | None]:
    """Physical-limit lap time and the pure-pursuit baseline's best lap (3-lap race)."""
    track = get_track(TRACK)
    limit = compute_racing_line(track).lap_time
    space = parse_action_space_spec(SPACE)
    config = arena.make_config(track=TRACK, action_space=space, laps=3, seed=0)
    result = run_race(config, {"car0": PurePursuitPolicy(track, space)})
    return limit, result.car("car0").best_lap


def train_case(
    case: str,
    max_minutes: float,
    out: Path,
    workers: int,
    critic: CriticInput,
    mode: str,
    seed: int = 0,
) -> dict:
    """Train one sensor case until a clean 3-lap evaluation or the time cap."""
    given = {
        "sync": mode == "sync",
        "seed": seed,
        "sensors": case.replace("+", ","),
        "minutes": max_minutes,
        "workers": workers,
        "races": max(1, workers),  # one race a worker: the recipe's 512 steps split evenly
        "critic": critic,
    }
    settings = RECIPE.settings(given, stop_on_clean_eval=True)
    started = time.monotonic()
    run_dir = out / f"{case.replace('+', '_')}_{mode}_seed{seed}"
    result = Trainer(settings, run_dir, RECIPE.hyperparameters_model()).run()
    evaluations = {s.elapsed_s: s.eval for s in result.evaluations if s.eval is not None}
    best = max(evaluations.values(), key=lambda e: e.progress, default=None)
    clean = evaluations.get(result.first_clean_eval_s)
    return {
        "clean_best_lap": clean.best_lap if clean else None,
        "clean_total": clean.total_time if clean else None,
        "case": f"{case} ({mode}, seed {seed})",
        "minutes": result.first_clean_eval_s / 60.0 if result.first_clean_eval_s else None,
        "wall_minutes": (time.monotonic() - started) / 60.0,
        "iterations": result.iterations,
        "best_lap": result.best_lap,
        "best_eval_progress": best.progress if best else 0.0,
    }


def main() -> None:
    """Parse arguments, run the cases, print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument(
        "--case",
        action="append",
        choices=CASES,
        help=f"sensor case, repeatable (default: {' and '.join(DEFAULT_CASES)})",
    )
    parser.add_argument("--max-minutes", type=float, default=15.0)
    parser.add_argument("--workers", type=int, default=0)
    parser.add_argument(
        "--mode", default="sync", help="comma-separated: sync,overlapped (default: train's)"
    )
    parser.add_argument("--seeds", default="0", help="comma-separated training seeds")
    parser.add_argument("--out", type=Path, default=Path("runs/time_to_lap"))
    parser.add_argument(
        "--critic",
        choices=get_args(CriticInput),
        default=TrainSettings.model_fields["critic"].default,
        help="what PPO's critic reads (default: train's)",
    )
    add_record_option(parser)
    args = parser.parse_args()
    cases = args.case or list(DEFAULT_CASES)
    limit, pursuit = references()
    rows = [
        train_case(c, args.max_minutes, args.out, args.workers, args.critic, mode, int(seed))
        for c in cases
        for mode in args.mode.split(",")
        for seed in args.seeds.split(",")
    ]
    columns = ("policy", "minutes to clean 3 laps", "iterations", "clean run: best lap / total")
    table = ResultTable(
        f"time to 3 clean laps on {TRACK} ({SPACE}, follow_center_line, {args.critic} critic)",
        (*columns, "best eval lap (s)", "best eval completion"),
    )
    for r in rows:
        reached = f"{r['minutes']:.1f}" if r["minutes"] else f"not in {args.max_minutes:g}"
        lap = f"{r['best_lap']:.2f}" if r["best_lap"] else "-"
        clean = "-"
        if r["clean_best_lap"] is not None:
            clean = f"{r['clean_best_lap']:.2f} / {r['clean_total']:.2f}"
        row = (r["case"], reached, str(r["iterations"]), clean, lap)
        table.add_row(*row, f"{r['best_eval_progress']:.0f}%")
    table.add_row(
        "pure pursuit (baseline)", "-", "-", "-", f"{pursuit:.2f}" if pursuit else "-", ""
    )
    table.add_row("physical limit (raceline)", "-", "-", "-", f"{limit:.2f}", "")
    write(table, args.record)


if __name__ == "__main__":
    main()
