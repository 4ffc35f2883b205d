"""DRIML (Mazoure et al., 2020) as the TACO paper re-implements it: TACO's loss with the first action only.

The TACO paper (section 5.1, Table 2) describes DRIML as the temporal contrastive loss in which "only the
first action of the action sequence is considered". Here the actions a_{t+1}..a_{t+K-1} are replaced by
zeros before the action sequence encoder, so the contrasted pair is (z_t, u_t) against z_{t+K} with the
same heads (G, H, W) and the same action encoder as TACO. A constant carries no information about the
sample, so only a_t informs the prediction; with K = 1 nothing is masked and the loss is TACO's.
"""

from __future__ import annotations

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext, info_nce


def first_action_only(action_seq: torch.Tensor) -> torch.Tensor:
    """(B, K, |A|) actions with every step after the first set to zero (unchanged when K = 1)."""
    keep = torch.zeros_like(action_seq[:1, :, :1])
    keep[:, 0] = 1.0
    return action_seq * keep


class DRIMLObjective(Objective):
    """InfoNCE between G(z_t, encode([a_t, 0, .., 0])) and H(z_{t+K}) with the shared bilinear W."""

    extra_metrics = ("acc",)

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        self.heads = ctx.shared()
        self.proj_sa = nn.Sequential(nn.Linear(ctx.feature_dim + ctx.seq_dim, ctx.hidden_dim), nn.ReLU(),
                                     nn.Linear(ctx.hidden_dim, ctx.feature_dim))
        self.proj_sa.apply(orthogonal_init)

    def first_action_code(self, aux: AuxBatch) -> torch.Tensor:
        """The action sequence encoder applied to [a_t, 0, .., 0]: (B, seq_dim), with gradient."""
        return aux.memo("u_first", lambda: aux.encode_actions(first_action_only(aux.batch["action_seq"])))

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        x = self.proj_sa(torch.cat([z, self.first_action_code(aux)], dim=-1))
        with torch.no_grad():
            y = self.heads.state_proj(aux.future())
        loss, acc = info_nce(self.heads.logits(x, y))
        return loss, {"driml_loss": loss.detach(), "driml_acc": acc}
