"""Learners: one protocol (base.Learner) and a registry keyed by ``agent.learner``."""

from repro.learners.base import (
    EpisodicActor,
    Learner,
    LearnerBase,
    OnlineLearner,
    ReturnConditioned,
    Sampler,
    SequenceLearner,
)
from repro.learners.registry import LEARNERS, build_learner, max_episode_length, samples_episodes

__all__ = ["LEARNERS", "EpisodicActor", "Learner", "LearnerBase", "OnlineLearner", "ReturnConditioned", "Sampler",
           "SequenceLearner", "build_learner", "max_episode_length",
           "samples_episodes"]
