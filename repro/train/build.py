"""What a run is built from, each from its config: the environment, the learner, the offline data and its batch
source, the evaluation videos and the W&B run. ``repro/train/api.py`` composes them into a run."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import torch
from omegaconf import DictConfig

from repro.config.compose import run_keys
from repro.config.schema import RunConfig
from repro.data.offline_replay import (
    DatasetError,
    OfflineData,
    load_offline_data,
    load_offline_episodes,
    resolve_dataset,
)
from repro.envs import run_action_dim
from repro.envs.base import Env
from repro.learners import Learner, SequenceLearner, build_learner, max_episode_length, samples_episodes
from repro.runs.video import VIDEO_DIR, EvalVideos
from repro.runs.wblog import WandbRun
from repro.train.devices import resolve_device
from repro.train.offline_loop import BatchSource


def build_env(rc: RunConfig, seed: int) -> Env:
    from repro.envs import make_env

    e = rc.env
    return make_env(rc.task.name, seed=seed, action_repeat=e.action_repeat, frame_stack=e.frame_stack,
                    image_size=e.image_size, distracting_dims=e.distracting_dims,
                    max_episode_frames=e.max_episode_frames, camera=e.camera)


def build_run_learner(rc: RunConfig, obs_shape: tuple[int, int, int], action_dim: int, device: str) -> Learner:
    """The learner named by ``agent.learner`` (the online Agent by default), seeded by the run's seed."""
    torch.manual_seed(rc.seed)
    return build_learner(rc.agent, obs_shape, action_dim, device, explore_steps=rc.train.explore_steps)


def eval_videos(rc: RunConfig, path: Path, unit: str) -> EvalVideos | None:
    """train.save_video: where (``{run}/videos``), how large and how often the loop writes evaluation videos."""
    if not rc.train.save_video:
        return None
    return EvalVideos(path / VIDEO_DIR, rc.train.video_size, rc.train.video_every, unit=unit)


def load_dataset(rc: RunConfig) -> OfflineData:
    """Resolve ``offline.dataset`` and load it into a replay sized to it (DatasetError: one line)."""
    if rc.offline.dataset is None:
        raise DatasetError(f"agent.learner={rc.agent.learner} trains from a dataset: set offline.dataset="
                           "medium|medium-replay|full-replay (under the results root) or a dataset folder.")
    directory = resolve_dataset(rc.offline.dataset, rc.runtime.results_root, rc.task.name)
    if samples_episodes(rc.agent.learner):  # the learner samples its own windows: episodes, no replay
        return load_offline_episodes(directory, task=rc.task.name, action_dim=run_action_dim(rc),
                                     frame_shape=(3, rc.env.image_size, rc.env.image_size),
                                     max_length=max_episode_length(rc.agent))
    return load_offline_data(directory, task=rc.task.name, action_dim=run_action_dim(rc),
                             frame_shape=(3, rc.env.image_size, rc.env.image_size), frame_stack=rc.env.frame_stack,
                             nstep=rc.agent.nstep, K=rc.agent.K, discount=rc.agent.discount, seed=rc.seed,
                             device=resolve_device(rc.replay.device),
                             sample_device=resolve_device(rc.runtime.device, "runtime.device"))


def batch_source(learner: Learner, data: OfflineData, seed: int) -> BatchSource:
    """The replay loaded from the dataset, or a SequenceLearner's sampler over its episodes."""
    if isinstance(learner, SequenceLearner):
        if data.episodes is None:
            raise DatasetError(f"{data.directory}: loaded as a replay, but this learner samples episode windows")
        return learner.make_sampler(data.episodes, seed)
    if data.buffer is None:
        raise DatasetError(f"{data.directory}: loaded as episodes, but this learner samples a replay")
    return data.buffer


def wandb_run(rc: RunConfig, cfg: DictConfig, path: Path) -> WandbRun:
    """runtime.wandb: the W&B run of the run directory ``path``, named by its identity (its folder under the
    results root), grouped by experiment/agent/variant/task (and dataset), tagged with the sweep and the seed;
    its config is the run's resolved config."""
    name = Path(os.path.relpath(path, rc.runtime.results_root)).as_posix()
    tags = ([f"sweep={rc.runtime.sweep}"] if rc.runtime.sweep else []) + [f"seed={rc.seed}"]
    config = run_keys(cfg)  # what config.yaml holds: the keys the run's learner reads
    return WandbRun(mode=str(rc.runtime.wandb_mode), project=rc.runtime.wandb_project, entity=rc.runtime.wandb_entity,
                    group=name.rsplit("/", 1)[0], name=name, tags=tuple(tags),
                    config={str(k): v for k, v in config.items()})


def with_resolved(wandb: WandbRun | None, values: dict[str, Any]) -> WandbRun | None:
    """The W&B config with the run's resolved values (resolved.json) beside the config."""
    return None if wandb is None else dataclasses.replace(wandb, config={**wandb.config, "resolved": values})
