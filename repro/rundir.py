"""The run directory contract (docs/run-format.md): path, identity check, metadata, DONE marker."""

from __future__ import annotations

import getpass
import hashlib
import json
import platform
import re
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import yaml
from omegaconf import DictConfig, OmegaConf

from repro.config import identity
from repro.fsutil import atomic_write_text
from repro.schema import RunConfig

CONFIG, META, DONE, CHECKPOINT = "config.yaml", "meta.json", "DONE", "checkpoint.pt"
PACKAGES = ("torch", "numpy", "mujoco", "dm-control", "metaworld", "hydra-core", "omegaconf", "submitit",
            "pandas", "rliable", "taco-repro")


class RunDirMismatch(ValueError):
    """The run directory holds a run with another config."""


def run_dir(cfg: DictConfig) -> Path:
    """``{results_root}/{experiment}/{agent}/{variant}/{task}/seed_{seed}`` from config values only;
    an offline run (``offline.dataset`` set) has ``{task}/{dataset}/seed_{seed}`` (see dataset_tag)."""
    task_dir = (Path(cfg.runtime.results_root) / str(cfg.experiment) / str(cfg.agent.name) / str(cfg.variant)
                / str(cfg.task.name))
    dataset = OmegaConf.select(cfg, "offline.dataset", default=None)
    if dataset is not None:
        task_dir = task_dir / dataset_tag(str(dataset))
    return task_dir / f"seed_{cfg.seed}"


def dataset_tag(value: str) -> str:
    """Run directory component of ``offline.dataset``: a kind (``medium``) as is; a folder: its name and the
    first 8 hex digits of the sha256 of the value as written (``84px-1a2b3c4d``), so two folders never share one."""
    if "/" not in value:
        return value
    name = re.sub(r"[^A-Za-z0-9_.\-]", "_", Path(value.rstrip("/")).name) or "dataset"
    return f"{name}-{hashlib.sha256(value.encode()).hexdigest()[:8]}"


def run_state(path: str | Path) -> str:
    """``done`` (DONE exists), ``partial`` (a config or checkpoint but no DONE) or ``absent``."""
    path = Path(path)
    if (path / DONE).exists():
        return "done"
    if (path / CHECKPOINT).exists() or (path / CONFIG).exists():
        return "partial"
    return "absent"


def saved_identity(path: str | Path) -> dict | None:
    file = Path(path) / CONFIG
    if not file.exists():
        return None
    data = yaml.safe_load(file.read_text()) or {}
    data.pop("runtime", None)
    return data


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
    return [d for d in diffs if not _added_at_default(d)]


def _added_at_default(diff: str) -> bool:
    """A key that a newer version added, absent from the saved run and at its default now, is no difference
    (so runs written before the key existed still resume)."""
    key, _, change = diff.partition(": ")
    old, _, new = change.partition(" -> ")
    if old != repr("<absent>"):
        return False
    default = OmegaConf.select(OmegaConf.structured(RunConfig), key, default="<no default>")
    if isinstance(default, DictConfig):
        default = OmegaConf.to_container(default, resolve=True)
    return repr(default) == new


def config_matches(path: str | Path, cfg: DictConfig) -> bool:
    return not config_diff(path, cfg)


def write_config(path: Path, cfg: DictConfig) -> None:
    atomic_write_text(path / CONFIG, OmegaConf.to_yaml(cfg, resolve=True))


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
