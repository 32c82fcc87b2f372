"""PPO that keeps what imitation taught: a critic warm-up and a decaying pull to the teacher.

PPO cloned from an imitation run starts with a good actor and a critic that knows nothing
(imitation trains none). Its first advantages are noise, and DeepRacer's 10 epochs a
rollout move the actor far on them: measured, the clone kept its parent's laps for about
3 minutes and then fell apart (benchmarks/RESULTS.md, "PPO after imitation").
:class:`AnchoredPPO` adds two levers to the project's PPO, the user's reward unchanged:

- **critic warm-up**: for the first ``critic_warmup`` updates only the critic learns; the
  actor (its weights and its action noise) is held, so the actor first moves on
  advantages from a critic fitted to its own rollouts;
- **anchor**: each PPO mini-batch's loss gains an imitation term, the distance of the
  actor's action (the Gaussian mean, or the logits with cross-entropy) to the teacher's
  in the same states (the :data:`~agents.imitation.EXPERT_GROUP` observations), weighted
  ``anchor_weight``; with ``anchor_updates`` the weight decays linearly to 0 over that
  many updates, after which PPO alone decides. Measured, a weight that holds kept the
  clone on the road while PPO made it faster; one that decayed over 30 updates let the
  off-tracks come back once it was spent. The term enters through rsl-rl's hook for an
  extra actor loss (its symmetry extension's "mirror loss"), so it is part of the same
  gradient step as PPO's.

The count of updates done is saved with the algorithm, so a resumed run goes on with the
schedule where it stopped; a clone starts it again.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from agents.imitation import EXPERT_GROUP, imitation_loss
from agents.return_scale import ReturnScaledPPO

ANCHORED_PPO_CLASS = "agents.anchor:AnchoredPPO"


class AnchoredPPO(ReturnScaledPPO):
    """The project's PPO with a critic warm-up and a decaying behaviour-cloning anchor."""

    def __init__(
        self,
        *args: Any,
        critic_warmup: int = 0,
        anchor_weight: float = 0.0,
        anchor_updates: int | None = None,
        discrete: bool = False,
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)
        self.critic_warmup = critic_warmup
        self.anchor_weight = anchor_weight
        self.anchor_updates = anchor_updates
        self.discrete = discrete
        self.updates_done = 0

    def anchor_weight_now(self) -> float:
        """The anchor's weight at the next update (0 once a decay has run out)."""
        if self.anchor_updates is None:
            return self.anchor_weight
        left = max(0.0, 1.0 - self.updates_done / self.anchor_updates)
        return self.anchor_weight * left

    def update(self) -> dict[str, float]:
        """PPO's update with the anchor's term while it weighs, the actor held while the
        critic warms up."""
        weight = self.anchor_weight_now()
        self.symmetry = _AnchorTerm(weight, self.discrete) if weight > 0.0 else None
        warming = self.updates_done < self.critic_warmup
        held = [p for p in self.actor.parameters() if p.requires_grad] if warming else []
        for parameter in held:
            parameter.requires_grad_(False)
        try:
            losses = super().update()
        finally:
            for parameter in held:
                parameter.requires_grad_(True)
            self.symmetry = None
        self.updates_done += 1
        anchor = losses.pop("symmetry", 0.0)
        return {**losses, "anchor": anchor, "anchor_weight": weight}

    def save(self) -> dict:
        """PPO's state and the count of updates done (the schedules' clock)."""
        return {**super().save(), "anchor_updates_done": self.updates_done}

    def load(self, loaded_dict: dict, load_cfg: dict | None, strict: bool) -> bool:
        """PPO's load; a resume (no ``load_cfg``) also restores the schedules' clock."""
        result = super().load(loaded_dict, load_cfg, strict)
        if load_cfg is None:
            self.updates_done = int(loaded_dict.get("anchor_updates_done", 0))
        return result


class _AnchorTerm:
    """The anchor in the shape of rsl-rl's symmetry extension: no augmented samples, and
    an extra actor loss (``compute_loss``) that PPO adds times ``mirror_loss_coeff``."""

    use_mirror_loss = True

    def __init__(self, weight: float, discrete: bool) -> None:
        self.mirror_loss_coeff = weight
        self.discrete = discrete

    def augment_batch(self, batch: Any, original_batch_size: int) -> None:
        """No augmentation: the batch is PPO's own."""

    def compute_loss(self, actor: nn.Module, batch: Any, original_batch_size: int) -> torch.Tensor:
        """The imitation loss of ``actor`` on the batch's states against the teacher's."""
        obs = batch.observations
        return imitation_loss(actor, obs, obs[EXPERT_GROUP], self.discrete)


def anchored_config(
    ppo_cfg: dict[str, Any],
    *,
    critic_warmup: int,
    anchor_weight: float,
    anchor_updates: int | None,
    discrete: bool,
) -> dict[str, Any]:
    """rsl-rl's runner config ``ppo_cfg`` with :class:`AnchoredPPO` as its algorithm."""
    algorithm = {
        **ppo_cfg["algorithm"],
        "class_name": ANCHORED_PPO_CLASS,
        "critic_warmup": critic_warmup,
        "anchor_weight": anchor_weight,
        "anchor_updates": anchor_updates,
        "discrete": discrete,
    }
    return {**ppo_cfg, "algorithm": algorithm}
