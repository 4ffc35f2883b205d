"""Learners by ``agent.learner``: the online actor-critic agent, the offline learners and the plugins' learners.

The table is built from the registrations (repro/config/schema.py ``learner_specs``: the built-in ones and the
entry-point group ``taco_repro.learners``): each names its class by ``factory``, imported here. A built-in learner
is registered exactly as a plugin's."""

from __future__ import annotations

from collections.abc import Callable
from typing import cast

import torch

from repro.agent.protocol import EpisodeLimit, Learner, SequenceLearner
from repro.config.plugins import load_factory
from repro.config.schema import AgentConfig, learner_specs

LearnerFactory = Callable[..., Learner]  # (cfg, obs_shape, action_dim, device=, explore_steps=) -> Learner

LEARNERS: dict[str, LearnerFactory] = {spec.name: cast(LearnerFactory, load_factory(spec))
                                       for spec in learner_specs().values()}
__all__ = ["LEARNERS", "LearnerFactory", "build_learner", "max_episode_length", "samples_episodes"]


def samples_episodes(name: str) -> bool:
    """Whether learner ``name`` trains on episode windows (``make_sampler``) instead of a transition replay."""
    factory = LEARNERS[name]
    return isinstance(factory, type) and issubclass(factory, SequenceLearner)


def max_episode_length(cfg: AgentConfig) -> EpisodeLimit | None:
    """The most steps a dataset episode may have for the learner of ``cfg`` (a :class:`SequenceLearner`'s
    ``max_episode_length``; None: any), known before the learner is built."""
    factory = LEARNERS[cfg.learner]
    if isinstance(factory, type) and issubclass(factory, SequenceLearner):
        return factory.max_episode_length(cfg)
    return None


def build_learner(cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
                  device: torch.device | str, explore_steps: int = 0) -> Learner:
    """The learner named by ``cfg.learner`` (KeyError for an unknown name; config validation names it first)."""
    return LEARNERS[cfg.learner](cfg, obs_shape, action_dim, device=device, explore_steps=explore_steps)
