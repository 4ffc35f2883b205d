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

from typing import Any

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext, register
from repro.agent.objectives.common import MomentumTarget, negative_cosine, read_params  # noqa: F401


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
