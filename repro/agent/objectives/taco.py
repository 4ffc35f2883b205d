"""The three objectives of TACO: temporal contrast, CURL and reward prediction."""

from __future__ import annotations

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext, info_nce


class TACOObjective(Objective):
    """InfoNCE between G(z_t, u_t..u_{t+K-1}) and H(z_{t+K}) with the shared bilinear W."""

    extra_metrics = ("acc",)

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        self.heads = ctx.shared()
        self.proj_sa = nn.Sequential(nn.Linear(ctx.feature_dim + ctx.seq_dim, ctx.hidden_dim), nn.ReLU(),
                                     nn.Linear(ctx.hidden_dim, ctx.feature_dim))
        self.proj_sa.apply(orthogonal_init)

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        x = self.proj_sa(torch.cat([z, aux.action_sequence()], dim=-1))
        with torch.no_grad():
            y = self.heads.state_proj(aux.future())
        loss, acc = info_nce(self.heads.logits(x, y))
        return loss, {"taco_loss": loss.detach(), "taco_acc": acc}


class CURLObjective(Objective):
    """InfoNCE between two augmentations of the same observation, through H and W."""

    extra_metrics = ("acc",)

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        self.heads = ctx.shared()

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        x = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        with torch.no_grad():
            y = self.heads.state_proj(aux.positive())
        loss, acc = info_nce(self.heads.logits(x, y))
        return loss, {"curl_loss": loss.detach(), "curl_acc": acc}


class RewardObjective(Objective):
    """Mean squared error of a reward head on (z_t, u_t..u_{t+K-1})."""

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        self.heads = ctx.shared()
        self.head = nn.Sequential(nn.Linear(ctx.feature_dim + ctx.seq_dim, ctx.hidden_dim), nn.ReLU(),
                                  nn.Linear(ctx.hidden_dim, 1))
        self.head.apply(orthogonal_init)

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        pred = self.head(torch.cat([z, aux.action_sequence()], dim=-1))
        loss = nn.functional.mse_loss(pred, aux.reward())
        return loss, {"reward_loss": loss.detach()}
