"""``RUN/checkpoints/last.pt``: state dicts, the iteration they finished and the training time.

The file holds plain tensors and numbers only (``actor_state_dict``, ``critic_state_dict``,
``optimizer_state_dict``, ``iteration``, ``elapsed_s``), so it loads with
``torch.load(path, weights_only=True)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch


def checkpoint_path(run_dir: str | Path) -> Path:
    """Where a run keeps its checkpoint."""
    return Path(run_dir) / "checkpoints" / "last.pt"


def checkpoint(algorithm_state: dict[str, Any], iteration: int, elapsed_s: float) -> dict[str, Any]:
    """The checkpoint content: the algorithm's state dicts, ``iteration``, ``elapsed_s``."""
    return {**algorithm_state, "iteration": iteration, "elapsed_s": elapsed_s}


def write_checkpoint(run_dir: str | Path, content: dict[str, Any]) -> Path:
    """Write the checkpoint (through a temporary file, so a crash leaves the old one whole)."""
    path = checkpoint_path(run_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(content, path.with_suffix(".tmp"))
    path.with_suffix(".tmp").replace(path)
    return path


def read_checkpoint(run_dir: str | Path, device: str | torch.device = "cpu") -> dict[str, Any]:
    """A run's checkpoint, its tensors on ``device``."""
    return torch.load(checkpoint_path(run_dir), weights_only=True, map_location=device)
