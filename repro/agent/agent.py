"""One online agent for TACO, DrQ-v2 and their ablations: switches, not copies.

The networks, optimizers and update steps are the DrQ-v2 backbone's (``backbone.py``), owned as ``backbone``;
this learner adds the online update's order and exploration. ``update()`` takes a batch of tensors and returns
a metrics dict of detached 0-d tensors (no host sync); it never touches files.
"""

from __future__ import annotations

from typing import ClassVar

import torch

from repro.agent import fast
from repro.agent.backbone import DRQV2, BackboneLearner, BackboneParts
from repro.agent.graphs import GraphedUpdate
from repro.agent.losses import ACTOR_METRICS, CRITIC_METRICS, Metrics
from repro.config.schema import AgentConfig

__all__ = ["ACTOR_METRICS", "CRITIC_METRICS", "Agent"]


class Agent(BackboneLearner):
    """DrQ-v2 actor-critic with an optional action encoder and pluggable auxiliary objectives (learner
    ``actor_critic``); on other backbone ``parts``, the online update of a DrQ-v2 variant (A-LIX: ``alix.py``)."""

    update_metrics: ClassVar[tuple[str, ...]] = CRITIC_METRICS + ACTOR_METRICS
    explores = True  # uniform actions for the first explore_steps, then noisy policy samples
    graphed = True  # agent.fast on CUDA: update() recorded once in a CUDA graph and replayed (graphs.py)

    def __init__(self, cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                 device: torch.device | str = "cpu", explore_steps: int = 0, parts: BackboneParts = DRQV2):
        super().__init__(cfg, obs_shape, action_dim, device, explore_steps, parts)
        self.graph = GraphedUpdate(self.static_update, self.device) if self.backbone.fast.graphs else None

    @property
    def resolved(self) -> dict[str, object]:
        """What resolved.json records beyond the config: agent.fast's plan, when it is on."""
        return fast.resolved(self.backbone.fast, self.cfg.fast)

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        """One DrQ-v2 update, as upstream DrQ-v2 (``drqv2.py``): critic with the encoder, actor on sg(h), target
        critic; then one auxiliary step (TACO's order). With a CUDA graph (``agent.fast`` on CUDA) the same steps
        are replayed from the graph."""
        if self.graph is not None:
            return self.graph(batch, self.cfg.stddev_schedule(step))
        return self._update(batch, step)

    def static_update(self, batch: dict[str, torch.Tensor], std: torch.Tensor) -> Metrics:
        """The update with the exploration stddev ``std`` (a 0-d tensor) in place of the schedule's value at the
        step: what a CUDA graph records (``repro/agent/graphs.py``)."""
        with self.backbone.fixed_stddev(std):
            return self._update(batch, 0)

    def load_state_dict(self, state: dict) -> None:
        super().load_state_dict(state)
        if self.graph is not None:
            self.graph.reset()  # the optimizers' state tensors were replaced: record the graph again

    def _update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        bb = self.backbone
        h, next_h, action, reward, discount = bb.encode_batch(batch)
        metrics = bb.critic_step(h, action, reward, discount, next_h, step)
        metrics.update(bb.actor_step(h.detach(), step))
        bb.update_target()
        metrics.update(bb.aux_step(batch))
        return metrics
