"""The learner protocol: what a trainer (online or offline) and the rest of the tree need from a learner. It lives
beside its defaults (``LearnerBase``, ``repro/agent/modules.py``) in layer 2, so that every layer from 2 up names a
learner by this type (``repro.runs.rundir.resolved_values``, ``repro.data.record``), never ``Any``.

A learner owns its networks and optimizers. ``update`` takes one batch of tensors as returned by
``ReplayBuffer.sample(batch_size, **learner.sample_options)`` and returns its metrics as detached 0-d tensors
whose keys are ``metric_names()`` (the train.csv columns); it makes no host sync (no ``.item()``): the loops
average the metrics on the device and fetch them when they write a row (``repro/train/common.py``
``MetricMeans``). It never touches files. ``state_dict`` is plain tensors and containers (``{"modules": {...},
"optimizers": {...}}``) so checkpoints load with ``weights_only=True``.

Every hook a caller uses is a member of ``Learner``; ``LearnerBase`` (``repro/agent/modules.py``) holds the
defaults of the optional ones (``weights``, ``action_encoder``, ``batch_size``, ``resolved``,
``set_dataset_returns``). The learners on the DrQ-v2 backbone own it as an attribute
(``repro/agent/backbone.py``). The narrower protocols below are capabilities a caller tests with ``isinstance``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple, Protocol, runtime_checkable

import numpy as np
import torch

from repro.agent.losses import Metrics
from repro.agent.modules import LearnerBase, count_parameters
from repro.agent.networks import ActionEncoder
from repro.config.schema import AgentConfig

__all__ = ["EpisodeLimit", "EpisodicActor", "Learner", "LearnerBase", "Metrics", "OnlineLearner", "ReturnConditioned",
           "Sampler", "SequenceLearner", "count_parameters"]


@runtime_checkable
class Learner(Protocol):
    cfg: AgentConfig
    sample_options: dict[str, Any]  # keyword arguments of ReplayBuffer.sample (e.g. future_seq)

    def act(self, obs: np.ndarray, step: int, eval_mode: bool) -> np.ndarray:
        """Action for one stacked observation (C, H, W) uint8; ``eval_mode``: the policy mean."""
        ...

    def update(self, batch: dict[str, torch.Tensor], step: int) -> Metrics:
        """One gradient update on ``batch``; ``step`` is the agent step (online) or update count (offline).
        Returns detached 0-d tensors (no host sync)."""
        ...

    def state_dict(self) -> dict:
        ...

    def load_state_dict(self, state: dict) -> None:
        ...

    def parameter_counts(self) -> list[tuple[str, int]]:
        """Trainable parameters per module, each parameter counted once."""
        ...

    def metric_names(self) -> list[str]:
        ...

    def train(self, training: bool = True) -> None:
        ...

    @property
    def weights(self) -> Mapping[str, float]:
        """The active auxiliary objectives' weights (resolved.json's ``objectives``)."""
        ...

    @property
    def action_encoder(self) -> ActionEncoder | None:
        """The action encoder u when the critic sees latent actions (resolved.json's ``latent_action_dim``)."""
        ...

    @property
    def batch_size(self) -> int:
        """Samples per update (``agent.batch_size`` unless the learner has its own, e.g. DT's windows)."""
        ...

    @property
    def resolved(self) -> Mapping[str, object]:
        """Values the learner used that analysis reads, added to resolved.json (``rundir.resolved_values``)."""
        ...

    def set_dataset_returns(self, returns: Sequence[float]) -> None:
        """The offline dataset's episode returns, before training (IQL's reward scaling reads them)."""
        ...


@runtime_checkable
class OnlineLearner(Learner, Protocol):
    """What the online loop needs on top: the exploration std at a step (a train.csv column), and the modules that
    act (``runtime.record=true`` keeps their state after each evaluation, ``repro/data/record.py``)."""

    def stddev(self, step: int) -> float:
        ...

    def acting_modules(self) -> Mapping[str, torch.nn.Module]:
        """The modules acting needs, by name (the DrQ-v2 backbone's ``encoder`` and ``actor``): a recorded policy
        snapshot holds their state dicts."""
        ...


class Sampler(Protocol):
    """Batches for a learner that does not sample single transitions (``SequenceLearner.make_sampler``).
    ``rng`` is its only state: the offline loop checkpoints ``rng.bit_generator.state`` (exact resume)."""

    rng: np.random.Generator

    def sample(self, batch_size: int) -> Mapping[str, Any]:
        ...


class EpisodeLimit(NamedTuple):
    """The most steps a dataset episode may have for a learner, and the setting that sets it (named in the
    refusal, so that the user knows what to raise)."""

    steps: int
    setting: str


@runtime_checkable
class SequenceLearner(Protocol):
    """An offline learner trained on windows of whole episodes (Decision Transformer): the offline loop
    builds its batches from the dataset's episodes with ``make_sampler`` instead of loading a replay."""

    def make_sampler(self, episodes: Sequence[Mapping[str, np.ndarray]], seed: int) -> Sampler:
        ...

    @staticmethod
    def max_episode_length(cfg: AgentConfig) -> EpisodeLimit | None:
        """The most steps a dataset episode may have for this learner's config and the setting that sets it (DT:
        the size of its timestep embedding), checked when the dataset loads, before the learner is built;
        None: any."""
        ...


@runtime_checkable
class EpisodicActor(Protocol):
    """A learner whose acting depends on the episode so far: evaluation calls ``begin_episode()`` before
    each episode's first ``act`` and ``observe(action, reward)`` after every environment step."""

    def begin_episode(self) -> None:
        ...

    def observe(self, action: np.ndarray, reward: float) -> None:
        ...


@runtime_checkable
class ReturnConditioned(EpisodicActor, Protocol):
    """A learner evaluated at a target return (Decision Transformer); the offline loop evaluates it at the
    best online return and at the dataset's best return (eval.csv: runformat.RETURN_TARGET_EVAL_COLUMNS)."""

    def set_target_return(self, value: float) -> None:
        ...
