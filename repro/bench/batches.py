"""The batches every update benchmark feeds a learner, drawn by the code that draws training batches: synthetic
episodes (random frames, actions in [-1, 1], rewards in [0, 1]) put into the online ReplayBuffer as a run puts them,
then sampled with what the learner and its objectives ask for (``learner.sample_options``: SPR's future frame
sequence, ...), or, for a sequence learner (Decision Transformer), windows from its own sampler (``make_sampler``), at
its own batch size. A synthetic batch made by hand misses what an objective needs (``repro bench update --agent spr``
failed with "the batch has no future_obs_seq"); this one has what training gives it."""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np

from repro.agent.protocol import SequenceLearner
from repro.config.schema import AgentConfig
from repro.data.replay import ReplayBuffer

FRAME_SHAPE = (3, 84, 84)


def synthetic_episodes(n_episodes: int = 4, length: int = 100, action_dim: int = 6, seed: int = 0,
                       frame_shape: tuple[int, int, int] = FRAME_SHAPE) -> list[dict[str, np.ndarray]]:
    """Episodes in the dataset contract's arrays (random frames, actions in [-1, 1], rewards in [0, 1])."""
    rng = np.random.default_rng(seed)
    return [{"frames": rng.integers(0, 256, (length + 1, *frame_shape), dtype=np.uint8),
             "actions": rng.uniform(-1, 1, (length, action_dim)).astype(np.float32),
             "rewards": rng.uniform(0, 1, length).astype(np.float32),
             "discounts": np.ones(length, dtype=np.float32), "ep_id": np.array(i)} for i in range(n_episodes)]


def fill_buffer(episodes: Sequence[Mapping[str, np.ndarray]], cfg: AgentConfig, frame_stack: int, seed: int,
                device: str) -> ReplayBuffer:
    """A ReplayBuffer holding ``episodes``, filled as the online loop fills it."""
    capacity = sum(len(ep["frames"]) for ep in episodes)
    action_dim = int(episodes[0]["actions"].shape[1])
    frame_shape = tuple(episodes[0]["frames"].shape[1:])
    buf = ReplayBuffer(capacity, frame_shape, action_dim, frame_stack, cfg.nstep, cfg.K, cfg.discount,
                       seed=seed, device=device)
    for ep in episodes:
        buf.add_episode(ep)
    return buf


def batch_stream(learner: Any, cfg: AgentConfig, frame_stack: int, episodes: Sequence[Mapping[str, np.ndarray]],
                 device: str, size: int | None = None, seed: int = 0) -> Iterator[Any]:
    """Batches of ``size`` (default: the learner's batch size) drawn one after another from ``episodes`` as
    ``learner``'s training draws them: one replay (or sequence sampler) filled once, sampled at every step. The
    same ``seed`` gives the same stream (the replay's own generator, not torch's), so two agents compared update by
    update (repro/bench/agreement.py, tests/test_graphs.py) see the same batches."""
    size = learner.batch_size if size is None else size
    if isinstance(learner, SequenceLearner):
        sampler = learner.make_sampler(episodes, seed=seed)
        while True:
            yield sampler.sample(size)
    buf = fill_buffer(episodes, cfg, frame_stack, seed=seed, device=device)
    while True:
        yield buf.sample(size, **learner.sample_options)


def training_batch(learner: Any, cfg: AgentConfig, frame_stack: int, episodes: Sequence[Mapping[str, np.ndarray]],
                   device: str, size: int | None = None, seed: int = 0) -> tuple[Any, int]:
    """(a batch of ``size`` (default: the learner's batch size) drawn from ``episodes`` as ``learner``'s training
    draws one, its batch size): the first of :func:`batch_stream`."""
    size = learner.batch_size if size is None else size
    return next(batch_stream(learner, cfg, frame_stack, episodes, device, size, seed)), size
