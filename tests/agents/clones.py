"""Shared check for the training tests: a ``--clone`` starts from the parent's actor."""

from __future__ import annotations

from pathlib import Path

import torch

from agents.run import Run
from agents.train import Trainer


def assert_clone_takes_the_actor(trainer: Trainer, parent: Path) -> None:
    """Build ``trainer``'s runner, load its clone weights, and check that its actor holds
    exactly the weights of ``parent``'s model."""
    env, _ = trainer._make_env()
    try:
        runner = trainer._make_runner(env)
        trainer._load_weights(runner)
        expected = Run.load(parent).actor()
        cloned = runner.alg.get_policy().state_dict()
        for key, value in expected.state_dict().items():
            assert torch.equal(cloned[key], value), key
    finally:
        env.close()
