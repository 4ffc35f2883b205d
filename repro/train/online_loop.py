"""The online training loop (as upstream DrQ-v2): it receives env, learner, buffer and logger.

Shared pieces (episode seeds, evaluation rollouts, RNG state) live in repro/train/common.py; the offline
loop is repro/train/offline_loop.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from repro.agent.protocol import OnlineLearner
from repro.config.schema import TrainConfig
from repro.data.episodes import EpisodeStore
from repro.data.record import Recorder
from repro.data.replay import ReplayBuffer
from repro.envs.base import Env, TimeStep
from repro.runs.logger import RunLogger
from repro.runs.video import EvalVideos
from repro.train.common import (
    MetricMeans,
    WallClock,
    episode_seed,
    eval_fields,
    rng_state,
    run_eval_episodes,
    set_rng_state,
)

__all__ = ["Counters", "OnlineLoop", "episode_seed"]


@dataclass
class Counters:
    step: int = 0  # agent steps
    episode: int = 0  # finished training episodes


@dataclass
class _Episode:
    """The training episode in progress: its last time step, its running return, length and success, when it
    started (wall clock) and its update metrics."""

    ts: TimeStep
    reward: float = 0.0
    length: int = 0  # agent steps
    success: float = 0.0
    started: float = field(default_factory=time.time)
    means: MetricMeans = field(default_factory=MetricMeans)

    def add(self, ts: TimeStep) -> None:
        self.ts = ts
        self.reward += ts.reward
        self.length += 1
        self.success = max(self.success, float(ts.info.get("success", 0.0)))


class OnlineLoop:
    """Drives an online run: the environment, the learner, its replay and the logs, from a fresh start or a
    checkpoint to ``train.frames``."""

    def __init__(self, cfg: TrainConfig, seed: int, action_repeat: int, env: Env, eval_env: Env, agent: OnlineLearner,
                 buffer: ReplayBuffer, logger: RunLogger, episodes: EpisodeStore,
                 save_checkpoint: Callable[[dict], None], progress=None,
                 save_frames: Callable[[np.ndarray], None] | None = None, recorder: Recorder | None = None,
                 videos: EvalVideos | None = None, budget_ends: tuple[int, ...] = (),
                 final_embedding: Callable[[OnlineLearner, int], None] | None = None):
        self.cfg, self.seed, self.action_repeat = cfg, seed, action_repeat
        self.env, self.eval_env, self.agent, self.buffer = env, eval_env, agent, buffer
        self.logger, self.episodes, self._save = logger, episodes, save_checkpoint
        self.progress = progress
        self.save_frames = save_frames
        self.recorder = recorder  # runtime.record: keeps every episode and a policy snapshot per evaluation
        self.videos = videos  # train.save_video: an MP4 of the first evaluation episode
        # F6's embedding of the final action encoder (tsne.npz: repro/train/action_tsne.py), at the final evaluation
        self.final_embedding = final_embedding
        # Budgets (frames) this run reached before it was extended: it evaluates there again, as it did when it
        # stopped there (an evaluation draws no training random number, so the trajectory is unchanged).
        self.budget_end_steps = frozenset(self._steps(f) for f in budget_ends)
        self.total_steps = self._steps(cfg.frames)
        self.eval_every = self._steps(cfg.eval_every_frames)
        self.seed_steps = cfg.seed_frames // action_repeat
        self.counters = Counters()
        self.batch_size = agent.batch_size
        self.metric_names = agent.metric_names()
        self.has_success = env.spec.has_success
        self.clock = WallClock()
        self.last_eval: float | None = None
        self._eval_seconds = 0.0  # evaluation time inside the current training episode (excluded from fps)

    # ----------------------------------------------------------------- helpers
    @property
    def frame(self) -> int:
        return self.counters.step * self.action_repeat

    def total_time(self) -> float:
        return self.clock.total()

    def _steps(self, frames: int) -> int:
        return max(frames // self.action_repeat, 1)

    def checkpoint_state(self) -> dict:
        agent_state = self.agent.state_dict()
        return {"counters": {"step": self.counters.step, "episode": self.counters.episode,
                             "total_time": self.total_time()},
                "agent": agent_state["modules"],
                "optimizers": agent_state["optimizers"],
                "rng": rng_state(),
                "buffer": self.buffer.state(), "csv": self.logger.offsets(), "last_eval": self.last_eval}

    def restore(self, state: dict) -> None:
        c = state["counters"]
        self.counters = Counters(int(c["step"]), int(c["episode"]))
        self.clock.resume(float(c["total_time"]))
        self.agent.load_state_dict({"modules": state["agent"], "optimizers": state["optimizers"]})
        set_rng_state(state["rng"])
        self.buffer.restore(state["buffer"], self.episodes.load)
        self.last_eval = state.get("last_eval")

    # ----------------------------------------------------------------- evaluation
    def evaluate(self, final: bool = False) -> None:
        started = time.time()
        try:
            self._evaluate(record=final and self.cfg.save_frames,
                           video=self.videos is not None and self.videos.wanted(final))
            if self.recorder is not None:
                assert self.last_eval is not None  # set by _evaluate
                self.recorder.snapshot(self.agent, self.counters.step, self.frame, self.last_eval)
            if final and self.final_embedding is not None:
                self.final_embedding(self.agent, self.frame)
        finally:
            self._eval_seconds += time.time() - started

    def _evaluate(self, record: bool = False, video: bool = False) -> None:
        """Evaluate with the policy mean; ``record`` saves the first episode's frames (frames.npz, for F13),
        ``video`` its evaluation video."""
        result = run_eval_episodes(self.eval_env, self.agent, self.cfg.eval_episodes, self.seed,
                                   self.counters.step, self.counters.step, record=record,
                                   video_size=self.videos.size if video and self.videos is not None else None)
        if result.video and self.videos is not None:
            self.videos.save(self.frame, result.video)
        if result.frames and self.save_frames is not None:
            self.save_frames(np.stack(result.frames))
        lengths = [n * self.action_repeat for n in result.lengths]  # in frames, as upstream
        shared = eval_fields(result, self.has_success)
        self.last_eval = shared["episode_reward"]
        self.logger.log_eval({
            "frame": self.frame, "step": self.counters.step, "episode": self.counters.episode, **shared,
            "episode_length": float(np.mean(lengths)) if lengths else float("nan"),
            "total_time": round(self.total_time(), 3)})

    # ----------------------------------------------------------------- training
    def _checkpoint(self) -> None:
        state = self.checkpoint_state()
        self._save(state)
        self.episodes.prune({rec[0] for rec in state["buffer"]["episodes"]})

    def run(self) -> Counters:
        """Train to ``train.frames``: at each agent step, evaluate when due, then act, update and step the
        environment (upstream's order); a finished episode writes its train.csv row and starts the next."""
        episode = self._start_episode()
        while True:
            self._maybe_evaluate()
            if self.progress is not None:
                self.progress(self.frame, self.last_eval)
            if self.counters.step >= self.total_steps:
                return self.counters
            self._act_update_step(episode)
            if episode.ts.last:
                self._end_episode(episode)
                episode = self._start_episode()

    def _start_episode(self) -> _Episode:
        """Reset the environment with the next training episode's seed and open the episode in the buffer."""
        ts = self.env.reset(seed=episode_seed(self.seed, 0, self.counters.episode))
        self.buffer.start_episode(ts.observation[-3:])
        self._eval_seconds = 0.0
        return _Episode(ts)

    def _maybe_evaluate(self) -> None:
        """Evaluate every ``train.eval_every_frames``, at the end and at a budget the run reached before."""
        step = self.counters.step
        due = step % self.eval_every == 0 or step >= self.total_steps or step in self.budget_end_steps
        if due and self.cfg.eval_episodes > 0:
            self.evaluate(final=step >= self.total_steps)

    def _act_update_step(self, episode: _Episode) -> None:
        """One agent step in upstream's order: act on the current observation, update on a sampled batch (past the
        seed frames, every ``train.update_every_steps`` steps), step the environment, store the transition."""
        step = self.counters.step
        action = self.agent.act(episode.ts.observation, step, eval_mode=False)
        if step >= self.seed_steps and step % self.cfg.update_every_steps == 0:
            episode.means.add(self.agent.update(self.buffer.sample(self.batch_size, **self.agent.sample_options), step))
        ts = self.env.step(action)
        self.buffer.add(action, ts.reward, ts.discount, ts.observation[-3:])
        self.counters.step += 1
        episode.add(ts)

    def _end_episode(self, episode: _Episode) -> None:
        """Count the finished episode, write its train.csv row, store it (and record it), checkpoint when due."""
        self.counters.episode += 1
        self.logger.log_train(self._episode_row(episode))
        stored = self.buffer.end_episode()
        self.episodes.save(stored)
        if self.recorder is not None:
            self.recorder.episode(stored, written=self.episodes.path(int(stored["ep_id"])))
        if self.counters.episode % self.cfg.checkpoint_every_episodes == 0:
            self._checkpoint()

    def _episode_row(self, episode: _Episode) -> dict[str, Any]:
        """The train.csv row of a finished episode: its return, length and success, the buffer's size, the
        exploration stddev, its frame rate (evaluation excluded) and the mean of its update metrics."""
        elapsed = max(time.time() - episode.started - self._eval_seconds, 1e-9)
        row: dict[str, Any] = {
            "frame": self.frame, "step": self.counters.step, "episode": self.counters.episode,
            "episode_reward": episode.reward, "episode_length": episode.length * self.action_repeat,
            "success": episode.success if self.has_success else None, "buffer_size": len(self.buffer),
            "stddev": self.agent.stddev(self.counters.step),
            "fps": round(episode.length * self.action_repeat / elapsed, 3),
            "total_time": round(self.total_time(), 3)}
        means = episode.means.means()
        row.update({k: means.get(k) for k in self.metric_names})
        return row
