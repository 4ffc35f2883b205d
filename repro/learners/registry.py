"""Learners by ``agent.learner``: the online actor-critic agent, the offline learners and the plugins' learners.

The names (and which train offline, their sections and labels) are registered in repro/config/schema.py
(``learner_specs``: the built-in ones and the entry-point group ``taco_repro.learners``); this table holds their
code: the built-in classes imported here, a plugin's the ``factory`` its registration names."""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import torch

from repro.agent.agent import Agent
from repro.config.plugins import load_factory
from repro.config.schema import AgentConfig, check_registry, learner_names, learner_specs
from repro.learners.base import Learner, SequenceLearner
from repro.learners.bc import BC
from repro.learners.cql import CQL
from repro.learners.dt import DT
from repro.learners.iql import IQL
from repro.learners.td3bc import TD3BC

LearnerFactory = Callable[..., Learner]  # (cfg, obs_shape, action_dim, device=, explore_steps=) -> Learner

LEARNERS: dict[str, LearnerFactory] = {
    "actor_critic": Agent,  # DrQ-v2 / TACO and the representation ablations (online)
    "bc": BC,  # behaviour cloning (offline)
    "td3bc": TD3BC,  # TD3+BC on the DrQ-v2 backbone (offline; agent=td3bc | td3bc_taco)
    "cql": CQL,  # CQL on the DrQ-v2 backbone (offline; agent=cql | cql_taco)
    "iql": IQL,  # IQL on the DrQ-v2 backbone (offline)
    "dt": DT,  # Decision Transformer on pixels (offline; samples episode windows, return-conditioned)
}
LEARNERS.update({spec.name: cast(LearnerFactory, load_factory(spec))
                 for spec in learner_specs().values() if spec.factory is not None})
check_registry("learner", LEARNERS, learner_names())  # every registered learner has its code, nothing else is here
__all__ = ["LEARNERS", "LearnerFactory", "build_learner", "samples_episodes"]


def samples_episodes(name: str) -> bool:
    """Whether learner ``name`` trains on episode windows (``make_sampler``) instead of a transition replay."""
    factory = LEARNERS[name]
    return isinstance(factory, type) and issubclass(factory, SequenceLearner)


def build_learner(cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                  device: torch.device | str, explore_steps: int = 0) -> Learner:
    """The learner named by ``cfg.learner`` (KeyError for an unknown name; config validation names it first)."""
    return LEARNERS[cfg.learner](cfg, obs_shape, action_dim, device=device, explore_steps=explore_steps)
