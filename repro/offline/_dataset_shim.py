"""PRIVATE SHIM, to be replaced by ``repro.offline.dataset`` (datasets helper) when it lands.

Implements only the reading half of the dataset contract (PLAN.md): a directory with ``episodes/*.npz``
and a ``manifest.json`` written last. Same names as the real module; repro/offline/replay.py imports from
here in exactly one line.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np

MANIFEST = "manifest.json"


class DatasetError(ValueError):
    """A dataset problem, explained in one line."""


@dataclass
class Manifest:
    format: int
    task: str
    action_dim: int
    frame_shape: list[int]
    kind: str
    transitions: int
    episodes: list[dict[str, Any]]
    source: dict[str, Any] = field(default_factory=dict)
    rule: dict[str, Any] = field(default_factory=dict)
    created_by: str = ""


def load_manifest(directory: str | Path) -> Manifest:
    path = Path(directory) / MANIFEST
    if not path.is_file():
        raise DatasetError(f"{directory}: no {MANIFEST} (not a dataset, or an incomplete one)")
    try:
        data = json.loads(path.read_text())
        return Manifest(**{k: data[k] for k in Manifest.__dataclass_fields__ if k in data})
    except (ValueError, TypeError, KeyError) as exc:
        raise DatasetError(f"{path}: unreadable manifest ({exc})") from None


def iter_episodes(directory: str | Path) -> Iterator[dict[str, np.ndarray]]:
    directory = Path(directory)
    for entry in load_manifest(directory).episodes:
        with np.load(directory / "episodes" / entry["file"]) as z:
            yield {k: z[k] for k in z.files}


def resolve_dataset(value: str, results_root: str | Path, task: str) -> Path:
    """A kind (``medium``) -> ``{results_root}/datasets/{task}/{kind}``; a value with a ``/`` is a folder."""
    path = Path(value) if "/" in value else Path(results_root) / "datasets" / task / value
    if not (path / MANIFEST).is_file():
        raise DatasetError(f"dataset '{value}' not found: {path} has no {MANIFEST}")
    return path
