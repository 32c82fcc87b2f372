"""Re-score a logged run with an edited reward function (``POST /api/rescore``).

The API process reads the log (a race's stored trace, or the simtrace CSVs of a training
run's zip) into plain columns, bounded in steps and bytes, and never runs the racer's
code: the reward functions run in a sandboxed child, ``python -m agents.rescore WORKDIR``
(:mod:`agents.rescore`), under a short CPU limit, as the training pre-check runs
(:func:`league.training.spec.check_reward`). The answer's shape is
:class:`league.schemas.RescoreOut`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import select
import shutil
import time
import uuid
import zipfile
from collections.abc import Iterator
from typing import Any

from agents.rescore import ORIGINAL_FILE, STEPS_FILE
from agents.train_job import REWARD_FILE
from league.settings import Settings
from league.training.launch import limits_of, start_child, stop_child
from league.training.spec import last_json
from tracks.catalog import builtin_names

MAX_STEPS = 20_000
"""The most control steps one re-score reads (and the child scores)."""
RESCORE_CPU_SECONDS = 20
"""CPU seconds the child may use: loading, rebuilding params and both reward functions."""
RESCORE_WALL_SECONDS = 45.0
MAX_OUTPUT = 8 * 1024 * 1024
"""The tail of the child's output kept (its answer is its last line)."""
MAX_SCAN_BYTES = 64 * 1024 * 1024
"""Uncompressed simtrace bytes one re-score may read from a run zip."""
MAX_SETTINGS_BYTES = 64 * 1024
COLUMNS = (
    "x", "y", "yaw", "steer", "throttle", "progress", "status", "all_wheels_on_track", "t",
)  # fmt: skip
"""The logged fields the child rebuilds params from (``yaw`` in radians), besides
``steps`` (per episode, from 1) and ``lap`` (from 0)."""
EVALUATION = re.compile(r"^evaluation-[^/]+/evaluation-simtrace/0-iteration\.csv$")
TRAINING = re.compile(r"^0/training-simtrace/(\d+)-iteration\.csv$")
SETTINGS_MEMBER = "training_settings.json"
FLAGS = ("status", "all_wheels_on_track")


class RescoreRefused(ValueError):
    """The run cannot be re-scored, or the reward function failed on it (422)."""


class Log:
    """A car's logged steps as columns, the track they ran on and the logged rewards."""

    def __init__(self, track: str, direction: str | None, race_type: str, car: str) -> None:
        self.track, self.direction, self.race_type, self.car = track, direction, race_type, car
        self.columns: dict[str, list[Any]] = {c: [] for c in (*COLUMNS, "steps", "lap")}
        self.logged: list[float] = []

    def __len__(self) -> int:
        return len(self.columns["x"])

    def add(self, step: dict[str, Any], logged: float | None = None) -> None:
        """Append one step (a value per :data:`COLUMNS`, ``steps`` and ``lap``)."""
        if len(self) >= MAX_STEPS:
            raise RescoreRefused(f"the run has over {MAX_STEPS} steps: re-scoring stops there")
        for name, values in self.columns.items():
            values.append(step[name])
        if logged is not None:
            self.logged.append(logged)

    def document(self) -> dict[str, Any]:
        """The child's ``steps.json``."""
        return {
            "track": self.track,
            "direction": self.direction,
            "race_type": self.race_type,
            "car": self.car,
            "columns": self.columns,
        }


def _number(value: Any, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise RescoreRefused(f"the log holds {str(value)[:40]!r} for {what}: not a number")
    return number


def _flag(value: Any) -> bool:
    return value is True or str(value).strip().lower() in ("true", "1")


def race_log(config: dict[str, Any], trace: Any, car: str) -> Log:
    """The steps of ``car`` in a stored race (its ``config`` and trace file)."""
    cars = trace.get("trace") if isinstance(trace, dict) else None
    columns = cars.get(car) if isinstance(cars, dict) else None
    if not isinstance(columns, dict):
        raise RescoreRefused(f"car {car!r} has no steps in this race's trace")
    race_type = str(config.get("race_type") or "time_trial")
    log = Log(str(config.get("track")), config.get("direction"), race_type, car)
    length = len(columns.get("x") or [])
    if any(not isinstance(columns.get(c), list) or len(columns[c]) != length for c in COLUMNS):
        raise RescoreRefused(f"the trace of car {car!r} lacks columns this re-score needs")
    lap = 0
    for i in range(length):
        step = {c: _number(columns[c][i], c) for c in COLUMNS if c not in FLAGS}
        status = str(columns["status"][i])
        log.add(
            {
                **step,
                "status": status,
                "all_wheels_on_track": _flag(columns["all_wheels_on_track"][i]),
                "steps": i + 1,
                "lap": lap,
            }
        )
        lap += status == "lap_complete"
    return log


def _csv_rows(archive: zipfile.ZipFile, name: str, budget: list[int]) -> Iterator[dict[str, str]]:
    """The rows of a simtrace member, charging its size to ``budget`` (bytes left)."""
    size = archive.getinfo(name).file_size
    if size > budget[0]:
        raise RescoreRefused(
            f"the run's simtrace files are over {MAX_SCAN_BYTES // (1024 * 1024)} MiB: "
            "too large to re-score"
        )
    budget[0] -= size
    with archive.open(name) as raw:
        text = io.TextIOWrapper(raw, encoding="utf-8", errors="replace", newline="")
        try:
            yield from csv.DictReader(text)
        except csv.Error as exc:
            raise RescoreRefused(f"{name}: not a readable simtrace: {exc}") from None


def _simtrace_step(row: dict[str, str], lap: int) -> tuple[dict[str, Any], float]:
    step = {
        "x": _number(row.get("X"), "X"),
        "y": _number(row.get("Y"), "Y"),
        "yaw": math.radians(_number(row.get("yaw"), "yaw")),
        "steer": _number(row.get("steer"), "steer"),
        "throttle": _number(row.get("throttle"), "throttle"),
        "progress": _number(row.get("progress"), "progress"),
        "status": str(row.get("episode_status") or "")[:32],
        "all_wheels_on_track": _flag(row.get("all_wheels_on_track")),
        "t": _number(row.get("tstamp"), "tstamp"),
        "steps": int(_number(row.get("steps"), "steps")),
        "lap": lap,
    }
    return step, _number(row.get("reward"), "reward")


def _run_settings(archive: zipfile.ZipFile, trains_on: dict[str, Any]) -> dict[str, Any]:
    """Track, direction and race type of a run: its ``training_settings.json``, else what
    the job's spec trains on (:func:`league.training.spec.trains_on`)."""
    found: dict[str, Any] = {}
    try:
        info = archive.getinfo(SETTINGS_MEMBER)
        if info.file_size <= MAX_SETTINGS_BYTES:
            found = json.loads(archive.read(info))
    except (KeyError, ValueError):
        pass
    if not isinstance(found, dict):
        found = {}
    return {key: found.get(key, trains_on[key]) for key in ("track", "direction", "race_type")}


def run_log(data: bytes, trains_on: dict[str, Any], episode: int | None) -> Log:
    """The steps of a training run's zip: its last evaluation (``episode`` None; lap ``k``
    is simtrace episode ``k``) or training episode ``episode``; ``logged`` holds the
    simtrace's reward column."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
    except zipfile.BadZipFile:
        raise RescoreRefused("the job's stored run is not a readable zip") from None
    with archive:
        found = _run_settings(archive, trains_on)
        log = Log(str(found["track"]), found["direction"], str(found["race_type"]), "agent")
        names = archive.namelist()
        budget = [MAX_SCAN_BYTES]
        if episode is None:
            evaluations = sorted(n for n in names if EVALUATION.match(n))
            if not evaluations:
                raise RescoreRefused("the job's run has no evaluation simtrace yet")
            for row in _csv_rows(archive, evaluations[-1], budget):
                log.add(*_simtrace_step(row, int(_number(row.get("episode"), "episode"))))
            return log
        iterations = sorted(
            (int(m.group(1)), n) for n in names if (m := TRAINING.match(n)) is not None
        )
        for _, name in iterations:
            for row in _csv_rows(archive, name, budget):
                if row.get("episode") == str(episode):
                    lap = sum(s == "lap_complete" for s in log.columns["status"])
                    log.add(*_simtrace_step(row, lap))
            if len(log):
                return log  # an episode is written by one iteration
        raise RescoreRefused(f"the job's training simtrace has no episode {episode}")


def _read_tail(child: Any, deadline: float) -> bytes | None:
    """The last :data:`MAX_OUTPUT` bytes the child prints until it ends; None past
    ``deadline`` (monotonic)."""
    fd = child.stdout.fileno()
    out = bytearray()
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            return None
        ready, _, _ = select.select([fd], [], [], left)
        if not ready:
            continue
        chunk = os.read(fd, 1 << 16)
        if not chunk:
            return bytes(out)
        out += chunk
        if len(out) > 2 * MAX_OUTPUT:
            del out[:-MAX_OUTPUT]


def score_in_sandbox(
    settings: Settings, log: Log, reward_source: str, original_source: str | None
) -> tuple[list[float], list[float] | None]:
    """The new rewards of every step of ``log`` and (given its source) the model's own,
    scored by the sandboxed child (blocking: call it in a thread). Raises
    :class:`RescoreRefused` naming the line and step, or the limit the reward ran into;
    :class:`~league.training.sandbox.SandboxUnavailable` when the host cannot sandbox."""
    workdir = settings.data_dir / "training" / "rescores" / uuid.uuid4().hex
    try:
        workdir.mkdir(parents=True)
        (workdir / STEPS_FILE).write_text(json.dumps(log.document()))
        (workdir / REWARD_FILE).write_text(reward_source, encoding="utf-8")
        if original_source is not None:
            (workdir / ORIGINAL_FILE).write_text(original_source, encoding="utf-8")
        limits = limits_of(settings, RESCORE_CPU_SECONDS)
        child = start_child([], workdir, settings, limits, module="agents.rescore")
        try:
            out = _read_tail(child, time.monotonic() + RESCORE_WALL_SECONDS)
        finally:
            stop_child(child)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    if out is None:
        raise RescoreRefused(
            f"reward.py: re-scoring took over {RESCORE_WALL_SECONDS:g} s: does "
            "reward_function loop forever or wait?"
        )
    return _answer_of(out, len(log), child.returncode)


def _answer_of(out: bytes, steps: int, code: int | None) -> tuple[list[float], list[float] | None]:
    verdict = last_json(out)
    if "error" in verdict:
        raise RescoreRefused(str(verdict["error"]))
    reward, original = verdict.get("reward"), verdict.get("original")
    if not _floats(reward, steps):
        tail = out[-400:].decode("utf-8", "replace").strip()
        raise RescoreRefused(
            f"reward.py: re-scoring was stopped without an answer (exit code {code}): the "
            f"reward function ran past its {RESCORE_CPU_SECONDS} s of CPU time or its memory "
            f"(does it loop forever?). Output: {tail}"
        )
    return reward, original if _floats(original, steps) else None


def _floats(values: Any, steps: int) -> bool:
    return (
        isinstance(values, list)
        and len(values) == steps
        and all(isinstance(v, int | float) and math.isfinite(v) for v in values)
    )


def answer(log: Log, reward: list[float], original: list[float] | None) -> dict[str, Any]:
    """The :class:`league.schemas.RescoreOut` fields of a scored log."""
    cols = log.columns
    laps: dict[int, dict[str, Any]] = {}
    for i, lap in enumerate(cols["lap"]):
        row = laps.setdefault(lap, {"lap": lap, "reward": 0.0, "original": None})
        row["reward"] += reward[i]
        if original is not None:
            row["original"] = (row["original"] or 0.0) + original[i]
    return {
        "steps": len(log),
        "x": cols["x"],
        "y": cols["y"],
        "progress": cols["progress"],
        "lap": cols["lap"],
        "reward": reward,
        "original": original,
        "laps": list(laps.values()),
        "total": math.fsum(reward),
        "original_total": None if original is None else math.fsum(original),
    }


def check_track(log: Log) -> None:
    """Refuse a log whose track is not built in (the child reads only those)."""
    if log.track not in builtin_names():
        raise RescoreRefused(f"track {log.track!r} is not a built-in track: cannot re-score")
