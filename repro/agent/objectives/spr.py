"""SPR (Schwarzer et al., 2021) on the DrQ-v2 backbone: predict the target encoder's future latents.

Online branch: z_t = H(f(aug(o_t))); a latent transition model rolled out one action at a time,
z^_{t+k} = T(z^_{t+k-1}, u_{t+k-1}) for k = 1..K (the horizon is ``agent.K``); projection g and linear
prediction head q. Target branch: g_m(H_m(f_m(aug(o_{t+k})))) for every k, where (f_m, H_m, g_m) is an
exponential moving average of (f, H, g). Loss: negative cosine similarity, averaged over the K steps.

SPR's own defaults: target momentum tau = 0 when augmentation is used (the target *is* the online
network with the gradient stopped), 0.99 without augmentation; prediction depth 5 in Atari (here K).
``rollout: false`` switches to a one-shot variant predicting only z_{t+K} from (z_t, u_t..u_{t+K-1}).
"""

from __future__ import annotations

import torch
from torch import nn

from repro.agent.networks import orthogonal_init
from repro.agent.objectives.base import AuxBatch, Objective, ObjectiveContext
from repro.agent.objectives.common import MomentumTarget, negative_cosine, typed_params
from repro.config.schema import SPRParams


class SPRObjective(Objective):
    """Negative cosine between q(g(T(z_t, u_seq))) and the momentum target's g_m(H_m(f_m(o_{t+K})))."""

    def __init__(self, ctx: ObjectiveContext):
        super().__init__(ctx)
        p = typed_params(ctx, SPRParams)  # agent.objective_params.spr
        proj_dim = p.projection_dim or ctx.hidden_dim
        self.heads = ctx.shared()
        self.rollout = p.rollout
        self.needs_future_seq = self.rollout
        action_in = ctx.step_dim if self.rollout else ctx.seq_dim
        self.transition = nn.Sequential(
            nn.Linear(ctx.feature_dim + action_in, ctx.hidden_dim), nn.ReLU(),
            nn.Linear(ctx.hidden_dim, ctx.feature_dim), nn.LayerNorm(ctx.feature_dim), nn.Tanh())
        self.projection = nn.Linear(ctx.feature_dim, proj_dim)
        self.prediction = nn.Linear(proj_dim, proj_dim)
        for mod in (self.transition, self.projection, self.prediction):
            mod.apply(orthogonal_init)
        self.momentum = p.momentum
        self.target: MomentumTarget | None = None
        if self.momentum > 0.0:
            if ctx.encoder is None:
                raise ValueError("spr with momentum > 0 needs the online encoder in the objective context.")
            self.target = MomentumTarget({"encoder": ctx.encoder, "state_proj": self.heads.state_proj,
                                          "projection": self.projection}, self.momentum)

    def predict(self, aux: AuxBatch) -> torch.Tensor:
        """Online predictions of the future projections: (B, K, P) with rollout, else (B, 1, P) for t+K."""
        z = aux.memo("z_anchor", lambda: self.heads.state_proj(aux.anchor()))
        if not self.rollout:
            z_next = self.transition(torch.cat([z, aux.action_sequence()], dim=-1))
            return self.prediction(self.projection(z_next)).unsqueeze(1)
        preds = []
        steps = aux.action_steps()
        for k in range(steps.shape[1]):
            z = self.transition(torch.cat([z, steps[:, k]], dim=-1))
            preds.append(self.prediction(self.projection(z)))
        return torch.stack(preds, dim=1)

    @torch.no_grad()
    def _target(self, aux: AuxBatch, k: int | None) -> torch.Tensor:
        """g_m(H_m(f_m(aug(o_{t+k})))) (k None: o_{t+K}); with momentum 0 the online modules themselves."""
        if self.target is None:
            h = aux.future() if k is None else aux.future_at(k)
            return self.projection(self.heads.state_proj(h))
        t = self.target
        obs = aux.batch["future_obs"] if k is None else aux.batch["future_obs_seq"][:, k - 1]
        return t["projection"](t["state_proj"](aux.encode_by(t["encoder"], aux.aug(obs))))

    @torch.no_grad()
    def target_projection(self, aux: AuxBatch) -> torch.Tensor:
        """Target projections matching ``predict``: (B, K, P) with rollout, else (B, 1, P)."""
        if not self.rollout:
            return self._target(aux, None).unsqueeze(1)
        K = aux.batch["action_seq"].shape[1]
        return torch.stack([self._target(aux, k) for k in range(1, K + 1)], dim=1)

    def forward(self, aux: AuxBatch) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        pred, target = self.predict(aux), self.target_projection(aux)
        loss = negative_cosine(pred.flatten(0, 1), target.flatten(0, 1))  # mean over rows and steps
        return loss, {"spr_loss": loss.detach()}

    def after_update(self) -> None:
        if self.target is not None:
            self.target.update()
