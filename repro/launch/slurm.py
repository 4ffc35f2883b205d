"""SLURM launcher: one submitit job-array task per run, checkpointable, non-blocking submission."""

from __future__ import annotations

import os
import shutil
import socket
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import submitit
import yaml
from rich.markup import escape

from repro.launch import lock
from repro.launch.local import LaunchReport
from repro.launch.runner import claim
from repro.launch.spec import PlannedRun, SweepError, close_matches
from repro.launch.state import RunRecord, read_record, write_record

ENV_CLUSTER_CONFIG = "REPRO_SLURM_CONFIG"
USER_CLUSTER_CONFIG = Path("~/.config/taco-repro/slurm.yaml")


@dataclass
class ClusterConfig:
    """SLURM resources of every job of a sweep (one YAML per cluster; see sweeps/launchers/)."""

    partition: str | None = None  # --partition; None: the cluster's default partition
    time_min: int = 24 * 60  # --time per job; a longer run is requeued and resumes from its checkpoint
    cpus_per_task: int = 8  # --cpus-per-task (also the run's torch threads)
    gpus_per_node: int = 0  # --gpus-per-node; 0: none requested
    mem_gb: float | None = None  # --mem in GB; None: the cluster's default
    array_parallelism: int = 64  # at most this many tasks of one array run at once (%N)
    max_array_size: int = 1000  # split larger grids into several arrays (SLURM MaxArraySize - 1)
    max_requeues_on_timeout: int = 20  # requeues after hitting --time before giving up
    signal_delay_s: int = 120  # USR2 this many seconds before the time limit (checkpoint + requeue)
    setup: list[str] = field(default_factory=list)  # shell lines run before the job (module load, ...)
    sbatch: dict[str, Any] = field(default_factory=dict)  # extra sbatch options, e.g. {account: x, qos: y}
    env: dict[str, str] = field(default_factory=dict)  # environment variables for the jobs

    def submitit_parameters(self, name: str) -> dict[str, Any]:
        params: dict[str, Any] = {
            "name": name, "timeout_min": self.time_min, "cpus_per_task": self.cpus_per_task,
            "slurm_array_parallelism": self.array_parallelism,
            "slurm_signal_delay_s": self.signal_delay_s,
        }
        if self.partition:
            params["slurm_partition"] = self.partition
        if self.gpus_per_node:
            params["gpus_per_node"] = self.gpus_per_node
        if self.mem_gb:
            params["mem_gb"] = self.mem_gb
        setup = [f"export {k}={_shell_quote(str(v))}" for k, v in self.env.items()] + list(self.setup)
        if setup:
            params["slurm_setup"] = setup
        if self.sbatch:
            params["slurm_additional_parameters"] = {str(k).replace("-", "_"): v for k, v in self.sbatch.items()}
        return params


def _shell_quote(value: str) -> str:
    return "'" + value.replace("'", "'\"'\"'") + "'"


def cluster_config_path(explicit: Path | None) -> Path | None:
    """The launcher config to use: --cluster-config, $REPRO_SLURM_CONFIG, ~/.config/taco-repro/slurm.yaml."""
    if explicit is not None:
        if not explicit.exists():
            raise SweepError(f"cluster config {explicit} does not exist.")
        return explicit
    if os.environ.get(ENV_CLUSTER_CONFIG):
        return Path(os.environ[ENV_CLUSTER_CONFIG])
    user = USER_CLUSTER_CONFIG.expanduser()
    return user if user.exists() else None


def load_cluster_config(path: Path | None) -> ClusterConfig:
    if path is None:
        return ClusterConfig()
    try:
        data = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise SweepError(f"cannot read cluster config {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise SweepError(f"cluster config {path} must be a mapping.")
    known = [f.name for f in fields(ClusterConfig)]
    for key in data:
        if key not in known:
            raise SweepError(f"cluster config {path}: unknown field '{key}'." + close_matches(str(key), sorted(known)))
    try:
        return ClusterConfig(**data)
    except TypeError as exc:
        raise SweepError(f"cluster config {path}: {exc}") from None


# ------------------------------------------------------------------------------------------ in the job

@dataclass(frozen=True)
class JobRun:
    """What one array task needs (pickled by submitit)."""

    key: str
    run_dir: str
    overrides: tuple[str, ...]
    lock_path: str
    token: str
    state_dir: str
    budget: int | None = None  # the run's budget in this sweep (RunRecord.budget)


class TrainJob(submitit.helpers.Checkpointable):
    """Train one run in the job's process; on USR2 (preemption or time limit) submitit calls
    ``checkpoint`` and requeues the task, which then resumes the run from its last checkpoint."""

    def __call__(self, job: JobRun) -> str:
        env = submitit.JobEnvironment()
        sdir, lpath = Path(job.state_dir), Path(job.lock_path)
        if not self._own_lock(job, lpath, env.job_id):
            return "skipped: the run is held by another launcher"
        paths = env.paths
        record = RunRecord(key=job.key, run_dir=job.run_dir, overrides=list(job.overrides), launcher="slurm",
                           status="running", job_id=env.job_id, pid=os.getpid(), budget=job.budget,
                           log=str(paths.stdout).replace("%t", "0"), stderr=str(paths.stderr).replace("%t", "0"))
        write_record(sdir, record)
        cpus = os.environ.get("SLURM_CPUS_PER_TASK")
        if cpus:
            os.environ.setdefault("OMP_NUM_THREADS", cpus)
            os.environ.setdefault("MKL_NUM_THREADS", cpus)
        os.environ.setdefault("MUJOCO_GL", "egl")
        try:
            from repro.train.api import train

            train(list(job.overrides))
        except Exception as exc:
            record.status, record.returncode = "failed", 1
            record.error = (traceback.format_exception_only(type(exc), exc)[-1]).strip()
            write_record(sdir, record)
            lock.release(lpath, job.token)
            raise
        record.status, record.returncode = "done", 0
        write_record(sdir, record)
        lock.release(lpath, job.token)
        return job.run_dir

    @staticmethod
    def _own_lock(job: JobRun, lpath: Path, job_id: str) -> bool:
        """Confirm the run's lock is ours (taken by the submitter) and record our job id in it."""
        changes = {"job_id": job_id, "host": socket.gethostname(), "pid": os.getpid(),
                   "pid_start": lock.process_start(os.getpid())}
        if lock.update(lpath, job.token, **changes):
            return True
        try:
            holder = lock.read(lpath)
        except ValueError:
            return False
        if holder is not None:
            return False
        info = lock.LockInfo.mine("slurm")
        info.token, info.job_id = job.token, job_id
        return lock.try_create(lpath, info)

    def checkpoint(self, job: JobRun) -> submitit.helpers.DelayedSubmission:
        """Called by submitit on USR2 before requeueing: the run's own checkpoint is already on disk."""
        record = read_record(Path(job.state_dir), job.key)
        if record is not None:
            record.status = "queued"
            write_record(Path(job.state_dir), record)
        return submitit.helpers.DelayedSubmission(self, job)


# ----------------------------------------------------------------------------------------- submission

def submit(planned: Sequence[PlannedRun], sweep: str, sdir: Path, cluster: ClusterConfig, force: bool,
           say: Callable[[str], None]) -> LaunchReport:
    """Claim every run that is neither done nor waiting for its dataset and submit the claimed ones as job
    arrays; returns once queued."""
    if shutil.which("sbatch") is None:
        raise SweepError("sbatch not found: run on a SLURM login node (or `scripts/slurm_local.sh up` and "
                         "export SLURM_CONF for the local test cluster).")
    report = LaunchReport()
    claims = []
    for p in report.to_launch(planned, say):  # done runs and runs waiting for their dataset are not submitted
        c = claim(p, "slurm", sweep, force)
        report.add_claim(c)
        if c.status == "locked":
            say(f"[yellow]skip[/] {p.key}: held by {report.locked[-1][1]}")
        if c.moved_to is not None:
            say(f"[yellow]moved[/] old run dir of {p.key} to {escape(str(c.moved_to))}")
        if c.status == "claimed":
            claims.append(c)
    if not claims:
        return report
    submitted = 0
    try:
        executor = submitit.AutoExecutor(folder=sdir / "slurm" / "%j", cluster="slurm",
                                         slurm_max_num_timeout=cluster.max_requeues_on_timeout)
        executor.update_parameters(**cluster.submitit_parameters(f"repro-{sweep}"))
        size = max(1, cluster.max_array_size)
        for start in range(0, len(claims), size):
            chunk = claims[start:start + size]
            tasks = [JobRun(key=c.planned.key, run_dir=str(c.planned.run_dir), overrides=c.planned.overrides,
                            lock_path=str(c.lock_path), token=c.info.token, state_dir=str(sdir),  # type: ignore[union-attr]
                            budget=c.planned.budget)
                     for c in chunk]
            jobs = executor.map_array(TrainJob(), tasks)
            submitted += len(chunk)
            for c, job in zip(chunk, jobs):
                _queued(sdir, c, job.job_id, job.paths)
                report.started.append(c.planned.key)
                report.job_ids.append(job.job_id)
            say(f"[cyan]submitted[/] {len(chunk)} run(s) as array {jobs[0].job_id.split('_')[0]}")
    except Exception as exc:  # submitit raises several types for a failed sbatch or bad parameters
        for c in claims[submitted:]:
            lock.release(c.lock_path, c.info.token)  # type: ignore[union-attr]
        lines = [ln for ln in str(exc).strip().splitlines() if ln.strip()]
        detail = lines[-1] if lines else type(exc).__name__
        if report.job_ids:
            detail += f" (arrays submitted before the failure: {', '.join(report.job_ids)})"
        raise SweepError(f"submission failed: {detail}") from None
    return report


def _queued(sdir: Path, c, job_id: str, paths) -> None:
    """Record a submitted run's job id in its lock and run record."""
    lock.update(c.lock_path, c.info.token, job_id=job_id)
    existing = read_record(sdir, c.planned.key)
    if existing is None or existing.job_id != job_id:
        write_record(sdir, RunRecord(
            key=c.planned.key, run_dir=str(c.planned.run_dir), overrides=list(c.planned.overrides),
            launcher="slurm", status="queued", job_id=job_id, log=str(paths.stdout), stderr=str(paths.stderr),
            budget=c.planned.budget))
