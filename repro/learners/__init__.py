"""Learners: the protocol (repro/agent/protocol.py, re-exported here) and the registry keyed by ``agent.learner``."""

from repro.agent.protocol import (
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
