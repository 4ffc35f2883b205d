"""DrQ-v2 with several critic steps per update (online learner ``toy_utd``): a higher update-to-data ratio for the
critic, composed from taco-repro's DrQ-v2 backbone (repro/agent/backbone.py) as the built-in online agent is.

Each update takes ``critic_steps`` critic steps on the same replay batch, each on its own random shift of the frames
(a fresh ``encode_batch``), then DrQ-v2's actor step on the last step's features, the target update and the
auxiliary step (if the agent file names objectives). With ``critic_steps: 1`` it is DrQ-v2's update.
"""

from __future__ import annotations

import torch

from repro.agent.backbone import BackboneLearner
from repro.agent.losses import ACTOR_METRICS, CRITIC_METRICS, Metrics
from repro.config.schema import AgentConfig, learner_section
from taco_repro_toy import UTDConfig


class UTD(BackboneLearner):
    """Online learner ``toy_utd``. ``BackboneLearner`` builds the backbone (the learner factory's signature) and
    forwards modules, optimizers, acting and the objectives' metric names to it; this class adds ``update()``."""

    update_metrics = CRITIC_METRICS + ACTOR_METRICS  # the last critic step's and the actor step's
    explores = True  # uniform actions for the first train.explore_steps, then noisy policy samples

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0):
        super().__init__(cfg, obs_shape, action_dim, device, explore_steps)
        self.own: UTDConfig = learner_section(cfg, UTDConfig)  # agent.toy_utd, typed

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        """``critic_steps`` DrQ-v2 critic steps (each with the encoder, on a fresh shift), one actor step on the last
        features, the target critic, then one auxiliary step; detached 0-d metrics (no host sync)."""
        bb = self.backbone
        for _ in range(self.own.critic_steps):  # each step on its own shift of the frames
            h, next_h, action, reward, discount = bb.encode_batch(batch)
            critic = bb.critic_step(h, action, reward, discount, next_h, step)
        actor = bb.actor_step(h.detach(), step)
        bb.update_target()
        return {**critic, **actor, **bb.aux_step(batch)}
