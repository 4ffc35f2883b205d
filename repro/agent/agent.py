"""One agent core for TACO, DrQ-v2 and their ablations: switches, not copies.

``update()`` takes a batch of tensors and returns a metrics dict; it never touches files.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import cast

import numpy as np
import torch
from torch import nn

from repro.agent import fast
from repro.agent.modules import ModuleSet
from repro.agent.networks import ActionEncoder, Actor, Critic, Encoder, default_latent_action_dim
from repro.agent.objectives import OBJECTIVES, AuxBatch, Objective, ObjectiveContext
from repro.config.schema import AgentConfig

CRITIC_METRICS = ("critic_loss", "critic_q1", "critic_q2", "critic_target_q")
ACTOR_METRICS = ("actor_loss", "actor_logprob", "actor_ent")


def soft_update(net: nn.Module, target: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for p, tp in zip(net.parameters(), target.parameters()):
            tp.lerp_(p, tau)


class Agent(ModuleSet):
    """DrQ-v2 actor-critic with an optional action encoder and pluggable auxiliary objectives."""

    untrained = ("critic_target",)  # the target critic follows by soft updates: eval mode, not counted

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        self.cfg = cfg
        self.device = torch.device(device)
        self.action_dim = action_dim
        self.explore_steps = explore_steps
        # agent.fast: the speed-ups resolved for this device (repro/agent/fast.py); all off on the plain path
        self.fast = fast.resolve_fast(cfg.fast, self.device)
        self.aug = fast.shift(self.fast)

        self.encoder = fast.prepare_encoder(Encoder(obs_shape).to(self.device), self.fast)
        # Opt-in speedups: a compiled encoder for updates, and bfloat16 autocast of the forward passes.
        compiled = cfg.compile or self.fast.compile
        self._encode = torch.compile(self.encoder, dynamic=False) if compiled else self.encoder
        repr_dim = self.encoder.repr_dim
        self.action_encoder: ActionEncoder | None = None
        if cfg.action_encoder:
            latent = cfg.latent_action_dim or default_latent_action_dim(action_dim, cfg.latent_action_rounding)
            self.action_encoder = ActionEncoder(action_dim, latent, cfg.K, cfg.action_hidden_dim).to(self.device)
            critic_action_dim, seq_dim = latent, cfg.K * latent
        else:
            critic_action_dim, seq_dim = action_dim, cfg.K * action_dim
        step_dim = critic_action_dim
        self.actor = Actor(repr_dim, action_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic = Critic(repr_dim, critic_action_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic_target = Critic(repr_dim, critic_action_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.requires_grad_(False)

        active = [name for name, w in cfg.objectives.items() if w]
        ctx = ObjectiveContext(repr_dim=repr_dim, feature_dim=cfg.feature_dim, hidden_dim=cfg.hidden_dim,
                               action_dim=action_dim, K=cfg.K, seq_dim=seq_dim, step_dim=step_dim,
                               encoder=self.encoder)
        objectives = OrderedDict()
        for name in active:
            ctx.params = dict(cfg.objective_params.get(name, {}))
            objectives[name] = OBJECTIVES[name](ctx)
        self.objectives = nn.ModuleDict(objectives).to(self.device)
        self.shared = ctx._shared.to(self.device) if ctx._shared is not None else None
        self.weights = {name: float(cfg.objectives[name]) for name in active}
        # what the replay must return for these objectives (passed to ReplayBuffer.sample)
        self.sample_options = {"future_seq": any(o.needs_future_seq for o in self.objectives.values())}

        lr, adam = cfg.lr, fast.adam(self.fast)
        self.encoder_opt = adam(self.encoder.parameters(), lr=lr)
        self.actor_opt = adam(self.actor.parameters(), lr=lr)
        critic_params = list(self.critic.parameters())
        if self.action_encoder is not None:
            critic_params += list(self.action_encoder.parameters())
        self.critic_opt = adam(critic_params, lr=lr)
        self.aux_opt: torch.optim.Optimizer | None = None
        if self.objectives:
            aux_params = list(self.encoder.parameters()) + list(self.objectives.parameters())
            if self.action_encoder is not None:
                aux_params += list(self.action_encoder.parameters())
            if self.shared is not None:
                aux_params += list(self.shared.parameters())
            self.aux_opt = adam(_unique(aux_params), lr=lr)
        self.train(True)

    @property
    def resolved(self) -> dict[str, object]:
        """What resolved.json records beyond the config: agent.fast's plan, when it is on."""
        return fast.resolved(self.fast, self.cfg.fast)

    # ----------------------------------------------------------------- modules and state
    def modules(self) -> dict[str, nn.Module]:
        """Every module with parameters, by name (DrQ-v2 has no auxiliary modules)."""
        mods: dict[str, nn.Module] = {"encoder": self.encoder, "actor": self.actor, "critic": self.critic,
                                      "critic_target": self.critic_target}
        if self.action_encoder is not None:
            mods["action_encoder"] = self.action_encoder
        if self.shared is not None:
            mods["shared_heads"] = self.shared
        for name, obj in self.objectives.items():
            mods[f"objective.{name}"] = obj
        return mods

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        opts: dict[str, torch.optim.Optimizer] = {"encoder": self.encoder_opt, "actor": self.actor_opt,
                                                  "critic": self.critic_opt}
        if self.aux_opt is not None:
            opts["aux"] = self.aux_opt
        return opts

    def metric_names(self) -> list[str]:
        names = list(CRITIC_METRICS) + list(ACTOR_METRICS)
        for objective in cast("dict[str, Objective]", self.objectives).values():
            names += objective.metric_keys()
        if self.objectives:
            names.append("aux_loss")
        return names

    # ----------------------------------------------------------------- acting
    def encode_action(self, action: torch.Tensor) -> torch.Tensor:
        return self.action_encoder(action) if self.action_encoder is not None else action

    def encode_action_steps(self, actions: torch.Tensor) -> torch.Tensor:
        """(B, K, |A|) -> (B, K, step_dim): each action encoded alone (raw without an action encoder)."""
        return self.action_encoder(actions) if self.action_encoder is not None else actions

    def encode_action_sequence(self, actions: torch.Tensor) -> torch.Tensor:
        if self.action_encoder is not None:
            return self.action_encoder.encode_sequence(actions)
        return actions.flatten(1)

    def stddev(self, step: int) -> float:
        return self.cfg.stddev_schedule(step)

    @torch.no_grad()
    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        """Mean action in eval mode; otherwise a noisy sample, uniform during the first exploration steps."""
        obs_t = torch.as_tensor(obs, device=self.device).float().unsqueeze(0)
        dist = self.actor(self.encoder(obs_t), self.stddev(step))
        if eval_mode:
            action = dist.mean
        else:
            action = dist.sample(clip=None)
            if step < self.explore_steps:
                action.uniform_(-1.0, 1.0)
        return action.cpu().numpy()[0].astype(np.float32)

    # ----------------------------------------------------------------- learning
    def _amp(self):
        """bfloat16 autocast of forward passes when ``agent.amp`` is on, or ``agent.fast`` where bf16 is native (losses
        stay float32)."""
        on = self.cfg.amp or self.fast.amp
        return torch.autocast(device_type=self.device.type, dtype=torch.bfloat16, enabled=on)

    def update(self, batch: dict[str, torch.Tensor], step: int) -> dict[str, float]:
        """One DrQ-v2 update (critic, actor, target) followed by one auxiliary step."""
        metrics: dict[str, float] = {}
        obs = self.aug(batch["obs"])
        next_obs = self.aug(batch["next_obs"])
        with self._amp():
            h = self._encode(obs)
            with torch.no_grad():
                next_h = self._encode(next_obs)
        metrics.update(self._update_critic(h, batch["action"], batch["reward"], batch["discount"], next_h, step))
        metrics.update(self._update_actor(h.detach(), step))
        soft_update(self.critic, self.critic_target, self.cfg.critic_target_tau)
        if self.aux_opt is not None:
            metrics.update(self._update_aux(batch))
        return metrics

    def _update_critic(self, h, action, reward, discount, next_h, step) -> dict[str, float]:
        with self._amp():
            with torch.no_grad():
                dist = self.actor(next_h, self.stddev(step))
                next_action = self.encode_action(dist.sample(clip=self.cfg.stddev_clip))
                tq1, tq2 = self.critic_target(next_h, next_action)
                target_q = (reward + discount * torch.min(tq1, tq2)).float()
            q1, q2 = self.critic(h, self.encode_action(action))
            q1, q2 = q1.float(), q2.float()
            loss = nn.functional.mse_loss(q1, target_q) + nn.functional.mse_loss(q2, target_q)
        self.encoder_opt.zero_grad(set_to_none=True)
        self.critic_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.critic_opt.step()
        self.encoder_opt.step()
        return {"critic_loss": loss.item(), "critic_q1": q1.mean().item(), "critic_q2": q2.mean().item(),
                "critic_target_q": target_q.mean().item()}

    def _update_actor(self, h, step) -> dict[str, float]:
        with self._amp():
            dist = self.actor(h, self.stddev(step))
            action = dist.sample(clip=self.cfg.stddev_clip)
            log_prob = dist.log_prob(action).sum(-1, keepdim=True)
            q1, q2 = self.critic(h, self.encode_action(action))
            loss = -torch.min(q1, q2).float().mean()
        self.actor_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.actor_opt.step()
        return {"actor_loss": loss.item(), "actor_logprob": log_prob.mean().item(),
                "actor_ent": dist.entropy().sum(-1).mean().item()}

    def _update_aux(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        aux = AuxBatch(batch, self._encode, self.aug, self.encode_action_sequence, self.cfg.reward_target,
                       self.encode_action_steps)
        total = torch.zeros((), device=self.device)
        metrics: dict[str, float] = {}
        with self._amp():
            for name, objective in self.objectives.items():
                loss, m = objective(aux)
                total = total + self.weights[name] * loss.float()
                metrics.update(m)
        assert self.aux_opt is not None
        self.aux_opt.zero_grad(set_to_none=True)
        total.backward()
        self.aux_opt.step()
        for objective in cast("dict[str, Objective]", self.objectives).values():
            objective.after_update()
        metrics["aux_loss"] = total.item()
        return metrics


def _unique(params: list[nn.Parameter]) -> list[nn.Parameter]:
    seen, out = set(), []
    for p in params:
        if id(p) not in seen:
            seen.add(id(p))
            out.append(p)
    return out
