"""``RUN/checkpoints/``: state dicts, the iteration they finished and the training time.

``last.pt`` is where training stands (``--resume`` continues it); ``best.pt`` holds the
weights of the run's best evaluation by completion (its ``eval_score``), as DeepRacer keeps
a best checkpoint beside the last, and ``fastest.pt`` those of the evaluation with the
fastest lap (its ``eval_best_lap``). A run's model (``model.zip``, ``evaluate``,
``--clone``) is ``best.pt`` when there is one; the others can be packed by name
(:data:`CHECKPOINTS`). The files hold plain tensors and numbers only
(``actor_state_dict``, ``critic_state_dict``, ``optimizer_state_dict``, ``iteration``,
``elapsed_s``), so they load with ``torch.load(path, weights_only=True)``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

if TYPE_CHECKING:  # torch is imported where checkpoints are read or written: the league's
    import torch  # API lists them (CHECKPOINTS) without it

Which = Literal["best", "fastest", "last"]
CHECKPOINTS: dict[Which, str] = {
    "best": "best completion (DeepRacer's best model)",
    "fastest": "fastest evaluation lap",
    "last": "last iteration",
}
"""The checkpoints a run keeps, by name, with what each one is the best by."""
CHECKPOINT_INDEX = "index.json"
"""What :meth:`agents.run.Run.pack_checkpoints` lists beside the archives it packs."""


def checkpoint_path(run_dir: str | Path, which: Which = "last") -> Path:
    """Where a run keeps its last (or best) checkpoint."""
    return Path(run_dir) / "checkpoints" / f"{which}.pt"


def model_checkpoint(run_dir: str | Path) -> Which:
    """The checkpoint holding a run's model: ``best`` when it has one, else ``last``."""
    return "best" if checkpoint_path(run_dir, "best").exists() else "last"


def checkpoint(algorithm_state: dict[str, Any], iteration: int, elapsed_s: float) -> dict[str, Any]:
    """The checkpoint content: the algorithm's state dicts, ``iteration``, ``elapsed_s``."""
    return {**algorithm_state, "iteration": iteration, "elapsed_s": elapsed_s}


def write_checkpoint(run_dir: str | Path, content: dict[str, Any], which: Which = "last") -> Path:
    """Write a checkpoint (through a temporary file, so a crash leaves the old one whole)."""
    import torch

    path = checkpoint_path(run_dir, which)
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(content, path.with_suffix(".tmp"))
    path.with_suffix(".tmp").replace(path)
    return path


def read_checkpoint(
    run_dir: str | Path, device: str | torch.device = "cpu", which: Which = "last"
) -> dict[str, Any]:
    """A run's last (or best) checkpoint, its tensors on ``device``."""
    import torch

    return torch.load(checkpoint_path(run_dir, which), weights_only=True, map_location=device)
