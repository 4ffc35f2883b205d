"""The composition root of one run: compose its config, plan how it starts, build it (environments, learner,
data, logger), run its loop and finish it. What each step is built from lives below: repro/train/start.py (how a
run starts), build.py and devices.py (what a run is built from), progress.py (the bar), online_loop.py and
offline_loop.py (the loops)."""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, Protocol, TypeVar, cast

import torch
from omegaconf import DictConfig

from repro.config.compose import compose, typed
from repro.config.schema import RunConfig
from repro.data.episodes import EpisodeStore
from repro.data.offline_replay import OfflineData
from repro.data.record import Recorder
from repro.data.reference import score_reference
from repro.data.replay import ReplayBuffer
from repro.learners import OnlineLearner, ReturnConditioned
from repro.runs import rundir
from repro.runs.checkpoint import save_checkpoint
from repro.runs.fsutil import remove_torn_temporaries, writable_folder
from repro.runs.logger import RunLogger
from repro.runs.runformat import TRAIN
from repro.runs.video import save_frames
from repro.runs.wblog import WandbRun
from repro.train.action_tsne import save_final_tsne
from repro.train.build import (
    batch_source,
    build_env,
    build_run_learner,
    eval_videos,
    with_resolved,
)
from repro.train.devices import resolve_device
from repro.train.offline_loop import OfflineLogger, OfflineLoop
from repro.train.online_loop import OnlineLoop
from repro.train.progress import ProgressBar, progress_bar
from repro.train.start import Checked, check_start, config_format, has_rows, recheck_start, remove_empty

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C (SIGINT) stopped the run's loop; its message is the one line `repro train` prints (exit 130). The
    run's files are closed and its writer lock released; its checkpoint resumes it. A KeyboardInterrupt, so code
    that stops on Ctrl-C stops on it as before."""

    def __init__(self, at: str):
        super().__init__(f"interrupted at {at}; run the same command to resume")


def train(overrides: list[str], echo: Callable[[str], None] = print, progress: bool | None = False) -> Path:
    """Compose the config from Hydra ``overrides`` and train it (resumable)."""
    return train_config(compose(overrides), echo=echo, progress=progress)


def train_config(cfg: DictConfig, echo: Callable[[str], None] = print, progress: bool | None = None) -> Path:
    """Train (or resume, extend, or skip if done) the run described by ``cfg``; return its run directory.

    Everything that can refuse the run is checked before anything is written (the config against the run
    directory's, the budget, the devices, the dataset, a checkpoint's dataset, a results root it cannot write), so
    a refusal leaves the run directory byte-identical. The run directory then has one writer: its writer lock is
    taken before the first write and the state is read again under it (RunLocked when another process holds it).
    A failure before the run's first update (no checkpoint, no train.csv row) removes a run directory this call
    created. Ctrl-C in the loop raises :class:`RunInterrupted` once the run's files are closed; the writer lock is
    released (and its file removed) however the call ends, short of a kill."""
    rc = typed(cfg)
    path = rundir.run_dir(cfg)
    checked = check_start(rc, cfg, path, echo)
    if checked is None:
        return path
    writable_folder(rc.runtime.results_root, "runtime.results_root")
    writable_folder(path, "run directory")
    created = not path.exists()
    path.mkdir(parents=True, exist_ok=True)
    try:
        lock = rundir.acquire_writer_lock(path)
    except BaseException:
        if created:
            remove_empty(path)
        raise
    with lock:
        checked = recheck_start(checked, rc, cfg, path, echo)
        if checked is None:
            return path
        try:
            _start(rc, cfg, path, checked, echo, progress)
        except BaseException:  # an error, Ctrl-C, a requeue's SystemExit
            if created and not (path / rundir.CHECKPOINT).exists() and not has_rows(path / TRAIN):
                shutil.rmtree(path, ignore_errors=True)  # failed before its first update: leave no directory
            raise
    return path


def _start(rc: RunConfig, cfg: DictConfig, path: Path, checked: Checked, echo: Callable[[str], None],
           progress: bool | None) -> None:
    """Under the writer lock: write config.yaml (today's format, the new budget) and meta.json, drop DONE of a run
    being extended, and train."""
    start, state = checked.start, checked.state
    remove_torn_temporaries(path)
    remove_torn_temporaries(path / rundir.REPLAY)
    resuming = state is not None
    saved = (path / rundir.CONFIG).exists()
    before = config_format(path) if saved else None
    rundir.write_config(path, cfg)  # the budget may have changed, and an older format is rewritten in today's
    if rc.runtime.threads:
        torch.set_num_threads(int(rc.runtime.threads))
    extension = (start.extend_from, start.budget) if start.extend_from is not None else None
    rundir.write_meta(path, checked.device, resumed=resuming, extension=extension, config_from=before)
    if start.extend_from is not None:
        (path / rundir.DONE).unlink(missing_ok=True)
        echo(f"extending from {start.extend_from} to {start.budget} {start.unit}: {path}")
    ends = tuple(b for b in start.reached if b < start.budget)
    if checked.data is not None:
        _train_offline(rc, path, checked.data, checked.device, state, echo, progress, ends, checked.wandb)
    else:
        _train_online(rc, path, checked.device, state, echo, progress, ends, checked.wandb)


def _train_online(rc: RunConfig, path: Path, device: str, state: dict | None, echo: Callable[[str], None],
                  progress: bool | None, ends: tuple[int, ...] = (), wandb: WandbRun | None = None) -> None:
    ckpt_file = path / rundir.CHECKPOINT
    env = build_env(rc, rc.seed)
    eval_env = build_env(rc, rc.seed + 10_000)
    try:
        spec = env.spec
        agent = cast(OnlineLearner, build_run_learner(rc, spec.obs_shape, spec.action_dim, device))  # not is_offline
        values = rundir.resolved_values(rc, agent)
        rundir.write_resolved(path, values)
        replay_device = resolve_device(rc.replay.device)
        buffer = ReplayBuffer(rc.replay.capacity, (3, *spec.obs_shape[1:]), spec.action_dim, rc.env.frame_stack,
                              rc.agent.nstep, rc.agent.K, rc.agent.discount, seed=rc.seed, device=replay_device,
                              sample_device=device)
        episodes = EpisodeStore(path / "replay")
        if state is None:
            episodes.prune(set())
        recorder = Recorder.open(path, rc.agent, spec.obs_shape, spec.action_dim, state) if rc.runtime.record else None
        logger = RunLogger(path, agent.metric_names(), offsets=state["csv"] if state else None, echo=echo,
                           tensorboard=rc.runtime.tensorboard, wandb=with_resolved(wandb, values))
        bar = progress_bar(rc, progress)
        loop = OnlineLoop(rc.train, rc.seed, rc.env.action_repeat, env, eval_env, agent, buffer, logger, episodes,
                          lambda s: save_checkpoint(ckpt_file, s), progress=bar.update if bar else None,
                          save_frames=partial(save_frames, path), recorder=recorder,
                          videos=eval_videos(rc, path, "frame"), budget_ends=ends,
                          final_embedding=final_embedding(rc, path, spec.action_dim))

        def resumed(saved: dict) -> None:
            episodes.prune({rec[0] for rec in saved["buffer"]["episodes"]})
            echo(f"resumed {path} at frame {loop.frame}")

        _restore_run_finish(path, loop, state, resumed, bar, logger,
                            lambda c: {"frame": c.step * rc.env.action_repeat, "step": c.step, "episode": c.episode},
                            rc.train.frames, lambda: f"frame {loop.frame}")
        if not rc.runtime.keep_replay:
            _drop_replay(path, rc.train.frames)
    finally:
        env.close()
        eval_env.close()


def final_embedding(rc: RunConfig, path: Path, action_dim: int) -> Callable[[OnlineLearner, int], None] | None:
    """A run with distracting action dims writes F6's embedding of its final action encoder (tsne.npz); None for the
    others (and for a learner without an action encoder, which the callable skips)."""
    distracting = int(rc.env.distracting_dims)
    if distracting <= 0:
        return None

    def save(agent: OnlineLearner, frame: int) -> None:
        if agent.action_encoder is not None:
            save_final_tsne(path, agent.action_encoder, action_dim, distracting, frame)

    return save


def _train_offline(rc: RunConfig, path: Path, data: OfflineData, device: str, state: dict | None,
                   echo: Callable[[str], None], progress: bool | None, ends: tuple[int, ...] = (),
                   wandb: WandbRun | None = None) -> None:
    ckpt_file = path / rundir.CHECKPOINT
    eval_env = build_env(rc, rc.seed + 10_000)
    try:
        spec = eval_env.spec
        learner = build_run_learner(rc, spec.obs_shape, spec.action_dim, device)
        learner.set_dataset_returns([float(r) for r in data.manifest.returns])  # IQL's optional reward scaling
        values = rundir.resolved_values(rc, learner)
        values.update({"dataset_dir": str(data.directory), "dataset_kind": data.manifest.kind,
                       "dataset_manifest_sha256": data.digest})
        rundir.write_resolved(path, values)
        logger = OfflineLogger(path, learner.metric_names(), offsets=state["csv"] if state else None, echo=echo,
                               return_conditioned=isinstance(learner, ReturnConditioned),
                               tensorboard=rc.runtime.tensorboard, wandb=with_resolved(wandb, values))
        bar = progress_bar(rc, progress, total=rc.offline.updates, unit="updates/s")
        loop = OfflineLoop(rc.offline, rc.seed, rc.env.action_repeat, eval_env, learner,
                           batch_source(learner, data, rc.seed), logger, lambda s: save_checkpoint(ckpt_file, s),
                           reference=score_reference(rc.task.name, data.manifest.source),
                           dataset_digest=data.digest, progress=bar.update if bar else None,
                           dataset_best_return=data.best_return, videos=eval_videos(rc, path, "update"),
                           budget_ends=ends)
        _restore_run_finish(path, loop, state, lambda _: echo(f"resumed {path} at update {loop.update}"), bar,
                            logger, lambda updates: {"update": updates, "dataset": str(data.directory),
                                                     "dataset_sha256": data.digest}, rc.offline.updates,
                            lambda: f"update {loop.update}")
    finally:
        eval_env.close()


class _Loop(Protocol[T_co]):
    """The part of :class:`OnlineLoop` and :class:`OfflineLoop` that :func:`_restore_run_finish` drives."""

    def restore(self, state: dict) -> None: ...

    def run(self) -> T_co: ...

    def total_time(self) -> float: ...


class _Closing(Protocol):
    def close(self, failing: bool = False) -> None: ...


def _restore_run_finish(path: Path, loop: _Loop[T], state: dict | None, resumed: Callable[[dict], None],
                        bar: ProgressBar | None, logger: _Closing, done: Callable[[T], dict[str, Any]],
                        budget: int, at: Callable[[], str]) -> None:
    """What an online and an offline run share once built: restore ``state`` (then ``resumed(state)``), run
    the loop, close the progress bar and the logger even when the loop fails, and mark the run done with
    ``done(result)`` followed by its total time and finishing time, ``budget`` recorded as reached. Ctrl-C in the
    loop raises :class:`RunInterrupted` naming where the loop was (``at()``: ``frame N``, ``update N``)."""
    if state is not None:
        loop.restore(state)
        resumed(state)
    try:
        result = loop.run()
    except BaseException as exc:  # a kill, a requeue's SystemExit, an error: closed, then raised as it was
        if bar:
            bar.close()
        logger.close(failing=True)
        if isinstance(exc, KeyboardInterrupt) and not isinstance(exc, RunInterrupted):
            raise RunInterrupted(at()) from None
        raise
    if bar:
        bar.close()
    logger.close()
    rundir.write_done(path, {**done(result), "total_time": round(loop.total_time(), 3),
                             "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}, budget)


def _drop_replay(path: Path, budget: int) -> None:
    """runtime.keep_replay=false: remove the done run's replay folder (an extension of it is then refused); DONE
    says so."""
    done = rundir.read_done(path) or {}
    rundir.write_done(path, {**done, "replay_dropped": True}, budget)
    shutil.rmtree(path / rundir.REPLAY, ignore_errors=True)
