"""The DrQ-v2 pixel backbone that TD3+BC, CQL and IQL share (``td3bc.py``, ``cql.py``, ``iql.py``).

The networks, the action encoder, the optimizers and the auxiliary objectives are the online agent's
(repro/agent/agent.py): with ``agent.objectives`` {taco, curl, reward} and ``agent.action_encoder: true`` the
critic sees latent actions u(a) and one TACO step follows each update, exactly as online. This base adds
only what the three offline algorithms' updates have in common: encoding a batch, DrQ-v2's critic target
and loss, an optimizer step, the target update and the auxiliary step. Each algorithm's ``update()``
calls them in its own order; its losses are pure functions in ``repro/learners/losses/``.

The noise schedule counts V-D4RL's loop steps (``stddev_schedule.step_scale`` 2 per update).
Checkpoint state is the agent's: ``modules()`` and ``optimizers()`` by name (an algorithm adds its own).
"""

from __future__ import annotations

from typing import cast

import torch
from torch import nn

from repro.agent.agent import Agent, soft_update
from repro.agent.objectives import Objective
from repro.config.schema import AgentConfig

EncodedBatch = tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]  # h, h', a, r, discount


class OfflineBackbone(Agent):
    """An offline actor-critic on the DrQ-v2 backbone; a subclass names itself and writes ``update()``."""

    algorithm: str  # the learner's name, recorded in resolved.json
    update_metrics: tuple[str, ...]  # the train.csv columns of update(), before the auxiliary step's

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        super().__init__(cfg, obs_shape, action_dim, device=device, explore_steps=0)  # offline: no exploration

    def metric_names(self) -> list[str]:
        names = list(self.update_metrics)
        for objective in cast("dict[str, Objective]", self.objectives).values():
            names += objective.metric_keys()
        if self.objectives:
            names.append("aux_loss")
        return names

    @property
    def resolved(self) -> dict[str, object]:
        """Values this learner used that analysis reads (recorded in the run directory)."""
        return {"algorithm": self.algorithm}

    # ----------------------------------------------------------------- the steps an update is made of
    def encode_batch(self, batch: dict[str, torch.Tensor]) -> EncodedBatch:
        """(h, h', a, r, discount): the shifted frames encoded (h with the encoder's gradient, h' without) and
        the dataset's action, reward and discount (gamma^n x not-done). Dataset actions are data: no gradient
        ever flows into them."""
        obs = self.aug(batch["obs"].float())
        next_obs = self.aug(batch["next_obs"].float())
        h = self._encode(obs)
        with torch.no_grad():
            next_h = self._encode(next_obs)
        return h, next_h, batch["action"].detach(), batch["reward"], batch["discount"]

    def critic_loss(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                    next_h: torch.Tensor, step: int
                    ) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor], dict[str, float]]:
        """DrQ-v2's critic loss sum_i mse(Q_i(h, u(a)), r + discount x min_i Qtarget_i(h', u(a'))), a' a
        clipped-noise policy sample at h'; returns the loss, (Q1, Q2) at the data actions and the metrics."""
        with torch.no_grad():
            dist = self.actor(next_h, self.stddev(step))
            next_action = self.encode_action(dist.sample(clip=self.cfg.stddev_clip))
            tq1, tq2 = self.critic_target(next_h, next_action)
            target_q = reward + discount * torch.min(tq1, tq2)
        q1, q2 = self.critic(h, self.encode_action(action))
        loss = nn.functional.mse_loss(q1, target_q) + nn.functional.mse_loss(q2, target_q)
        metrics = {"critic_loss": loss.item(), "critic_q1": q1.mean().item(), "critic_q2": q2.mean().item(),
                   "critic_target_q": target_q.mean().item()}
        return loss, (q1, q2), metrics

    def _update_critic(self, h: torch.Tensor, action: torch.Tensor, reward: torch.Tensor, discount: torch.Tensor,
                       next_h: torch.Tensor, step: int) -> dict[str, float]:
        """One step of DrQ-v2's critic loss on the critic and the encoder."""
        loss, _, metrics = self.critic_loss(h, action, reward, discount, next_h, step)
        self.optimize(loss, self.encoder_opt, self.critic_opt)
        return metrics

    def optimize(self, loss: torch.Tensor, *opts: torch.optim.Optimizer) -> None:
        """Zero the gradients of ``opts``, backpropagate ``loss`` and step each optimizer."""
        for opt in opts:
            opt.zero_grad(set_to_none=True)
        loss.backward()
        for opt in opts:
            opt.step()

    def update_target(self) -> None:
        """Polyak averaging of the target critic (``critic_target_tau``)."""
        soft_update(self.critic, self.critic_target, self.cfg.critic_target_tau)

    def auxiliary_step(self, batch: dict[str, torch.Tensor]) -> dict[str, float]:
        """One step of the auxiliary objectives (TACO's, with the ``_taco`` agent files); none: no metrics."""
        return self._update_aux(batch) if self.aux_opt is not None else {}
