"""TD3+BC (Fujimoto & Gu 2021) in V-D4RL's DrQ+BC form on the DrQ-v2 pixel backbone: learner ``td3bc``
(agent files ``td3bc`` and ``td3bc_taco``).

Networks: the backbone's (``repro/agent/backbone.py``: encoder, actor, twin critic, target critic; with TACO the
action encoder and the auxiliary heads); nothing of its own.

Update, in V-D4RL's order (``drqbc/drqv2.py``'s DrQ+BC):
1. critic with the encoder: DrQ-v2's critic loss (the backbone's ``critic_step``, without autocast);
2. actor on sg(h): -lambda x Q(sg(h), u(a~)) + (a~ - a)^2, a~ the clipped-noise policy sample, lambda =
   ``td3bc.alpha`` / mean|Q| (``losses/td3bc.py``); the BC term stays in raw action space;
3. target critic: soft update;
4. with TACO, one auxiliary step.
The noise schedule counts V-D4RL's loop steps (``stddev_schedule.step_scale`` 2 per update).
"""

from __future__ import annotations

import torch

from repro.agent.backbone import BackboneLearner, optimize
from repro.agent.losses import CRITIC_METRICS, SATURATION_METRICS, Metrics, saturation_metrics
from repro.config.schema import TD3BCConfig, learner_section
from repro.learners.losses import td3bc as td3bc_loss

ACTOR_METRICS = ("actor_loss", "actor_lambda", "actor_bc", "actor_q", *SATURATION_METRICS)


class TD3BC(BackboneLearner):
    """Offline learner ``td3bc``."""

    update_metrics = CRITIC_METRICS + ACTOR_METRICS

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        bb = self.backbone
        h, next_h, action, reward, discount = bb.encode_batch(batch, autocast=False)
        metrics = bb.critic_step(h, action, reward, discount, next_h, step)
        metrics.update(self._actor_step(h.detach(), action, step))
        bb.update_target()
        metrics.update(bb.aux_step(batch))
        return metrics

    def _actor_step(self, h: torch.Tensor, data_action: torch.Tensor, step: int) -> Metrics:
        """One actor step on TD3+BC's loss at sg(h); ``td3bc.lambda_from`` picks min(Q1, Q2) or Q1."""
        bb = self.backbone
        dist = bb.actor(h, bb.stddev(step))
        policy_action = dist.sample(clip=self.cfg.stddev_clip)
        q1, q2 = bb.critic(h, bb.encode_action(policy_action))
        c = learner_section(self.cfg, TD3BCConfig)
        loss, metrics = td3bc_loss.actor_loss(q1, q2, policy_action, data_action, alpha=c.alpha,
                                              lambda_from=c.lambda_from)
        optimize(loss, bb.actor_opt)
        return {**metrics, **saturation_metrics(dist.loc, dist.pre_tanh)}
