"""The DrQ-v2 pixel backbone as one component: what the online agent (``agent.py``), A-LIX (``alix.py``) and the
offline learners on it (TD3+BC, CQL, IQL: ``repro/learners/``) own as their ``backbone`` attribute.

It holds the networks (encoder, optional action encoder u, actor, twin critic, target critic), the auxiliary
objectives (``agent.objectives``) and their shared heads, the optimizers, the augmentation ``aug`` and the encode
function ``_encode`` (the compiled encoder with ``agent.compile``), and the steps an update is made of: encoding a
batch, the critic loss and step, DrQ-v2's actor step, the target update and the auxiliary step. Each learner's
``update()`` calls them in its reference's order. The losses are the pure functions of ``repro/agent/losses.py``.

**Its parts** (:class:`BackboneParts`, a constructor argument, as drqv2's ``DrQV2Agent`` names its encoder, critic
and optimizers): the encoder, the twin critic, the critic loss, the encoder optimizer's parameter groups and the
frames' augmentation, DrQ-v2's by default. A variant passes its own (A-LIX: ``alix.py``; docs/extending.md, "A
backbone variant"); the backbone builds them in one order, which draws the initialisation: augmentation, encoder,
action encoder, actor, critic, target critic (a copy), objectives, optimizers.

``autocast``: with ``agent.amp`` (or ``agent.fast`` where bf16 is native) the online agent runs the encoder's
convolutions under bfloat16 autocast and everything after them in float32: the trunks, the actor's tanh, the Q heads,
the objectives' heads and every loss (``encode``). Under a wider autocast the actor's tanh rounds to exactly +-1 from
|mu| ~ 3.5 on (bf16 has 8 bits), so its gradient is exactly 0 and a policy saturated early never recovers, and the Q
values are rounded to 0.125 at Q ~ 27, coarser than the differences between actions the critic must learn: the
verification run of issue 33 stayed at 136 on cartpole_balance that way (docs/verification.md). The offline learners
encode without it (``autocast=False``), as they always have.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, replace
from typing import Any, ClassVar, Protocol, cast

import numpy as np
import torch
from torch import nn

from repro.agent import fast, losses
from repro.agent.losses import Metrics
from repro.agent.modules import LearnerBase, ModuleSet
from repro.agent.networks import ActionEncoder, Actor, Critic, Encoder, default_latent_action_dim
from repro.agent.objectives import OBJECTIVES, AuxBatch, Objective, ObjectiveContext
from repro.config.compose import objective_params
from repro.config.schema import AgentConfig

EncodedBatch = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]  # h, h', a, r, discount
Augment = Callable[[torch.Tensor], torch.Tensor]  # a batch of uint8 frames -> the encoder's input
ParamGroup = dict[str, Any]  # one parameter group of a torch optimizer: "params" and the options it sets itself


def soft_update(net: nn.Module, target: nn.Module, tau: float) -> None:
    """Polyak averaging: target <- (1 - tau) target + tau net."""
    with torch.no_grad():
        for p, tp in zip(net.parameters(), target.parameters()):
            tp.lerp_(p, tau)


def optimize(loss: torch.Tensor, *opts: torch.optim.Optimizer) -> None:
    """Zero the gradients of ``opts``, backpropagate ``loss`` and step each optimizer."""
    for opt in opts:
        opt.zero_grad(set_to_none=True)
    loss.backward()
    for opt in opts:
        opt.step()


class CriticLoss(Protocol):
    """A critic loss: from the critic and its target, the features ``h`` (with the encoder's gradient), the data
    actions as the critic takes them (``u(a)``), the reward, the discount (gamma^n x not-done), the next features
    ``next_h`` and a policy sample at them as the critic takes it (``u(a')``, no gradient), it returns the loss,
    (Q1, Q2) at the data actions (float32, (B, 1) each) and the critic's metrics (``losses.CRITIC_METRICS``). The
    target is computed without gradient (the target critic's parameters take none)."""

    def __call__(self, critic: nn.Module, critic_target: nn.Module, h: torch.Tensor, action: torch.Tensor,
                 reward: torch.Tensor, discount: torch.Tensor, next_h: torch.Tensor, next_action: torch.Tensor
                 ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor], Metrics]: ...


def twin_critic_loss(critic: nn.Module, critic_target: nn.Module, h: torch.Tensor, action: torch.Tensor,
                     reward: torch.Tensor, discount: torch.Tensor, next_h: torch.Tensor, next_action: torch.Tensor
                     ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor], Metrics]:
    """DrQ-v2's critic loss (a :class:`CriticLoss`): sum_i mse(Q_i(h, u(a)), r + discount x min_i Qtarget_i(h',
    u(a'))), in float32 always (the module docstring says why)."""
    with torch.no_grad():
        tq1, tq2 = critic_target(next_h, next_action)
        target_q = losses.critic_target(reward, discount, tq1, tq2)
    q1, q2 = critic(h, action)
    loss, (q1, q2) = losses.critic_loss(q1, q2, target_q)
    return loss, (q1, q2), losses.critic_metrics(loss, q1, q2, target_q)


def one_group(encoder: nn.Module) -> list[ParamGroup]:
    """DrQ-v2's encoder optimizer: every parameter of the encoder in one group, at ``agent.lr``."""
    return [{"params": list(encoder.parameters())}]


@dataclass(frozen=True)
class BackboneParts:
    """What a backbone variant replaces, each DrQ-v2's by default. The backbone calls each once (the critic twice:
    the critic and its target) with what it knows then; a variant binds its own settings with
    ``functools.partial``."""

    encoder: Callable[[tuple[int, int, int]], Encoder] = Encoder
    """(C, H, W) -> the conv encoder: an :class:`Encoder` (its ``repr_dim``; acting and the objectives use it)."""
    critic: Callable[[int, int, int, int], nn.Module] = Critic
    """(repr_dim, action_in_dim, feature_dim, hidden_dim) -> a twin critic: ``critic(h, u(a))`` gives (Q1, Q2), each
    (B, 1). The backbone builds two: the critic and its target (a copy, without gradient)."""
    critic_loss: CriticLoss = twin_critic_loss
    """The critic step's loss (:class:`CriticLoss`), over the critic this part's ``critic`` built."""
    encoder_groups: Callable[[nn.Module], list[ParamGroup]] = one_group
    """encoder -> the parameter groups of its Adam (torch's ``{"params": [...], option: value}``, options over
    ``agent.lr``). The first group is also trained by the auxiliary step (with objectives); the others are the
    critic step's alone."""
    aug: Callable[[fast.FastPlan], Augment] = fast.shift
    """agent.fast's plan -> the augmentation of the frames before the encoder (DrQ-v2's random shift by 4)."""


DRQV2 = BackboneParts()  # DrQ-v2's parts: the online agent's, TD3+BC's, CQL's, IQL's


class DrQV2Backbone:
    """DrQ-v2's networks, optimizers and update steps, with an optional action encoder and auxiliary objectives;
    ``parts``: the encoder, critic, critic loss, encoder parameter groups and augmentation (DrQ-v2's by default)."""

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", graphs: bool = False, parts: BackboneParts = DRQV2):
        self.cfg = cfg
        self.parts = parts
        self.device = torch.device(device)
        self.action_dim = action_dim
        # agent.fast: the speed-ups resolved for this device (repro/agent/fast.py); all off on the plain path.
        # ``graphs``: whether the owner records its update in a CUDA graph where the plan allows (the online agent)
        plan = fast.resolve_fast(cfg.fast, self.device)
        self.fast = plan if graphs else replace(plan, graphs=False)
        self._std: torch.Tensor | None = None  # fixed_stddev's tensor, read in place of the schedule
        self.aug: Augment = parts.aug(self.fast)  # takes the raw (uint8) frames
        self._build_networks(obs_shape)
        self._build_objectives()
        self._build_optimizers()

    # ----------------------------------------------------------------- building (in this order: it draws the init)
    def _build_networks(self, obs_shape: tuple[int, int, int]) -> None:
        """Encoder, action encoder (``agent.action_encoder``), actor, critic and its target (a copy)."""
        cfg, parts = self.cfg, self.parts
        self.encoder = fast.prepare_encoder(parts.encoder(obs_shape).to(self.device), self.fast)
        # Opt-in speedup: a compiled encoder for updates (acting uses the plain one).
        self._encode: Callable[[torch.Tensor], torch.Tensor] = (
            torch.compile(self.encoder, dynamic=False) if cfg.compile or self.fast.compile else self.encoder)
        self.repr_dim = repr_dim = self.encoder.repr_dim
        self.action_encoder: ActionEncoder | None = None
        if cfg.action_encoder:
            latent = cfg.latent_action_dim or default_latent_action_dim(self.action_dim, cfg.latent_action_rounding)
            self.action_encoder = ActionEncoder(self.action_dim, latent, cfg.K, cfg.action_hidden_dim).to(self.device)
            self.step_dim = latent
        else:
            self.step_dim = self.action_dim  # one encoded action: d_u, or |A| without an action encoder
        self.actor = Actor(repr_dim, self.action_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic = parts.critic(repr_dim, self.step_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic_target = parts.critic(repr_dim, self.step_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.critic_target.requires_grad_(False)

    def _build_objectives(self) -> None:
        """The objectives of nonzero weight, in ``agent.objectives`` order, and the heads they share."""
        cfg = self.cfg
        active = [name for name, w in cfg.objectives.items() if w]
        ctx = ObjectiveContext(repr_dim=self.repr_dim, feature_dim=cfg.feature_dim, hidden_dim=cfg.hidden_dim,
                               action_dim=self.action_dim, K=cfg.K, seq_dim=cfg.K * self.step_dim,
                               step_dim=self.step_dim, encoder=self.encoder)
        objectives = OrderedDict()
        for name in active:
            ctx.params = objective_params(name, cfg.objective_params.get(name))  # typed (checked by validate)
            objectives[name] = OBJECTIVES[name](ctx)
        self.objectives = nn.ModuleDict(objectives).to(self.device)
        self.shared = ctx._shared.to(self.device) if ctx._shared is not None else None
        self.weights = {name: float(cfg.objectives[name]) for name in active}
        # what the replay must return for these objectives (passed to ReplayBuffer.sample)
        self.sample_options = {"future_seq": any(o.needs_future_seq for o in self.objectives.values())}

    def _build_optimizers(self) -> None:
        """Adam for the encoder (over the parts' ``encoder_groups``), the actor, the critic (with the action encoder)
        and, with objectives, one for the auxiliary step over the encoder's first group, the action encoder, the
        shared heads and the objectives."""
        lr, adam = self.cfg.lr, fast.adam(self.fast)  # agent.fast: fused Adam
        groups = self.parts.encoder_groups(self.encoder)
        self.encoder_opt = adam(groups, lr=lr)
        self.actor_opt = adam(self.actor.parameters(), lr=lr)
        critic_params = list(self.critic.parameters())
        if self.action_encoder is not None:
            critic_params += list(self.action_encoder.parameters())
        self.critic_opt = adam(critic_params, lr=lr)
        self.aux_opt: torch.optim.Optimizer | None = None
        if self.objectives:
            aux_params = list(groups[0]["params"]) + list(self.objectives.parameters())
            if self.action_encoder is not None:
                aux_params += list(self.action_encoder.parameters())
            if self.shared is not None:
                aux_params += list(self.shared.parameters())
            self.aux_opt = adam(_unique(aux_params), lr=lr)

    # ----------------------------------------------------------------- modules and state
    def modules(self) -> dict[str, nn.Module]:
        """Every module with parameters, by name (the checkpoint's keys)."""
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

    def aux_metric_names(self) -> list[str]:
        """The auxiliary step's train.csv columns (none without objectives)."""
        names: list[str] = []
        for objective in cast("dict[str, Objective]", self.objectives).values():
            names += objective.metric_keys()
        return names + ["aux_loss"] if self.objectives else names

    # ----------------------------------------------------------------- acting
    def encode_action(self, action: torch.Tensor) -> torch.Tensor:
        """(..., |A|) -> (..., step_dim): each action encoded alone (raw without an action encoder)."""
        return self.action_encoder(action) if self.action_encoder is not None else action

    def encode_action_sequence(self, actions: torch.Tensor) -> torch.Tensor:
        if self.action_encoder is not None:
            return self.action_encoder.encode_sequence(actions)
        return actions.flatten(1)

    def stddev(self, step: int) -> float | torch.Tensor:
        """The exploration noise's stddev at agent step ``step`` (``agent.stddev_schedule``), or the tensor of
        :meth:`fixed_stddev` while one is set."""
        return self.cfg.stddev_schedule(step) if self._std is None else self._std

    @contextmanager
    def fixed_stddev(self, std: torch.Tensor) -> Iterator[None]:
        """Within the block, every stddev the update steps read is ``std`` (a 0-d tensor, whatever the step): how a
        CUDA graph of the update reads the schedule's value of each replay (repro/agent/graphs.py)."""
        self._std = std
        try:
            yield
        finally:
            self._std = None

    @torch.no_grad()
    def act(self, obs: np.ndarray, step: int, eval_mode: bool, explore_steps: int = 0) -> np.ndarray:
        """Mean action in eval mode; otherwise a noisy sample, uniform during the first ``explore_steps``."""
        obs_t = torch.as_tensor(obs, device=self.device).float().unsqueeze(0)
        dist = self.actor(self.encoder(obs_t), self.stddev(step))
        if eval_mode:
            action = dist.mean
        else:
            action = dist.sample(clip=None)
            if step < explore_steps:
                action.uniform_(-1.0, 1.0)
        return action.cpu().numpy()[0].astype(np.float32)

    # ----------------------------------------------------------------- the steps an update is made of
    def autocast(self, enabled: bool = True) -> torch.autocast:
        """bfloat16 autocast when ``enabled`` and ``agent.amp`` is on, or ``agent.fast`` where bf16 is native: used
        around the encoder's convolutions only (``encode``)."""
        on = enabled and (self.cfg.amp or self.fast.amp)
        # a CUDA graph must not keep autocast's cast weights from its recording (graphs.py): no cache then
        return torch.autocast(device_type=self.device.type, dtype=torch.bfloat16, enabled=on,
                              cache_enabled=not self.fast.graphs)

    def encode(self, obs: torch.Tensor, autocast: bool = True) -> torch.Tensor:
        """The encoder's output for shifted frames, in float32: its convolutions under :meth:`autocast` (bf16 with
        ``agent.amp`` / ``agent.fast``), nothing after them (see the module docstring)."""
        return self.encode_with(self._encode, obs, autocast)

    def encode_with(self, encoder: Callable[[torch.Tensor], torch.Tensor], obs: torch.Tensor,
                    autocast: bool = True) -> torch.Tensor:
        """:meth:`encode` with another encoder of the same kind (an objective's momentum target)."""
        with self.autocast(autocast):
            h = encoder(obs)
        return h.float()

    def encode_batch(self, batch: dict[str, torch.Tensor], autocast: bool = True) -> EncodedBatch:
        """(h, h', a, r, discount): the shifted frames encoded (h with the encoder's gradient, h' without) and the
        batch's action, reward and discount (gamma^n x not-done). Actions are data: no gradient flows into them."""
        obs = self.aug(batch["obs"])  # the shift converts the uint8 frames (agent.fast: after cropping)
        next_obs = self.aug(batch["next_obs"])
        h = self.encode(obs, autocast)
        with torch.no_grad():
            next_h = self.encode(next_obs, autocast)
        return h, next_h, batch["action"].detach(), batch["reward"], batch["discount"]

    def critic_loss(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                    next_h: torch.Tensor, step: int
                    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor], Metrics]:
        """The parts' critic loss (DrQ-v2's: :func:`twin_critic_loss`) at a' a clipped-noise policy sample at h';
        returns the loss, (Q1, Q2) at the data actions and the metrics. In float32 always (the module docstring
        says why)."""
        with torch.no_grad():
            dist = self.actor(next_h, self.stddev(step))
            next_action = self.encode_action(dist.sample(clip=self.cfg.stddev_clip))
        return self.parts.critic_loss(self.critic, self.critic_target, h, self.encode_action(action), reward,
                                      discount, next_h, next_action)

    def critic_step(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                    next_h: torch.Tensor, step: int) -> Metrics:
        """One step of DrQ-v2's critic loss on the critic (with the action encoder) and the encoder."""
        loss, _, metrics = self.critic_loss(h, action, reward, discount, next_h, step)
        optimize(loss, self.critic_opt, self.encoder_opt)
        return metrics

    def actor_step(self, h: torch.Tensor, step: int) -> Metrics:
        """One step of DrQ-v2's actor loss -min_i Q_i(h, u(a~)) on the actor (``h``: detached features), in
        float32 always: the policy's tanh saturates to exactly +-1 in bf16 (the module docstring)."""
        dist = self.actor(h, self.stddev(step))
        action = dist.sample(clip=self.cfg.stddev_clip)
        log_prob = dist.log_prob(action).sum(-1, keepdim=True)
        q1, q2 = self.critic(h, self.encode_action(action))
        loss = losses.actor_loss(q1, q2)
        optimize(loss, self.actor_opt)
        return losses.actor_metrics(loss, log_prob, dist.entropy().sum(-1), dist.loc, dist.pre_tanh)

    def update_target(self) -> None:
        """Polyak averaging of the target critic (``critic_target_tau``)."""
        soft_update(self.critic, self.critic_target, self.cfg.critic_target_tau)

    def aux_step(self, batch: dict[str, torch.Tensor]) -> Metrics:
        """One step of the weighted sum of the auxiliary objectives (with their own fresh shifts of the frames);
        without objectives nothing, and no metrics."""
        if self.aux_opt is None:
            return {}
        aux = AuxBatch(batch, self.encode, self.aug, self.encode_action_sequence, self.cfg.reward_target,
                       self.encode_action, self.encode_with)
        total = torch.zeros((), device=self.device)
        metrics: Metrics = {}
        for name, objective in self.objectives.items():  # the encoder under autocast (encode), the heads in float32
            loss, m = objective(aux)
            total = total + self.weights[name] * loss
            metrics.update(m)
        optimize(total, self.aux_opt)
        for objective in cast("dict[str, Objective]", self.objectives).values():
            objective.after_update()
        metrics["aux_loss"] = total.detach()
        return metrics


class BackboneLearner(LearnerBase, ModuleSet):
    """What a learner that owns a ``DrQV2Backbone`` (as ``backbone``) forwards to it: its modules and optimizers
    (a learner with networks of its own extends them), acting, the noise schedule, the objectives' weights, the
    action encoder and the auxiliary step's metric names after the learner's own ``update_metrics``. Its
    constructor builds the backbone (the learner registry's signature, and the backbone's ``parts``: a variant's
    learner passes its own, as A-LIX does); a learner with networks of its own builds them after it. Not a learner
    itself: a learner adds ``update()``."""

    untrained = ("critic_target",)  # the target critic follows by soft updates: not counted
    update_metrics: ClassVar[tuple[str, ...]]  # the train.csv columns of update(), before the auxiliary step's
    explores: ClassVar[bool] = False  # whether acting explores (online): offline learners ignore explore_steps
    graphed: ClassVar[bool] = False  # whether update() is recorded in a CUDA graph where agent.fast allows it

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0, parts: BackboneParts = DRQV2):
        self.cfg = cfg
        self.explore_steps = explore_steps if self.explores else 0  # agent steps of uniform random actions
        self.backbone = DrQV2Backbone(cfg, obs_shape, action_dim, device, graphs=self.graphed, parts=parts)
        self.sample_options = self.backbone.sample_options  # what the replay returns for the objectives

    def modules(self) -> dict[str, nn.Module]:
        return self.backbone.modules()

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return self.backbone.optimizers()

    def metric_names(self) -> list[str]:
        return list(self.update_metrics) + self.backbone.aux_metric_names()

    @property
    def action_dim(self) -> int:
        return self.backbone.action_dim

    @property
    def device(self) -> torch.device:
        return self.backbone.device

    @property
    def weights(self) -> Mapping[str, float]:
        return self.backbone.weights

    @property
    def action_encoder(self) -> ActionEncoder | None:
        return self.backbone.action_encoder

    def acting_modules(self) -> dict[str, nn.Module]:
        """The encoder and the actor: what a recorded policy snapshot keeps (the online protocol's hook)."""
        modules = self.modules()
        return {"encoder": modules["encoder"], "actor": modules["actor"]}

    def stddev(self, step: int) -> float:
        return self.cfg.stddev_schedule(step)

    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        return self.backbone.act(obs, step, eval_mode, self.explore_steps)


def _unique(params: list[nn.Parameter]) -> list[nn.Parameter]:
    seen, out = set(), []
    for p in params:
        if id(p) not in seen:
            seen.add(id(p))
            out.append(p)
    return out
