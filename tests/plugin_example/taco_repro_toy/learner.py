"""Reward-weighted behaviour cloning on the DrQ-v2 pixel encoder and actor (offline learner ``toy_rwbc``).

Behaviour cloning whose per-transition squared error is weighted by exp(r / temperature) normalised over the batch:
the policy imitates the dataset's higher-return transitions more (r: the replay's n-step return, ``batch["reward"]``).
A temperature -> infinity gives plain BC.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from repro.agent.aug import RandomShift
from repro.agent.modules import LearnerBase, ModuleSet
from repro.agent.networks import Actor, Encoder
from repro.config.schema import AgentConfig, learner_section
from taco_repro_toy import RWBCConfig
from taco_repro_toy.losses import return_weights, weighted_bc_loss

METRICS = ("rwbc_loss", "rwbc_max_weight")


class RWBC(ModuleSet, LearnerBase):
    """Offline learner ``toy_rwbc``: the signature every learner factory has (repro/learners/registry.py). One Adam
    over the encoder and the actor, which the weighted loss trains together. The protocol's optional hooks (no
    objectives, no action encoder, ``agent.batch_size`` per update) are ``LearnerBase``'s defaults."""

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        self.cfg = cfg
        self.own: RWBCConfig = learner_section(cfg, RWBCConfig)  # agent.toy_rwbc, typed
        self.device = torch.device(device)
        self.aug = RandomShift(pad=4)
        encoder = Encoder(obs_shape)
        self.nets = nn.ModuleDict({"encoder": encoder, "actor": Actor(encoder.repr_dim, action_dim, cfg.feature_dim,
                                                                      cfg.hidden_dim)}).to(self.device)
        self.opt = torch.optim.Adam(self.nets.parameters(), lr=cfg.lr)
        self.sample_options: dict = {}
        self.train(True)

    def modules(self) -> dict[str, nn.Module]:
        return dict(self.nets.items())

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        return {"rwbc": self.opt}

    def metric_names(self) -> list[str]:
        return list(METRICS)

    def policy(self, obs: torch.Tensor) -> torch.Tensor:
        """The actor's tanh mean, in [-1, 1], for float observations (B, C, H, W)."""
        return self.nets["actor"](self.nets["encoder"](obs), 1.0).mean

    @torch.no_grad()
    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        action = self.policy(torch.as_tensor(obs[None], device=self.device).float())
        return action[0].cpu().numpy().astype(np.float32)

    def update(self, batch: dict[str, torch.Tensor], step: int) -> dict[str, torch.Tensor]:
        """One step on the weighted loss; the metrics are detached 0-d tensors (no host sync)."""
        weights = return_weights(batch["reward"], self.own.temperature, self.own.max_weight)
        loss = weighted_bc_loss(self.policy(self.aug(batch["obs"].float())), batch["action"], weights)
        self.opt.zero_grad(set_to_none=True)
        loss.backward()
        self.opt.step()
        return {"rwbc_loss": loss.detach(), "rwbc_max_weight": weights.max()}
