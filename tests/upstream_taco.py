"""The upstream TACO agent's update, re-expressed from facts, to compare this project's update against it.

Source of the facts: github FrankZheng2022/TACO, ``agents/taco.py`` (``RandomShiftsAug``, ``Encoder``, ``TACO``,
``Actor``, ``Critic``, ``TACOAgent``) and ``utils.py`` (``ActionEncoding``, ``weight_init``, ``TruncatedNormal``,
``soft_update_params``, ``schedule``), HEAD 84c38e3 (``agents/taco.py`` at blob commit 46534b4). This module is
written in this project's words; it copies no upstream code. Used by ``scripts/upstream_drift.py`` and
``tests/test_upstream_drift.py``.

What upstream's agent is, as facts
----------------------------------
Modules (built in this order; every Linear orthogonal with gain 1 and zero bias, every Conv2d orthogonal with the
ReLU gain and zero bias):

1. ``act_tok``, the action encoder: ``action_tokenizer`` = Linear(|A|, 64), Tanh, Linear(64, d_u), and
   ``action_seq_tokenizer`` = Linear(K d_u, K d_u), LayerNorm, Tanh. Called with ``seq=False`` on (B, |A|) it gives
   (B, d_u); with ``seq=True`` on (B, K, |A|) it tokenizes each step, reshapes to (B, K d_u) and applies the
   sequence tokenizer. d_u = int(1.25 |A|) + 1 by default.
2. ``encoder``: obs / 255 - 0.5, four 3x3 convolutions (stride 2, 1, 1, 1) of 32 channels with ReLU, flattened.
3. ``actor``: trunk Linear(repr, 50), LayerNorm, Tanh; policy MLP 50 -> hidden -> hidden -> |A| (ReLU);
   mu = tanh(policy output); a ``TruncatedNormal(mu, std)``.
4. ``critic`` and ``critic_target`` (a state-dict copy of the critic): trunk as the actor's; twin heads ``Q1``,
   ``Q2`` (50 + d_u) -> hidden -> hidden -> 1. ``forward(obs, action, act_tok)`` encodes the action with
   ``act_tok`` (per step, ``seq=False``) before concatenating it with the trunk's output. The target critic is
   called with the ONLINE ``act_tok`` (there is no target action encoder).
5. ``TACO``: holds the ``encoder`` and ``act_tok`` as submodules (the same objects), ``proj_sa`` (Linear(50 + K d_u,
   hidden), ReLU, Linear(hidden, 50)), ``proj_s`` (Linear(repr, 50), LayerNorm, Tanh), ``reward`` (Linear(50 + K d_u,
   hidden), ReLU, Linear(hidden, 1)) and ``W`` = torch.rand(50, 50). Its constructor applies the weight init to
   every submodule, so the encoder's and the action encoder's weights are drawn a second time there (W, a bare
   Parameter, keeps its uniform draw). Only the random draws differ from this project's build order, not the
   distribution; the comparison copies this project's initial weights in, so it does not matter here.

Optimizers (Adam, lr 1e-4 everywhere; on CPU torch's default is the single-tensor loop, so each parameter's step
depends only on its own state):

* ``encoder_opt`` over the encoder AND ``act_tok``;
* ``actor_opt`` over the actor;
* ``critic_opt`` over the critic only;
* ``taco_opt`` over ``TACO.parameters()``: W, the encoder, ``proj_sa``, ``act_tok``, ``proj_s``, ``reward``.

This project groups the action encoder with the critic's optimizer instead of the encoder's (``critic_opt``) and
names the TACO optimizer ``aux_opt``; both put each parameter under exactly the same Adam steps (one in the critic
step, one in the TACO step for the encoder and the action encoder), so the grouping is the same arithmetic.

One update (``TACOAgent.update``), with the random draws in upstream's order:

1. shift ``obs`` [draw 1: shifts], shift ``next_obs`` [draw 2]; encode both, ``next_obs`` under no_grad.
2. critic step (``update_critic``): under no_grad, std = schedule(step), a' = actor(next_h).sample(clip 0.3)
   [draw 3: normal noise (B, |A|)], target = r + discount * min(Qt1, Qt2)(next_h, act_tok(a')); the loss
   mse(Q1, target) + mse(Q2, target) at (h, act_tok(a)); ``encoder_opt.zero_grad(set_to_none=True)``,
   ``critic_opt.zero_grad(set_to_none=True)``, backward, ``critic_opt.step()`` then ``encoder_opt.step()``.
3. actor step (``update_actor``) on h.detach(): a~ = sample(clip 0.3) [draw 4: normal noise], log_prob,
   loss -mean min(Q1, Q2)(h, act_tok(a~)); ``actor_opt.zero_grad(set_to_none=True)``, backward, ``actor_opt.step()``.
   The backward also leaves gradients on the critic's and ``act_tok``'s parameters (nothing detaches them), which
   no optimizer steps here: STALE gradients. ``act_tok``'s are dropped by ``taco_opt.zero_grad()`` in step 5 before
   anything reads them; the critic's stay until the next update's ``critic_opt.zero_grad(set_to_none=True)``. So
   no stale gradient is ever used (this project's ``optimize`` does the same: it zeroes only the stepped
   optimizer's parameters, and the next step that uses them zeroes them first).
4. soft update: target <- tau * online + (1 - tau) * target (``soft_update_params``, written as that expression;
   this project uses ``lerp_``, the same value up to rounding).
5. TACO step (``update_taco``) on the RAW batch: anchor = shift(obs) [draw 5], positive = shift(obs) [draw 6];
   z_a = proj_s(encoder(anchor)) with gradient, z_pos = the same under no_grad; curl logits z_a W z_pos^T minus
   the row max, cross-entropy against the diagonal; ``act_tok(action, seq=False)`` is computed and never used
   (no draw, no gradient); u = act_tok(action_seq, seq=True); reward loss mse(reward(cat[z_a, u]), r) with r the
   batch's n-step reward; future z = proj_s(encoder(shift(obs_{t+K}))) [draw 7] under no_grad; taco logits
   proj_sa(cat[z_a, u]) W z^T minus the row max, cross-entropy against the diagonal;
   ``taco_opt.zero_grad()``, backward of taco + curl + reward, ``taco_opt.step()``.
   ``zero_grad()`` without an argument sets gradients to None on torch >= 2.0; upstream's environment.yml pins no
   torch version (cudatoolkit 11.1, so torch 1.8-1.10 in 2023), where it zeroes them in place instead. With all
   three losses on, every parameter of ``taco_opt`` receives a gradient in this backward, so both give the same
   step; with a loss switched off its head would get a zero gradient on torch 1.x, and Adam's moments of a
   parameter that never had a gradient are 0, so it still does not move.

Random shift (``RandomShiftsAug``): replicate-pad by 4, then ``grid_sample`` (bilinear, zero padding,
align_corners False) at a grid of pixel centres linspace(-1 + 1/(h+8), 1 - 1/(h+8), h+8)[:h] (x along the width,
y along the height) plus an integer shift s drawn by ``torch.randint(0, 9, (n, 1, 1, 2))`` as FLOATS, scaled by
2 / (h+8); component 0 of s moves x (columns), component 1 moves y (rows). Float rounding of the grid can make a
sample fall a hair off the pixel centre, so the result may differ from an exact integer crop in the last bits.
This project draws ``torch.randint(0, 9, (n, 2))`` (int64; the same integers from the same RNG state) and crops
exactly, component 0 moving ROWS: from one RNG state the two shift an image along swapped axes. Its auxiliary
step also draws anchor, future, positive (the objectives' order taco, curl, reward) where upstream draws anchor,
positive, future. So one seed gives the two codes different augmentations; a comparison feeds both the same
shifts by role (``shifts=`` here, ``FedShift`` in ``scripts/upstream_drift.py``).

``TruncatedNormal.sample`` draws ``empty(shape).normal_()`` (torch's ``_standard_normal``), multiplies by the
scale in place, clamps to +-clip, adds the mean and clamps to [-1 + 1e-6, 1 - 1e-6] with a straight-through
gradient. ``torch.randn`` (this project's draw) is ``empty().normal_()`` too: the same numbers from one RNG state.

Diagnostic switches (NOT upstream; each replaces one rounding-level difference by this project's arithmetic, to
find which one the two codes differ by): ``grid_shift=False`` crops exactly instead of ``grid_sample``;
``polyak="lerp"`` soft-updates with ``lerp_``; ``aux_order="project"`` builds the TACO step's losses in this
project's order (taco, curl, reward) instead of upstream's (curl, reward, taco), which changes the order in which
autograd sums the three gradients reaching z_a.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.config.schema import AgentConfig

PAD = 4
ROLES_UPSTREAM = ("obs", "next_obs", "anchor", "positive", "future")  # upstream's draw order within one update


# ``utils.weight_init``: orthogonal Linear (gain 1) and Conv2d (ReLU gain) weights, biases zero: the same rule as this
# project's (the comparison copies the weights anyway: the init only decides the shapes' first values)
upstream_init = orthogonal_init


class GridShift(nn.Module):
    """``RandomShiftsAug``: replicate padding, then bilinear ``grid_sample`` at a float grid moved by integer
    shifts. ``shift``: (n, 2) integers (x, y) in [0, 2 pad] to use instead of drawing them; ``exact``: crop the
    padded frames at those integer offsets instead (a diagnostic, not upstream)."""

    def __init__(self, pad: int = PAD, exact: bool = False):
        super().__init__()
        self.pad, self.exact = pad, exact

    def forward(self, x: torch.Tensor, shift: torch.Tensor | None = None) -> torch.Tensor:
        n, _, h, w = x.shape
        assert h == w, "upstream's shift assumes square frames"
        side = h + 2 * self.pad
        padded = F.pad(x, (self.pad,) * 4, mode="replicate")
        if shift is None:  # upstream's draw: float integers, component 0 for x, 1 for y
            s = torch.randint(0, 2 * self.pad + 1, size=(n, 1, 1, 2), device=x.device, dtype=x.dtype)
        else:
            s = shift.to(device=x.device, dtype=x.dtype).reshape(n, 1, 1, 2)
        if self.exact:
            off = s.reshape(n, 2).long()
            rows = off[:, 1:2] + torch.arange(h, device=x.device)[None]
            cols = off[:, 0:1] + torch.arange(w, device=x.device)[None]
            idx = torch.arange(n, device=x.device)[:, None, None]
            return padded.permute(0, 2, 3, 1)[idx, rows[:, :, None], cols[:, None, :]].permute(0, 3, 1, 2).contiguous()
        half = 1.0 / side
        centres = torch.linspace(-1.0 + half, 1.0 - half, side, device=x.device, dtype=x.dtype)[:h]
        gx = centres.unsqueeze(0).repeat(h, 1)  # [i, j] = centres[j]: x runs along the width
        grid = torch.stack([gx, gx.t()], dim=2).unsqueeze(0).repeat(n, 1, 1, 1)  # (n, h, w, (x, y))
        s = s * (2.0 / side)
        return F.grid_sample(padded, grid + s, padding_mode="zeros", align_corners=False)


class UpActionEncoding(nn.Module):
    """``utils.ActionEncoding``."""

    def __init__(self, action_dim: int, latent: int, K: int):
        super().__init__()
        self.action_tokenizer = nn.Sequential(nn.Linear(action_dim, 64), nn.Tanh(), nn.Linear(64, latent))
        self.action_seq_tokenizer = nn.Sequential(nn.Linear(latent * K, latent * K), nn.LayerNorm(latent * K),
                                                  nn.Tanh())
        self.apply(upstream_init)

    def forward(self, action: torch.Tensor, seq: bool = False) -> torch.Tensor:
        tokens = self.action_tokenizer(action)
        if not seq:
            return tokens
        return self.action_seq_tokenizer(tokens.reshape(action.shape[0], -1))


class UpEncoder(nn.Module):
    def __init__(self, obs_shape: tuple[int, int, int]):
        super().__init__()
        layers: list[nn.Module] = []
        for i in range(4):
            layers += [nn.Conv2d(obs_shape[0] if i == 0 else 32, 32, 3, stride=2 if i == 0 else 1), nn.ReLU()]
        self.convnet = nn.Sequential(*layers)
        side = (obs_shape[1] - 3) // 2 + 1 - 6  # upstream hard-codes 35 (84x84 frames)
        self.repr_dim = 32 * side * side
        self.apply(upstream_init)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        h = self.convnet(obs / 255.0 - 0.5)
        return h.view(h.shape[0], -1)


def _trunk(repr_dim: int, feature_dim: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(repr_dim, feature_dim), nn.LayerNorm(feature_dim), nn.Tanh())


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class UpTruncatedNormal(torch.distributions.Normal):
    """``utils.TruncatedNormal``: noise from ``empty().normal_()`` scaled in place, clipped, added to the mean, and
    the sum clamped to (-1, 1) by 1e-6 with a straight-through gradient."""

    def __init__(self, loc: torch.Tensor, scale: torch.Tensor, eps: float = 1e-6):
        super().__init__(loc, scale, validate_args=False)
        self.eps = eps

    def sample(self, clip: float | None = None,  # type: ignore[override]
               sample_shape: torch.Size = torch.Size()) -> torch.Tensor:
        noise = torch.empty(self._extended_shape(sample_shape), dtype=self.loc.dtype,
                            device=self.loc.device).normal_()
        noise *= self.scale
        if clip is not None:
            noise = noise.clamp(-clip, clip)
        x = self.loc + noise
        return x - x.detach() + x.clamp(-1.0 + self.eps, 1.0 - self.eps).detach()


class UpActor(nn.Module):
    def __init__(self, repr_dim: int, action_dim: int, feature_dim: int, hidden_dim: int):
        super().__init__()
        self.trunk = _trunk(repr_dim, feature_dim)
        self.policy = _mlp([feature_dim, hidden_dim, hidden_dim, action_dim])
        self.apply(upstream_init)

    def pre_tanh(self, h: torch.Tensor) -> torch.Tensor:
        return self.policy(self.trunk(h))

    def forward(self, h: torch.Tensor, std: float) -> UpTruncatedNormal:
        mu = torch.tanh(self.pre_tanh(h))
        return UpTruncatedNormal(mu, torch.ones_like(mu) * std)


class UpCritic(nn.Module):
    def __init__(self, repr_dim: int, latent: int, feature_dim: int, hidden_dim: int):
        super().__init__()
        self.trunk = _trunk(repr_dim, feature_dim)
        self.Q1 = _mlp([feature_dim + latent, hidden_dim, hidden_dim, 1])
        self.Q2 = _mlp([feature_dim + latent, hidden_dim, hidden_dim, 1])
        self.apply(upstream_init)

    def forward(self, h: torch.Tensor, action: torch.Tensor,
                act_tok: UpActionEncoding | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        if act_tok is not None:
            action = act_tok(action)
        x = torch.cat([self.trunk(h), action], dim=-1)
        return self.Q1(x), self.Q2(x)


class UpTACOModule(nn.Module):
    """Upstream's ``TACO`` module: the encoder and the action encoder as submodules, the heads, and W."""

    def __init__(self, repr_dim: int, feature_dim: int, latent: int, hidden_dim: int, act_tok: UpActionEncoding,
                 encoder: UpEncoder, K: int):
        super().__init__()
        self.encoder = encoder
        self.proj_sa = _mlp([feature_dim + latent * K, hidden_dim, feature_dim])
        self.act_tok = act_tok
        self.proj_s = _trunk(repr_dim, feature_dim)
        self.reward = _mlp([feature_dim + latent * K, hidden_dim, 1])
        self.W = nn.Parameter(torch.rand(feature_dim, feature_dim))
        self.apply(upstream_init)  # re-draws the encoder's and act_tok's weights too (their submodules)

    def encode(self, x: torch.Tensor, grad: bool = True) -> torch.Tensor:
        with torch.set_grad_enabled(grad and torch.is_grad_enabled()):
            return self.proj_s(self.encoder(x))

    def logits(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        out = torch.matmul(a, torch.matmul(self.W, b.T))
        return out - torch.max(out, 1)[0][:, None]


class UpstreamTACO:
    """Upstream's ``TACOAgent`` (update and its parts; no acting loop, no replay). ``cfg``: this project's agent
    config, read for the values upstream takes from its own (lr, sizes, tau, clip, K, the std schedule, the latent
    action size, which of curl and reward are on; the taco loss is always on upstream)."""

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int, latent: int,
                 grid_shift: bool = True, polyak: str = "upstream", aux_order: str = "upstream"):
        assert polyak in ("upstream", "lerp") and aux_order in ("upstream", "project")
        self.cfg = cfg
        self.tau, self.clip = cfg.critic_target_tau, cfg.stddev_clip
        self.use_curl = bool(cfg.objectives.get("curl", 0))
        self.use_reward = bool(cfg.objectives.get("reward", 0))
        self.polyak, self.aux_order = polyak, aux_order
        self.act_tok = UpActionEncoding(action_dim, latent, cfg.K)
        self.encoder = UpEncoder(obs_shape)
        repr_dim = self.encoder.repr_dim
        self.actor = UpActor(repr_dim, action_dim, cfg.feature_dim, cfg.hidden_dim)
        self.critic = UpCritic(repr_dim, latent, cfg.feature_dim, cfg.hidden_dim)
        self.critic_target = UpCritic(repr_dim, latent, cfg.feature_dim, cfg.hidden_dim)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.TACO = UpTACOModule(repr_dim, cfg.feature_dim, latent, cfg.hidden_dim, self.act_tok, self.encoder,
                                 cfg.K)
        lr = cfg.lr
        self.encoder_opt = torch.optim.Adam([*self.encoder.parameters(), *self.act_tok.parameters()], lr=lr)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=lr)
        self.taco_opt = torch.optim.Adam(self.TACO.parameters(), lr=lr)
        self.aug = GridShift(PAD, exact=not grid_shift)

    def stddev(self, step: int) -> float:
        """``utils.schedule`` of ``linear(start, end, duration)``: the mix clipped to [0, 1] (float64)."""
        s = self.cfg.stddev_schedule
        mix = min(max(step / s.duration, 0.0), 1.0)
        return (1.0 - mix) * s.start + mix * s.end

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"encoder": self.encoder_opt, "actor": self.actor_opt, "critic": self.critic_opt,
                "taco": self.taco_opt}

    # ------------------------------------------------------------------ the update, in upstream's order
    def update(self, batch: Mapping[str, torch.Tensor], step: int,
               shifts: Mapping[str, torch.Tensor] | None = None) -> dict[str, torch.Tensor]:
        """One ``TACOAgent.update`` on a batch of this project's replay (obs, action, action_seq, reward, discount,
        next_obs, future_obs = upstream's r_next_obs). ``shifts``: (n, 2) integer (x, y) shifts by role
        (``ROLES_UPSTREAM``) instead of drawing them; the policy noise is drawn from torch's RNG either way."""
        def shift(x: torch.Tensor, role: str) -> torch.Tensor:
            return self.aug(x.float(), None if shifts is None else shifts[role])

        obs, action = batch["obs"], batch["action"]
        reward, discount = batch["reward"], batch["discount"]
        h = self.encoder(shift(obs, "obs"))
        next_shifted = shift(batch["next_obs"], "next_obs")
        with torch.no_grad():
            next_h = self.encoder(next_shifted)
        metrics = self._critic_step(h, action, reward, discount, next_h, step)
        metrics.update(self._actor_step(h.detach(), step))
        self._soft_update()
        metrics.update(self._taco_step(batch, shift))
        return metrics

    def _critic_step(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                     next_h: torch.Tensor, step: int) -> dict[str, torch.Tensor]:
        with torch.no_grad():
            next_action = self.actor(next_h, self.stddev(step)).sample(clip=self.clip)
            tq1, tq2 = self.critic_target(next_h, next_action, self.act_tok)
            target = reward + discount * torch.min(tq1, tq2)
        q1, q2 = self.critic(h, action, self.act_tok)
        loss = F.mse_loss(q1, target) + F.mse_loss(q2, target)
        self.encoder_opt.zero_grad(set_to_none=True)
        self.critic_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.critic_opt.step()
        self.encoder_opt.step()
        return {"critic_target_q": target.mean().detach(), "critic_q1": q1.mean().detach(),
                "critic_q2": q2.mean().detach(), "critic_loss": loss.detach()}

    def _actor_step(self, h: torch.Tensor, step: int) -> dict[str, torch.Tensor]:
        dist = self.actor(h, self.stddev(step))
        a = dist.sample(clip=self.clip)
        log_prob = dist.log_prob(a).sum(-1, keepdim=True)
        q1, q2 = self.critic(h, a, self.act_tok)  # gradients reach the critic and act_tok too (stale, unused)
        loss = -torch.min(q1, q2).mean()
        self.actor_opt.zero_grad(set_to_none=True)
        loss.backward()
        self.actor_opt.step()
        return {"actor_loss": loss.detach(), "actor_logprob": log_prob.mean().detach(),
                "actor_ent": dist.entropy().sum(dim=-1).mean().detach()}

    def _soft_update(self) -> None:
        with torch.no_grad():
            for p, tp in zip(self.critic.parameters(), self.critic_target.parameters()):
                if self.polyak == "lerp":
                    tp.lerp_(p, self.tau)
                else:
                    tp.copy_(self.tau * p + (1 - self.tau) * tp)

    def _taco_step(self, batch: Mapping[str, torch.Tensor], shift) -> dict[str, torch.Tensor]:
        taco = self.TACO
        obs = batch["obs"]
        anchor = shift(obs, "anchor")
        positive = shift(obs, "positive")
        z_a = taco.encode(anchor)
        z_pos = taco.encode(positive, grad=False)
        labels = torch.arange(z_a.shape[0], device=z_a.device)

        def curl() -> torch.Tensor:
            if not self.use_curl:
                return torch.tensor(0.0)
            return F.cross_entropy(taco.logits(z_a, z_pos), labels)

        def reward_loss(u: torch.Tensor) -> torch.Tensor:
            if not self.use_reward:
                return torch.tensor(0.0)
            return F.mse_loss(taco.reward(torch.cat([z_a, u], dim=-1)), batch["reward"])

        def taco_loss(u: torch.Tensor) -> torch.Tensor:
            z_future = taco.encode(shift(batch["future_obs"], "future"), grad=False)
            return F.cross_entropy(taco.logits(taco.proj_sa(torch.cat([z_a, u], dim=-1)), z_future), labels)

        if self.aux_order == "upstream":
            c = curl()
            taco.act_tok(batch["action"], seq=False)  # computed upstream and never used
            u = taco.act_tok(batch["action_seq"], seq=True)
            r = reward_loss(u)
            t = taco_loss(u)
        else:  # diagnostic: the losses built in this project's order (taco, curl, reward)
            u = taco.act_tok(batch["action_seq"], seq=True)
            t = taco_loss(u)
            c = curl()
            r = reward_loss(u)
        self.taco_opt.zero_grad()
        (t + c + r).backward()
        self.taco_opt.step()
        return {"reward_loss": r.detach(), "curl_loss": c.detach(), "taco_loss": t.detach()}


# ---------------------------------------------------------------------- this project's weights into upstream's
# (this project's module, its parameter path) -> (upstream's module, its path); trunks and MLPs share layouts
PREFIXES = (
    ("encoder", "", "encoder", ""),
    ("actor", "", "actor", ""),
    ("critic", "q1.", "critic", "Q1."),
    ("critic", "q2.", "critic", "Q2."),
    ("critic", "trunk.", "critic", "trunk."),
    ("critic_target", "q1.", "critic_target", "Q1."),
    ("critic_target", "q2.", "critic_target", "Q2."),
    ("critic_target", "trunk.", "critic_target", "trunk."),
    ("action_encoder", "step.", "act_tok", "action_tokenizer."),
    ("action_encoder", "seq.", "act_tok", "action_seq_tokenizer."),
    ("shared_heads", "state_proj.", "TACO", "proj_s."),
    ("shared_heads", "W", "TACO", "W"),
    ("objective.taco", "proj_sa.", "TACO", "proj_sa."),
    ("objective.reward", "head.", "TACO", "reward."),
)


def upstream_modules(up: UpstreamTACO) -> dict[str, nn.Module]:
    return {"encoder": up.encoder, "actor": up.actor, "critic": up.critic, "critic_target": up.critic_target,
            "act_tok": up.act_tok, "TACO": up.TACO}


def parameter_pairs(backbone, up: UpstreamTACO) -> list[tuple[str, str, torch.Tensor, torch.Tensor]]:
    """Every (this project's name, upstream's name, its tensor, upstream's tensor) pair of parameters and buffers,
    one-to-one: each of this project's tensors and each of upstream's distinct tensors (the TACO module's encoder
    and act_tok are the agent's own) maps exactly once."""
    ours = backbone.modules()
    ups = upstream_modules(up)
    pairs: list[tuple[str, str, torch.Tensor, torch.Tensor]] = []
    for mod, pre, umod, upre in PREFIXES:
        state: dict[str, torch.Tensor] = {**dict(ours[mod].named_parameters()), **dict(ours[mod].named_buffers())}
        ustate: dict[str, torch.Tensor] = {**dict(ups[umod].named_parameters()), **dict(ups[umod].named_buffers())}
        for name, t in state.items():
            if name == pre or (pre.endswith(".") and name.startswith(pre)) or (mod in ("encoder", "actor")):
                uname = upre + name[len(pre):]
                pairs.append((f"{mod}.{name}", f"{umod}.{uname}", t, ustate[uname]))
    ours_ids = {id(t) for m in ours.values() for t in [*m.parameters(), *m.buffers()]}  # shared heads once
    ups_ids = {id(t) for m in ups.values() for t in [*m.parameters(), *m.buffers()]}
    got_ours = [id(p[2]) for p in pairs]
    got_ups = [id(p[3]) for p in pairs]
    assert len(set(got_ours)) == len(got_ours) and set(got_ours) == ours_ids, \
        "a parameter of this project's agent is not mapped exactly once"
    assert len(set(got_ups)) == len(got_ups) and set(got_ups) == ups_ids, \
        "a parameter of the upstream agent is not mapped exactly once"
    return pairs


def load_from_project(up: UpstreamTACO, backbone) -> None:
    """Copy every weight of this project's TACO backbone (``agent.backbone``) into ``up``."""
    with torch.no_grad():
        for _, _, t, u in parameter_pairs(backbone, up):
            assert t.shape == u.shape, (t.shape, u.shape)
            u.copy_(t)


def from_project(agent, obs_shape: tuple[int, int, int], cls: type[UpstreamTACO] | None = None,
                 **switches) -> UpstreamTACO:
    """An upstream agent (``cls``, default :class:`UpstreamTACO`) with ``agent``'s (this project's TACO ``Agent``)
    config and initial weights."""
    bb = agent.backbone
    assert bb.action_encoder is not None and list(bb.objectives) == ["taco", "curl", "reward"], \
        "the upstream agent is TACO with its action encoder and the taco, curl and reward objectives"
    state = torch.get_rng_state()  # building upstream's modules draws; leave the caller's RNG as it was
    up = (cls or UpstreamTACO)(agent.cfg, obs_shape, bb.action_dim, bb.step_dim, **switches)
    torch.set_rng_state(state)
    load_from_project(up, bb)
    return up


# ---------------------------------------------------------------------- driving both on the same batches and draws
class FedShift:
    """Wraps this project's shift (``RandomShift`` or the fast path's ``ShiftU8``, called as it is) so that its one
    ``torch.randint(0, 2 pad + 1, (n, 2))`` returns the offsets fed for the call's role instead of drawing. The role
    is told by which batch tensor the call shifts: ``obs`` (1st call: the critic's, 2nd: the anchor, 3rd: the
    positive), ``next_obs`` or ``future_obs``; offsets are (n, 2) integers (rows, cols), this project's order."""

    ROLE_OF = {"obs": ("obs", "anchor", "positive"), "next_obs": ("next_obs",), "future_obs": ("future",)}

    def __init__(self, inner):
        self.inner = inner
        self.batch: Mapping[str, torch.Tensor] = {}
        self.offsets: Mapping[str, torch.Tensor] = {}
        self.calls: list[str] = []

    def feed(self, batch: Mapping[str, torch.Tensor], offsets: Mapping[str, torch.Tensor]) -> None:
        self.batch, self.offsets, self.calls = batch, offsets, []

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        key = next(k for k in self.ROLE_OF if self.batch.get(k) is x)
        role = self.ROLE_OF[key][sum(c in self.ROLE_OF[key] for c in self.calls)]
        self.calls.append(role)
        fed = self.offsets[role]
        real = torch.randint

        def randint(low, high, size, device=None, **kwargs):  # the shift's only draw
            assert (low, high, tuple(size)) == (0, 2 * PAD + 1, (x.shape[0], 2)) and not kwargs
            return fed.to(device)

        torch.randint = randint  # type: ignore[assignment]
        try:
            return self.inner(x)
        finally:
            torch.randint = real


def draw_offsets(n: int, seed: int) -> dict[str, torch.Tensor]:
    """One update's shifts by role, (n, 2) integers in [0, 2 PAD] (rows, cols), from their own generator."""
    g = torch.Generator().manual_seed(seed)
    return {role: torch.randint(0, 2 * PAD + 1, (n, 2), generator=g) for role in ROLES_UPSTREAM}


def as_upstream_shifts(offsets: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """(rows, cols) offsets as upstream's (x, y) shifts: the same crop of every image."""
    return {role: o[:, [1, 0]] for role, o in offsets.items()}


GROUPS = {  # report group -> this project's modules in it
    "encoder": ("encoder",), "actor": ("actor",), "critic": ("critic",), "critic_target": ("critic_target",),
    "action_encoder": ("action_encoder",), "taco_heads": ("shared_heads", "objective.taco", "objective.reward"),
}
METRICS = ("critic_loss", "critic_q1", "critic_q2", "critic_target_q", "actor_loss", "actor_logprob", "actor_ent",
           "taco_loss", "curl_loss", "reward_loss")


def _group(name: str) -> str:
    """The report group of one of this project's tensors, named ``module.path``."""
    return next(g for g, mods in GROUPS.items() if any(name.startswith(m + ".") for m in mods))


def _maxdiff(a: torch.Tensor, b: torch.Tensor) -> float:
    return float((a.detach().double() - b.detach().double()).abs().max())


def _adam_states(opts: Mapping[str, torch.optim.Optimizer], aux: str) -> dict[int, dict[str, dict]]:
    """id(parameter) -> {"main" | "aux": its Adam state}: ``aux`` names the auxiliary (TACO) optimizer."""
    out: dict[int, dict[str, dict]] = {}
    for name, opt in opts.items():
        for group in opt.param_groups:
            for p in group["params"]:
                if p in opt.state:
                    out.setdefault(id(p), {})["aux" if name == aux else "main"] = opt.state[p]
    return out


def compare_to_upstream(backbone, up: UpstreamTACO) -> dict[str, float]:
    """Max |difference| per parameter group, and of the Adam moments (``adam``: relative, max |difference| over the
    largest |entry| of each moment tensor, every mapped parameter in both of its optimizers; a state one side has
    and the other lacks counts as inf)."""
    out = dict.fromkeys(GROUPS, 0.0)
    adam = 0.0
    ours_state = _adam_states(backbone.optimizers(), "aux")
    ups_state = _adam_states(up.optimizers(), "taco")
    for name, _, t, u in parameter_pairs(backbone, up):
        g = _group(name)
        out[g] = max(out[g], _maxdiff(t, u))
        so, su = ours_state.get(id(t), {}), ups_state.get(id(u), {})
        if so.keys() != su.keys():
            adam = float("inf")
            continue
        for role in so:
            for k in ("exp_avg", "exp_avg_sq"):
                a, b = so[role][k], su[role][k]
                adam = max(adam, _maxdiff(a, b) / max(float(a.abs().max()), 1e-30))
    out["adam"] = adam
    return out


def compare_projects(a, b) -> dict[str, float]:
    """Max |difference| per parameter group between two of this project's backbones (plain and fast)."""
    out = dict.fromkeys(GROUPS, 0.0)
    ma, mb = a.modules(), b.modules()
    for mod in ma:
        if mod == "objective.curl":
            continue  # only the shared heads, counted under shared_heads
        sa, sb = ma[mod].state_dict(), mb[mod].state_dict()
        for k, v in sa.items():
            name = f"{mod}.{k}"
            if mod.startswith("objective.") and k.startswith("heads."):
                continue
            g = _group(name)
            out[g] = max(out[g], _maxdiff(v, sb[k]))
    return out


def pre_tanh(encoder: nn.Module, actor: Any, probe: torch.Tensor) -> torch.Tensor:
    """The actor's pre-tanh output on the probe frames (no shift), float32."""
    with torch.no_grad():
        return actor.policy(actor.trunk(encoder(probe.float())))


# name -> the diagnostic switches of the upstream agent (faithful: none; matched: all three)
VARIANTS: dict[str, dict[str, Any]] = {
    "faithful": {},
    "matched": {"grid_shift": False, "polyak": "lerp", "aux_order": "project"},
    "grid_only": {"polyak": "lerp", "aux_order": "project"},  # only upstream's grid_sample shift left
    "polyak_only": {"grid_shift": False, "aux_order": "project"},  # only upstream's soft-update formula left
    "order_only": {"grid_shift": False, "polyak": "lerp"},  # only upstream's loss order in the TACO step left
}


def build_project_agent(task: str, image: int, batch: int, overrides: Sequence[str] = ()) -> Any:
    """This project's TACO ``Agent`` for ``task`` on (9, image, image) frames, built as a run builds it (its seed
    seeds torch first), and its typed config."""
    from repro.config.compose import compose, typed
    from repro.envs import run_action_dim
    from repro.train import build

    rc = typed(compose(["agent=taco", f"task={task}", f"agent.batch_size={batch}", *overrides]))
    obs_shape = (3 * rc.env.frame_stack, image, image)
    return build.build_run_learner(rc, obs_shape, run_action_dim(rc), "cpu"), rc, obs_shape


def run_drift(task: str = "cartpole_balance", updates: int = 10, image: int = 32, batch: int = 32,
              overrides: Sequence[str] = (), variant: str = "faithful", fast: bool = False,
              draws: str = "fed", step0: int = 2000, probe_size: int = 64, seed: int = 0,
              upstream_agent=None, on_row=None, episodes: Sequence[Mapping[str, Any]] | None = None,
              init: Mapping[str, Mapping[str, torch.Tensor]] | None = None) -> list[dict]:
    """``updates`` updates of this project's plain agent and of the upstream re-expression (``variant``) from the
    same initial weights on the same batches (one replay of synthetic episodes, repro.bench.batches), with
    ``torch.manual_seed(seed + i)`` before update i on each side (the policy noise) and, with ``draws="fed"``, the
    same shifts by role fed to both (``draws="native"``: each side draws its own from that seed). With ``fast``,
    this project's fast path (agent.fast=true) gets the same batches, seeds and shifts. One row per update: max
    |difference| per parameter group, of the Adam moments, of each metric and of the probe's pre-tanh output;
    ``upstream_agent``: a factory (agent, obs_shape) -> upstream agent to use instead of ``from_project``.
    ``episodes`` (a run's replay episodes) replace the synthetic ones and ``init`` (a run checkpoint's modules) the
    agent's initial weights: the same updates from a real run's state on its real data (scripts/upstream_drift.py
    --run)."""
    from repro.bench.batches import batch_stream, synthetic_episodes

    agent, rc, obs_shape = build_project_agent(task, image, batch, ["agent.fast=false", *overrides])
    if init is not None:
        for name, mod in agent.backbone.modules().items():
            mod.load_state_dict(init[name])
    up = (upstream_agent or (lambda a, s: from_project(a, s, **VARIANTS[variant])))(agent, obs_shape)
    fast_agent = None
    if fast:
        fast_agent, _, _ = build_project_agent(task, image, batch, ["agent.fast=true", *overrides])
        for name, mod in agent.backbone.modules().items():
            fast_agent.backbone.modules()[name].load_state_dict(mod.state_dict())
    feeders = []
    if draws == "fed":
        for a in (agent, fast_agent):
            if a is not None:
                a.backbone.aug = FedShift(a.backbone.aug)
                feeders.append(a.backbone.aug)
    if episodes is None:
        episodes = synthetic_episodes(action_dim=agent.action_dim, frame_shape=(3, image, image), seed=seed)
    stream = batch_stream(agent, rc.agent, rc.env.frame_stack, episodes, "cpu", batch, seed=seed)
    probe = next(batch_stream(agent, rc.agent, rc.env.frame_stack, episodes, "cpu", probe_size, seed=seed + 1))["obs"]
    rows = []
    for i in range(updates):
        b = next(stream)
        step = step0 + 2 * i
        offsets = draw_offsets(batch, 10_000 + seed + i) if draws == "fed" else None
        for f in feeders:
            f.feed(b, offsets)
        torch.manual_seed(seed + i)
        m_ours = agent.update(b, step)
        torch.manual_seed(seed + i)
        m_up = up.update(b, step, None if offsets is None else as_upstream_shifts(offsets))
        row: dict = {"update": i + 1, "upstream": compare_to_upstream(agent.backbone, up)}
        row["metrics"] = {k: abs(float(m_ours[k]) - float(m_up[k])) for k in METRICS}
        row["upstream"]["metrics"] = max(row["metrics"].values())
        p_ours = pre_tanh(agent.backbone.encoder, agent.backbone.actor, probe)
        row["upstream"]["pre_tanh"] = _maxdiff(p_ours, pre_tanh(up.encoder, up.actor, probe))
        row["pre_tanh_range"] = [float(p_ours.min()), float(p_ours.max())]
        row["pre_tanh_mean"] = {"plain": float(p_ours.mean()),
                                "upstream": float(pre_tanh(up.encoder, up.actor, probe).mean())}
        if fast_agent is not None:
            torch.manual_seed(seed + i)
            m_fast = fast_agent.update(b, step)
            row["fast"] = compare_projects(agent.backbone, fast_agent.backbone)
            row["fast"]["metrics"] = max(abs(float(m_ours[k]) - float(m_fast[k])) for k in METRICS)
            p_fast = pre_tanh(fast_agent.backbone.encoder, fast_agent.backbone.actor, probe)
            row["fast"]["pre_tanh"] = _maxdiff(p_ours, p_fast)
            row["pre_tanh_mean"]["fast"] = float(p_fast.mean())
        rows.append(row)
        if on_row is not None:
            on_row(row)
    return rows
