"""Ask SLURM for job states and pending reasons (squeue first, then sacct for jobs that left the queue)."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterable
from dataclasses import dataclass

# States in which a job may still run or is still being cleaned up (squeue lists these).
ACTIVE = {"PENDING", "RUNNING", "REQUEUED", "REQUEUE_HOLD", "REQUEUE_FED", "CONFIGURING", "COMPLETING",
          "SUSPENDED", "RESIZING", "STOPPED", "SIGNALING", "STAGE_OUT", "RESV_DEL_HOLD", "PREEMPTED"}
QUEUED = {"PENDING", "REQUEUED", "REQUEUE_HOLD", "REQUEUE_FED", "CONFIGURING", "RESV_DEL_HOLD", "SUSPENDED",
          "STOPPED", "PREEMPTED"}
FAILED = {"FAILED", "TIMEOUT", "CANCELLED", "NODE_FAIL", "OUT_OF_MEMORY", "BOOT_FAIL", "DEADLINE"}


def is_active(state: str | None) -> bool:
    return state in ACTIVE


def available() -> bool:
    return shutil.which("squeue") is not None


def _run(cmd: list[str]) -> str | None:
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout if out.returncode == 0 else None


def _base(job_id: str) -> str:
    return job_id.split("_")[0].split(".")[0]


@dataclass(frozen=True)
class JobState:
    """What SLURM says of one job: its state word (RUNNING, PENDING, CANCELLED, ...) and, while it is queued,
    squeue's reason (Resources, Priority, PartitionConfig, ...; empty when there is none)."""

    state: str
    reason: str = ""


# squeue's pending reasons, in a few words each (`man squeue`, JOB REASON CODES); the others are shown as they are.
REASONS = {
    "Resources": "waiting for the resources it asks for to be free",
    "Priority": "behind jobs of higher priority",
    "PartitionConfig": "no node of the partition has what it asks for (CPUs, GPUs, memory or time)",
    "PartitionTimeLimit": "its time limit exceeds the partition's (time_min)",
    "PartitionNodeLimit": "it asks for more nodes than the partition allows",
    "PartitionDown": "its partition is down",
    "PartitionInactive": "its partition is inactive",
    "ReqNodeNotAvail": "a node it needs is unavailable (down, drained or reserved)",
    "BeginTime": "held until its begin time (a requeued job: `scontrol update JobId=N StartTime=now` releases it)",
    "Dependency": "waiting for the jobs it depends on",
    "DependencyNeverSatisfied": "its dependency can never be satisfied",
    "JobHeldUser": "held by its user (`scontrol release`)",
    "JobHeldAdmin": "held by an administrator",
    "InvalidAccount": "its account is invalid (sbatch: account)",
    "InvalidQOS": "its QOS is invalid (sbatch: qos)",
    "BadConstraints": "its constraints can never be met",
    "QOSMaxGRESPerUser": "the QOS limits the GPUs of one user",
    "QOSMaxGRESPerJob": "the QOS limits the GPUs of one job",
    "AssocGrpGRES": "the account's GPU limit is reached",
    "QOSMaxWallDurationPerJobLimit": "its time limit exceeds the QOS's (time_min)",
    "AssocMaxWallDurationPerJobLimit": "its time limit exceeds the account's (time_min)",
}
# Reasons a pending job keeps until someone changes it or the cluster: a job that has one never starts by itself.
NEVER_STARTS = {"PartitionConfig", "PartitionTimeLimit", "PartitionNodeLimit", "DependencyNeverSatisfied",
                "InvalidAccount", "InvalidQOS", "BadConstraints", "QOSMaxGRESPerJob", "QOSMaxWallDurationPerJobLimit",
                "AssocMaxWallDurationPerJobLimit", "JobHeldAdmin", "PartitionInactive"}


def explain(reason: str) -> str:
    """``Reason: what it means`` for a pending reason (the reason alone when it has no explanation here)."""
    words = REASONS.get(reason)
    return f"{reason}: {words}" if words else reason


def _array_tasks(spec: str) -> set[str] | None:
    """The task ids of sacct's ``[0-3,7%2]`` (a part of an array that never started), None when not one."""
    if not (spec.startswith("[") and spec.endswith("]")):
        return None
    tasks: set[str] = set()
    for part in spec[1:-1].split("%")[0].split(","):
        lo, _, hi = part.partition("-")
        if not lo.isdigit() or (hi and not hi.isdigit()):
            return None
        tasks.update(str(i) for i in range(int(lo), int(hi or lo) + 1))
    return tasks


def _sacct(rest: list[str]) -> dict[str, str]:
    """Job id -> sacct state for ``rest``. sacct lists the tasks of an array that never started as one row,
    ``123_[0-3%2]`` (and knows nothing of ``123_0`` asked alone), so it is asked for the arrays' base ids and
    such rows are expanded."""
    text = _run(["sacct", "-n", "-P", "-X", "-o", "JobID,State", "-j", ",".join(sorted({_base(j) for j in rest}))])
    found: dict[str, str] = {}
    for line in (text or "").splitlines():
        jid, _, state = line.strip().partition("|")
        if not jid or not state:
            continue
        word = state.split()[0]
        base, _, task = jid.partition("_")
        tasks = _array_tasks(task)
        if tasks is None:
            found[jid] = word
        else:
            for t in tasks:
                found.setdefault(f"{base}_{t}", word)
    return {j: found[j] for j in rest if j in found}


def job_details(job_ids: Iterable[str]) -> dict[str, JobState] | None:
    """Job id (``123`` or array task ``123_4``) -> its state (and pending reason). Jobs that neither squeue
    nor sacct know are absent from the result. None when SLURM cannot be asked at all."""
    wanted = sorted({j for j in job_ids if j})
    if not wanted:
        return {}
    if not available():
        return None
    bases = sorted({_base(j) for j in wanted})
    states: dict[str, JobState] = {}
    fmt = ["-o", "%i|%T|%r"]
    text = _run(["squeue", "-h", "-r", *fmt, "-j", ",".join(bases)])
    if text is None:
        # squeue fails for ids it no longer knows; ask one by one.
        text = "".join(_run(["squeue", "-h", "-r", *fmt, "-j", b]) or "" for b in bases)
    for line in text.splitlines():
        jid, _, rest_of_line = line.strip().partition("|")
        state, _, reason = rest_of_line.partition("|")
        if jid:
            reason = reason.strip()
            states[jid] = JobState(state.split()[0] if state.strip() else "UNKNOWN",
                                   "" if reason in ("None", "(null)") else reason)
    rest = [j for j in wanted if j not in states]
    if rest and shutil.which("sacct"):
        states.update({j: JobState(s) for j, s in _sacct(rest).items()})
    return {j: s for j, s in states.items() if j in wanted}


def job_states(job_ids: Iterable[str]) -> dict[str, str] | None:
    """Job id -> state word, e.g. RUNNING (:func:`job_details` without the reasons)."""
    details = job_details(job_ids)
    return None if details is None else {j: d.state for j, d in details.items()}
