"""SLURM launcher: one submitit job-array task per run, checkpointable, non-blocking submission."""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import socket
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import submitit
import yaml
from rich.markup import escape

from repro.launch import lock
from repro.launch.doctor import DoctorInputs, DoctorReport, preflight_job, summary
from repro.launch.local import LaunchReport
from repro.launch.runner import claim
from repro.launch.slurm_query import NEVER_STARTS, QUEUED, explain, is_active, job_details
from repro.launch.spec import PlannedRun, SweepError, close_matches
from repro.launch.state import RunRecord, read_record, write_record

ENV_CLUSTER_CONFIG = "REPRO_SLURM_CONFIG"
USER_CLUSTER_CONFIG = Path("~/.config/taco-repro/slurm.yaml")
EXAMPLE_CLUSTER_CONFIG = Path(__file__).resolve().parents[2] / "sweeps" / "launchers" / "example.yaml"
PREFLIGHT_TIME_MIN = 15  # --time of the preflight job (at most the cluster config's time_min)
PREFLIGHT_WAIT_S = 600  # how long `repro sweep` waits for the preflight job to start (--preflight-wait)


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

    def asks(self) -> str:
        """What each job asks for, in a few words (the refusals name it)."""
        extra = ", ".join(f"{k}={v}" for k, v in self.sbatch.items())
        return (f"partition {self.partition or '(default)'}, {self.cpus_per_task} CPU(s), {self.gpus_per_node} GPU(s), "
                f"{f'{self.mem_gb:g} GB' if self.mem_gb else 'default memory'}, {self.time_min} min"
                + (f", {extra}" if extra else ""))


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


def require_cluster_config(explicit: Path | None) -> Path:
    """The cluster config a SLURM sweep needs; without one, a SweepError (one line) before anything is written:
    the defaults would ask for no GPU and 8 CPUs for a day, which few clusters want."""
    path = cluster_config_path(explicit)
    if path is None:
        raise SweepError(f"--launcher slurm needs a cluster config (the partition, GPUs, CPUs, memory and time of each "
                         f"job): copy {_shown(EXAMPLE_CLUSTER_CONFIG)}, edit it for your cluster and pass "
                         f"--cluster-config FILE (or save it as {USER_CLUSTER_CONFIG}, or set ${ENV_CLUSTER_CONFIG})")
    return path


def _shown(path: Path) -> str:
    """``path`` relative to the working directory when below it (sweeps/launchers/example.yaml in a checkout)."""
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)


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
        gpus = ", ".join(f"{k}={os.environ[k]}" for k in ("CUDA_VISIBLE_DEVICES", "MUJOCO_EGL_DEVICE_ID", "MUJOCO_GL")
                         if k in os.environ)
        print(f"run {job.key} on {socket.gethostname()} (job {env.job_id}): {gpus}", flush=True)
        # meta.json records the run's own command (`repro train OVERRIDES`, as a local run's), not submitit's
        sys.argv = [str(Path(__file__).resolve().parents[1] / "__main__.py"), "train", *job.overrides]
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

def require_sbatch() -> None:
    if shutil.which("sbatch") is None:
        raise SweepError("sbatch not found: run on a SLURM login node (or `scripts/slurm_local.sh up` and "
                         "export SLURM_CONF for the local test cluster).")


def submit(planned: Sequence[PlannedRun], sweep: str, sdir: Path, cluster: ClusterConfig, force: bool,
           say: Callable[[str], None],
           before: Callable[[list[PlannedRun]], None] | None = None) -> LaunchReport:
    """Claim every run that is neither done nor waiting for its dataset and submit the claimed ones as job
    arrays; returns once queued. ``before`` (the preflight) is called with the claimed runs before anything is
    submitted; when it raises, the claims are released and nothing is submitted."""
    require_sbatch()
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
    if before is not None:
        try:
            before([c.planned for c in claims])
        except BaseException:
            for c in claims:
                lock.release(c.lock_path, c.info.token)  # type: ignore[union-attr]
                locks = c.planned.results_root / ".locks"
                _prune_empty(*[d for d in c.lock_path.parents if d == locks or locks in d.parents])
            raise
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
            with contextlib.redirect_stderr(io.StringIO()):  # sbatch's error is in the exception: one line
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
        detail = f"{_last_line(str(exc)) or type(exc).__name__} (each job asks for: {cluster.asks()})"
        if report.job_ids:
            detail += f" (arrays submitted before the failure: {', '.join(report.job_ids)})"
        raise SweepError(f"submission failed: {detail}") from None
    return report


# ------------------------------------------------------------------------------------------- preflight

class PreflightFailed(SweepError):
    """The preflight job found a check that fails, or could not run: one line; nothing of the grid submitted."""

    def __init__(self, message: str, code: int = 1) -> None:
        super().__init__(message)
        self.code = code


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.strip().splitlines() if ln.strip()]
    return " ".join(lines[-1].split()) if lines else ""


def _result_ready(job: Any) -> bool:
    folder = job.paths.folder
    try:
        folder.chmod(folder.stat().st_mode)  # refresh a shared filesystem's cache (as submitit does)
    except OSError:
        pass
    return bool(job.paths.result_pickle.exists())


def _prune_empty(*folders: Path) -> None:
    """Remove each of ``folders`` that is empty, in order (what a refused submission made and left empty)."""
    for folder in folders:
        try:
            folder.rmdir()
        except OSError:
            return


def _scancel(job_id: str) -> None:
    subprocess.run(["scancel", job_id], capture_output=True, timeout=30, check=False)


def preflight(inputs: DoctorInputs, sweep: str, sdir: Path, cluster: ClusterConfig, say: Callable[[str], None],
              wait_s: float = PREFLIGHT_WAIT_S) -> DoctorReport:
    """Run ``repro doctor``'s checks as one short job with the sweep's cluster config (the node, GPUs and
    environment its runs get) and wait for them: the report when no check fails, else :class:`PreflightFailed`
    (one line naming the check). A job that cannot start (a pending reason it never leaves, or pending longer
    than ``wait_s``) is cancelled and refused the same way."""
    require_sbatch()
    executor = submitit.AutoExecutor(folder=sdir / "preflight" / "%j", cluster="slurm", slurm_max_num_timeout=0)
    params = cluster.submitit_parameters(f"repro-{sweep}-preflight")
    params["timeout_min"] = max(1, min(cluster.time_min, PREFLIGHT_TIME_MIN))
    executor.update_parameters(**params)
    folder = sdir / "preflight"
    before = set(folder.iterdir()) if folder.is_dir() else set()
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # sbatch's error is in the exception: one line
            job = executor.submit(preflight_job, inputs)
    except Exception as exc:  # a failed sbatch: the grid's jobs would be refused the same way
        for left in (set(folder.iterdir()) if folder.is_dir() else set()) - before:  # submitit's pickle and script
            if left.is_file():
                left.unlink(missing_ok=True)
        _prune_empty(folder, sdir, sdir.parent)
        raise PreflightFailed(f"the preflight job was not submitted: {_last_line(str(exc)) or type(exc).__name__} "
                              f"(each job asks for: {cluster.asks()}); nothing submitted", code=2) from None
    jid = job.job_id
    log = job.paths.stdout
    say(f"[cyan]preflight[/] job {jid}: `repro doctor` on the node the runs get ({cluster.asks()})")
    start, last_ask, told = time.time(), 0.0, ""
    try:
        while not _result_ready(job):
            now = time.time()
            if now - last_ask >= 1.0:
                last_ask = now
                st = (job_details([jid]) or {}).get(jid)
                if st is None or not is_active(st.state):
                    end = time.time() + 10  # the result file may show a moment after the job left the queue
                    while not _result_ready(job) and time.time() < end:
                        time.sleep(0.2)
                    if _result_ready(job):
                        break
                    err = _last_line(job.paths.stderr.read_text()) if job.paths.stderr.exists() else ""
                    raise PreflightFailed(f"the preflight job {jid} ended {st.state if st else 'unknown to SLURM'} "
                                          f"before reporting{': ' + err if err else ''} (log {job.paths.stderr}); "
                                          "nothing submitted")
                if st.state in QUEUED and st.reason in NEVER_STARTS:
                    _scancel(jid)
                    raise PreflightFailed(f"the preflight job {jid} cannot start: {explain(st.reason)} (each job asks "
                                          f"for: {cluster.asks()}); cancelled it, nothing submitted: fix the "
                                          "cluster config", code=2)
                if st.state in QUEUED and now - start > wait_s:
                    _scancel(jid)
                    raise PreflightFailed(f"the preflight job {jid} did not start in {wait_s:g} s (pending: "
                                          f"{explain(st.reason) if st.reason else st.state}); cancelled it, nothing "
                                          "submitted: try again later, or skip it with --no-preflight")
                if st.state in QUEUED and st.reason and st.reason != told:
                    told = st.reason
                    say(f"[dim]preflight job {jid} pending: {escape(explain(st.reason))}[/]")
            time.sleep(0.2)
    except KeyboardInterrupt:
        _scancel(jid)
        raise PreflightFailed(f"interrupted: cancelled the preflight job {jid}; nothing submitted", code=130) from None
    try:
        report = DoctorReport.from_json(job.result())
    except Exception as exc:  # the job raised: submitit's error holds its traceback
        raise PreflightFailed(f"the preflight job {jid} failed: {_last_line(str(exc))} (log {job.paths.stderr}); "
                              "nothing submitted") from None
    where = f"on {report.host} (job {jid})"
    if report.failed:
        raise PreflightFailed(f"preflight {where} failed: {summary(report)}; nothing submitted (log {log}); fix it, "
                              "or skip the preflight with --no-preflight")
    env = ", ".join(f"{k}={v}" for k, v in report.env.items())
    say(f"[green]preflight ok[/] {where}: {summary(report)}" + (f" ({escape(env)})" if env else ""))
    for c in report.checks:
        if c.status != "ok":
            say(f"[yellow]{escape(c.line())}[/]")
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
