"""The offline training loop: gradient updates on a fixed dataset, evaluation in the environment.

At update u (u updates done): evaluate when u % eval_every_updates == 0 or u == updates (update 0 included),
then stop if u == updates, else sample a batch and update. After an update, a train.csv row every
log_every_updates and a checkpoint every checkpoint_every_updates. A resume from a checkpoint at u truncates
the CSVs to the offsets stored in it and recomputes everything after, so the files equal an uninterrupted
run's in every non-wall-clock column.

Nothing depends on the budget but where the run stops: a run extended from a budget it reached (``budget_ends``)
evaluates, logs and checkpoints there again as when it stopped there, and a train.csv row at a budget's end off the
log grid keeps the metrics summing, so every other row equals a run trained to the larger budget in one go.

Batches come from a ReplayBuffer of single transitions or, for a ``SequenceLearner`` (Decision
Transformer), from the learner's own sampler over the dataset's episodes; either way the batch source's RNG
is checkpointed. A ``ReturnConditioned`` learner is evaluated at two target returns (see ``evaluate``).
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Callable, Sequence
from typing import Any, Union

import numpy as np

from repro.agent.protocol import Learner, ReturnConditioned, Sampler
from repro.config.schema import OfflineConfig
from repro.data.offline_replay import DatasetError
from repro.data.reference import normalized_score
from repro.data.replay import ReplayBuffer
from repro.envs.base import Env
from repro.runs.logger import CsvPairLogger
from repro.runs.runformat import OFFLINE_TRAIN_COLUMNS, offline_eval_columns
from repro.runs.video import EvalVideos
from repro.runs.wblog import WandbRun
from repro.train.common import (
    EvalResult,
    MetricMeans,
    WallClock,
    eval_fields,
    rng_state,
    run_eval_episodes,
    set_rng_state,
)

BatchSource = Union[ReplayBuffer, Sampler]  # where update batches come from (both have ``rng`` and ``sample``)
LEARNER_STATE = ("modules", "optimizers")  # learner state_dict keys stored as "agent" / "optimizers"


def check_resume_dataset(state: dict, digest: str) -> None:
    """DatasetError when the checkpoint ``state`` was trained on another dataset than the one of ``digest``."""
    if state.get("offline", {}).get("dataset") != digest:
        raise DatasetError("the dataset changed since this run started (its manifest.json differs from the "
                           "one the checkpoint was trained on); use another variant or move the run away")


class OfflineLogger(CsvPairLogger):
    """eval.csv and train.csv of an offline run (columns: repro/runs/runformat.py), TensorBoard and W&B step =
    update."""

    def __init__(self, run_dir: str | os.PathLike, metric_names: Sequence[str],
                 offsets: dict[str, int] | None = None, echo: Callable[[str], None] = print,
                 return_conditioned: bool = False, tensorboard: bool = False, wandb: WandbRun | None = None):
        super().__init__(run_dir, offline_eval_columns(return_conditioned),
                         OFFLINE_TRAIN_COLUMNS + list(metric_names), offsets, echo, tensorboard, "update", wandb)

    def log_eval(self, row: dict[str, Any]) -> None:
        self._write_eval(row)
        score = row.get("normalized_score")
        extra = f"  score {score:.1f} ({row['score_reference']})" if score is not None else ""
        if row.get("episode_reward_dataset_target") is not None:
            extra += f"  (dataset target: return {row['episode_reward_dataset_target']:.2f})"
        self.echo(f"eval  update {row['update']:>8}  return {row['episode_reward']:8.2f}"
                  f" ± {row['episode_reward_std']:.2f}{extra}")


class OfflineLoop:
    def __init__(self, cfg: OfflineConfig, seed: int, action_repeat: int, eval_env: Env, learner: Learner,
                 buffer: BatchSource, logger: OfflineLogger, save_checkpoint: Callable[[dict], None],
                 reference: tuple[float | None, str], dataset_digest: str,
                 progress: Callable[[int, float | None], None] | None = None,
                 dataset_best_return: float | None = None, videos: EvalVideos | None = None,
                 budget_ends: tuple[int, ...] = ()):
        self.cfg, self.seed, self.action_repeat = cfg, seed, action_repeat
        self.eval_env, self.learner, self.buffer, self.logger = eval_env, learner, buffer, logger
        self._save, self.progress = save_checkpoint, progress
        self.reference_return, self.reference_kind = reference
        self.dataset_digest = dataset_digest
        self.videos = videos  # train.save_video: an MP4 of the first evaluation episode, named by update
        # Budgets (updates) this run reached before it was extended: evaluated, logged and checkpointed there again
        # as when it stopped there.
        self.budget_ends = frozenset(budget_ends)
        self.has_success = eval_env.spec.has_success
        self.dataset_best_return = dataset_best_return  # a ReturnConditioned learner's second target
        self.batch_size = learner.batch_size  # DT: agent.dt.batch_size
        self.update = 0
        self.clock = WallClock()
        self.last_eval: float | None = None
        self.means = MetricMeans()  # the update metrics since the last train.csv row
        self._window_seconds = 0.0  # update time (evaluation excluded) since the last train.csv row

    def total_time(self) -> float:
        return self.clock.total()

    # ----------------------------------------------------------------- checkpoints
    def checkpoint_state(self) -> dict:
        state = self.learner.state_dict()
        return {"offline": {"update": self.update, "total_time": self.total_time(), "dataset": self.dataset_digest,
                            **self.means.state(), "window_seconds": self._window_seconds},
                "agent": state["modules"], "optimizers": state["optimizers"],
                "learner": {k: v for k, v in state.items() if k not in LEARNER_STATE}, "rng": rng_state(),
                "replay_rng": self.buffer.rng.bit_generator.state, "csv": self.logger.offsets(),
                "last_eval": self.last_eval}

    def restore(self, state: dict) -> None:
        check_resume_dataset(state, self.dataset_digest)
        off = state["offline"]
        self.update = int(off["update"])
        self.means.load(off["sums"], off["n"])
        self._window_seconds = float(off["window_seconds"])
        self.learner.load_state_dict({**state.get("learner", {}), "modules": state["agent"],
                                      "optimizers": state["optimizers"]})
        set_rng_state(state["rng"])
        self.buffer.rng.bit_generator.state = state["replay_rng"]
        self.last_eval = state.get("last_eval")
        self.clock.resume(float(off["total_time"]))

    # ----------------------------------------------------------------- evaluation and logging
    def eval_targets(self) -> list[tuple[float, str]]:
        """A ReturnConditioned learner's (target return, where it comes from): the best online return first
        (the eval.csv's main columns; the dataset's best when no online reference is known), then the
        dataset's best episode return."""
        if self.dataset_best_return is None:
            raise ValueError("a return-conditioned learner needs dataset_best_return")
        online = (self.reference_return, self.reference_kind) if self.reference_return is not None else None
        dataset = (self.dataset_best_return, "dataset")
        return [online or dataset, dataset]

    def _rollouts(self, video_size: int | None = None) -> EvalResult:
        return run_eval_episodes(self.eval_env, self.learner, self.cfg.eval_episodes, self.seed, self.update,
                                 self.update, video_size=video_size)

    def evaluate(self) -> None:
        extra: dict[str, Any] = {}
        if isinstance(self.learner, ReturnConditioned):
            (target, kind), (dataset_target, _) = self.eval_targets()
            self.learner.set_target_return(dataset_target)
            other = self._rollouts().returns
            other_mean = float(np.mean(other)) if other else math.nan
            extra = {"target_return": target, "target_reference": kind, "dataset_target_return": dataset_target,
                     "episode_reward_dataset_target": other_mean,
                     "episode_reward_std_dataset_target": float(np.std(other)) if other else math.nan,
                     "normalized_score_dataset_target": normalized_score(other_mean, self.reference_return)}
            self.learner.set_target_return(target)
        video = self.videos is not None and self.videos.wanted(self.update >= self.cfg.updates)
        result = self._rollouts(video_size=self.videos.size if video and self.videos else None)
        if result.video and self.videos is not None:
            self.videos.save(self.update, result.video)
        shared = eval_fields(result, self.has_success)
        mean = self.last_eval = shared["episode_reward"]
        self.logger.log_eval({**extra, "update": self.update, **shared,
            "episode_length": float(np.mean(result.lengths)) * self.action_repeat if result.returns else math.nan,
            "normalized_score": normalized_score(mean, self.reference_return),
            "reference_return": self.reference_return, "score_reference": self.reference_kind,
            "total_time": round(self.total_time(), 3)})

    def _log_train(self, reset: bool = True) -> None:
        """A train.csv row of the metrics since the last row on the grid; ``reset=False`` (a budget's end off the
        grid) keeps them summing, so the next grid row equals a run that never stopped there."""
        row: dict[str, Any] = {"update": self.update,
                               "updates_per_s": round(self.means.n / max(self._window_seconds, 1e-9), 3),
                               "total_time": round(self.total_time(), 3)}
        means = self.means.means()
        row.update({k: means[k] for k in self.learner.metric_names() if k in means})
        self.logger.log_train(row)
        if reset:
            self.means.reset()
            self._window_seconds = 0.0

    # ----------------------------------------------------------------- loop
    def run(self) -> int:
        cfg = self.cfg
        while True:
            at_end = self.update >= cfg.updates or self.update in self.budget_ends
            if self.update % cfg.eval_every_updates == 0 or at_end:
                if cfg.eval_episodes > 0:
                    self.evaluate()
            if self.progress is not None:
                self.progress(self.update, self.last_eval)
            if self.update >= cfg.updates:
                break
            started = time.time()
            batch: Any = self.buffer.sample(self.batch_size, **self.learner.sample_options)
            self.means.add(self.learner.update(batch, self.update))
            self.update += 1
            self._window_seconds += time.time() - started
            at_end = self.update >= cfg.updates or self.update in self.budget_ends
            on_grid = self.update % cfg.log_every_updates == 0
            if on_grid or at_end:
                self._log_train(reset=on_grid)
            if self.update % cfg.checkpoint_every_updates == 0 or at_end:
                self._save(self.checkpoint_state())
        return self.update
