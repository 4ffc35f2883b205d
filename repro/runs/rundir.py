"""Writing a run directory (format: repro/runs/runformat.py, docs/run-format.md): path, identity check, metadata,
resolved values, DONE marker."""

from __future__ import annotations

import getpass
import json
import os
import platform
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import TYPE_CHECKING, Any

import yaml
from omegaconf import DictConfig, OmegaConf

from repro.config.compose import ABSENT, compose_base, drop_non_identity, get_key, identity, run_keys, set_key, validate
from repro.config.errors import UserError
from repro.config.schema import RunConfig, budget_key, is_offline, unread_keys
from repro.runs import migrate
from repro.runs.fsutil import HolderLock, atomic_write_text, flock_holder, holder_words, try_flock
from repro.runs.runformat import (
    CHECKPOINT,
    CONFIG,
    DONE,
    META,
    REPLAY,
    RESOLVED,
    RESOLVED_FIELDS,
    WRITER_LOCK,
    reached_budgets,
    read_done,
    resolved_json,
    run_path,
    run_state,
)

if TYPE_CHECKING:  # the type only: rundir is read by commands that build no learner (torch stays unimported)
    from repro.agent.protocol import Learner

__all__ = ["CHECKPOINT", "CONFIG", "DONE", "META", "REPLAY", "RESOLVED", "WRITER_LOCK", "RunDirMismatch",
           "config_text", "read_done", "run_budget", "read_meta", "read_saved_config", "reached_budgets",
           "saved_config",
           "RunLocked", "WriterLock", "acquire_writer_lock", "config_diff", "config_matches", "lock_holder",
           "locked_message", "resolved_values", "run_dir", "run_state", "write_config", "write_done", "write_meta",
           "write_resolved", "writer_lock_holder"]
PACKAGES = ("torch", "numpy", "mujoco", "dm-control", "metaworld", "hydra-core", "omegaconf", "submitit",
            "pandas", "rliable", "taco-repro")


class RunDirMismatch(UserError, ValueError):
    """The run directory holds a run with another config."""


def run_dir(cfg: DictConfig) -> Path:
    """``{results_root}/{experiment}/{agent}/{variant}/{task}/seed_{seed}`` from config values only;
    an offline run (``offline.dataset`` set) has ``{task}/{dataset}/seed_{seed}`` (see runformat.dataset_tag)."""
    dataset = OmegaConf.select(cfg, "offline.dataset", default=None)
    return run_path(cfg.runtime.results_root, cfg.experiment, cfg.agent.name, cfg.variant, cfg.task.name, cfg.seed,
                    dataset=None if dataset is None else str(dataset))


def run_budget(cfg: DictConfig) -> int:
    """The budget of the run ``cfg`` describes: train.frames online, offline.updates offline (schema.budget_key)."""
    return int(OmegaConf.select(cfg, budget_key(str(cfg.agent.learner))))


def read_saved_config(path: str | Path) -> dict | None:
    """The run directory's config.yaml in the current format (repro/runs/migrate.py); None when it has none."""
    file = Path(path) / CONFIG
    if not file.exists():
        return None
    data = yaml.load(file.read_text(encoding="utf-8"), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader)) or {}
    if not isinstance(data, dict):
        raise migrate.FormatError(f"{file} is not a mapping")
    return migrate.migrate_config(data)


def saved_identity(path: str | Path) -> dict | None:
    """The identity (compose.identity) of the run saved in ``path``, migrated to the current format."""
    saved = read_saved_config(path)
    return None if saved is None else drop_non_identity(saved)


def config_diff(path: str | Path, cfg: DictConfig) -> list[migrate.Diff]:
    """Where the identity of the saved run and that of ``cfg`` differ (path, old, new): the keys both runs' learner
    reads, less runtime, the video switches and the budget. Empty when ``path`` holds no run."""
    saved = saved_identity(path)
    if saved is None:
        return []
    return migrate.diff(saved, identity(cfg))


def config_matches(path: str | Path, cfg: DictConfig) -> bool:
    return not config_diff(path, cfg)


def config_text(cfg: DictConfig) -> str:
    """The text of config.yaml for ``cfg``: the format number, then what the run's learner reads."""
    return OmegaConf.to_yaml(OmegaConf.create({"format": migrate.CONFIG_FORMAT, **run_keys(cfg)}))


def write_config(path: Path, cfg: DictConfig) -> None:
    atomic_write_text(path / CONFIG, config_text(cfg))


def saved_config(path: str | Path) -> DictConfig:
    """The saved run's config as a full, validated config (for code that reads typed values of a finished run,
    e.g. ``repro dataset make``): the keys its learner does not read are today's defaults."""
    saved = read_saved_config(path)
    if saved is None:
        raise FileNotFoundError(f"{Path(path) / CONFIG} does not exist")
    saved.pop("format", None)
    base = OmegaConf.to_container(compose_base(), resolve=True, enum_to_str=True)
    assert isinstance(base, dict)
    for key in unread_keys(str(saved["agent"]["learner"])):
        value = get_key(base, key)
        if value is not ABSENT:
            set_key(saved, key, value)
    saved["runtime"] = {**base["runtime"], **(saved.get("runtime") or {})}  # runtime keys added since
    return validate(OmegaConf.create(saved))


def resolved_values(rc: RunConfig, learner: Learner) -> dict[str, Any]:
    """What ``learner`` (as built for ``rc``) actually uses, as resolved.json records it (runformat.RESOLVED_FIELDS).

    Read from the learner (``repro.agent.protocol.Learner``), not recomputed: the latent action dim is its
    ``action_encoder.latent_dim`` (None without an action encoder), the objectives are its active ``weights``. A
    learner adds or replaces fields (CQL: ``cql_alpha``, ...) through ``resolved``; a field no learner gives is null.
    """
    encoder = learner.action_encoder
    values: dict[str, Any] = dict.fromkeys(RESOLVED_FIELDS)
    values.update({
        "learner": rc.agent.learner,
        "K": int(rc.agent.K),
        "batch_size": int(rc.agent.batch_size),
        "action_repeat": int(rc.env.action_repeat),
        "nstep": int(rc.agent.nstep),
        "action_encoder": encoder is not None,
        "latent_action_dim": None if encoder is None else int(encoder.latent_dim),
        "objectives": {str(k): float(w) for k, w in learner.weights.items()},
        "dataset": rc.offline.dataset if is_offline(rc.agent.learner) else None,
    })
    values.update(learner.resolved)
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


def cpu_model() -> str:
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


def _read_meta_file(path: str | Path) -> dict | None:
    """The run directory's meta.json as written (any format); None when it has none."""
    file = Path(path) / META
    if not file.exists():
        return None
    meta = json.loads(file.read_text(encoding="utf-8"))
    if not isinstance(meta, dict):
        raise migrate.FormatError(f"{file} is not a JSON object")
    return meta


def read_meta(path: str | Path) -> dict | None:
    """The run directory's meta.json in the current format (migrate.migrate_meta); None when it has none."""
    meta = _read_meta_file(path)
    return None if meta is None else migrate.migrate_meta(meta, read_done(path))


def write_meta(path: Path, device: str, resumed: bool, extension: tuple[int, int] | None = None,
               config_from: int | None = None) -> dict:
    """Create meta.json on the first start; append to its ``resumes`` list on each resume, and to ``extensions``
    (``extension``: the budget reached and the new one) when a done run is extended. ``config_from``: the format
    config.yaml had before this start rewrote it (recorded under ``migrations`` when older than today's)."""
    file = path / META
    now = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    entry = {"time": now, "host": socket.gethostname(), "command": sys.argv, "device": device_name(device)}
    written = _read_meta_file(path)
    if written is not None:
        meta = migrate.migrate_meta(written, read_done(path))
        before = written.get("format", 1)
        if before != migrate.META_FORMAT:
            meta["migrations"].append({"file": META, "from": before, "to": migrate.META_FORMAT, "time": now})
        if resumed:
            meta.setdefault("resumes", []).append(entry)
    else:
        sha = _git("rev-parse", "HEAD")
        status = _git("status", "--porcelain", "--untracked-files=no")
        meta = {"format": migrate.META_FORMAT, "git_sha": sha,
                "git_dirty": bool(status) if status is not None else None,
                "versions": _versions(), "host": socket.gethostname(), "user": getpass.getuser(),
                "device": device_name(device), "cpu": cpu_model(), "command": sys.argv, "started": now,
                "platform": platform.platform(), "resumes": [], "budgets": [], "extensions": [], "migrations": []}
    if config_from is not None and config_from != migrate.CONFIG_FORMAT:
        meta["migrations"].append({"file": CONFIG, "from": config_from, "to": migrate.CONFIG_FORMAT, "time": now})
    if extension is not None:
        meta["extensions"].append({"from": extension[0], "to": extension[1], "time": now})
    atomic_write_text(file, json.dumps(meta, indent=2) + "\n")
    return meta


def write_done(path: Path, summary: dict, budget: int | None = None) -> None:
    """Record ``budget`` (default: the summary's ``frame`` or ``update``) as reached in meta.json, then write DONE
    (last: a run is done when DONE exists)."""
    if budget is None:
        budget = summary.get("frame", summary.get("update"))
    meta = read_meta(path)
    if meta is not None and isinstance(budget, int):
        if budget not in {b.get("budget") for b in meta["budgets"]}:
            meta["budgets"].append({"budget": budget, "finished": summary.get("finished")})
        atomic_write_text(path / META, json.dumps(meta, indent=2) + "\n")
    atomic_write_text(path / DONE, json.dumps(summary, indent=2) + "\n")


# ---------------------------------------------------------------------------------------------- one writer
class RunLocked(UserError, RuntimeError):
    """Another process is writing this run directory (one line naming it)."""


WriterLock = HolderLock  # the run directory's writer lock: an flock on {run}/.writer.lock (acquire_writer_lock)
# On NFS (v4, or v3 with lockd) Linux maps ``flock`` to a server-side lock: a lost node's lock goes when the server's
# lease for it expires (NFSv4: about 90 s) or its lockd is told the node rebooted (v3); a SLURM requeue after a node
# failure may be refused for that long and then succeeds on the next try.


def lock_holder(path: str | Path) -> str:
    """Who last held (or holds) the writer lock of the run directory ``path``, in words."""
    return holder_words(Path(path) / WRITER_LOCK)


def locked_message(path: Path, holder: str) -> str:
    return (f"{path} is being written by {holder}; a run directory has one writer: wait for it to finish "
            "(or stop it) and re-run to resume")


def writer_lock_holder(path: str | Path) -> str | None:
    """Who holds the run directory's writer lock now, in words; None when nobody does (writes nothing)."""
    return flock_holder(Path(path) / WRITER_LOCK)


def acquire_writer_lock(path: str | Path) -> WriterLock:
    """Take the run directory's writer lock now, or raise :class:`RunLocked` (never waits: a second start
    of a running run is a mistake to report, not a queue; the sweep launcher skips runs it sees locked).
    While held, the file names its holder for the refusal message; released, the file is removed (a run that
    ended, done or interrupted, leaves no ``.writer.lock``; a killed one leaves it, unlocked)."""
    path = Path(path)
    lock = try_flock(path / WRITER_LOCK, {"pid": os.getpid(), "host": socket.gethostname(),
                                         "since": time.strftime("%Y-%m-%dT%H:%M:%S%z")})
    if lock is None:
        raise RunLocked(locked_message(path, lock_holder(path)))
    return lock
