"""CQL (Kumar et al. 2020) as V-D4RL's pixel CQL (``drqbc/cql.py``) on the DrQ-v2 backbone: learner ``cql``
(agent files ``cql`` and ``cql_taco``).

Networks: the backbone's (``repro/agent/backbone.py``: encoder, actor, twin critic, target critic; with TACO the
action encoder and the auxiliary heads); nothing of its own.

Update, in V-D4RL's order:
1. critic with the encoder: DrQ-v2's critic loss plus, for each head, CQL's regulariser alpha x (logsumexp
   over Q at uniform actions, policy samples at h and at h' (and the data action) - Q at the data action)
   (``losses/cql.py``); alpha is ``cql.alpha`` (Table 6's value for the task and dataset unless set);
2. actor on sg(h): DrQ-v2's (the backbone's ``actor_step``: -min_i Q_i(sg(h), u(a~)));
3. target critic: soft update;
4. with TACO, one auxiliary step.
Uniform actions are drawn in raw action space and encoded like the data actions.
"""

from __future__ import annotations

import torch

from repro.agent.backbone import BackboneLearner, optimize
from repro.agent.losses import ACTOR_METRICS, CRITIC_METRICS, Metrics
from repro.agent.networks import TruncatedNormal
from repro.config.schema import CQLConfig, learner_section
from repro.learners.losses import cql as cql_loss

REGULARISER_METRICS = tuple(f"cql_{part}_q{i}" for i in (1, 2)
                            for part in ("reg", "lse", "q_data", "q_uniform", "q_policy", "q_next_policy"))


class CQL(BackboneLearner):
    """Offline learner ``cql``."""

    update_metrics = CRITIC_METRICS + REGULARISER_METRICS + ACTOR_METRICS

    @property
    def resolved(self) -> dict[str, object]:
        return {"cql_alpha": learner_section(self.cfg, CQLConfig).alpha}

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        bb = self.backbone
        h, next_h, action, reward, discount = bb.encode_batch(batch, autocast=False)
        metrics = self._critic_step(h, action, reward, discount, next_h, step)
        metrics.update(bb.actor_step(h.detach(), step))
        bb.update_target()
        metrics.update(bb.aux_step(batch))
        return metrics

    def _critic_step(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                     next_h: torch.Tensor, step: int) -> Metrics:
        """One step of DrQ-v2's critic loss plus both heads' regularisers on the critic and the encoder."""
        bb = self.backbone
        loss, q_data, metrics = bb.critic_loss(h, action, reward, discount, next_h, step)
        regs, reg_metrics = self._regularisers(h, next_h, q_data, step)
        loss = loss + regs[0] + regs[1]
        metrics.update(reg_metrics)
        metrics["critic_loss"] = loss.detach()
        optimize(loss, bb.encoder_opt, bb.critic_opt)
        return metrics

    def _regularisers(self, h: torch.Tensor, next_h: torch.Tensor, q_data: tuple[torch.Tensor, torch.Tensor],
                      step: int) -> tuple[tuple[torch.Tensor, ...], Metrics]:
        """V-D4RL's draw order: N uniform actions, then N policy samples at h, then N at h' (each (B, N, A),
        noise clipped to ``stddev_clip`` unless ``cql.clip_policy_samples`` is off)."""
        bb, c = self.backbone, learner_section(self.cfg, CQLConfig)
        n, batch = c.n_samples, h.shape[0]
        std = bb.stddev(step)
        clip = self.cfg.stddev_clip if c.clip_policy_samples else None
        uniform = cql_loss.uniform_actions(batch, n, bb.action_dim, like=h)
        with torch.no_grad():  # policy samples carry no gradient (CQL issue 5)
            policy, log_p = self._policy_samples(h.detach(), std, n, clip)
            next_policy, log_np = self._policy_samples(next_h, std, n, clip)

        def critic(h_rows: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            return bb.critic(h_rows, bb.encode_action(actions))

        assert c.alpha is not None, "agent.cql.alpha is resolved when the config is composed"
        include_data = c.include_data_in_logsumexp and not c.importance_sampling  # V-D4RL: the no-IS form only
        return cql_loss.critic_regularisers(critic, h, q_data, uniform, policy, next_policy, float(c.alpha),
                                            c.temperature, importance_sampling=c.importance_sampling,
                                            log_prob_policy=log_p, log_prob_next_policy=log_np,
                                            include_data_in_logsumexp=include_data)

    def _policy_samples(self, h: torch.Tensor, std: float | torch.Tensor, n: int,
                        clip: float | None) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N, A) samples of pi(.|h) and their (B, N) log-probabilities (summed over action dimensions)."""
        dist = self.backbone.actor(h, std)
        expanded = TruncatedNormal(dist.loc.unsqueeze(1).expand(-1, n, -1),
                                   dist.scale.unsqueeze(1).expand(-1, n, -1))
        samples = expanded.sample(clip=clip)
        return samples, expanded.log_prob(samples).sum(-1)
