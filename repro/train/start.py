"""How a run starts, decided from its run directory before anything is written: afresh, resumed from its
checkpoint, a done run extended to a larger budget, or nothing to do; and the refusals (another config in the
directory, a budget the checkpoint has passed, an unreadable checkpoint or one of another dataset)."""

from __future__ import annotations

import dataclasses
import pickle
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml
from omegaconf import DictConfig

from repro.config.errors import UserError
from repro.config.schema import RunConfig, budget_key, is_offline
from repro.data.offline_replay import OfflineData
from repro.runs import migrate, rundir
from repro.runs.checkpoint import load_checkpoint
from repro.runs.wblog import WandbRun, check_wandb
from repro.train.build import load_dataset, wandb_run
from repro.train.devices import resolve_device
from repro.train.offline_loop import check_resume_dataset


class CheckpointError(UserError, ValueError):
    """A run's checkpoint that cannot be read (one line)."""


class BudgetError(UserError, ValueError):
    """A budget that cannot be honoured for the run directory (one line)."""


@dataclass(frozen=True)
class Start:
    """How a start proceeds: the run's budget (frames online, updates offline) and its unit, the budgets it reached
    before (their evaluations and checkpoints are kept on the way), and the budget a done run is extended from."""

    budget: int
    unit: str
    reached: tuple[int, ...]
    extend_from: int | None = None


@dataclass(frozen=True)
class Checked:
    """What the checks before the first write found: how the run starts, its device, its W&B run (None unless
    ``runtime.wandb``), an offline run's dataset (read and checked whole) and the checkpoint (None without one)."""

    start: Start
    device: str
    wandb: WandbRun | None
    data: OfflineData | None
    state: dict | None


def check_start(rc: RunConfig, cfg: DictConfig, path: Path, echo: Callable[[str], None]) -> Checked | None:
    """Everything that can refuse the run, before anything is written (so a refusal leaves the run directory
    byte-identical): the config against the run directory's, the budget, the devices, W&B, another writer, the
    dataset and a checkpoint's dataset. None (said in a line) when the run is done already."""
    start = plan_start(path, cfg, echo)
    if start is None:
        return None
    device = resolve_device(rc.runtime.device, "runtime.device")
    resolve_device(rc.replay.device, "replay.device")
    wandb = wandb_run(rc, cfg, path) if rc.runtime.wandb else None
    if wandb is not None:
        check_wandb()  # WandbError (one line) without the package
    holder = rundir.writer_lock_holder(path)  # refuse a running run before reading a large dataset for nothing
    if holder is not None:
        raise rundir.RunLocked(rundir.locked_message(path, holder))
    # An offline run reads and checks its whole dataset before anything is written.
    data = load_dataset(rc) if is_offline(rc.agent.learner) else None
    state = load_state(path, data)
    check_progress(path, start, state, rc.env.action_repeat)
    return Checked(start, device, wandb, data, state)


def recheck_start(checked: Checked, rc: RunConfig, cfg: DictConfig, path: Path,
                  echo: Callable[[str], None]) -> Checked | None:
    """:func:`check_start` again under the writer lock, where another writer may have finished, started or changed
    the run since: the plan and the checkpoint are read again (the checkpoint only when it changed)."""
    start = plan_start(path, cfg, echo)
    if start is None:
        return None
    state = checked.state
    if (state is None) != (not (path / rundir.CHECKPOINT).exists()) or (
            state is not None and checkpoint_changed(path, state)):
        state = load_state(path, checked.data)
    check_progress(path, start, state, rc.env.action_repeat)
    return dataclasses.replace(checked, start=start, state=state)


def plan_start(path: Path, cfg: DictConfig, echo: Callable[[str], None]) -> Start | None:
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


def check_progress(path: Path, start: Start, state: dict | None, action_repeat: int) -> None:
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


def load_state(path: Path, data: OfflineData | None) -> dict | None:
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


def checkpoint_changed(path: Path, state: dict) -> bool:
    """Whether the checkpoint ``state`` was read from has been rewritten (or removed) since."""
    try:
        return (path / rundir.CHECKPOINT).stat().st_mtime_ns != state.get("_mtime_ns")
    except FileNotFoundError:
        return True


def config_format(path: Path) -> int | None:
    """The format version of the run directory's config.yaml (None when it cannot be read)."""
    try:
        return migrate.config_version(yaml.safe_load((path / rundir.CONFIG).read_text(encoding="utf-8")) or {})
    except (OSError, yaml.YAMLError, migrate.FormatError):
        return None


def remove_empty(path: Path) -> None:
    """Remove ``path`` and the lock file in it when nothing else was written (a refused first start)."""
    try:
        if {p.name for p in path.iterdir()} <= {rundir.WRITER_LOCK}:
            (path / rundir.WRITER_LOCK).unlink(missing_ok=True)
            path.rmdir()
    except OSError:
        pass


def has_rows(csv: Path) -> bool:
    """Whether a CSV has a row below its header (a train.csv row: the run has made updates)."""
    try:
        with csv.open("rb") as f:
            return len(f.read(1 << 16).splitlines()) > 1
    except OSError:
        return False
