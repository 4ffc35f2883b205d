"""Build a run from its config and train it: the one place where env, agent, buffer and logger are made."""

from __future__ import annotations

import dataclasses
import os
import pickle
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, TypeVar, cast

import torch
import yaml
from omegaconf import DictConfig

from repro.config.compose import compose, run_keys, typed
from repro.config.schema import Device, RunConfig, budget_key, is_offline
from repro.data.episodes import EpisodeStore
from repro.data.offline_replay import (
    DatasetError,
    OfflineData,
    load_offline_data,
    load_offline_episodes,
    resolve_dataset,
)
from repro.data.record import Recorder
from repro.data.reference import score_reference
from repro.data.replay import ReplayBuffer
from repro.learners import (
    Learner,
    OnlineLearner,
    ReturnConditioned,
    SequenceLearner,
    build_learner,
    samples_episodes,
)
from repro.runs import migrate, rundir
from repro.runs.checkpoint import load_checkpoint, save_checkpoint
from repro.runs.fsutil import remove_torn_temporaries
from repro.runs.logger import RunLogger
from repro.runs.runformat import TRAIN
from repro.runs.video import VIDEO_DIR, EvalVideos
from repro.runs.wblog import WandbRun, check_wandb
from repro.train.offline import BatchSource, OfflineLogger, OfflineTrainer, check_resume_dataset
from repro.train.online import Trainer

T = TypeVar("T")
T_co = TypeVar("T_co", covariant=True)


class CheckpointError(ValueError):
    """A run's checkpoint that cannot be read (one line)."""


class DeviceError(ValueError):
    """A device name that is unknown or not present on this machine (one line)."""


def resolve_device(name: str, key: str = "device") -> str:
    """``auto`` -> cuda when available, else cpu; ``cpu``/``cuda``/``cuda:N`` as given when present.

    Raises :class:`DeviceError` (one line, naming ``key``) for another name or a CUDA device this machine
    lacks, before anything is written."""
    name = str(name)  # a Device member (runtime.device, replay.device) or a plain name such as cuda:1
    if name == Device.auto:
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == Device.cpu:
        return name
    if name == Device.cuda or (name.startswith("cuda:") and name[5:].isdigit()):
        if not torch.cuda.is_available():
            raise DeviceError(f"{key}={name}: this machine has no CUDA device (torch sees none); use cpu or auto")
        if ":" in name and int(name[5:]) >= torch.cuda.device_count():
            raise DeviceError(f"{key}={name}: this machine has {torch.cuda.device_count()} CUDA device(s)")
        return name
    raise DeviceError(f"{key}={name}: unknown device; one of auto, cpu, cuda, cuda:N")


def build_env(rc: RunConfig, seed: int):
    from repro.envs import make_env

    e = rc.env
    return make_env(rc.task.name, seed=seed, action_repeat=e.action_repeat, frame_stack=e.frame_stack,
                    image_size=e.image_size, distracting_dims=e.distracting_dims,
                    max_episode_frames=e.max_episode_frames, camera=e.camera)


def build_agent(rc: RunConfig, obs_shape: tuple[int, int, int], action_dim: int, device: str) -> Learner:
    """The learner named by ``agent.learner`` (the online Agent by default), seeded by the run's seed."""
    torch.manual_seed(rc.seed)
    return build_learner(rc.agent, obs_shape, action_dim, device, explore_steps=rc.train.explore_steps)


class BudgetError(ValueError):
    """A budget that cannot be honoured for the run directory (one line)."""


@dataclass(frozen=True)
class Start:
    """How a start proceeds: the run's budget (frames online, updates offline) and its unit, the budgets it reached
    before (their evaluations and checkpoints are kept on the way), and the budget a done run is extended from."""

    budget: int
    unit: str
    reached: tuple[int, ...]
    extend_from: int | None = None


def train_config(cfg: DictConfig, echo: Callable[[str], None] = print, progress: bool | None = None) -> Path:
    """Train (or resume, extend, or skip if done) the run described by ``cfg``; return its run directory.

    Everything that can refuse the run is checked before anything is written (the config against the run
    directory's, the budget, the devices, the dataset, a checkpoint's dataset), so a refusal leaves the run
    directory byte-identical. The run directory then has one writer: its writer lock is taken before the first
    write and the state is read again under it (RunLocked when another process holds it). A failure before the
    run's first update (no checkpoint, no train.csv row) removes a run directory this call created."""
    rc = typed(cfg)
    path = rundir.run_dir(cfg)
    start = _plan_start(path, cfg, echo)
    if start is None:
        return path
    device = resolve_device(rc.runtime.device, "runtime.device")
    resolve_device(rc.replay.device, "replay.device")
    wandb = wandb_run(rc, cfg, path) if rc.runtime.wandb else None
    if wandb is not None:
        check_wandb()  # WandbError (one line) without the package
    holder = rundir.writer_lock_holder(path)  # refuse a running run before reading a large dataset for nothing
    if holder is not None:
        raise rundir.RunLocked(rundir.locked_message(path, holder))
    # An offline run reads and checks its whole dataset before anything is written.
    data = _load_dataset(rc) if is_offline(rc.agent.learner) else None
    state = _load_state(path, data)
    _check_progress(path, start, state, rc.env.action_repeat)
    created = not path.exists()
    path.mkdir(parents=True, exist_ok=True)
    try:
        lock = rundir.acquire_writer_lock(path)
    except BaseException:
        if created:
            _remove_empty(path)
        raise
    with lock:
        # Under the lock: another writer may have finished, started or changed the run since the checks above.
        start = _plan_start(path, cfg, echo)
        if start is None:
            return path
        if (state is None) != (not (path / rundir.CHECKPOINT).exists()) or (
                state is not None and _checkpoint_changed(path, state)):
            state = _load_state(path, data)
        _check_progress(path, start, state, rc.env.action_repeat)
        try:
            _start(rc, cfg, path, start, device, data, state, echo, progress, wandb)
        except Exception:
            if created and not (path / rundir.CHECKPOINT).exists() and not _has_rows(path / TRAIN):
                shutil.rmtree(path, ignore_errors=True)  # failed before its first update: leave no directory
            raise
    return path


def _start(rc: RunConfig, cfg: DictConfig, path: Path, start: Start, device: str, data: OfflineData | None,
           state: dict | None, echo: Callable[[str], None], progress: bool | None,
           wandb: WandbRun | None = None) -> None:
    """Under the writer lock: write config.yaml (today's format, the new budget) and meta.json, drop DONE of a run
    being extended, and train."""
    remove_torn_temporaries(path)
    remove_torn_temporaries(path / rundir.REPLAY)
    resuming = state is not None
    saved = (path / rundir.CONFIG).exists()
    before = _config_format(path) if saved else None
    rundir.write_config(path, cfg)  # the budget may have changed, and an older format is rewritten in today's
    if rc.runtime.threads:
        torch.set_num_threads(int(rc.runtime.threads))
    extension = (start.extend_from, start.budget) if start.extend_from is not None else None
    rundir.write_meta(path, device, resumed=resuming, extension=extension, config_from=before)
    if start.extend_from is not None:
        (path / rundir.DONE).unlink(missing_ok=True)
        echo(f"extending from {start.extend_from} to {start.budget} {start.unit}: {path}")
    ends = tuple(b for b in start.reached if b < start.budget)
    if data is not None:
        _train_offline(rc, path, data, device, state, echo, progress, ends, wandb)
    else:
        _train_online(rc, path, device, state, echo, progress, ends, wandb)


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


def _with_resolved(wandb: WandbRun | None, values: dict[str, Any]) -> WandbRun | None:
    """The W&B config with the run's resolved values (resolved.json) beside the config."""
    return None if wandb is None else dataclasses.replace(wandb, config={**wandb.config, "resolved": values})


def _has_rows(csv: Path) -> bool:
    """Whether a CSV has a row below its header (a train.csv row: the run has made updates)."""
    try:
        with csv.open("rb") as f:
            return len(f.read(1 << 16).splitlines()) > 1
    except OSError:
        return False


def _config_format(path: Path) -> int | None:
    try:
        return migrate.config_version(yaml.safe_load((path / rundir.CONFIG).read_text(encoding="utf-8")) or {})
    except (OSError, yaml.YAMLError, migrate.FormatError):
        return None


def _plan_start(path: Path, cfg: DictConfig, echo: Callable[[str], None]) -> Start | None:
    """RunDirMismatch when ``path`` holds a run of another config; None (said in a line) when the run has reached
    the budget of ``cfg`` already; else how it starts (afresh, resumed, or a done run extended)."""
    diff = rundir.config_diff(path, cfg)
    if diff:
        raise rundir.RunDirMismatch(f"{path} holds a run with another config ({diff[0]}"
                                    f"{f' and {len(diff) - 1} more' if len(diff) > 1 else ''}); "
                                    "use another experiment/variant name or move it away.")
    learner = str(cfg.agent.learner)
    key = budget_key(learner)
    budget = rundir.run_budget(cfg)
    unit = "updates" if is_offline(learner) else "frames"
    reached = tuple(rundir.reached_budgets(path))
    done = (path / rundir.DONE).exists()
    if reached and reached[-1] >= budget:
        echo(f"already done: {path} (trained to {reached[-1]} {unit}; {key}={budget} asks no more)")
        return None
    if done:
        if not (path / rundir.CHECKPOINT).exists():
            raise BudgetError(f"{path} is done at {reached[-1] if reached else '?'} {unit} and has no "
                              f"{rundir.CHECKPOINT}, so it cannot be extended to {budget}; train it under another "
                              "experiment/variant name")
        dropped = rundir.read_done(path) or {}
        if not is_offline(learner) and (dropped.get("replay_dropped") or not (path / rundir.REPLAY).is_dir()):
            raise BudgetError(f"{path} dropped its replay when it finished (runtime.keep_replay=false), so it cannot "
                              f"be extended from {reached[-1] if reached else '?'} to {budget} {unit}; train it "
                              "under another experiment/variant name")
        return Start(budget, unit, reached, extend_from=reached[-1] if reached else 0)
    return Start(budget, unit, reached)


def _check_progress(path: Path, start: Start, state: dict | None, action_repeat: int) -> None:
    """BudgetError when the checkpoint is past ``start.budget`` (a smaller budget than a run being trained to a
    larger one has passed, and that the run never stopped at)."""
    if state is None:
        return
    if "offline" in state:
        at = int(state["offline"]["update"])
    else:
        at = int(state["counters"]["step"]) * action_repeat
    if at > start.budget:
        raise BudgetError(f"{path} has trained past {start.budget} {start.unit} (its checkpoint is at {at}) without "
                          f"stopping there; re-run it with a budget of at least {at}")


def _load_state(path: Path, data: OfflineData | None) -> dict | None:
    """The run's checkpoint (None without one), refused (DatasetError) when it was trained on another dataset."""
    file = path / rundir.CHECKPOINT
    if not file.exists():
        return None
    try:
        state = load_checkpoint(file)
    except (OSError, RuntimeError, ValueError, EOFError, pickle.UnpicklingError) as exc:  # torn, or not a checkpoint
        raise CheckpointError(f"{file} cannot be read ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                              "); move the run directory away to start it afresh") from None
    if data is not None:
        check_resume_dataset(state, data.digest)
    state["_mtime_ns"] = file.stat().st_mtime_ns
    return state


def _checkpoint_changed(path: Path, state: dict) -> bool:
    try:
        return (path / rundir.CHECKPOINT).stat().st_mtime_ns != state.get("_mtime_ns")
    except FileNotFoundError:
        return True


def _remove_empty(path: Path) -> None:
    """Remove ``path`` and the lock file in it when nothing else was written (a refused first start)."""
    try:
        if {p.name for p in path.iterdir()} <= {rundir.WRITER_LOCK}:
            (path / rundir.WRITER_LOCK).unlink(missing_ok=True)
            path.rmdir()
    except OSError:
        pass


def _train_online(rc: RunConfig, path: Path, device: str, state: dict | None, echo: Callable[[str], None],
                  progress: bool | None, ends: tuple[int, ...] = (), wandb: WandbRun | None = None) -> None:
    ckpt_file = path / rundir.CHECKPOINT
    env = build_env(rc, rc.seed)
    eval_env = build_env(rc, rc.seed + 10_000)
    try:
        spec = env.spec
        agent = cast(OnlineLearner, build_agent(rc, spec.obs_shape, spec.action_dim, device))  # not is_offline
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
                           tensorboard=rc.runtime.tensorboard, wandb=_with_resolved(wandb, values))
        bar = _progress(rc, progress)
        trainer = Trainer(rc.train, rc.seed, rc.env.action_repeat, env, eval_env, agent, buffer, logger, episodes,
                          lambda s: save_checkpoint(ckpt_file, s), progress=bar.update if bar else None,
                          save_frames=lambda frames: _save_frames(path / "frames.npz", frames), recorder=recorder,
                          videos=eval_videos(rc, path, "frame"), budget_ends=ends)

        def resumed(saved: dict) -> None:
            episodes.prune({rec[0] for rec in saved["buffer"]["episodes"]})
            echo(f"resumed {path} at frame {trainer.frame}")

        _restore_run_finish(path, trainer, state, resumed, bar, logger,
                            lambda c: {"frame": c.step * rc.env.action_repeat, "step": c.step, "episode": c.episode},
                            rc.train.frames)
        if not rc.runtime.keep_replay:
            _drop_replay(path, rc.train.frames)
    finally:
        env.close()
        eval_env.close()


class _Loop(Protocol[T_co]):
    """The part of :class:`Trainer` and :class:`OfflineTrainer` that :func:`_restore_run_finish` drives."""

    def restore(self, state: dict) -> None: ...

    def run(self) -> T_co: ...

    def total_time(self) -> float: ...


class _Closing(Protocol):
    def close(self, failing: bool = False) -> None: ...


def _restore_run_finish(path: Path, trainer: _Loop[T], state: dict | None, resumed: Callable[[dict], None],
                        bar: _Progress | None, logger: _Closing, done: Callable[[T], dict[str, Any]],
                        budget: int) -> None:
    """What an online and an offline run share once built: restore ``state`` (then ``resumed(state)``), run
    the loop, close the progress bar and the logger even when the loop fails, and mark the run done with
    ``done(result)`` followed by its total time and finishing time, ``budget`` recorded as reached."""
    if state is not None:
        trainer.restore(state)
        resumed(state)
    try:
        result = trainer.run()
    except BaseException:  # a kill, a requeue's SystemExit, an error: closed, then raised as it was
        if bar:
            bar.close()
        logger.close(failing=True)
        raise
    if bar:
        bar.close()
    logger.close()
    rundir.write_done(path, {**done(result), "total_time": round(trainer.total_time(), 3),
                             "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}, budget)


def _drop_replay(path: Path, budget: int) -> None:
    """runtime.keep_replay=false: remove the done run's replay folder (an extension of it is then refused); DONE
    says so."""
    done = rundir.read_done(path) or {}
    rundir.write_done(path, {**done, "replay_dropped": True}, budget)
    shutil.rmtree(path / rundir.REPLAY, ignore_errors=True)


def eval_videos(rc: RunConfig, path: Path, unit: str) -> EvalVideos | None:
    """train.save_video: where (``{run}/videos``), how large and how often the loop writes evaluation videos."""
    if not rc.train.save_video:
        return None
    return EvalVideos(path / VIDEO_DIR, rc.train.video_size, rc.train.video_every, unit=unit)


def _load_dataset(rc: RunConfig) -> OfflineData:
    """Resolve ``offline.dataset`` and load it into a replay sized to it (DatasetError: one line)."""
    if rc.offline.dataset is None:
        raise DatasetError(f"agent.learner={rc.agent.learner} trains from a dataset: set offline.dataset="
                           "medium|medium-replay|full-replay (under the results root) or a dataset folder.")
    directory = resolve_dataset(rc.offline.dataset, rc.runtime.results_root, rc.task.name)
    if samples_episodes(rc.agent.learner):  # the learner samples its own windows: episodes, no replay
        return load_offline_episodes(directory, task=rc.task.name, action_dim=run_action_dim(rc),
                                     frame_shape=(3, rc.env.image_size, rc.env.image_size),
                                     max_length=rc.agent.dt.max_timestep)
    return load_offline_data(directory, task=rc.task.name, action_dim=run_action_dim(rc),
                             frame_shape=(3, rc.env.image_size, rc.env.image_size), frame_stack=rc.env.frame_stack,
                             nstep=rc.agent.nstep, K=rc.agent.K, discount=rc.agent.discount, seed=rc.seed,
                             device=resolve_device(rc.replay.device),
                             sample_device=resolve_device(rc.runtime.device, "runtime.device"))


def run_action_dim(rc: RunConfig) -> int:
    """|A| of the run's environment without building it (the task's plus any distracting dimensions)."""
    from repro.envs import get_task

    return get_task(rc.task.name).action_dim + rc.env.distracting_dims


def _train_offline(rc: RunConfig, path: Path, data: OfflineData, device: str, state: dict | None,
                   echo: Callable[[str], None], progress: bool | None, ends: tuple[int, ...] = (),
                   wandb: WandbRun | None = None) -> None:
    ckpt_file = path / rundir.CHECKPOINT
    eval_env = build_env(rc, rc.seed + 10_000)
    try:
        spec = eval_env.spec
        learner = build_agent(rc, spec.obs_shape, spec.action_dim, device)
        set_returns = getattr(learner, "set_dataset_returns", None)
        if set_returns is not None:  # IQL's optional reward scaling reads the dataset's episode returns
            set_returns([float(r) for r in data.manifest.returns])
        values = rundir.resolved_values(rc, learner)
        values.update({"dataset_dir": str(data.directory), "dataset_kind": data.manifest.kind,
                       "dataset_manifest_sha256": data.digest})
        rundir.write_resolved(path, values)
        logger = OfflineLogger(path, learner.metric_names(), offsets=state["csv"] if state else None, echo=echo,
                               return_conditioned=isinstance(learner, ReturnConditioned),
                               tensorboard=rc.runtime.tensorboard, wandb=_with_resolved(wandb, values))
        bar = _progress(rc, progress, total=rc.offline.updates, unit="updates/s")
        trainer = OfflineTrainer(rc.offline, rc.seed, rc.env.action_repeat, eval_env, learner,
                                 _batch_source(learner, data, rc.seed), logger, lambda s: save_checkpoint(ckpt_file, s),
                                 reference=score_reference(rc.task.name, data.manifest.source),
                                 dataset_digest=data.digest, progress=bar.update if bar else None,
                                 dataset_best_return=data.best_return, videos=eval_videos(rc, path, "update"),
                                 budget_ends=ends)
        _restore_run_finish(path, trainer, state, lambda _: echo(f"resumed {path} at update {trainer.update}"), bar,
                            logger, lambda updates: {"update": updates, "dataset": str(data.directory),
                                                     "dataset_sha256": data.digest}, rc.offline.updates)
    finally:
        eval_env.close()


def _batch_source(learner: Learner, data: OfflineData, seed: int) -> BatchSource:
    """The replay loaded from the dataset, or a SequenceLearner's sampler over its episodes."""
    if isinstance(learner, SequenceLearner):
        if data.episodes is None:
            raise DatasetError(f"{data.directory}: loaded as a replay, but this learner samples episode windows")
        return learner.make_sampler(data.episodes, seed)
    if data.buffer is None:
        raise DatasetError(f"{data.directory}: loaded as episodes, but this learner samples a replay")
    return data.buffer


def _save_frames(path: Path, frames) -> None:
    """Frames of one evaluation episode, uint8 (T, H, W, 3), compressed and written atomically."""
    import io

    import numpy as np

    from repro.runs.fsutil import atomic_write

    def write(f) -> None:
        buf = io.BytesIO()
        np.savez_compressed(buf, frames=frames)
        f.write(buf.getvalue())

    atomic_write(path, write)


def train(overrides: list[str], echo: Callable[[str], None] = print, progress: bool | None = False) -> Path:
    """Compose the config from Hydra ``overrides`` and train it (resumable)."""
    return train_config(compose(overrides), echo=echo, progress=progress)


class _Progress:
    """A rich progress bar: frames (offline: updates), their rate, last eval return, ETA."""

    def __init__(self, total_frames: int, start_frame: int, label: str, unit: str = "fps"):
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._p = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                           TextColumn(f"{{task.fields[fps]}} {unit}"), TextColumn("eval {task.fields[ret]}"),
                           TimeElapsedColumn(), TimeRemainingColumn(), transient=False)
        self._p.start()
        self._task = self._p.add_task(label, total=total_frames, completed=start_frame, fps="-", ret="-")
        self._t, self._f = time.time(), start_frame

    def update(self, frame: int, last_eval: float | None) -> None:
        now = time.time()
        fps = (frame - self._f) / max(now - self._t, 1e-9)
        fields: dict[str, Any] = {"ret": f"{last_eval:.1f}" if last_eval is not None else "-"}
        if now - self._t > 2.0:
            fields["fps"] = f"{fps:.0f}"
            self._t, self._f = now, frame
        self._p.update(self._task, completed=frame, **fields)

    def close(self) -> None:
        self._p.stop()


def _progress(rc: RunConfig, forced: bool | None, total: int | None = None, unit: str = "fps") -> _Progress | None:
    setting = rc.runtime.progress if forced is None else forced
    enabled = sys.stderr.isatty() if setting == "auto" else bool(setting)
    if not enabled:
        return None
    return _Progress(rc.train.frames if total is None else total, 0, f"{rc.agent.name} {rc.task.name} s{rc.seed}",
                     unit=unit)
