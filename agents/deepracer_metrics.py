"""DeepRacer's metrics files and training parameters, as deepracer-for-cloud writes them.

- ``RUN/metrics/TrainingMetrics.json``: ``{"metrics": [...], "version", "best_model_metric"}``
  with one entry per training episode (phase ``training``) and per lap of each periodic
  evaluation (phase ``evaluation``), the simapp's fields (``reward_score``, ``metric_time``,
  ``start_time``, ``elapsed_time_in_milliseconds``, ``episode``, ``trial``, ``phase``,
  ``completion_percentage``, ``episode_status``); read by deepracer-utils'
  ``deepracer.logs.metrics.TrainingMetrics``.
- ``RUN/metrics/EvaluationMetrics-<unix seconds>.json``: ``{"metrics": [...]}``, one entry per
  lap of a ``slipstream evaluate`` race.
- ``RUN/training_params.yaml``: ``WORLD_NAME`` (the track's Slipstream name) and friends.

Times are simulated seconds, written in milliseconds as the simapp does. Files are written
whole to a temporary file and moved into place, so a reader never sees half a file.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml

METRICS_VERSION = "2"
TRAINING_METRICS = Path("metrics") / "TrainingMetrics.json"

# The simapp's ``EpisodeStatus.get_episode_status_label``.
STATUS_LABELS = {
    "crashed": "Crashed",
    "off_track": "Off track",
    "in_progress": "In progress",
    "immobilized": "Immobilized",
    "time_up": "Time up",
    "lap_complete": "Lap complete",
    "reversed": "Reversed",
    "pause": "Pause",
    "park": "Park",
    "prepare": "Prepare",
}
_RESETS = ("crashed", "immobilized", "off_track", "reversed")


def _ms(seconds: float) -> int:
    return int(round(seconds * 1000.0))


def write_text_atomic(path: Path, text: str) -> Path:
    """Write ``text`` to ``path`` through a temporary file and ``os.replace``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def lap_metrics(lap_rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per lap (one entry per episode of a car's :func:`arena.simtrace.lap_rows`): the
    simapp's ``EvalMetrics`` fields plus ``reward`` (the lap's summed reward)."""
    laps: dict[int, list[dict[str, Any]]] = {}
    for row in lap_rows:
        laps.setdefault(row["episode"], []).append(row)
    out, start, trials = [], 0.0, 0
    for rows in laps.values():
        last = rows[-1]
        counts = {s: sum(r["episode_status"] == s for r in rows) for s in _RESETS}
        trials += last["episode_status"] == "lap_complete"
        out.append(
            {
                "completion_percentage": int(last["progress"]),
                "metric_time": _ms(last["tstamp"]),
                "start_time": _ms(start),
                "elapsed_time_in_milliseconds": _ms(last["tstamp"] - start),
                "episode_status": STATUS_LABELS.get(last["episode_status"], last["episode_status"]),
                "crash_count": counts["crashed"],
                "immobilized_count": counts["immobilized"],
                "off_track_count": counts["off_track"],
                "reversed_count": counts["reversed"],
                "reset_count": sum(counts.values()),
                "trial": trials,
                "reward": float(sum(r["reward"] for r in rows)),
            }
        )
        start = float(last["tstamp"])
    return out


def write_evaluation_metrics(
    run_dir: str | Path, lap_rows: Iterable[dict[str, Any]], stamp: float | None = None
) -> Path:
    """``RUN/metrics/EvaluationMetrics-<unix seconds>.json`` of a car's evaluation (its
    :func:`arena.simtrace.lap_rows`); a second later if that name is taken."""
    laps = [{k: v for k, v in lap.items() if k != "reward"} for lap in lap_metrics(lap_rows)]
    second = int(time.time() if stamp is None else stamp)
    folder = Path(run_dir) / "metrics"
    while (folder / f"EvaluationMetrics-{second}.json").exists():
        second += 1
    path = folder / f"EvaluationMetrics-{second}.json"
    return write_text_atomic(path, json.dumps({"metrics": laps}))


class TrainingMetricsLog:
    """``RUN/metrics/TrainingMetrics.json`` kept in memory and rewritten by :meth:`write`.

    ``resume`` continues an existing file (episode numbers go on); otherwise it starts empty.
    """

    def __init__(self, run_dir: str | Path, resume: bool = False) -> None:
        self.path = Path(run_dir) / TRAINING_METRICS
        self.metrics: list[dict[str, Any]] = []
        if resume and self.path.exists():
            self.metrics = list(json.loads(self.path.read_text())["metrics"])
        training = [m for m in self.metrics if m["phase"] == "training"]
        self.episode = max((m["episode"] for m in training), default=0)
        self.trial = training[-1]["trial"] if training else 0

    def add_training(self, episodes: Iterable[dict[str, Any]]) -> None:
        """One iteration's finished episodes (:meth:`agents.vecenv.RacingVecEnv.pop_episodes`)."""
        self.trial = 0
        for e in episodes:
            self.episode += 1
            self.trial += 1
            start, end = float(e.get("start_time", 0.0)), float(e.get("end_time", 0.0))
            label = STATUS_LABELS.get(e["status"], e["status"])
            self.metrics.append(
                self._entry(e["reward"], start, end, "training", e["progress"], label)
            )

    def add_evaluation(self, lap_rows: Iterable[dict[str, Any]]) -> None:
        """Each lap of an evaluation (a car's :func:`arena.simtrace.lap_rows`), as the simapp's
        phase ``evaluation`` entries (the episode and trial numbers of the last training
        episode)."""
        for lap in lap_metrics(lap_rows):
            start, end = lap["start_time"] / 1000.0, lap["metric_time"] / 1000.0
            progress, label = lap["completion_percentage"], lap["episode_status"]
            self.metrics.append(
                self._entry(lap["reward"], start, end, "evaluation", progress, label)
            )

    def _entry(
        self, reward: float, start: float, end: float, phase: str, progress: float, label: str
    ) -> dict[str, Any]:
        return {
            "reward_score": int(round(reward)),
            "metric_time": _ms(end),
            "start_time": _ms(start),
            "elapsed_time_in_milliseconds": _ms(end - start),
            "episode": self.episode,
            "trial": self.trial,
            "phase": phase,
            "completion_percentage": int(progress),
            "episode_status": label,
        }

    def write(self) -> Path:
        """Write the whole file (atomically)."""
        body = {
            "metrics": self.metrics,
            "version": METRICS_VERSION,
            "best_model_metric": "progress",
        }
        return write_text_atomic(self.path, json.dumps(body))


def write_training_params(
    run_dir: str | Path, track: str, race_type: str, reversed_direction: bool = False
) -> Path:
    """``RUN/training_params.yaml`` as deepracer-for-cloud uploads it (a subset of its keys):
    ``WORLD_NAME`` is the track's Slipstream name."""
    params = {
        "JOB_TYPE": "TRAINING",
        "WORLD_NAME": track,
        "RACE_TYPE": race_type.upper(),
        "REVERSE_DIR": str(reversed_direction).lower(),
    }
    text = yaml.safe_dump(params, explicit_start=True, default_flow_style=False)
    return write_text_atomic(Path(run_dir) / "training_params.yaml", text)
