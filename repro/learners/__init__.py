"""Learners: one protocol (base.Learner) and a registry keyed by ``agent.learner``."""

from repro.learners.base import Learner, OnlineLearner
from repro.learners.registry import LEARNERS, build_learner, is_offline

__all__ = ["LEARNERS", "Learner", "OnlineLearner", "build_learner", "is_offline"]
