"""Per-run locks that work on a local disk and on a shared (NFS) filesystem.

A lock is a small JSON file created atomically with ``link(2)`` from a fully written temporary file,
so a reader never sees a half-written lock and exactly one of two racing creators wins (the classic
NFS-safe recipe: a link that reports an error but raised the link count to 2 also won). The file
names its owner: a random token, host, pid (with the pid's start time, so a reused pid is not taken
for the owner) and, for SLURM, the job id. A lock is *stale* when its owner is provably gone: a local
process that no longer exists, or a SLURM job that is no longer queued or running. Stale locks are
broken under a short-lived guard lock so that two breakers cannot remove a fresh lock.
"""

from __future__ import annotations

import json
import os
import socket
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path

from repro.runs.fsutil import atomic_write_text

GUARD_STALE_S = 30.0  # a break guard older than this is left over from a crashed breaker
UNREADABLE_STALE_S = 60.0  # an unparseable lock older than this is treated as stale

SlurmLookup = Callable[[list[str]], Mapping[str, str] | None]  # None: SLURM cannot be asked


@dataclass
class LockInfo:
    """Who holds a run's lock."""

    token: str
    host: str
    pid: int
    pid_start: str | None
    launcher: str  # local | slurm
    sweep: str = ""
    job_id: str | None = None
    child_pid: int | None = None
    child_start: str | None = None
    created: float = field(default_factory=time.time)

    @classmethod
    def mine(cls, launcher: str, sweep: str = "") -> LockInfo:
        """A new lock owned by this process."""
        return cls(token=uuid.uuid4().hex, host=socket.gethostname(), pid=os.getpid(),
                   pid_start=process_start(os.getpid()), launcher=launcher, sweep=sweep)

    def describe(self) -> str:
        if self.job_id:
            return f"SLURM job {self.job_id}"
        return f"pid {self.child_pid or self.pid} on {self.host}"


def process_start(pid: int) -> str | None:
    """The start time of a process in clock ticks since boot (Linux), to tell a reused pid apart."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2:].split()
    return fields[19] if len(fields) > 19 else None


def pid_alive(pid: int, start: str | None) -> bool:
    """Whether ``pid`` runs on this host and is the same process that recorded ``start``."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return True  # no /proc: trust kill(0)
    after = stat[stat.rfind(")") + 2:].split()
    if after and after[0] == "Z":
        return False
    return start is None or len(after) < 20 or after[19] == start


def _write_tmp(path: Path, info: LockInfo) -> Path:
    tmp = path.with_name(f".{path.name}.{socket.gethostname()}.{os.getpid()}.{uuid.uuid4().hex[:8]}")
    with open(tmp, "w") as fh:
        json.dump(asdict(info), fh)
        fh.flush()
        os.fsync(fh.fileno())
    return tmp


def try_create(path: Path, info: LockInfo) -> bool:
    """Create the lock file atomically; False when it already exists."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _write_tmp(path, info)
    try:
        os.link(tmp, path)
        return True
    except FileExistsError:
        return False
    except OSError:
        # NFS: the link may have happened although the reply was lost.
        return os.stat(tmp).st_nlink == 2
    finally:
        tmp.unlink(missing_ok=True)


def read(path: Path) -> LockInfo | None:
    """The lock's owner; None when there is no lock. Raises ValueError for an unreadable lock."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    try:
        data = json.loads(text)
        return LockInfo(**data)
    except (json.JSONDecodeError, TypeError) as exc:
        raise ValueError(f"unreadable lock {path}") from exc


def _own(path: Path, token: str) -> LockInfo | None:
    """The lock's info when it is ours (its token is ``token``), else None (gone, unreadable or another's)."""
    try:
        info = read(path)
    except ValueError:
        return None
    return info if info is not None and info.token == token else None


def update(path: Path, token: str, **changes: object) -> bool:
    """Rewrite our own lock with ``changes`` (atomic replace); False when we no longer hold it."""
    info = _own(path, token)
    if info is None:
        return False
    for key, value in changes.items():
        setattr(info, key, value)
    atomic_write_text(path, json.dumps(asdict(info)))
    return True


def release(path: Path, token: str) -> bool:
    """Remove our own lock; False when it is not ours (or gone)."""
    if _own(path, token) is None:
        return False
    path.unlink(missing_ok=True)
    return True


def is_stale(info: LockInfo, slurm_states: Mapping[str, str] | None) -> bool:
    """Whether the owner is provably gone.

    ``slurm_states`` maps job ids to SLURM states (see ``slurm_query.job_states``); None when SLURM
    cannot be asked, in which case a job-owned lock counts as live. A local owner on another host
    cannot be checked and counts as live.
    """
    from repro.launch.slurm_query import is_active

    if info.job_id:
        if slurm_states is None:
            return False
        return not is_active(slurm_states.get(info.job_id))
    if info.host != socket.gethostname():
        return False
    owners = [(info.pid, info.pid_start)]
    if info.child_pid:
        owners.append((info.child_pid, info.child_start))
    return not any(pid_alive(pid, start) for pid, start in owners)


def _lock_age(path: Path) -> float:
    try:
        return time.time() - path.stat().st_mtime
    except FileNotFoundError:
        return 0.0


def break_if_stale(path: Path, slurm_lookup: SlurmLookup | None) -> bool:
    """Remove the lock at ``path`` if its owner is gone; True when it was removed (or already gone)."""
    guard = path.with_name(path.name + ".break")
    if guard.exists() and _lock_age(guard) > GUARD_STALE_S:
        guard.unlink(missing_ok=True)
    me = LockInfo.mine("break")
    if not try_create(guard, me):
        return False
    try:
        try:
            info = read(path)
        except ValueError:
            if _lock_age(path) > UNREADABLE_STALE_S:
                path.unlink(missing_ok=True)
                return True
            return False
        if info is None:
            return True
        states = slurm_lookup([info.job_id]) if (info.job_id and slurm_lookup) else None
        if is_stale(info, states):
            path.unlink(missing_ok=True)
            return True
        return False
    finally:
        guard.unlink(missing_ok=True)


def acquire(path: Path, info: LockInfo, slurm_lookup: SlurmLookup | None = None) -> tuple[bool, LockInfo | None]:
    """Take the lock, breaking a stale one once. Returns (acquired, current owner if not acquired)."""
    for _ in range(2):
        if try_create(path, info):
            return True, None
        if not break_if_stale(path, slurm_lookup):
            break
    try:
        return False, read(path)
    except ValueError:
        return False, None


def lock_path(results_root: Path, run_dir: Path) -> Path:
    """``{results_root}/.locks/<experiment>/<agent>/<variant>/<task>/seed_N.lock``: outside the run
    tree, so analysis globs over run directories never see lock files."""
    rel = Path(os.path.relpath(run_dir, results_root))
    return results_root / ".locks" / rel.parent / f"{rel.name}.lock"
