"""What the online and offline loops share: episode seeds, evaluation rollouts and their eval.csv fields, RNG
state, wall-clock time and the mean of the update metrics."""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np
import torch

from repro.agent.protocol import EpisodicActor, Learner
from repro.envs.base import Env


def episode_seed(seed: int, kind: int, index: int, sub: int = 0) -> int:
    """Deterministic per-episode environment seed (kind 0: training, 1: evaluation)."""
    return int(np.random.SeedSequence([seed, kind, index, sub]).generate_state(1)[0])


@dataclass
class EvalResult:
    returns: list[float] = field(default_factory=list)
    lengths: list[int] = field(default_factory=list)  # agent steps per episode
    successes: list[float] = field(default_factory=list)  # 1.0 if success was reached at any step
    frames: list[np.ndarray] = field(default_factory=list)  # first episode's frames (H, W, 3) when recorded
    video: list[np.ndarray] = field(default_factory=list)  # first episode's render_view frames when asked


def run_eval_episodes(env: Env, learner: Learner, episodes: int, seed: int, index: int, step: int,
                      record: bool = False, video_size: int | None = None) -> EvalResult:
    """``episodes`` evaluation episodes with the policy mean; resets seeded by (seed, index, episode).

    ``video_size``: also render the first episode with ``env.render_view`` (after the reset and after every
    step: length + 1 frames) for an evaluation video; rendering draws no random number and leaves the
    observations as they are. An ``EpisodicActor`` (e.g. the Decision Transformer) is told each episode's
    start and every step."""
    out = EvalResult()
    episodic = learner if isinstance(learner, EpisodicActor) else None
    learner.train(False)
    for ep in range(episodes):
        ts = env.reset(seed=episode_seed(seed, 1, index, ep))
        if episodic is not None:
            episodic.begin_episode()
        total, length, success = 0.0, 0, 0.0
        if record and ep == 0:
            out.frames.append(ts.observation[-3:].transpose(1, 2, 0))
        if video_size is not None and ep == 0:
            out.video.append(env.render_view(video_size))
        while not ts.last:
            action = learner.act(ts.observation, step, eval_mode=True)
            ts = env.step(action)
            if episodic is not None:
                episodic.observe(action, ts.reward)
            total += ts.reward
            length += 1
            success = max(success, float(ts.info.get("success", 0.0)))
            if record and ep == 0:
                out.frames.append(ts.observation[-3:].transpose(1, 2, 0))
            if video_size is not None and ep == 0:
                out.video.append(env.render_view(video_size))
        out.returns.append(total)
        out.lengths.append(length)
        out.successes.append(success)
    learner.train(True)
    return out


def rng_state() -> dict:
    return {"torch": torch.get_rng_state(),
            "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else []}


def set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    if state["cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


class WallClock:
    """Seconds since the run first started, summed over resumes (``before``: from the checkpoint)."""

    def __init__(self, before: float = 0.0):
        self.before = before
        self._t0 = time.time()

    def total(self) -> float:
        return self.before + (time.time() - self._t0)

    def resume(self, before: float) -> None:
        self.before, self._t0 = before, time.time()


def eval_fields(result: EvalResult, has_success: bool) -> dict[str, Any]:
    """The eval.csv fields both loops share: the mean and std of the returns, the success rate (None for a task
    without success) and the number of episodes (NaN means without episodes)."""
    returns = result.returns
    return {"episode_reward": float(np.mean(returns)) if returns else math.nan,
            "episode_reward_std": float(np.std(returns)) if returns else math.nan,
            "success": float(np.mean(result.successes)) if (has_success and returns) else None,
            "eval_episodes": len(returns)}


Sum = Union[torch.Tensor, float]


class MetricMeans:
    """The mean of each update metric since the last ``reset``, summed where the metrics are (on the device).

    ``add`` takes one update's metrics (detached 0-d tensors; a plain number works too) and makes no host sync;
    ``means`` fetches every mean at once, when a row is written. The arithmetic is the loops' former Python
    arithmetic: a float64 sum from 0.0 of each value in update order, divided by the number of updates, so the
    logged values are the same bits. ``state``/``load`` carry the sums as floats through a checkpoint.
    """

    def __init__(self) -> None:
        self.sums: dict[str, Sum] = {}
        self.n = 0

    def add(self, metrics: Mapping[str, torch.Tensor | float]) -> None:
        for k, v in metrics.items():
            value = v.detach().double() if isinstance(v, torch.Tensor) else float(v)
            self.sums[k] = self.sums.get(k, 0.0) + value
        self.n += 1

    def means(self) -> dict[str, float]:
        """Each metric's mean over the updates since the last reset (empty before the first update)."""
        if not self.n:
            return {}
        return {k: s / self.n for k, s in self._fetch().items()}

    def reset(self) -> None:
        self.sums, self.n = {}, 0

    def state(self) -> dict[str, Any]:
        """The sums as floats and the count (a checkpoint's ``sums`` and ``n``)."""
        return {"sums": self._fetch(), "n": self.n}

    def load(self, sums: Mapping[str, float], n: int) -> None:
        self.sums, self.n = {k: float(v) for k, v in sums.items()}, int(n)

    def _fetch(self) -> dict[str, float]:
        """The sums as Python floats: one transfer per device holding any."""
        out: dict[str, float] = {k: v for k, v in self.sums.items() if not isinstance(v, torch.Tensor)}
        held = {k: v for k, v in self.sums.items() if isinstance(v, torch.Tensor)}
        for device in {v.device for v in held.values()}:
            keys = [k for k, v in held.items() if v.device == device]
            out.update(zip(keys, torch.stack([held[k] for k in keys]).tolist()))
        return {k: out[k] for k in self.sums}
