"""Runs waiting for their offline dataset: found before launch, skipped by both launchers, shown by status.

An offline run (``offline.dataset`` set) can start only once its dataset is complete, i.e. its folder holds
a valid ``manifest.json`` (repro.data.dataset.load_manifest). Until then the run is *waiting*: the
local launcher does not start it, the SLURM launcher does not submit it, and ``repro status`` says which
dataset it waits for and how to make it. A dataset made later is picked up by the next launch.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from omegaconf import DictConfig

from repro.config.compose import is_folder_value
from repro.data.dataset import DatasetError, dataset_path, load_manifest


@dataclass(frozen=True)
class DatasetNeed:
    """The dataset an offline run reads: its ``offline.dataset`` value, task and folder."""

    value: str
    task: str
    path: Path

    def to_json(self) -> dict[str, str]:
        return {"value": self.value, "task": self.task, "path": str(self.path)}

    @classmethod
    def from_json(cls, data: Any) -> DatasetNeed | None:
        if not isinstance(data, Mapping) or not {"value", "task", "path"} <= set(data):
            return None
        return cls(str(data["value"]), str(data["task"]), Path(str(data["path"])))

    def label(self) -> str:
        return f"dataset {self.value} for {self.task}"


def dataset_need(cfg: DictConfig) -> DatasetNeed | None:
    """The dataset a composed run config reads, or None for an online run."""
    offline = cfg.get("offline")
    value = offline.get("dataset") if offline is not None else None
    if value is None or not str(value).strip():
        return None
    value = str(value).strip()
    try:
        path = dataset_path(value, str(cfg.runtime.results_root), str(cfg.task.name))
    except DatasetError:
        return None
    return DatasetNeed(value, str(cfg.task.name), path.expanduser().absolute())


def missing_reason(need: DatasetNeed | None) -> str | None:
    """Why the run cannot start yet (one line), or None when its dataset is complete (or it needs none)."""
    if need is None:
        return None
    try:
        load_manifest(need.path)
    except DatasetError as exc:
        if is_folder_value(need.value):
            return (f"{need.label()} not there yet ({exc}); `repro dataset import` or `repro dataset make --out` "
                    "writes it")
        state = "not made yet" if not need.path.exists() else f"not complete ({exc})"
        return (f"{need.label()} {state}: `repro dataset make --source RUN_DIR --kind {need.value} --out "
                f"{need.path}` makes it (RUN_DIR: a recorded {need.task} run, e.g. of sweep offline_data)")
    return None


def waiting_lines(waiting: Sequence[tuple[str, str]]) -> list[str]:
    """One line per distinct reason for ``(run key, reason)`` pairs, with the number of runs it holds back."""
    by_reason: dict[str, int] = {}
    for _, reason in waiting:
        by_reason[reason] = by_reason.get(reason, 0) + 1
    return [f"{n} run(s) waiting: {reason}" for reason, n in by_reason.items()]
