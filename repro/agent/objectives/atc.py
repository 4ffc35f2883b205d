"""ATC (Stooke et al., 2021) on the DrQ-v2 backbone: augmented temporal contrast, no actions.

Anchor: c_t = H(f(aug(o_t))) through a residual predictor p = c_t + MLP(c_t). Positive: the momentum
target's c~_{t+K} = H_m(f_m(aug(o_{t+K}))), with (f_m, H_m) an exponential moving average of (f, H).
Logits p W c~^T (bilinear, no temperature, minus the row max as ATC's code does), InfoNCE against the
diagonal: the other rows' targets are the negatives.

ATC's DMControl defaults: target update rate 0.01 every step (momentum 0.99), predictor hidden size 512,
temporal shift k = 1 (here the agent's K, which task files set to 1 on quadruped_run and walker_run).
"""

from __future__ import annotations

import math

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext, info_nce
from repro.agent.objectives.common import MomentumTarget, typed_params
from repro.config.schema import ATCParams


class ATCObjective(Objective):
    """InfoNCE between (c_t + MLP(c_t)) W and the momentum target's latent of o_{t+K}."""

    extra_metrics = ("acc",)

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        p = typed_params(ctx, ATCParams)  # agent.objective_params.atc
        if ctx.encoder is None:
            raise ValueError("atc needs the online encoder in the objective context (momentum target).")
        d = ctx.feature_dim
        self.heads = ctx.shared()
        self.predictor = nn.Sequential(nn.Linear(d, p.predictor_hidden), nn.ReLU(), nn.Linear(p.predictor_hidden, d))
        self.predictor.apply(orthogonal_init)
        # ATC's W is a bias-free linear layer with PyTorch's default initialisation U(-1/sqrt(d), 1/sqrt(d)).
        bound = 1.0 / math.sqrt(d)
        self.W = nn.Parameter(torch.empty(d, d).uniform_(-bound, bound))
        self.target = MomentumTarget({"encoder": ctx.encoder, "state_proj": self.heads.state_proj},
                                     p.momentum)

    def logits(self, anchor: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """(c + MLP(c)) W c~^T minus each row's max (the shift leaves the cross-entropy unchanged)."""
        pred = anchor + self.predictor(anchor)
        logits = pred @ self.W @ target.T
        return logits - logits.max(dim=1, keepdim=True).values

    @torch.no_grad()
    def target_latent(self, aux: AuxBatch) -> torch.Tensor:
        """H_m(f_m(aug(o_{t+K}))) from the momentum target, with a fresh random shift."""
        h = aux.encode_by(self.target["encoder"], aux.aug(aux.batch["future_obs"]))
        return self.target["state_proj"](h)

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        c = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        loss, acc = info_nce(self.logits(c, self.target_latent(aux)))
        return loss, {"atc_loss": loss.detach(), "atc_acc": acc}

    def after_update(self) -> None:
        self.target.update()
