"""SPR (Schwarzer et al., 2021) on the DrQ-v2 backbone: predict the target encoder's future latent.

Online branch: z_t = H(f(aug(o_t))), a latent transition model T(z_t, u_t..u_{t+K-1}) -> z^_{t+K},
projection g and linear prediction head q. Target branch: g_m(H_m(f_m(aug(o_{t+K})))), where
(f_m, H_m, g_m) is an exponential moving average of (f, H, g). Loss: negative cosine similarity.

SPR's own defaults: target momentum tau = 0 when augmentation is used (the target *is* the online
network with the gradient stopped), 0.99 without augmentation; prediction depth 5 in Atari. The replay
here gives only o_{t+K}, so this predicts the single latent K steps ahead (see docs/deviations.md).

This module also holds the small helpers shared with ATC: ``MomentumTarget``, ``negative_cosine``
and ``read_params``.
"""

from __future__ import annotations

import copy
from typing import Any

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext, register


def read_params(ctx: ObjectiveContext, defaults: dict[str, Any], name: str) -> dict[str, Any]:
    """``defaults`` updated with ``agent.objective_params.<name>``; unknown keys are refused."""
    unknown = sorted(set(ctx.params) - set(defaults))
    if unknown:
        raise ValueError(f"agent.objective_params.{name}: unknown key(s) {', '.join(unknown)}; "
                         f"known: {', '.join(sorted(defaults))}.")
    return {**defaults, **ctx.params}


def negative_cosine(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean over rows of -cos(pred_i, target_i) (SPR's loss; equal to BYOL's 2 - 2cos up to an affine map)."""
    pred = nn.functional.normalize(pred, dim=-1)
    target = nn.functional.normalize(target, dim=-1)
    return -(pred * target).sum(dim=-1).mean()


class MomentumTarget(nn.Module):
    """Frozen copies of online modules, moved towards them by ``update()``.

    ``update`` computes target <- momentum * target + (1 - momentum) * online for every parameter and
    copies buffers. The online modules are kept as plain references (not registered), so their
    parameters are neither counted nor saved twice under the owning objective.
    """

    def __init__(self, online: dict[str, nn.Module], momentum: float):
        super().__init__()
        if not 0.0 <= momentum < 1.0:
            raise ValueError(f"momentum must be in [0, 1) (got {momentum}).")
        self.momentum = float(momentum)
        self.copies = nn.ModuleDict({name: copy.deepcopy(mod) for name, mod in online.items()})
        self.copies.requires_grad_(False)
        self._online: tuple[tuple[str, nn.Module], ...] = tuple(online.items())

    def __getitem__(self, name: str) -> nn.Module:
        return self.copies[name]

    @torch.no_grad()
    def update(self) -> None:
        for name, online in self._online:
            target = self.copies[name]
            for tp, p in zip(target.parameters(), online.parameters()):
                tp.lerp_(p, 1.0 - self.momentum)
            for tb, b in zip(target.buffers(), online.buffers()):
                tb.copy_(b)


@register("spr")
class SPRObjective(Objective):
    """Negative cosine between q(g(T(z_t, u_seq))) and the momentum target's g_m(H_m(f_m(o_{t+K})))."""

    DEFAULTS: dict[str, Any] = {
        "momentum": 0.0,          # SPR with augmentation: tau = 0 (target = online, gradient stopped)
        "projection_dim": None,   # null: hidden_dim (SPR projects with the first layer of the Q head)
    }

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        p = read_params(ctx, self.DEFAULTS, "spr")
        proj_dim = int(p["projection_dim"] or ctx.hidden_dim)
        self.heads = ctx.shared()
        self.transition = nn.Sequential(
            nn.Linear(ctx.feature_dim + ctx.seq_dim, ctx.hidden_dim), nn.ReLU(),
            nn.Linear(ctx.hidden_dim, ctx.feature_dim), nn.LayerNorm(ctx.feature_dim), nn.Tanh())
        self.projection = nn.Linear(ctx.feature_dim, proj_dim)
        self.prediction = nn.Linear(proj_dim, proj_dim)
        for mod in (self.transition, self.projection, self.prediction):
            mod.apply(orthogonal_init)
        self.momentum = float(p["momentum"])
        self.target: MomentumTarget | None = None
        if self.momentum > 0.0:
            if ctx.encoder is None:
                raise ValueError("spr with momentum > 0 needs the online encoder in the objective context.")
            self.target = MomentumTarget({"encoder": ctx.encoder, "state_proj": self.heads.state_proj,
                                          "projection": self.projection}, self.momentum)

    def predict(self, aux: AuxBatch) -> torch.Tensor:
        """q(g(T(z_t, u_t..u_{t+K-1}))): the online prediction of the future projection."""
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        z_next = self.transition(torch.cat([z, aux.action_sequence()], dim=-1))
        return self.prediction(self.projection(z_next))

    @torch.no_grad()
    def target_projection(self, aux: AuxBatch) -> torch.Tensor:
        """g_m(H_m(f_m(aug(o_{t+K})))) without gradient; with momentum 0 the online modules themselves."""
        if self.target is None:
            return self.projection(self.heads.state_proj(aux.future()))
        t = self.target
        h = t["encoder"](aux.aug(aux.batch["future_obs"].float()))
        return t["projection"](t["state_proj"](h))

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, float]]:
        loss = negative_cosine(self.predict(aux), self.target_projection(aux))
        return loss, {"spr_loss": loss.item()}

    def after_update(self) -> None:
        if self.target is not None:
            self.target.update()
