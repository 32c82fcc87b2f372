"""Per-iteration training statistics, and ``RUN/metrics.csv``: the one place they are formatted."""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from agents.evaluate import EvalSummary

METRICS_COLUMNS = (
    "iteration",
    "elapsed_s",
    "steps",
    "episodes",
    "mean_reward",
    "mean_progress",
    "lap_completion",
    "eval_progress",
    "eval_laps",
    "eval_best_lap",
    "eval_total_time",
    "eval_off_track",
    "eval_crashes",
    "value_loss",
    "surrogate_loss",
    "entropy",
    "imitation_loss",
)


@dataclass(frozen=True)
class IterationStats:
    """What one training iteration did: its rollout's episodes, losses, evaluation.

    A PPO iteration has value, surrogate and entropy losses; an imitation iteration
    (``--teacher``) has the imitation loss alone (None: the loss is not the algorithm's).
    """

    iteration: int
    elapsed_s: float  # training time of the run so far, earlier sessions included
    steps: int  # learner steps in the iteration's training simtrace
    episodes: int  # episodes that ended during the rollout
    mean_reward: float  # per ended episode (0 when none ended)
    mean_progress: float  # % of a lap, per ended episode
    lap_completion: float  # share of ended episodes that completed their lap
    value_loss: float | None
    surrogate_loss: float | None
    entropy: float | None
    eval: EvalSummary | None = None  # the evaluation race after this iteration, if one ran
    imitation_loss: float | None = None

    @classmethod
    def of_iteration(
        cls,
        iteration: int,
        elapsed_s: float,
        steps: int,
        episodes: Sequence[dict[str, Any]],
        losses: dict[str, float],
        evaluation: EvalSummary | None,
    ) -> IterationStats:
        """Statistics from the rollout's ended episodes (``RacingVecEnv.pop_episodes``)."""
        n = max(1, len(episodes))
        return cls(
            iteration=iteration,
            elapsed_s=elapsed_s,
            steps=steps,
            episodes=len(episodes),
            mean_reward=sum(e["reward"] for e in episodes) / n,
            mean_progress=sum(e["progress"] for e in episodes) / n,
            lap_completion=sum(e["lap_complete"] for e in episodes) / n,
            value_loss=losses.get("value"),
            surrogate_loss=losses.get("surrogate"),
            entropy=losses.get("entropy"),
            eval=evaluation,
            imitation_loss=losses.get("imitation"),
        )


def metrics_row(stats: IterationStats) -> dict[str, Any]:
    """The CSV row of ``stats``: elapsed time to 0.01 s, an absent value as an empty cell."""
    row: dict[str, Any] = {
        "iteration": stats.iteration,
        "elapsed_s": round(stats.elapsed_s, 2),
        "steps": stats.steps,
        "episodes": stats.episodes,
        "mean_reward": stats.mean_reward,
        "mean_progress": stats.mean_progress,
        "lap_completion": stats.lap_completion,
        **_evaluation_cells(stats.eval),
        "value_loss": stats.value_loss,
        "surrogate_loss": stats.surrogate_loss,
        "entropy": stats.entropy,
        "imitation_loss": stats.imitation_loss,
    }
    return {key: "" if value is None else value for key, value in row.items()}


def _evaluation_cells(evaluation: EvalSummary | None) -> dict[str, Any]:
    if evaluation is None:
        return dict.fromkeys(c for c in METRICS_COLUMNS if c.startswith("eval_"))
    return {
        "eval_progress": evaluation.progress,
        "eval_laps": evaluation.laps,
        "eval_best_lap": evaluation.best_lap,
        "eval_total_time": evaluation.total_time,
        "eval_off_track": evaluation.off_track,
        "eval_crashes": evaluation.crashes,
    }


def append_metrics(path: str | Path, stats: IterationStats) -> None:
    """Append ``stats`` to ``RUN/metrics.csv`` (the header first when the file is new).

    A file begun by an older version keeps its own columns: a resumed run's rows stay
    under the right headers, and columns the file lacks are left out.
    """
    path = Path(path)
    columns = _header(path) or METRICS_COLUMNS
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, extrasaction="ignore")
        if handle.tell() == 0:
            writer.writeheader()
        writer.writerow(metrics_row(stats))


def _header(path: Path) -> tuple[str, ...] | None:
    """The column names of an existing, non-empty ``metrics.csv`` (else None)."""
    if not path.is_file():
        return None
    with path.open(newline="") as handle:
        header = next(csv.reader(handle), None)
    return tuple(header) if header else None
