"""TD3+BC (Fujimoto & Gu 2021) in V-D4RL's DrQ+BC form on the DrQ-v2 pixel backbone: learner ``td3bc``
(agent files ``td3bc`` and ``td3bc_taco``).

Networks: the backbone's (encoder, actor, twin critic, target critic; with TACO the action encoder and the
auxiliary heads); nothing of its own.

Update, in V-D4RL's order (``drqbc/drqv2.py``'s DrQ+BC):
1. critic with the encoder: DrQ-v2's critic loss (the backbone's ``critic_loss``);
2. actor on sg(h): -lambda x Q(sg(h), u(a~)) + (a~ - a)^2, a~ the clipped-noise policy sample, lambda =
   ``td3bc.alpha`` / mean|Q| (``losses/td3bc.py``); the BC term stays in raw action space;
3. target critic: soft update;
4. with TACO, one auxiliary step.
"""

from __future__ import annotations

import torch

from repro.agent.agent import CRITIC_METRICS
from repro.learners.backbone import OfflineBackbone
from repro.learners.losses import td3bc as td3bc_loss

ACTOR_METRICS = ("actor_loss", "actor_lambda", "actor_bc", "actor_q")


class TD3BC(OfflineBackbone):
    """Offline learner ``td3bc``."""

    algorithm = "td3bc"
    update_metrics = CRITIC_METRICS + ACTOR_METRICS

    def update(self, batch: dict[str, torch.Tensor], step: int) -> dict[str, float]:
        h, next_h, action, reward, discount = self.encode_batch(batch)
        metrics = self._update_critic(h, action, reward, discount, next_h, step)
        metrics.update(self._update_actor_bc(h.detach(), action, step))
        self.update_target()
        metrics.update(self.auxiliary_step(batch))
        return metrics

    def _update_actor_bc(self, h: torch.Tensor, data_action: torch.Tensor, step: int) -> dict[str, float]:
        """One actor step on TD3+BC's loss at sg(h); ``td3bc.lambda_from`` picks min(Q1, Q2) or Q1."""
        dist = self.actor(h, self.stddev(step))
        policy_action = dist.sample(clip=self.cfg.stddev_clip)
        q1, q2 = self.critic(h, self.encode_action(policy_action))
        c = self.cfg.td3bc
        loss, metrics = td3bc_loss.actor_loss(q1, q2, policy_action, data_action, alpha=c.alpha,
                                              lambda_from=c.lambda_from)
        self.optimize(loss, self.actor_opt)
        return metrics
