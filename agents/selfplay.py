"""Opponents for head-to-model training: prioritised fictitious self-play (PFSP).

The pool holds frozen snapshots of the learner (exported to ONNX every few iterations)
and any ONNX policies the user adds. Each race gets an opponent sampled with PFSP's
"hard" weighting: an opponent the learner beats with rate ``p`` is drawn with weight
``(1 - p) ** 2`` (plus a small floor so no opponent is forgotten), so training time goes
to the opponents the learner still loses to. Win rates are exponential moving averages
of episode outcomes (see :class:`agents.vecenv.EnvGroup` for what counts as a win).
Bots (head-to-bot) and boxes (object avoidance) come from the race config instead.
"""

from __future__ import annotations

import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from submissions.runner import OnnxRunner

WEIGHT_FLOOR = 0.05
UNPLAYED_WIN_RATE = 0.5


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


@dataclass
class _Entry:
    graph: bytes
    win_rate: float = UNPLAYED_WIN_RATE
    games: int = 0
    snapshot: bool = True


class OpponentPool:
    """Frozen snapshots plus user policies, sampled by PFSP.

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

    def __len__(self) -> int:
        return len(self.entries)

    def add_snapshot(self, name: str, graph: bytes) -> None:
        """Add a frozen copy of the learner (ONNX bytes)."""
        self.entries[name] = _Entry(graph)
        snapshots = [k for k, e in self.entries.items() if e.snapshot]
        for old in snapshots[: max(0, len(snapshots) - self.max_snapshots)]:
            del self.entries[old]

    def add_policy(self, path: str | Path) -> str:
        """Add a user policy (``.onnx`` or submission ``.zip``); returns its pool name."""
        name = f"user:{Path(path).name}"
        self.entries[name] = _Entry(read_policy_graph(path), snapshot=False)
        return name

    def record(self, name: str, win: bool) -> None:
        """Fold one episode's outcome against ``name`` into its win rate."""
        entry = self.entries.get(name)
        if entry is not None:
            entry.games += 1
            entry.win_rate += self.ema * (float(win) - entry.win_rate)

    def sample(self, count: int) -> list[tuple[str, bytes]]:
        """``count`` opponents drawn (with replacement) by PFSP weights."""
        if not self.entries:
            raise ValueError("the opponent pool is empty")
        probabilities = self.probabilities()
        names = list(probabilities)
        picks = self.rng.choice(len(names), size=count, p=list(probabilities.values()))
        return [(names[i], self.entries[names[i]].graph) for i in picks]

    def probabilities(self) -> dict[str, float]:
        """Each opponent's chance of being drawn (:func:`pfsp_weights` of the win rates)."""
        weights = pfsp_weights([e.win_rate for e in self.entries.values()])
        return dict(zip(self.entries, weights.tolist(), strict=True))

    def win_rates(self) -> dict[str, float]:
        """Current win rate against every opponent."""
        return {name: e.win_rate for name, e in self.entries.items()}
