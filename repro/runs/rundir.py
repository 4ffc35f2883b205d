"""Writing a run directory (format: repro/runs/runformat.py, docs/run-format.md): path, identity check, metadata,
resolved values, DONE marker."""

from __future__ import annotations

import fcntl
import getpass
import json
import os
import platform
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import yaml
from omegaconf import DictConfig, OmegaConf

from repro.config.compose import compose_base, drop_non_identity, identity
from repro.config.schema import Choice, LearnerName, RunConfig, is_offline
from repro.runs.fsutil import atomic_write_text, named_os_error
from repro.runs.runformat import (
    CHECKPOINT,
    CONFIG,
    DONE,
    META,
    REPLAY,
    RESOLVED,
    WRITER_LOCK,
    resolved_json,
    run_path,
    run_state,
)

__all__ = ["CHECKPOINT", "CONFIG", "DONE", "META", "REPLAY", "RESOLVED", "WRITER_LOCK", "RunDirMismatch",
           "RunLocked", "WriterLock", "acquire_writer_lock", "config_diff", "config_matches", "lock_holder",
           "locked_message", "resolved_values", "run_dir", "run_state", "write_config", "write_done", "write_meta",
           "write_resolved", "writer_lock_holder"]
PACKAGES = ("torch", "numpy", "mujoco", "dm-control", "metaworld", "hydra-core", "omegaconf", "submitit",
            "pandas", "rliable", "taco-repro")


class RunDirMismatch(ValueError):
    """The run directory holds a run with another config."""


def run_dir(cfg: DictConfig) -> Path:
    """``{results_root}/{experiment}/{agent}/{variant}/{task}/seed_{seed}`` from config values only;
    an offline run (``offline.dataset`` set) has ``{task}/{dataset}/seed_{seed}`` (see runformat.dataset_tag)."""
    dataset = OmegaConf.select(cfg, "offline.dataset", default=None)
    return run_path(cfg.runtime.results_root, cfg.experiment, cfg.agent.name, cfg.variant, cfg.task.name, cfg.seed,
                    dataset=None if dataset is None else str(dataset))


def saved_identity(path: str | Path) -> dict | None:
    file = Path(path) / CONFIG
    if not file.exists():
        return None
    return drop_non_identity(yaml.safe_load(file.read_text()) or {})


def config_diff(path: str | Path, cfg: DictConfig) -> list[str]:
    """Dotted keys whose values differ between the saved run config and ``cfg`` (runtime ignored)."""
    saved = saved_identity(path)
    if saved is None:
        return []
    new = identity(cfg)
    diffs: list[str] = []

    def walk(a, b, prefix: str) -> None:
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b), key=str):
                walk(a.get(k, "<absent>"), b.get(k, "<absent>"), f"{prefix}{k}.")
        elif a != b:
            diffs.append(f"{prefix[:-1]}: {a!r} -> {b!r}")

    walk(saved, new, "")
    learner = str(OmegaConf.select(cfg, "agent.learner", default=""))
    return [d for d in diffs if not _still_same(d, learner)]


# Keys that came with a change of behaviour (issue 16): a run of these learners written before the key existed
# behaved as the value here, not as the new default, so it is not the same run and is not resumed; for any
# other learner the key changes nothing.
# The old behaviours are plain values (compared with the saved run's YAML text), not Enum members.
_L = LearnerName
ADDED_WITH_OLD_BEHAVIOUR: dict[str, tuple[tuple[LearnerName, ...], object]] = {
    "agent.stddev_schedule.step_scale": ((_L.td3bc, _L.cql, _L.iql), 1),
    "agent.cql.clip_policy_samples": ((_L.cql,), False),
    "agent.iql.value_for_targets": ((_L.iql,), "actor before, critic after the value step"),
    "agent.dt.activation": ((_L.dt,), "gelu"),
    "agent.dt.init": ((_L.dt,), "torch"),
    "agent.dt.ff_dropout": ((_L.dt,), True),
    "agent.dt.action_pad": ((_L.dt,), 0.0),
}


def _still_same(diff: str, learner: str) -> bool:
    """A difference that is none: a key of :data:`ADDED_WITH_OLD_BEHAVIOUR` absent from the saved run, when
    ``learner`` does not read it or its old behaviour equals the new value; else a key added at its default."""
    key, _, change = diff.partition(": ")
    old, _, new = change.partition(" -> ")
    if old == repr("<absent>") and key in ADDED_WITH_OLD_BEHAVIOUR:
        learners, before = ADDED_WITH_OLD_BEHAVIOUR[key]
        return learner not in learners or repr(before) == new
    return _added_at_default(diff)


def _added_at_default(diff: str) -> bool:
    """A key that a newer version added, absent from the saved run and at its default now, is no difference
    (so runs written before the key existed still resume)."""
    key, _, change = diff.partition(": ")
    old, _, new = change.partition(" -> ")
    if old != repr("<absent>"):
        return False
    if key.startswith(("agent.objectives.", "agent.objective_params.")):
        return False  # a name in a free mapping, not a field a newer version added
    # The default is the packaged YAML's value (the schema has types only): the config with no overrides.
    default = OmegaConf.select(compose_base(), key, default="<no default>")
    if isinstance(default, DictConfig):
        default = OmegaConf.to_container(default, resolve=True, enum_to_str=True)
    elif isinstance(default, Choice):  # as identity() has it: the plain value
        default = default.value
    return repr(default) == new


def config_matches(path: str | Path, cfg: DictConfig) -> bool:
    return not config_diff(path, cfg)


def write_config(path: Path, cfg: DictConfig) -> None:
    atomic_write_text(path / CONFIG, OmegaConf.to_yaml(cfg, resolve=True))


def resolved_values(rc: RunConfig, learner: Any) -> dict[str, Any]:
    """What ``learner`` (as built for ``rc``) actually uses, as resolved.json records it (runformat.RESOLVED_FIELDS).

    Read from the learner, not recomputed: the latent action dim is its ``action_encoder.latent_dim`` (None
    without an action encoder), the objectives are its active ``weights``. A learner adds or replaces fields
    (an offline learner: ``dataset``, ``cql_alpha``, ...) through a ``resolved`` dict attribute.
    """
    encoder = getattr(learner, "action_encoder", None)
    values: dict[str, Any] = {
        "learner": rc.agent.learner,
        "K": int(rc.agent.K),
        "batch_size": int(rc.agent.batch_size),
        "action_repeat": int(rc.env.action_repeat),
        "nstep": int(rc.agent.nstep),
        "action_encoder": encoder is not None,
        "latent_action_dim": None if encoder is None else int(encoder.latent_dim),
        "objectives": {str(k): float(w) for k, w in getattr(learner, "weights", {}).items()},
        "dataset": rc.offline.dataset if is_offline(rc.agent.learner) else None,
        "cql_alpha": None,
    }
    values.update(getattr(learner, "resolved", None) or {})
    return values


def write_resolved(path: Path, values: dict[str, Any]) -> None:
    """Write resolved.json (checked against the format, atomic); the same values on every (re)start."""
    atomic_write_text(path / RESOLVED, resolved_json(values))


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).parent, capture_output=True, text=True,
                             timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


def _versions() -> dict[str, str | None]:
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for pkg in PACKAGES:
        try:
            versions[pkg] = metadata.version(pkg)
        except metadata.PackageNotFoundError:
            versions[pkg] = None
    return versions


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def device_name(device: str) -> str:
    import torch

    if device.startswith("cuda") and torch.cuda.is_available():
        return f"cuda:{torch.cuda.get_device_name(0)}"
    return "cpu"


def write_meta(path: Path, device: str, resumed: bool) -> dict:
    """Create meta.json on the first start; append to its ``resumes`` list on each resume."""
    file = path / META
    now = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    entry = {"time": now, "host": socket.gethostname(), "command": sys.argv, "device": device_name(device)}
    if file.exists():
        meta = json.loads(file.read_text())
        if resumed:
            meta.setdefault("resumes", []).append(entry)
    else:
        sha = _git("rev-parse", "HEAD")
        status = _git("status", "--porcelain", "--untracked-files=no")
        meta = {"git_sha": sha, "git_dirty": bool(status) if status is not None else None,
                "versions": _versions(), "host": socket.gethostname(), "user": getpass.getuser(),
                "device": device_name(device), "cpu": _cpu_model(), "command": sys.argv, "started": now,
                "platform": platform.platform(), "resumes": []}
    atomic_write_text(file, json.dumps(meta, indent=2) + "\n")
    return meta


def write_done(path: Path, summary: dict) -> None:
    atomic_write_text(path / DONE, json.dumps(summary, indent=2) + "\n")


# ---------------------------------------------------------------------------------------------- one writer
class RunLocked(RuntimeError):
    """Another process is writing this run directory (one line naming it)."""


@dataclass
class WriterLock:
    """An exclusive ``flock`` on ``{run}/.writer.lock``, held while a process writes the run directory.

    The kernel releases it when the holder exits in any way (SIGKILL included), so a dead holder never
    blocks a resume; the file stays (removing it would let a third process lock a fresh file while a second
    still waits on the old one) and names the last holder (pid, host, start time) for the refusal message.
    On NFS (v4, or v3 with lockd) Linux maps ``flock`` to a server-side lock: a lost node's lock goes when
    the server's lease for it expires (NFSv4: about 90 s) or its lockd is told the node rebooted (v3); a
    SLURM requeue after a node failure may be refused for that long and then succeeds on the next try.
    """

    path: Path
    fd: int

    def release(self) -> None:
        if self.fd >= 0:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
            os.close(self.fd)
            self.fd = -1

    def __enter__(self) -> WriterLock:
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()


def lock_holder(path: str | Path) -> str:
    """Who last held (or holds) the writer lock of the run directory ``path``, in words."""
    try:
        info = json.loads((Path(path) / WRITER_LOCK).read_text())
        return f"pid {info['pid']} on {info['host']} (since {info['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another process"


def locked_message(path: Path, holder: str) -> str:
    return (f"{path} is being written by {holder}; a run directory has one writer: wait for it to finish "
            "(or stop it) and re-run to resume")


def writer_lock_holder(path: str | Path) -> str | None:
    """Who holds the run directory's writer lock now, in words; None when nobody does (writes nothing)."""
    file = Path(path) / WRITER_LOCK
    try:
        fd = os.open(file, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return lock_holder(path)
    finally:
        os.close(fd)  # closing drops a shared lock taken just now
    return None


def acquire_writer_lock(path: str | Path) -> WriterLock:
    """Take the run directory's writer lock now, or raise :class:`RunLocked` (never waits: a second start
    of a running run is a mistake to report, not a queue; the sweep launcher skips runs it sees locked)."""
    path = Path(path)
    file = path / WRITER_LOCK
    fd = os.open(file, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise RunLocked(locked_message(path, lock_holder(path))) from None
    except OSError as exc:  # a filesystem without locks: an error, never a silent second writer
        os.close(fd)
        raise named_os_error(exc, file) from None
    try:
        text = json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                           "since": time.strftime("%Y-%m-%dT%H:%M:%S%z")}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, text, 0)
    except OSError as exc:
        fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        raise named_os_error(exc, file) from None
    return WriterLock(file, fd)
