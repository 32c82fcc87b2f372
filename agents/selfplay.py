"""Opponents for head-to-model training: prioritised fictitious self-play (PFSP).

The pool holds frozen snapshots of the learner (exported to ONNX every few iterations),
any ONNX policies the user adds, and paced racers: the pure-pursuit driver on the racing
line at a share of the learner's own pace (its laps in its last evaluation), so that it
meets slower cars to pass and equal ones to race. Each race gets an opponent sampled
with PFSP's "hard" weighting: an opponent the learner beats with rate ``p`` is drawn with
weight ``(1 - p) ** 2`` (plus a small floor so no opponent is forgotten), so training
time goes to the opponents the learner still loses to. Win rates are exponential moving averages
of episode outcomes (see :class:`agents.vecenv.EnvGroup` for what counts as a win).
Bots (head-to-bot) and boxes (object avoidance) come from the race config instead.
"""

from __future__ import annotations

import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from arena.actions import ActionSpace
    from arena.config import RaceConfig
    from arena.policy import Policy
    from submissions.runner import OnnxRunner
    from tracks.track import Track

WEIGHT_FLOOR = 0.05
UNPLAYED_WIN_RATE = 0.5


@dataclass(frozen=True)
class Opponent:
    """What drives a race's non-learner cars: a frozen ONNX policy (``graph``), or the
    pure-pursuit driver at ``pace``, a share of its speed profile
    (:class:`arena.pursuit.PurePursuitPolicy`)."""

    name: str
    graph: bytes = b""
    pace: float | None = None


def pfsp_weights(win_rates: list[float] | np.ndarray) -> np.ndarray:
    """PFSP "hard" sampling probabilities ``(1 - p)^2 + floor``, normalised."""
    p = np.clip(np.asarray(win_rates, dtype=float), 0.0, 1.0)
    weights = (1.0 - p) ** 2 + WEIGHT_FLOOR
    return weights / weights.sum()


def read_policy_graph(path: str | Path) -> bytes:
    """The ONNX bytes of a ``.onnx`` file or of a submission zip's ``policy.onnx``."""
    path = Path(path)
    if path.suffix == ".zip":
        with zipfile.ZipFile(path) as archive:
            return archive.read("policy.onnx")
    return path.read_bytes()


def opponent_policy(graph: bytes, discrete: bool, name: str = "opponent") -> OnnxRunner:
    """A frozen opponent (ONNX bytes, submission convention) that drives one car greedily.

    Non-finite outputs are zeroed (``"zero"``): a diverged snapshot keeps driving, badly,
    instead of stopping the training run.
    """
    from submissions.runner import OnnxRunner  # onnxruntime loads only when opponents race

    return OnnxRunner.from_graph(graph, discrete, non_finite="zero", name=name)


def opponent_driver(opponent: Opponent, track: Track, action_space: ActionSpace) -> Policy:
    """The policy that drives one of a race's non-learner cars as ``opponent`` says."""
    from arena.actions import DiscreteActionSpace
    from arena.pursuit import PurePursuitPolicy

    if opponent.pace is not None:
        return PurePursuitPolicy(track, action_space, pace=opponent.pace)
    discrete = isinstance(action_space, DiscreteActionSpace)
    return opponent_policy(opponent.graph, discrete, opponent.name)


def pursuit_lap_s(config: RaceConfig) -> float | None:
    """The pure-pursuit driver's mean lap at full pace in the time trial ``config``, from
    its standing start (None if it does not finish): what paced racers are scaled by."""
    from agents.evaluate import evaluate_policy
    from arena.config import resolve_track
    from arena.pursuit import PurePursuitPolicy

    car = config.cars[0]
    driver = PurePursuitPolicy(resolve_track(config)[0], car.action_space)
    result = evaluate_policy(config, driver).car(car.name)
    return result.total_time / result.laps if result.total_time and result.laps else None


@dataclass
class _Entry:
    graph: bytes
    win_rate: float = UNPLAYED_WIN_RATE
    games: int = 0
    snapshot: bool = True
    share: float | None = None  # a paced racer: its share of the learner's pace


class OpponentPool:
    """Frozen snapshots, user policies and paced racers, sampled by PFSP.

    Paced racers are drawn only once the learner's pace is known (:meth:`set_pace`).

    Args:
        max_snapshots: snapshots kept (oldest dropped first); user policies always stay.
        ema: weight of a new outcome in the win-rate average.
        seed: sampling seed.
    """

    def __init__(self, max_snapshots: int = 8, ema: float = 0.05, seed: int = 0) -> None:
        self.max_snapshots = max_snapshots
        self.ema = ema
        self.rng = np.random.default_rng(seed)
        self.entries: OrderedDict[str, _Entry] = OrderedDict()
        self.pace: float | None = None  # the learner's speed over the pursuit driver's

    def __len__(self) -> int:
        return len(self.entries)

    def add_snapshot(self, name: str, graph: bytes) -> None:
        """Add a frozen copy of the learner (ONNX bytes)."""
        self.entries[name] = _Entry(graph)
        snapshots = [k for k, e in self.entries.items() if e.snapshot]
        for old in snapshots[: max(0, len(snapshots) - self.max_snapshots)]:
            del self.entries[old]

    def add_policy(self, path: str | Path) -> str:
        """Add a user policy (``.onnx`` or submission ``.zip``); returns its pool name:
        ``user:`` and the file's name, numbered from ``#2`` when another has the name (two
        runs' ``model.zip``)."""
        base = name = f"user:{Path(path).name}"
        count = 1
        while name in self.entries:
            count += 1
            name = f"{base}#{count}"
        self.entries[name] = _Entry(read_policy_graph(path), snapshot=False)
        return name

    def add_paced(self, share: float) -> str:
        """Add the pursuit driver at ``share`` (0-1] of the learner's pace; returns its name."""
        name = f"pursuit:{share:.0%}"
        self.entries[name] = _Entry(b"", snapshot=False, share=share)
        return name

    def set_pace(self, learner_lap_s: float, pursuit_lap_s: float) -> None:
        """The learner's mean lap against the pursuit driver's own at full pace: paced
        racers then drive at their share of the learner's speed (at most the driver's)."""
        if learner_lap_s <= 0 or pursuit_lap_s <= 0:
            raise ValueError("lap times must be positive")
        self.pace = pursuit_lap_s / learner_lap_s

    def record(self, name: str, win: bool) -> None:
        """Fold one episode's outcome against ``name`` into its win rate."""
        entry = self.entries.get(name)
        if entry is not None:
            entry.games += 1
            entry.win_rate += self.ema * (float(win) - entry.win_rate)

    def sample(self, count: int) -> list[Opponent]:
        """``count`` opponents drawn (with replacement) by PFSP weights."""
        probabilities = self.probabilities()
        if not probabilities:
            raise ValueError("the opponent pool has no opponent to draw")
        names = list(probabilities)
        picks = self.rng.choice(len(names), size=count, p=list(probabilities.values()))
        return [self._opponent(names[i]) for i in picks]

    def _opponent(self, name: str) -> Opponent:
        entry = self.entries[name]
        if entry.share is None:
            return Opponent(name, entry.graph)
        assert self.pace is not None  # drawn only once the pace is known
        return Opponent(name, pace=min(1.0, entry.share * self.pace))

    def probabilities(self) -> dict[str, float]:
        """Each drawable opponent's chance of being drawn (:func:`pfsp_weights` of the win
        rates); paced racers are left out while the learner's pace is unknown."""
        drawable = {
            name: e for name, e in self.entries.items() if e.share is None or self.pace is not None
        }
        if not drawable:
            return {}
        weights = pfsp_weights([e.win_rate for e in drawable.values()])
        return dict(zip(drawable, weights.tolist(), strict=True))

    def win_rates(self) -> dict[str, float]:
        """Current win rate against every opponent."""
        return {name: e.win_rate for name, e in self.entries.items()}

    def table(self) -> list[dict[str, Any]]:
        """Every opponent: its games, the learner's win rate against it, its chance of
        being drawn and, for a paced racer, the pace it drives at (None until known)."""
        probabilities = self.probabilities()
        rows = []
        for name, e in self.entries.items():
            row = {"opponent": name, "games": e.games, "win_rate": round(e.win_rate, 4)}
            row["draw_probability"] = round(probabilities.get(name, 0.0), 4)
            if e.share is not None:
                pace = self._opponent(name).pace if self.pace is not None else None
                row["pace"] = None if pace is None else round(pace, 4)
            rows.append(row)
        return rows
