"""IQL (Kostrikov et al. 2022) on the DrQ-v2 pixel backbone: learner ``iql`` (agent file ``iql``).

Networks: the backbone's (``repro/agent/backbone.py``: encoder, actor, twin critic, target critic), plus a state
value V(h) (``ValueNet``, its own optimizer) and, with ``iql.learned_log_std``, the JAX actor's learned log-std
(``LogStd``, trained by the actor's optimizer).

Update, in the JAX reference code's order (ikostrikov/implicit_q_learning ``learner.py``):
1. value: expectile regression of V(sg(h)) onto min_i Qtarget_i(h, u(a)) (``losses/iql.py``);
2. actor on sg(h): advantage-weighted regression, weight min(exp(beta x (min_i Qtarget_i - V(h))), max_weight);
3. critic with the encoder: target r + discount x V(h');
4. target critic: soft update;
5. with TACO objectives, one auxiliary step.
The actor's advantage and the critic's target use V after the value step (the JAX code), or both V before it
(``iql.value_for_targets: before``, CORL's order). With ``iql.reward_scaling: return_range`` the rewards are
scaled by 1000 / (best - worst episode return) of the dataset (the JAX code's normalize()).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from repro.agent import fast
from repro.agent.backbone import BackboneLearner, optimize
from repro.agent.losses import CRITIC_METRICS, SATURATION_METRICS, Metrics, saturation_metrics
from repro.agent.networks import mlp, orthogonal_init, trunk
from repro.config.schema import AgentConfig, IQLConfig, RewardScaling, ValueForTargets, learner_section
from repro.learners.losses import iql as iql_loss

VALUE_METRICS = ("value_loss", "value_v")
ACTOR_METRICS = ("actor_loss", "actor_adv", "actor_weight", "actor_logprob", *SATURATION_METRICS)


class ValueNet(nn.Module):
    """IQL's state value V(h): the DrQ-v2 trunk and a ReLU MLP."""

    def __init__(self, repr_dim: int, feature_dim: int, hidden_dim: int):
        super().__init__()
        self.trunk = trunk(repr_dim, feature_dim)
        self.v = mlp(feature_dim, hidden_dim, 1)
        self.apply(orthogonal_init)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        return self.v(self.trunk(h))


class LogStd(nn.Module):
    """The JAX IQL actor's state-independent, learned log-std (``log_stds``: zeros at start, clipped to
    [LOG_STD_MIN, LOG_STD_MAX] when used); switch ``iql.learned_log_std``."""

    LOG_STD_MIN, LOG_STD_MAX = -5.0, 2.0  # learner.py: log_std_min=-5.0; policy.py: LOG_STD_MAX = 2.0

    def __init__(self, action_dim: int):
        super().__init__()
        self.log_std = nn.Parameter(torch.zeros(action_dim))

    def forward(self) -> torch.Tensor:
        return self.log_std.clamp(self.LOG_STD_MIN, self.LOG_STD_MAX).exp()


class IQL(BackboneLearner):
    """Offline learner ``iql``."""

    update_metrics = CRITIC_METRICS + VALUE_METRICS + ACTOR_METRICS

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        # the Enums raise ValueError for a value outside them (compose refuses one first, in one line)
        self.own = own = learner_section(cfg, IQLConfig)  # agent.iql
        self.targets_from_v_before = ValueForTargets(own.value_for_targets) == ValueForTargets.before  # CORL's
        self.scales_rewards = RewardScaling(own.reward_scaling) == RewardScaling.return_range
        self.reward_scale = 1.0  # set by set_dataset_returns when scales_rewards
        super().__init__(cfg, obs_shape, action_dim, device)  # the backbone
        bb = self.backbone
        self.value = ValueNet(bb.repr_dim, cfg.feature_dim, cfg.hidden_dim).to(bb.device)
        self.value_opt = fast.adam(bb.fast)(self.value.parameters(), lr=cfg.lr)  # the backbone's Adam
        self.log_std: LogStd | None = None
        if own.learned_log_std:  # trained by the actor's optimizer, as the JAX actor's log_stds
            self.log_std = LogStd(action_dim).to(bb.device)
            bb.actor_opt.add_param_group({"params": list(self.log_std.parameters())})

    def set_dataset_returns(self, returns: Sequence[float]) -> None:
        """The dataset's episode returns, for ``iql.reward_scaling: return_range`` (the JAX code's normalize():
        rewards / (best - worst episode return) x 1000); ignored with ``none``."""
        if self.scales_rewards:
            spread = float(max(returns)) - float(min(returns))
            if not spread > 0:
                raise ValueError("agent.iql.reward_scaling=return_range needs episodes of different returns")
            self.reward_scale = 1000.0 / spread

    def modules(self) -> dict[str, nn.Module]:
        mods = {**self.backbone.modules(), "value": self.value}
        if self.log_std is not None:
            mods["log_std"] = self.log_std
        return mods

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {**self.backbone.optimizers(), "value": self.value_opt}

    @property
    def resolved(self) -> dict[str, object]:
        # iql_reward_scale: 1.0 unless iql.reward_scaling=return_range
        return {"iql_reward_scale": self.reward_scale}

    # ----------------------------------------------------------------- update
    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        bb = self.backbone
        h, next_h, action, reward, discount = bb.encode_batch(batch, autocast=False)
        v_before = self._values(h, next_h) if self.targets_from_v_before else None
        (tq1, tq2), metrics = self._value_step(h.detach(), action)
        v_h, next_v = v_before if v_before is not None else self._values(h, next_h)
        metrics.update(self._actor_step(h.detach(), action, tq1, tq2, v_h, step))
        metrics.update(self._critic_step(h, action, reward, discount, next_v))
        bb.update_target()
        metrics.update(bb.aux_step(batch))
        return metrics

    def _values(self, h: torch.Tensor, next_h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(V(h), V(h')) without gradient: the actor's baseline and the critic target's bootstrap."""
        with torch.no_grad():
            return self.value(h.detach()), self.value(next_h)

    def _value_step(self, h: torch.Tensor, action: torch.Tensor
                    ) -> tuple[tuple[torch.Tensor, torch.Tensor], Metrics]:
        """One expectile step on V(h); returns the target critic's (Q1, Q2) at the data actions."""
        bb = self.backbone
        with torch.no_grad():
            tq1, tq2 = bb.critic_target(h, bb.encode_action(action))
        v = self.value(h)
        loss, metrics = iql_loss.value_loss(tq1, tq2, v, expectile=self.own.expectile)
        optimize(loss, self.value_opt)
        return (tq1, tq2), metrics

    def _actor_step(self, h: torch.Tensor, action: torch.Tensor, tq1: torch.Tensor, tq2: torch.Tensor,
                    v: torch.Tensor, step: int) -> Metrics:
        """One advantage-weighted regression step of log pi(a|sg(h)) (learning rate: ``iql.actor_lr_cosine_updates``
        decays it to 0 like the JAX code's schedule; null keeps it constant)."""
        bb, c = self.backbone, self.own
        if c.actor_lr_cosine_updates is not None:
            for group in bb.actor_opt.param_groups:
                group["lr"] = iql_loss.cosine_lr(self.cfg.lr, step, c.actor_lr_cosine_updates)
        dist = bb.actor(h, bb.stddev(step))
        health = saturation_metrics(dist.loc, dist.pre_tanh)
        if self.log_std is not None:  # the JAX actor: Normal(tanh mean, exp(clip(log_stds)))
            dist = torch.distributions.Normal(dist.loc, self.log_std().expand_as(dist.loc))
        log_prob = dist.log_prob(action).sum(-1, keepdim=True)
        loss, metrics = iql_loss.actor_loss(log_prob, tq1, tq2, v, beta=c.beta, max_weight=c.max_weight)
        optimize(loss, bb.actor_opt)
        return {**metrics, **health}

    def _critic_step(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor,
                     discount: torch.Tensor, next_v: torch.Tensor) -> Metrics:
        """One step of sum_i mse(Q_i(h, u(a)), r x reward_scale + discount x V(h')) on the critic and the encoder."""
        bb = self.backbone
        target = iql_loss.critic_target(reward * self.reward_scale, discount, next_v)
        q1, q2 = bb.critic(h, bb.encode_action(action))
        loss, metrics = iql_loss.critic_loss(q1, q2, target)
        optimize(loss, bb.encoder_opt, bb.critic_opt)
        return metrics
