"""Learners by ``agent.learner``: the online actor-critic agent and the offline learners."""

from __future__ import annotations

from collections.abc import Callable

import torch

from repro.agent.agent import Agent
from repro.config.schema import AgentConfig, LearnerName, check_registry
from repro.learners.base import Learner, SequenceLearner
from repro.learners.bc import BCLearner
from repro.learners.cql import CQL
from repro.learners.dt import DTLearner
from repro.learners.iql import IQL
from repro.learners.td3bc import TD3BC

LearnerFactory = Callable[..., Learner]  # (cfg, obs_shape, action_dim, device=, explore_steps=) -> Learner

LEARNERS: dict[str, LearnerFactory] = {
    "actor_critic": Agent,  # DrQ-v2 / TACO and the representation ablations (online)
    "bc": BCLearner,  # behaviour cloning (offline)
    "td3bc": TD3BC,  # TD3+BC on the DrQ-v2 backbone (offline; agent=td3bc | td3bc_taco)
    "cql": CQL,  # CQL on the DrQ-v2 backbone (offline; agent=cql | cql_taco)
    "iql": IQL,  # IQL on the DrQ-v2 backbone (offline)
    "dt": DTLearner,  # Decision Transformer on pixels (offline; samples episode windows, return-conditioned)
}
check_registry("learner", LEARNERS, LearnerName)  # the names (and which train offline) are schema data
__all__ = ["LEARNERS", "LearnerFactory", "build_learner", "samples_episodes"]


def samples_episodes(name: str) -> bool:
    """Whether learner ``name`` trains on episode windows (``make_sampler``) instead of a transition replay."""
    factory = LEARNERS[name]
    return isinstance(factory, type) and issubclass(factory, SequenceLearner)


def build_learner(cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                  device: torch.device | str, explore_steps: int = 0) -> Learner:
    """The learner named by ``cfg.learner`` (KeyError for an unknown name; config validation names it first)."""
    return LEARNERS[cfg.learner](cfg, obs_shape, action_dim, device=device, explore_steps=explore_steps)
