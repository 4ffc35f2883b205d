"""A sweep's state folder: what was launched, how, and where its logs are.

Layout under ``{results_root}/.sweeps/{sweep}/``::

    state.json        sweep-level: spec path, every launch (time, launcher, host, argv, job ids)
                      and the grid launched so far (run key -> run dir, overrides)
    runs/KEY.json     one record per run, written only by the holder of the run's lock
    logs/KEY.log      stdout+stderr of local runs
    slurm/            submitit folders (job scripts, pickles, %j_0_log.out/.err)

Every file is written atomically (repro/runs/fsutil.py). ``state.json`` is shared by
concurrent launches, so its read-modify-write happens under a short lock.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from repro.launch import lock
from repro.runs.fsutil import atomic_write_text

STATE_FILE = "state.json"


def state_dir(results_root: Path, sweep: str) -> Path:
    return results_root / ".sweeps" / sweep


def atomic_write_json(path: Path, data: Any) -> None:
    """``data`` as indented JSON, written atomically (repro/runs/fsutil.py)."""
    atomic_write_text(path, json.dumps(data, indent=2, sort_keys=False) + "\n")


def read_json(path: Path) -> Any | None:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        return None
    except json.JSONDecodeError:
        return None


@dataclass
class RunRecord:
    """What the launcher knows about one run (``runs/KEY.json``)."""

    key: str
    run_dir: str
    overrides: list[str]
    launcher: str
    status: str  # queued | running | done | failed | interrupted
    job_id: str | None = None
    log: str | None = None  # local log, or SLURM stdout
    stderr: str | None = None  # SLURM stderr (local runs: same as log)
    returncode: int | None = None
    host: str = field(default_factory=socket.gethostname)
    pid: int | None = None
    updated: float = field(default_factory=time.time)
    error: str | None = None
    budget: int | None = None  # the run's budget in this sweep (frames online, updates offline): done when reached


def record_path(sdir: Path, key: str) -> Path:
    return sdir / "runs" / f"{key}.json"


def log_path(sdir: Path, key: str) -> Path:
    return sdir / "logs" / f"{key}.log"


def write_record(sdir: Path, record: RunRecord) -> None:
    record.updated = time.time()
    atomic_write_json(record_path(sdir, record.key), asdict(record))


def read_record(sdir: Path, key: str) -> RunRecord | None:
    data = read_json(record_path(sdir, key))
    if not isinstance(data, dict):
        return None
    try:
        return RunRecord(**data)
    except TypeError:
        return None


def update_state(sdir: Path, change: Callable[[dict], None], timeout_s: float = 30.0) -> dict:
    """Apply ``change`` to state.json under a short lock; returns the new state."""
    path = sdir / STATE_FILE
    guard = sdir / f"{STATE_FILE}.lock"
    me = lock.LockInfo.mine("state")
    deadline = time.time() + timeout_s
    while not lock.try_create(guard, me):
        if time.time() > deadline:
            # Break the guard only if its holder is gone; otherwise keep waiting a little longer.
            if not lock.break_if_stale(guard, None):
                deadline = time.time() + timeout_s
        time.sleep(0.05)
    try:
        state = read_json(path) or {}
        change(state)
        atomic_write_json(path, state)
        return state
    finally:
        lock.release(guard, me.token)


def record_launch(sdir: Path, sweep: str, spec_path: Path, launcher: str, runs: dict[str, dict],
                  job_ids: list[str] | None = None, extra: dict | None = None) -> None:
    """Append a launch to state.json and add its runs to the sweep's known grid."""

    def change(state: dict) -> None:
        state.setdefault("sweep", sweep)
        state["spec"] = str(spec_path)
        state.setdefault("runs", {}).update(runs)
        state.setdefault("launches", []).append({
            "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "launcher": launcher,
            "host": socket.gethostname(), "pid": os.getpid(), "argv": sys.argv,
            "runs": sorted(runs), "job_ids": job_ids or [], **(extra or {})})

    update_state(sdir, change)


def read_state(sdir: Path) -> dict:
    return read_json(sdir / STATE_FILE) or {}
