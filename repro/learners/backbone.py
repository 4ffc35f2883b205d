"""TD3+BC, CQL and IQL on the DrQ-v2 pixel backbone, each with or without TACO's auxiliary step.

The networks, the action encoder and the auxiliary objectives are the online agent's (repro/agent/agent.py):
with ``agent.objectives`` {taco, curl, reward} and ``agent.action_encoder: true`` the critic sees latent
actions u(a) and one TACO step follows the critic and actor updates, exactly as online. The BC term of
TD3+BC and CQL's uniform actions stay in raw action space. Each algorithm's loss is a pure function in
``repro/learners/losses/``; this file only wires networks to losses and steps the optimizers.

Update order: TD3+BC and CQL as DrQ-v2 (critic with the encoder, actor on sg(h), target, auxiliary);
IQL as the JAX reference code (value, actor, critic with the encoder, target, auxiliary), the actor's advantage
and the critic's target from the updated V (``iql.value_for_targets: before``: CORL's, from V before the value
step). The noise schedule counts V-D4RL's loop steps (``stddev_schedule.step_scale`` 2 per update).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import torch
from torch import nn

from repro.agent.agent import Agent, soft_update
from repro.agent.networks import TruncatedNormal, mlp, orthogonal_init, trunk
from repro.agent.objectives import Objective
from repro.config.schema import AgentConfig
from repro.learners.losses import cql as cql_loss
from repro.learners.losses import iql as iql_loss
from repro.learners.losses import td3bc as td3bc_loss

CRITIC = ("critic_loss", "critic_q1", "critic_q2", "critic_target_q")
CQL_METRICS = tuple(f"cql_{part}_q{i}" for i in (1, 2)
                    for part in ("reg", "lse", "q_data", "q_uniform", "q_policy", "q_next_policy"))
ALGORITHMS = ("td3bc", "cql", "iql")


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


class OfflineActorCritic(Agent):
    """Learners ``td3bc``, ``cql`` and ``iql`` (the ``_taco`` agent files switch on the auxiliary step)."""

    algorithm = "td3bc"
    value: ValueNet | None = None  # IQL's V(h); set before Agent.__init__ lists the modules
    log_std: LogStd | None = None  # IQL's learned log-std (iql.learned_log_std)
    reward_scale: float = 1.0  # IQL's reward factor (iql.reward_scaling), set from the dataset's returns

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        super().__init__(cfg, obs_shape, action_dim, device=device, explore_steps=0)
        if self.algorithm == "iql":
            if cfg.iql.value_for_targets not in ("after", "before"):
                raise ValueError(f"agent.iql.value_for_targets must be 'after' or 'before', "
                                 f"got {cfg.iql.value_for_targets!r}")
            self.value = ValueNet(self.encoder.repr_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
            self.value_opt = torch.optim.Adam(self.value.parameters(), lr=cfg.lr)
            self.value.train(True)
            if cfg.iql.reward_scaling not in ("none", "return_range"):
                raise ValueError(f"agent.iql.reward_scaling must be 'none' or 'return_range', "
                                 f"got {cfg.iql.reward_scaling!r}")
            if cfg.iql.learned_log_std:  # trained by the actor's optimizer, as the JAX actor's log_stds
                self.log_std = LogStd(action_dim).to(self.device)
                self.actor_opt.add_param_group({"params": list(self.log_std.parameters())})

    def set_dataset_returns(self, returns: Sequence[float]) -> None:
        """The dataset's episode returns, for IQL's ``iql.reward_scaling: return_range`` (the JAX code's
        normalize(): rewards / (best - worst episode return) x 1000); other learners and settings ignore them."""
        if self.algorithm == "iql" and self.cfg.iql.reward_scaling == "return_range":
            spread = float(max(returns)) - float(min(returns))
            if not spread > 0:
                raise ValueError("agent.iql.reward_scaling=return_range needs episodes of different returns")
            self.reward_scale = 1000.0 / spread

    # ----------------------------------------------------------------- protocol
    def modules(self) -> dict[str, nn.Module]:
        mods = super().modules()
        if self.value is not None:
            mods["value"] = self.value
        if self.log_std is not None:
            mods["log_std"] = self.log_std
        return mods

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        opts = super().optimizers()
        if self.value is not None:
            opts["value"] = self.value_opt
        return opts

    def metric_names(self) -> list[str]:
        names = list(CRITIC)
        if self.algorithm == "td3bc":
            names += ["actor_loss", "actor_lambda", "actor_bc", "actor_q"]
        elif self.algorithm == "cql":
            names += list(CQL_METRICS) + ["actor_loss", "actor_logprob", "actor_ent"]
        else:
            names += ["value_loss", "value_v", "actor_loss", "actor_adv", "actor_weight", "actor_logprob"]
        for objective in cast("dict[str, Objective]", self.objectives).values():
            names += objective.metric_keys()
        if self.objectives:
            names.append("aux_loss")
        return names

    @property
    def resolved(self) -> dict[str, object]:
        """Values this learner used that analysis reads (recorded in the run directory)."""
        out: dict[str, object] = {"algorithm": self.algorithm}
        if self.algorithm == "cql":
            out["cql_alpha"] = self.cfg.cql.alpha
        if self.algorithm == "iql":
            out["iql_reward_scale"] = self.reward_scale  # 1.0 unless iql.reward_scaling=return_range
        return out

    # ----------------------------------------------------------------- updates
    def update(self, batch: dict[str, torch.Tensor], step: int) -> dict[str, float]:
        metrics: dict[str, float] = {}
        obs = self.aug(batch["obs"].float())
        next_obs = self.aug(batch["next_obs"].float())
        h = self._encode(obs)
        with torch.no_grad():
            next_h = self._encode(next_obs)
        # dataset actions are data: no gradient ever flows into them
        action, reward, discount = batch["action"].detach(), batch["reward"], batch["discount"]
        if self.algorithm == "iql":
            metrics.update(self._iql(h, action, reward, discount, next_h, step))
        else:
            metrics.update(self._critic(h, action, reward, discount, next_h, step))
            if self.algorithm == "td3bc":
                metrics.update(self._td3bc_actor(h.detach(), action, step))
            else:
                metrics.update(self._update_actor(h.detach(), step))
        soft_update(self.critic, self.critic_target, self.cfg.critic_target_tau)
        if self.aux_opt is not None:
            metrics.update(self._update_aux(batch))
        return metrics

    def _step(self, loss: torch.Tensor, *opts: torch.optim.Optimizer) -> None:
        for opt in opts:
            opt.zero_grad(set_to_none=True)
        loss.backward()
        for opt in opts:
            opt.step()

    def _critic(self, h, action, reward, discount, next_h, step) -> dict[str, float]:
        """DrQ-v2's critic loss; CQL adds its regulariser for each head."""
        with torch.no_grad():
            dist = self.actor(next_h, self.stddev(step))
            next_action = self.encode_action(dist.sample(clip=self.cfg.stddev_clip))
            tq1, tq2 = self.critic_target(next_h, next_action)
            target_q = reward + discount * torch.min(tq1, tq2)
        q1, q2 = self.critic(h, self.encode_action(action))
        loss = nn.functional.mse_loss(q1, target_q) + nn.functional.mse_loss(q2, target_q)
        metrics = {"critic_loss": loss.item(), "critic_q1": q1.mean().item(), "critic_q2": q2.mean().item(),
                   "critic_target_q": target_q.mean().item()}
        if self.algorithm == "cql":
            regs, cql_metrics = self._cql_regularisers(h, next_h, (q1, q2), step)
            loss = loss + regs[0] + regs[1]
            metrics.update(cql_metrics)
            metrics["critic_loss"] = loss.item()
        self._step(loss, self.encoder_opt, self.critic_opt)
        return metrics

    def _cql_regularisers(self, h, next_h, q_data, step):
        """V-D4RL's draw order: N uniform actions, then N policy samples at h, then N at h' (each (B, N, A),
        noise clipped to ``stddev_clip`` unless ``cql.clip_policy_samples`` is off)."""
        c = self.cfg.cql
        n, batch = c.n_samples, h.shape[0]
        std = self.stddev(step)
        clip = self.cfg.stddev_clip if c.clip_policy_samples else None
        uniform = cql_loss.uniform_actions(batch, n, self.action_dim, like=h)
        with torch.no_grad():  # policy samples carry no gradient (CQL issue 5)
            policy, log_p = self._policy_samples(h.detach(), std, n, clip)
            next_policy, log_np = self._policy_samples(next_h, std, n, clip)

        def critic(h_rows: torch.Tensor, actions: torch.Tensor):
            return self.critic(h_rows, self.encode_action(actions))

        assert c.alpha is not None, "agent.cql.alpha is resolved when the config is composed"
        include_data = c.include_data_in_logsumexp and not c.importance_sampling  # V-D4RL: the no-IS form only
        return cql_loss.critic_regularisers(critic, h, q_data, uniform, policy, next_policy, float(c.alpha),
                                            c.temperature, importance_sampling=c.importance_sampling,
                                            log_prob_policy=log_p, log_prob_next_policy=log_np,
                                            include_data_in_logsumexp=include_data)

    def _policy_samples(self, h: torch.Tensor, std: float, n: int,
                        clip: float | None) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, N, A) samples of pi(.|h) and their (B, N) log-probabilities (summed over action dimensions)."""
        dist = self.actor(h, std)
        expanded = TruncatedNormal(dist.loc.unsqueeze(1).expand(-1, n, -1),
                                   dist.scale.unsqueeze(1).expand(-1, n, -1))
        samples = expanded.sample(clip=clip)
        return samples, expanded.log_prob(samples).sum(-1)

    def _td3bc_actor(self, h, data_action, step) -> dict[str, float]:
        dist = self.actor(h, self.stddev(step))
        policy_action = dist.sample(clip=self.cfg.stddev_clip)
        q1, q2 = self.critic(h, self.encode_action(policy_action))
        c = self.cfg.td3bc
        loss, metrics = td3bc_loss.actor_loss(q1, q2, policy_action, data_action, alpha=c.alpha,
                                              lambda_from=c.lambda_from)
        self._step(loss, self.actor_opt)
        return metrics

    def _iql_value(self, h, action) -> tuple[torch.Tensor, torch.Tensor, dict[str, float]]:
        """The expectile value step on V(h); returns the target critic's (Q1, Q2) at the data actions."""
        assert self.value is not None
        with torch.no_grad():
            tq1, tq2 = self.critic_target(h, self.encode_action(action))
        v = self.value(h)
        v_loss, metrics = iql_loss.value_loss(tq1, tq2, v, expectile=self.cfg.iql.expectile)
        self._step(v_loss, self.value_opt)
        return tq1, tq2, metrics

    def _iql_actor(self, h, action, tq1, tq2, v, step) -> dict[str, float]:
        c = self.cfg.iql
        if c.actor_lr_cosine_updates is not None:
            for group in self.actor_opt.param_groups:
                group["lr"] = iql_loss.cosine_lr(self.cfg.lr, step, c.actor_lr_cosine_updates)
        dist = self.actor(h, self.stddev(step))
        if self.log_std is not None:  # the JAX actor: Normal(tanh mean, exp(clip(log_stds)))
            dist = torch.distributions.Normal(dist.loc, self.log_std().expand_as(dist.loc))
        log_prob = dist.log_prob(action).sum(-1, keepdim=True)
        a_loss, metrics = iql_loss.actor_loss(log_prob, tq1, tq2, v, beta=c.beta, max_weight=c.max_weight)
        self._step(a_loss, self.actor_opt)
        return metrics

    def _iql(self, h, action, reward, discount, next_h, step) -> dict[str, float]:
        """IQL's update: value, actor, critic (with the encoder). The actor's advantage uses V(h) and the
        critic's target V(h'), both after the value step (the JAX learner.py) or both before it (CORL)."""
        assert self.value is not None
        before = self.cfg.iql.value_for_targets == "before"
        if before:
            with torch.no_grad():
                v_h, next_v = self.value(h.detach()), self.value(next_h)
        tq1, tq2, metrics = self._iql_value(h.detach(), action)
        if not before:
            with torch.no_grad():
                v_h, next_v = self.value(h.detach()), self.value(next_h)
        metrics.update(self._iql_actor(h.detach(), action, tq1, tq2, v_h, step))
        target = iql_loss.critic_target(reward * self.reward_scale, discount, next_v)
        q1, q2 = self.critic(h, self.encode_action(action))
        loss, critic_metrics = iql_loss.critic_loss(q1, q2, target)
        self._step(loss, self.encoder_opt, self.critic_opt)
        metrics.update(critic_metrics)
        return metrics


class TD3BC(OfflineActorCritic):
    algorithm = "td3bc"


class CQL(OfflineActorCritic):
    algorithm = "cql"


class IQL(OfflineActorCritic):
    algorithm = "iql"
