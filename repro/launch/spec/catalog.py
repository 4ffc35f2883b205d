"""The packaged sweep files: where they are, their names, loading one by name or path."""

from __future__ import annotations

import os
from pathlib import Path

from repro.config.compose import close_matches
from repro.launch.spec.errors import SweepError
from repro.launch.spec.sweepfile import SweepSpec, load_file

ENV_SWEEPS_DIR = "REPRO_SWEEPS_DIR"


def sweeps_dir() -> Path:
    """Folder of the packaged sweep files (``$REPRO_SWEEPS_DIR`` overrides it)."""
    if os.environ.get(ENV_SWEEPS_DIR):
        return Path(os.environ[ENV_SWEEPS_DIR])
    return Path(__file__).resolve().parents[3] / "sweeps"


def sweep_names() -> list[str]:
    return sorted(p.stem for p in sweeps_dir().glob("*.yaml"))


def load(name: str) -> SweepSpec:
    """A packaged sweep by name, or a sweep file by path (``*.yaml``)."""
    if name.endswith((".yaml", ".yml")) or os.sep in name:
        path = Path(name)
        if not path.exists():
            raise SweepError(f"sweep file {name} does not exist.")
        return load_file(path)
    path = sweeps_dir() / f"{name}.yaml"
    if not path.exists():
        raise SweepError(f"unknown sweep '{name}'." + close_matches(name, sweep_names()))
    spec = load_file(path)
    if spec.name != name:
        raise SweepError(f"{path}: name '{spec.name}' differs from the file name '{name}'.")
    return spec


def load_all() -> list[SweepSpec]:
    return [load(n) for n in sweep_names()]
