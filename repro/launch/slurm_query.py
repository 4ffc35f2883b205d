"""Ask SLURM for job states (squeue first, then sacct for jobs that left the queue)."""

from __future__ import annotations

import shutil
import subprocess
from collections.abc import Iterable

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


def job_states(job_ids: Iterable[str]) -> dict[str, str] | None:
    """Job id (``123`` or array task ``123_4``) -> state word, e.g. RUNNING. Jobs that neither squeue
    nor sacct know are absent from the result. None when SLURM cannot be asked at all."""
    wanted = sorted({j for j in job_ids if j})
    if not wanted:
        return {}
    if not available():
        return None
    bases = sorted({_base(j) for j in wanted})
    states: dict[str, str] = {}
    text = _run(["squeue", "-h", "-r", "-o", "%i|%T", "-j", ",".join(bases)])
    if text is None:
        # squeue fails for ids it no longer knows; ask one by one.
        text = "".join(_run(["squeue", "-h", "-r", "-o", "%i|%T", "-j", b]) or "" for b in bases)
    for line in text.splitlines():
        jid, _, state = line.strip().partition("|")
        if jid:
            states[jid] = state.split()[0] if state else "UNKNOWN"
    rest = [j for j in wanted if j not in states]
    if rest and shutil.which("sacct"):
        text = _run(["sacct", "-n", "-P", "-X", "-o", "JobID,State", "-j", ",".join(rest)]) or ""
        for line in text.splitlines():
            jid, _, state = line.strip().partition("|")
            if jid in rest and state:
                states[jid] = state.split()[0]
    return {j: s for j, s in states.items() if j in wanted}
