"""Behaviour cloning on the DrQ-v2 pixel backbone: encoder + deterministic actor head, MSE to the dataset action.

The encoder sees randomly shifted observations and is trained by the BC loss (no critic). The policy is the
DrQ-v2 Actor's tanh mean; its std argument plays no role.
"""

from __future__ import annotations

import numpy as np
import torch

from repro.agent.aug import RandomShift
from repro.agent.backbone import optimize
from repro.agent.losses import SATURATION_METRICS, Metrics, saturation_metrics
from repro.agent.modules import LearnerBase, ModuleSet
from repro.agent.networks import Actor, Encoder
from repro.config.schema import AgentConfig

METRICS = ("bc_loss", *SATURATION_METRICS)


def bc_loss(predicted: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean over batch and action dimensions of (predicted - target)^2."""
    if predicted.shape != target.shape:
        raise ValueError(f"bc_loss: predicted {tuple(predicted.shape)} vs target {tuple(target.shape)}")
    return (predicted - target).pow(2).mean()


class BC(LearnerBase, ModuleSet):
    """Offline learner ``bc``."""

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        self.cfg = cfg
        self.device = torch.device(device)
        self.action_dim = action_dim
        self.aug = RandomShift(pad=4)
        self.encoder = Encoder(obs_shape).to(self.device)
        self.actor = Actor(self.encoder.repr_dim, action_dim, cfg.feature_dim, cfg.hidden_dim).to(self.device)
        self.encoder_opt = torch.optim.Adam(self.encoder.parameters(), lr=cfg.lr)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr)
        self.sample_options: dict = {}
        self.train(True)

    def modules(self) -> dict[str, torch.nn.Module]:
        return {"encoder": self.encoder, "actor": self.actor}

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"encoder": self.encoder_opt, "actor": self.actor_opt}

    def metric_names(self) -> list[str]:
        return list(METRICS)

    def policy(self, obs: torch.Tensor) -> torch.Tensor:
        """Deterministic action in [-1, 1] for float observations (B, C, H, W)."""
        return self.actor(self.encoder(obs), 1.0).mean

    @torch.no_grad()
    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        obs_t = torch.as_tensor(obs, device=self.device).float().unsqueeze(0)
        return self.policy(obs_t).cpu().numpy()[0].astype(np.float32)

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        dist = self.actor(self.encoder(self.aug(batch["obs"].float())), 1.0)
        loss = bc_loss(dist.mean, batch["action"])
        optimize(loss, self.actor_opt, self.encoder_opt)
        return {"bc_loss": loss.detach(), **saturation_metrics(dist.loc, dist.pre_tanh)}
