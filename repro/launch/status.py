"""``repro status``: where every run of a sweep stands (done / running / queued / failed / cancelled / pending /
waiting)."""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from repro.launch import lock
from repro.launch.slurm_query import FAILED, NEVER_STARTS, QUEUED, explain, job_details
from repro.launch.state import read_record, read_state
from repro.launch.waiting import DatasetNeed, missing_reason
from repro.runs.health import Saturation, read_at_bound
from repro.runs.runformat import EVAL, STATE_DONE, STATE_PARTIAL, TRAIN, run_state

STATUSES = ("done", "running", "queued", "failed", "pending", "waiting", "cancelled")


@dataclass
class RunStatus:
    key: str
    run_dir: Path
    status: str  # one of STATUSES
    frame: int | None
    eval_return: float | None
    job_id: str | None
    detail: str  # failed: the error; running: where; queued: SLURM's pending reason; cancelled: before or after it
    # started; pending: partial or not started; waiting: the dataset
    log: str | None = None  # failed runs: the file holding the error (local log or SLURM stderr)
    bound: Saturation | None = None  # the actor's stretch at the bound at the end of train.csv (repro/runs/health.py)

    @property
    def health(self) -> str:
        """Whatever the status: "actor saturated since ..." once the rule holds, "actor at the bound since ..."
        before; "" when the actor is not at the bound."""
        return self.bound.message() if self.bound is not None else ""

    @property
    def saturated(self) -> bool:
        """The rule holds: the actor has been at the bound for the whole stretch."""
        return self.bound is not None and self.bound.saturated


def last_row(path: Path, tail_bytes: int = 8192) -> dict[str, str] | None:
    """The header-keyed last data row of a CSV file, reading only its head and tail."""
    try:
        with open(path, "rb") as fh:
            header = fh.readline().decode()
            size = fh.seek(0, os.SEEK_END)
            fh.seek(max(len(header), size - tail_bytes))
            tail = fh.read().decode(errors="replace")
    except OSError:
        return None
    lines = [ln for ln in tail.splitlines() if ln.strip()]
    if not header.strip() or not lines or lines[-1] == header.strip():
        return None
    row = next(csv.reader(io.StringIO(lines[-1])))
    names = next(csv.reader(io.StringIO(header)))
    return dict(zip(names, row)) if len(row) == len(names) else None


def _num(value: str | None) -> float | None:
    try:
        return float(value) if value not in (None, "") else None
    except ValueError:
        return None


def progress(run_dir: Path) -> tuple[int | None, float | None]:
    """(last frame seen in train.csv or eval.csv, last evaluation return)."""
    ev = last_row(run_dir / EVAL)
    tr = last_row(run_dir / TRAIN)
    frames = [f for f in (_num(ev.get("frame") if ev else None), _num(tr.get("frame") if tr else None))
              if f is not None]
    return (int(max(frames)) if frames else None, _num(ev.get("episode_reward") if ev else None))


def _lock_owner(results_root: Path, run_dir: Path) -> lock.LockInfo | None:
    """Who holds the run's launcher lock (None when nobody does or the lock file is unreadable)."""
    try:
        return lock.read(lock.lock_path(results_root, run_dir))
    except ValueError:
        return None


def run_status(key: str, run_dir: Path, results_root: Path, sdir: Path,
               slurm_states: dict[str, str] | None, waiting: str | None = None,
               slurm_reasons: Mapping[str, str] | None = None) -> RunStatus:
    """The run's status; ``waiting`` (why its dataset is not usable yet) makes a run that is neither done
    nor held ``waiting``, even one whose earlier attempt failed. ``slurm_reasons``: squeue's pending reason per
    job id (shown, explained, for a queued run)."""
    frame, ret = progress(run_dir)
    record = read_record(sdir, key)
    budget = record.budget if record is not None else None  # done at the sweep's budget, even while extended beyond
    state = run_state(run_dir, budget)
    owner = _lock_owner(results_root, run_dir)
    job = (owner.job_id if owner and owner.job_id else None) or (record.job_id if record else None)
    bound = read_at_bound(run_dir) if frame is not None else None

    def make(status: str, detail: str) -> RunStatus:
        return RunStatus(key, run_dir, status, frame, ret, job, detail, bound=bound)

    if state == STATE_DONE:
        return make("done", "")
    if owner is not None and not lock.is_stale(owner, slurm_states):
        if owner.job_id:
            sstate = (slurm_states or {}).get(owner.job_id, "UNKNOWN")
            status = "queued" if sstate in QUEUED else "running"
            shown = "" if sstate in ("PENDING", "RUNNING") else f"SLURM {sstate}"
            reason = (slurm_reasons or {}).get(owner.job_id, "") if status == "queued" else ""
            why = explain(reason) + ("; it never starts by itself: scancel it, fix the cluster config, launch the "
                                     "sweep again" if reason in NEVER_STARTS else "") if reason else ""
            parts = (shown, why, "partial" if state == STATE_PARTIAL else "")
            return make(status, ", ".join(x for x in parts if x))
        return make("running", f"pid {owner.child_pid or owner.pid} on {owner.host}")
    if waiting:
        return make("waiting", waiting)
    if record is not None:
        sstate = (slurm_states or {}).get(record.job_id or "", "")
        if sstate == "CANCELLED" and record.status != "failed":
            when = "before it started" if record.status == "queued" and state != STATE_PARTIAL else "while it ran"
            resume = "partial: resumes from checkpoint; " if state == STATE_PARTIAL else ""
            return make("cancelled", f"its job was cancelled {when} ({resume}launching the sweep again submits it)")
        if record.status == "failed" or sstate in FAILED:
            why = record.error or (f"SLURM {sstate}" if sstate else f"exit {record.returncode}")
            failed = make("failed", why)
            failed.log = record.stderr or record.log
            return failed
    if state == STATE_PARTIAL and run_state(run_dir) == STATE_DONE:
        return make("pending", f"done at a smaller budget: extends to {budget}")
    return make("pending", "partial: resumes from checkpoint" if state == STATE_PARTIAL else "not started")


def sweep_runs(sdir: Path) -> dict[str, Path]:
    """Run key -> run dir of every run ever launched by the sweep (from state.json)."""
    runs = read_state(sdir).get("runs", {})
    return {k: Path(v["run_dir"]) for k, v in sorted(runs.items())}


def collect(runs: dict[str, Path], results_root: Path, sdir: Path) -> list[RunStatus]:
    """Status of each run, asking SLURM once for all job ids involved."""
    jobs: list[str] = []
    for key, run_dir in runs.items():
        record = read_record(sdir, key)
        if record and record.job_id:
            jobs.append(record.job_id)
        owner = _lock_owner(results_root, run_dir)
        if owner and owner.job_id:
            jobs.append(owner.job_id)
    details = job_details(jobs) if jobs else {}
    states = None if details is None else {j: d.state for j, d in details.items()}
    pending = {j: d.reason for j, d in (details or {}).items() if d.reason}
    reasons = waiting_reasons(sdir, runs)
    return [run_status(k, d, results_root, sdir, states, reasons.get(k), pending) for k, d in runs.items()]


def waiting_reasons(sdir: Path, runs: dict[str, Path]) -> dict[str, str]:
    """Run key -> why its dataset is not usable yet, for the offline runs of ``runs`` (datasets recorded
    in state.json at launch), checking each dataset once, now."""
    grid = read_state(sdir).get("runs", {})
    checked: dict[DatasetNeed, str | None] = {}
    out: dict[str, str] = {}
    for key in runs:
        entry = grid.get(key)
        need = DatasetNeed.from_json(entry.get("dataset")) if isinstance(entry, dict) else None
        if need is None:
            continue
        if need not in checked:
            checked[need] = missing_reason(need)
        reason = checked[need]
        if reason:
            out[key] = reason
    return out


def counts(statuses: Sequence[RunStatus]) -> dict[str, int]:
    return {s: sum(1 for r in statuses if r.status == s) for s in STATUSES}
