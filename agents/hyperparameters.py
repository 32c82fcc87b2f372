"""DeepRacer's training hyperparameters (``hyperparameters.json``) and their rsl-rl mapping.

Key names and defaults follow the ``hyperparameters.json`` that deepracer-for-cloud writes
for a model. :meth:`Hyperparameters.to_rsl_rl` turns them into rsl-rl's PPO and runner
settings; ``docs/training.md`` lists what maps to what and what has no equivalent.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from agents.settings import SLOTS_PER_WORKER
from arena.config import validation_problems

# Fixed in DeepRacer's clipped-PPO preset (not user settings there either).
PPO_CLIP = 0.2
GAE_LAMBDA = 0.95
# rsl-rl collects a fixed number of steps per slot, not whole episodes: an "episode" of
# num_episodes_between_training is converted to steps with this estimate.
STEPS_PER_EPISODE_ESTIMATE = 64
# The slots (parallel races x learner cars) whose iteration DeepRacer's numbers describe when
# the iteration grows with the machine (``to_rsl_rl(grow=True)``): a 2-core machine's
# default of 2 workers, 160 steps per slot.
REFERENCE_SLOTS = 2 * SLOTS_PER_WORKER
VALUE_LOSS_COEF = 1.0
# rsl-rl's PPO, learning from rewards scaled by the running std of the return.
PPO_CLASS = "agents.return_scale:ReturnScaledPPO"
# rsl-rl critic classes -> their Huber-loss variants (agents/huber.py).
HUBER_CRITICS = {
    "MLPModel": "agents.huber:HuberMLPModel",
    "CNNModel": "agents.huber:HuberCNNModel",
    "agents.networks:PooledCNNModel": "agents.huber:HuberPooledCNNModel",
}


class Hyperparameters(BaseModel):
    """DeepRacer hyperparameters, by their ``hyperparameters.json`` names and defaults."""

    model_config = ConfigDict(extra="ignore", frozen=True)

    batch_size: int = Field(
        default=64, ge=1, le=4096, description="Samples in each gradient step's minibatch."
    )
    beta_entropy: float = Field(
        default=0.01, ge=0.0, le=1.0, description="Entropy bonus: more keeps exploring longer."
    )
    discount_factor: float = Field(
        default=0.999, ge=0.0, le=1.0, description="How much future reward counts (0-1)."
    )
    e_greedy_value: float = Field(
        default=0.05, ge=0.0, le=1.0, description="DeepRacer's epsilon; read, not used by PPO."
    )
    epsilon_steps: int = Field(
        default=10000, ge=0, description="DeepRacer's epsilon decay; read, not used by PPO."
    )
    exploration_type: Literal["categorical", "additive_noise"] = Field(
        default="categorical", description="DeepRacer's exploration kind; PPO samples its policy."
    )
    loss_type: Literal["huber", "mean squared error"] = Field(
        default="huber", description="The critic's loss."
    )
    lr: float = Field(default=3e-4, gt=0.0, le=1e-2, description="Learning rate of the updates.")
    num_episodes_between_training: int = Field(
        default=20, ge=1, le=1000, description="Episodes collected before each update."
    )
    num_epochs: int = Field(
        default=10, ge=1, le=100, description="Passes over each batch of episodes per update."
    )
    stack_size: int = Field(
        default=1, ge=1, le=8, description="Camera frames the network sees at once."
    )
    term_cond_avg_score: float = Field(
        default=350.0, description="DeepRacer's stop condition on average reward; read, not used."
    )
    term_cond_max_episodes: int = Field(
        default=100000, ge=1, description="DeepRacer's stop condition on episodes; read, not used."
    )
    sac_alpha: float = Field(default=0.2, ge=0.0, description="SAC only; read, not used by PPO.")

    @classmethod
    def read(cls, path: str | Path) -> tuple[Hyperparameters, list[str]]:
        """Read a DeepRacer ``hyperparameters.json``: the settings, and the keys it ignored.

        Like DeepRacer, it reads the keys it knows and ignores the rest (``learning_rate``,
        ...); a known key with a bad value is a ``ValueError`` naming the key.
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{path} is not valid JSON: {exc}") from None
        if not isinstance(data, dict):
            raise ValueError(f"{path} must hold a JSON object, got {data!r:.80}")
        try:
            hp = cls.model_validate(data)
        except ValidationError as exc:
            raise ValueError(f"{path}: {validation_problems(exc)}") from None
        return hp, sorted(data.keys() - cls.model_fields.keys())

    @classmethod
    def load(cls, path: str | Path) -> Hyperparameters:
        """Read a DeepRacer ``hyperparameters.json``, ignoring keys it does not know."""
        return cls.read(path)[0]

    def write(self, run_dir: str | Path) -> Path:
        """Write ``RUN/ip/hyperparameters.json`` with DeepRacer's key names."""
        path = Path(run_dir) / "ip" / "hyperparameters.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.model_dump(), indent=2) + "\n")
        return path

    def steps_per_env(self, num_envs: int) -> int:
        """Rollout length per slot that collects about ``num_episodes_between_training``."""
        total = self.num_episodes_between_training * STEPS_PER_EPISODE_ESTIMATE
        return max(8, math.ceil(total / max(1, num_envs)))

    def to_rsl_rl(
        self,
        num_envs: int,
        actor: dict[str, Any],
        critic: dict[str, Any],
        obs_groups: dict[str, list[str]],
        num_steps_per_env: int | None = None,
        grow: bool = False,
    ) -> dict[str, Any]:
        """rsl-rl's ``OnPolicyRunner`` config for these hyperparameters and models.

        As written, an iteration holds about ``num_episodes_between_training`` episodes
        whatever ``num_envs``, in minibatches of ``batch_size``. ``grow`` (more than
        :data:`REFERENCE_SLOTS` slots, no ``num_steps_per_env``): every slot collects what a
        slot of the reference machine does, so the iteration grows with ``num_envs``, and
        so does each minibatch: the update still takes ``num_epochs`` passes of the same
        number of gradient steps, each sample used ``num_epochs`` times, as DeepRacer's
        numbers say; only the minibatch, and the samples per iteration, are larger.
        """
        grows = grow and num_steps_per_env is None and num_envs > REFERENCE_SLOTS
        steps = num_steps_per_env or self.steps_per_env(REFERENCE_SLOTS if grows else num_envs)
        slots = REFERENCE_SLOTS if grows else num_envs
        mini_batches = max(1, round(steps * slots / self.batch_size))
        return {
            "num_steps_per_env": steps,
            "obs_groups": obs_groups,
            "logger": "tensorboard",
            "multi_gpu": None,
            "check_for_nan": True,  # agents.runner stops on NaN from the env, naming the iteration
            "algorithm": {
                "class_name": PPO_CLASS,
                "learning_rate": self.lr,
                "num_learning_epochs": self.num_epochs,
                "num_mini_batches": mini_batches,
                "clip_param": PPO_CLIP,
                "gamma": self.discount_factor,
                "lam": GAE_LAMBDA,
                "entropy_coef": self.beta_entropy,
                "value_loss_coef": VALUE_LOSS_COEF,
                "use_clipped_value_loss": True,
                "max_grad_norm": 1.0,
                "schedule": "fixed",
                "desired_kl": 0.01,
            },
            "actor": actor,
            "critic": self._critic(critic),
        }

    def _critic(self, critic: dict[str, Any]) -> dict[str, Any]:
        """The critic config, with the Huber-loss variant of its class for ``huber``."""
        if self.loss_type != "huber":
            return critic
        return {**critic, "class_name": HUBER_CRITICS[critic["class_name"]]}
