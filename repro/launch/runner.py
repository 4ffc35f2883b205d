"""Steps shared by the launchers: claim a run (lock + fresh state check), move a mismatched run dir
aside, the ``repro train`` command line, and a child's tie to its parent."""

from __future__ import annotations

import ctypes
import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from repro.launch import lock
from repro.launch.slurm_query import job_states
from repro.launch.spec import PlannedRun


@dataclass
class Claim:
    """The outcome of trying to claim a run for execution."""

    planned: PlannedRun
    status: str  # claimed | done | locked | mismatch
    info: lock.LockInfo | None = None  # our lock when claimed, the other owner when locked
    moved_to: Path | None = None

    @property
    def lock_path(self) -> Path:
        return lock.lock_path(self.planned.results_root, self.planned.run_dir)


def train_args(overrides: tuple[str, ...] | list[str]) -> list[str]:
    """The arguments of ``repro train OVERRIDES`` after the program name."""
    return ["train", *overrides]


def train_command(overrides: tuple[str, ...] | list[str]) -> list[str]:
    """``repro train OVERRIDES`` with the interpreter (and import path) running this process."""
    return [sys.executable, "-m", "repro", *train_args(overrides)]


def die_with_parent(signum: int = signal.SIGTERM) -> None:
    """In a child: get ``signum`` when its parent dies, even by SIGKILL (Linux prctl; elsewhere nothing)."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signum)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def move_aside(planned: PlannedRun) -> Path:
    """Move a run directory to ``{results_root}/.replaced/{time}/...`` (never deleted)."""
    rel = Path(os.path.relpath(planned.run_dir, planned.results_root))
    dest = planned.results_root / ".replaced" / time.strftime("%Y%m%dT%H%M%S") / rel
    n = 1
    while dest.exists():
        dest = dest.with_name(f"{rel.name}.{n}")
        n += 1
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.move(str(planned.run_dir), str(dest))
    return dest


def _writer(holder: str) -> lock.LockInfo:
    """A LockInfo that describes the holder of a run directory's writer lock (``describe()``: pid N on HOST)."""
    words = holder.split()
    if len(words) >= 4 and words[0] == "pid" and words[1].isdigit() and words[2] == "on":
        return lock.LockInfo(token="", host=words[3], pid=int(words[1]), pid_start=None, launcher="train")
    return lock.LockInfo(token="", host="?", pid=0, pid_start=None, launcher="train")


def claim(planned: PlannedRun, launcher: str, sweep: str, force: bool) -> Claim:
    """Lock the run, then re-read its state under the lock (another launcher may have finished it)."""
    from repro.runs.rundir import config_diff, run_state, writer_lock_holder

    info = lock.LockInfo.mine(launcher, sweep)
    path = lock.lock_path(planned.results_root, planned.run_dir)
    ok, owner = lock.acquire(path, info, job_states)
    if not ok:
        return Claim(planned, "locked", owner)
    holder = writer_lock_holder(planned.run_dir)  # a `repro train` started by hand or from another root
    if holder is not None:
        lock.release(path, info.token)
        return Claim(planned, "locked", _writer(holder))
    state = run_state(planned.run_dir, planned.budget)
    diff = config_diff(planned.run_dir, planned.cfg) if state != "absent" else []
    if diff and not force:
        lock.release(path, info.token)
        return Claim(planned, "mismatch")
    if state == "done" and not diff:
        lock.release(path, info.token)
        return Claim(planned, "done")
    moved = move_aside(planned) if diff else None
    return Claim(planned, "claimed", info, moved)
