"""What the online and offline loops share: episode seeds, evaluation rollouts, RNG state, wall-clock time."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import torch

from repro.envs.base import Env
from repro.learners.base import EpisodicActor, Learner


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
