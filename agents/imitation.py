"""Learning to drive by imitation: a sensor student taught by a driver that sees the track.

``slipstream train --teacher pursuit`` trains the actor by DAgger-style distillation
instead of PPO (rsl-rl's :class:`~rsl_rl.algorithms.Distillation`): the student drives
with its own sensors (sampling from its action distribution, so it visits the states
its mistakes lead to), and in every state the teacher says what it would have done.
The teacher is :class:`arena.pursuit.PassingPursuitPolicy`, pure pursuit on the track's
racing line at its speed profile that steers around boxes and cars: it reads DeepRacer's
params, which the student never sees. Its actions are computed in the env workers and
travel as the observation group :data:`EXPERT_GROUP`, which :class:`ExpertModel` hands to
rsl-rl as the teacher's output.

After each rollout the student regresses its action (the Gaussian mean, or the logits
with cross-entropy for a discrete space) onto the teacher's, over shuffled mini-batches.
The checkpoint stores the student as the actor (``actor_state_dict``), so
``--clone`` of an imitation run goes on with PPO and the user's reward from there.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn as nn
from rsl_rl.algorithms import Distillation
from tensordict import TensorDict

from agents.fused_adam import fuse_adam
from arena.actions import ContinuousActionSpace, DiscreteActionSpace
from arena.pursuit import PassingPursuitPolicy
from tracks.track import Track

# The observation group that carries the teacher's action for each learner slot.
EXPERT_GROUP = "expert"
DISTILLATION_CLASS = "agents.imitation:BehaviourCloning"
TEACHER_CLASS = "agents.imitation:ExpertModel"
# The Gaussian student's action noise (its std is not trained by imitation): small, so
# the student visits the states its own greedy driving reaches, where the teacher's
# corrections matter.
STUDENT_STD = 0.1


class ExpertDriver:
    """The teacher's action for one car, as the network's output row.

    Continuous spaces: the ``[-1, 1]^2`` action. Discrete spaces: a one-hot row.
    """

    def __init__(self, track: Track, space: DiscreteActionSpace | ContinuousActionSpace) -> None:
        self.space = space
        self.policy = PassingPursuitPolicy(track, space)

    def reset(self) -> None:
        """A new episode (the pursuit driver forgets its carried steering)."""
        self.policy.reset()

    def action(self, params: dict[str, Any]) -> np.ndarray:
        """What the teacher does in the state that ``params`` describe."""
        action = self.policy.act(None, params)
        if isinstance(self.space, DiscreteActionSpace):
            row = np.zeros(self.space.n, dtype=np.float32)
            row[int(action)] = 1.0
            return row
        return np.asarray(action, dtype=np.float32)


def imitation_loss(
    actor: nn.Module, obs: TensorDict, targets: torch.Tensor, discrete: bool
) -> torch.Tensor:
    """How far ``actor``'s outputs in the states ``obs`` are from the teacher's ``targets``:
    squared error of the Gaussian mean, or cross-entropy of the logits (``discrete``)."""
    outputs = actor.mlp(actor.get_latent(obs))
    if discrete:
        return nn.functional.cross_entropy(outputs, targets.argmax(dim=-1))
    return nn.functional.mse_loss(outputs, targets)


class ExpertModel(nn.Module):
    """rsl-rl's teacher model: it returns the :data:`EXPERT_GROUP` observation as is.

    It has no parameters; the signature and the no-op methods are those rsl-rl's
    :class:`~rsl_rl.algorithms.Distillation` calls on a teacher.
    """

    is_recurrent = False

    def __init__(self, obs: TensorDict, obs_groups: dict, obs_set: str, output_dim: int) -> None:
        super().__init__()
        groups = obs_groups[obs_set]
        if groups != [EXPERT_GROUP]:
            raise ValueError(f"the teacher reads the {EXPERT_GROUP!r} group alone, got {groups}")
        if obs[EXPERT_GROUP].shape[-1] != output_dim:
            raise ValueError(f"the expert group has {obs[EXPERT_GROUP].shape[-1]} values")

    def forward(self, obs: TensorDict, *args: Any, **kwargs: Any) -> torch.Tensor:
        """The teacher's action rows."""
        return obs[EXPERT_GROUP]

    def reset(self, dones: torch.Tensor | None = None, hidden_state: Any = None) -> None:
        """Nothing to reset (no memory)."""

    def get_hidden_state(self) -> None:
        """No memory."""

    def detach_hidden_state(self, dones: torch.Tensor | None = None) -> None:
        """No memory."""


class BehaviourCloning(Distillation):
    """rsl-rl's ``Distillation``, updated over shuffled mini-batches of the whole rollout.

    rsl-rl steps through the rollout one time step (one row per env) at a time, which for
    a CNN student and a handful of envs means tiny batches; a feedforward student needs no
    time order, so each epoch here shuffles every stored transition into ``num_mini_batches``.
    The loss is mean squared error on the Gaussian mean for continuous spaces and
    cross-entropy on the logits for discrete ones. The teacher needs no weights.
    """

    def __init__(
        self,
        *args: Any,
        num_mini_batches: int = 1,
        discrete: bool = False,
        teacher_drives: float = 0.0,
        **kwargs: Any,
    ):
        super().__init__(*args, **kwargs)
        fuse_adam(self.optimizer)
        self.num_mini_batches = num_mini_batches
        self.discrete = discrete
        self.teacher_loaded = True  # the teacher is the pursuit driver, not a network
        self.teacher_drives = teacher_drives
        self._driven: torch.Tensor | None = None  # per learner slot: the teacher drives

    def act(self, obs: TensorDict) -> torch.Tensor:
        """The student's sampled actions, and the teacher's instead in the episodes it
        drives (``teacher_drives``: each episode's chance, drawn when it starts)."""
        actions = super().act(obs)
        if not self.teacher_drives:
            return actions
        if self._driven is None:
            self._driven = self._draw(actions.shape[0])
        return torch.where(self._driven.unsqueeze(-1), obs[EXPERT_GROUP], actions)

    def process_env_step(
        self, obs: TensorDict, rewards: torch.Tensor, dones: torch.Tensor, extras: Any
    ) -> None:
        """rsl-rl's step record; a slot whose episode ended draws who drives the next."""
        super().process_env_step(obs, rewards, dones, extras)
        if self._driven is not None:
            ended = dones.view(-1).bool()
            self._driven = torch.where(ended, self._draw(ended.numel()), self._driven)

    def _draw(self, count: int) -> torch.Tensor:
        return torch.rand(count, device=self.device) < self.teacher_drives

    def update(self) -> dict[str, float]:
        """Epochs of shuffled mini-batches: the student's outputs onto the teacher's."""
        storage = self.storage
        observations = storage.observations.flatten(0, 1)
        targets = storage.privileged_actions.flatten(0, 1)
        total = targets.shape[0]
        size = max(1, total // self.num_mini_batches)
        losses = []
        for _ in range(self.num_learning_epochs):
            order = torch.randperm(total, device=self.device)
            for start in range(0, total - size + 1, size):
                batch = order[start : start + size]
                loss = imitation_loss(
                    self.student, observations[batch], targets[batch], self.discrete
                )
                self.optimizer.zero_grad()
                loss.backward()
                if self.max_grad_norm:
                    nn.utils.clip_grad_norm_(self.student.parameters(), self.max_grad_norm)
                self.optimizer.step()
                losses.append(loss.item())
        self.student.update_normalization(observations)
        storage.clear()
        return {"imitation": float(np.mean(losses)) if losses else float("nan")}

    def save(self) -> dict:
        """The student as the actor (what ``--clone`` and packing read), and the optimizer."""
        return {
            "actor_state_dict": self._raw_student.state_dict(),
            "optimizer_state_dict": self.optimizer.state_dict(),
        }

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """Resume from :meth:`save`'s dict (``load_cfg`` ``{"actor": True}`` loads only the
        student)."""
        self._raw_student.load_state_dict(loaded_dict["actor_state_dict"], strict=strict)
        if load_cfg is None or load_cfg.get("optimizer", False):
            self.optimizer.load_state_dict(loaded_dict["optimizer_state_dict"])
            fuse_adam(self.optimizer)
        return True


def imitation_config(
    ppo_cfg: dict[str, Any], discrete: bool, teacher_drives: float = 0.0
) -> dict[str, Any]:
    """rsl-rl's runner config for imitation, from the PPO config of the same run.

    The student is PPO's actor (same network, so the run can be cloned into PPO); its
    learning rate, epochs and mini-batches are PPO's (DeepRacer's ``lr``, ``num_epochs``,
    ``batch_size``); a Gaussian student's noise is :data:`STUDENT_STD`; the teacher is
    :class:`ExpertModel`, and drives that share of the episodes (``teacher_drives``).
    """
    ppo = ppo_cfg["algorithm"]
    student = dict(ppo_cfg["actor"])
    if not discrete:
        student["distribution_cfg"] = {**student["distribution_cfg"], "init_std": STUDENT_STD}
    return {
        **{k: v for k, v in ppo_cfg.items() if k not in ("actor", "critic", "algorithm")},
        "obs_groups": {"student": ppo_cfg["obs_groups"]["actor"], "teacher": [EXPERT_GROUP]},
        "algorithm": {
            "class_name": DISTILLATION_CLASS,
            "learning_rate": ppo["learning_rate"],
            "num_learning_epochs": ppo["num_learning_epochs"],
            "num_mini_batches": ppo["num_mini_batches"],
            "max_grad_norm": ppo["max_grad_norm"],
            "gradient_length": 1,
            "discrete": discrete,
            "teacher_drives": teacher_drives,
        },
        "student": student,
        "teacher": {"class_name": TEACHER_CLASS},
    }
