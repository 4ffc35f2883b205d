"""Inverse dynamics as an auxiliary objective (``toy_inv``): predict the actions a_t..a_{t+K-1} from the
representations of o_t and o_{t+K}. The encoder learns what the agent's actions change."""

from __future__ import annotations

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext
from repro.agent.objectives.common import typed_params
from taco_repro_toy import InvParams
from taco_repro_toy.losses import inverse_dynamics_loss


class InverseDynamics(Objective):
    """MLP([H(f(aug o_t)), H(f(aug o_{t+K}))]) -> (a_t..a_{t+K-1}); the gradient reaches the encoder through o_t."""

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        hidden = typed_params(ctx, InvParams).hidden_dim or ctx.hidden_dim  # agent.objective_params.toy_inv, typed
        self.heads = ctx.shared()  # the state projection H shared with the other objectives
        self.head = nn.Sequential(nn.Linear(2 * ctx.feature_dim, hidden), nn.ReLU(),
                                  nn.Linear(hidden, ctx.K * ctx.action_dim), nn.Tanh())
        self.head.apply(orthogonal_init)

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        with torch.no_grad():
            z_future = self.heads.state_proj(aux.future())
        loss = inverse_dynamics_loss(self.head(torch.cat([z, z_future], dim=-1)), aux.batch["action_seq"])
        return loss, {"toy_inv_loss": loss.detach()}
