"""The online training loop (as upstream DrQ-v2): it receives env, learner, buffer and logger.

Shared pieces (episode seeds, evaluation rollouts, RNG state) live in repro/train/common.py; the offline
loop is repro/train/offline_loop.py.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from repro.config.schema import TrainConfig
from repro.data.episodes import EpisodeStore
from repro.data.record import Recorder
from repro.data.replay import ReplayBuffer
from repro.envs.base import Env
from repro.learners.base import OnlineLearner
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


class OnlineLoop:
    def __init__(self, cfg: TrainConfig, seed: int, action_repeat: int, env: Env, eval_env: Env, agent: OnlineLearner,
                 buffer: ReplayBuffer, logger: RunLogger, episodes: EpisodeStore,
                 save_checkpoint: Callable[[dict], None], progress=None,
                 save_frames: Callable[[np.ndarray], None] | None = None, recorder: Recorder | None = None,
                 videos: EvalVideos | None = None, budget_ends: tuple[int, ...] = ()):
        self.cfg, self.seed, self.action_repeat = cfg, seed, action_repeat
        self.env, self.eval_env, self.agent, self.buffer = env, eval_env, agent, buffer
        self.logger, self.episodes, self._save = logger, episodes, save_checkpoint
        self.progress = progress
        self.save_frames = save_frames
        self.recorder = recorder  # runtime.record: keeps every episode and a policy snapshot per evaluation
        self.videos = videos  # train.save_video: an MP4 of the first evaluation episode
        # Budgets (frames) this run reached before it was extended: it evaluates there again, as it did when it
        # stopped there (an evaluation draws no training random number, so the trajectory is unchanged).
        self.budget_end_steps = frozenset(self._steps(f) for f in budget_ends)
        self.counters = Counters()
        self.batch_size = agent.batch_size
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
        cfg = self.cfg
        total_steps = self._steps(cfg.frames)
        eval_every = self._steps(cfg.eval_every_frames)
        seed_steps = cfg.seed_frames // self.action_repeat
        metric_names = self.agent.metric_names()

        def new_episode():
            ts = self.env.reset(seed=episode_seed(self.seed, 0, self.counters.episode))
            self.buffer.start_episode(ts.observation[-3:])
            return ts

        ts = new_episode()
        ep_reward, ep_len, ep_success, ep_start = 0.0, 0, 0.0, time.time()
        means = MetricMeans()  # the update metrics of the current episode
        while True:
            if (self.counters.step % eval_every == 0 or self.counters.step >= total_steps
                    or self.counters.step in self.budget_end_steps):
                if cfg.eval_episodes > 0:
                    self.evaluate(final=self.counters.step >= total_steps)
            if self.progress is not None:
                self.progress(self.frame, self.last_eval)
            if self.counters.step >= total_steps:
                break
            step = self.counters.step
            action = self.agent.act(ts.observation, step, eval_mode=False)
            if step >= seed_steps and step % cfg.update_every_steps == 0:
                means.add(self.agent.update(self.buffer.sample(self.batch_size, **self.agent.sample_options), step))
            ts = self.env.step(action)
            self.buffer.add(action, ts.reward, ts.discount, ts.observation[-3:])
            self.counters.step += 1
            ep_reward += ts.reward
            ep_len += 1
            ep_success = max(ep_success, float(ts.info.get("success", 0.0)))
            if ts.last:
                self.counters.episode += 1
                elapsed = max(time.time() - ep_start - self._eval_seconds, 1e-9)
                row = {"frame": self.frame, "step": self.counters.step, "episode": self.counters.episode,
                       "episode_reward": ep_reward, "episode_length": ep_len * self.action_repeat,
                       "success": ep_success if self.has_success else None, "buffer_size": len(self.buffer),
                       "stddev": self.agent.stddev(self.counters.step),
                       "fps": round(ep_len * self.action_repeat / elapsed, 3),
                       "total_time": round(self.total_time(), 3)}
                episode_means = means.means()
                row.update({k: episode_means.get(k) for k in metric_names})
                self.logger.log_train(row)
                episode = self.buffer.end_episode()
                self.episodes.save(episode)
                if self.recorder is not None:
                    self.recorder.episode(episode, written=self.episodes.path(int(episode["ep_id"])))
                if self.counters.episode % cfg.checkpoint_every_episodes == 0:
                    self._checkpoint()
                ts = new_episode()
                ep_reward, ep_len, ep_success, ep_start = 0.0, 0, 0.0, time.time()
                means.reset()
                self._eval_seconds = 0.0
        return self.counters
