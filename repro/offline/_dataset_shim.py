"""PRIVATE STAND-IN for repro/offline/dataset.py (owned by the `datasets` helper), with the contract's names.

Only what `dataset make` needs: the coordinator replaces the import in make.py by `repro.offline.dataset`
and deletes this file.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from repro import __version__
from repro.fsutil import atomic_write, atomic_write_text

MANIFEST, EPISODES, FORMAT = "manifest.json", "episodes", 1


class DatasetError(ValueError):
    """A dataset problem, explained in one line."""


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def load_manifest(folder: str | Path) -> dict[str, Any]:
    file = Path(folder) / MANIFEST
    try:
        data = json.loads(file.read_text())
    except (OSError, ValueError) as exc:
        raise DatasetError(f"{folder}: no valid {MANIFEST} ({type(exc).__name__})") from None
    if data.get("format") != FORMAT:
        raise DatasetError(f"{folder}: unknown dataset format {data.get('format')!r}")
    return data


def iter_episodes(folder: str | Path) -> Iterator[dict[str, np.ndarray]]:
    for ep in load_manifest(folder)["episodes"]:
        with np.load(Path(folder) / ep["file"]) as z:
            yield {k: z[k] for k in z.files}


def write_dataset(folder: str | Path, episodes: Iterable[dict[str, np.ndarray]], *, task: str, kind: str,
                  source: dict[str, Any] | None = None, rule: dict[str, Any] | None = None) -> dict[str, Any]:
    """As the datasets helper's (keyword arguments; action_dim and frame_shape from the episodes)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / MANIFEST).unlink(missing_ok=True)
    rows, total = [], 0
    for i, ep in enumerate(episodes):
        name = f"{EPISODES}/ep_{i:07d}.npz"
        ep = {**ep, "ep_id": np.array(i, dtype=np.int64)}

        def write(f, ep=ep) -> None:
            buf = io.BytesIO()
            np.savez_compressed(buf, **ep)
            f.write(buf.getvalue())

        atomic_write(folder / name, write)
        n = int(len(ep["actions"]))
        total += n
        rows.append({"file": name, "sha256": _sha256(folder / name), "transitions": n,
                     "return": float(np.sum(ep["rewards"], dtype=np.float64))})
    manifest = {"format": FORMAT, "task": task, "action_dim": int(ep["actions"].shape[1]),
                "frame_shape": [int(x) for x in ep["frames"].shape[1:]], "kind": kind,
                "source": json.loads(json.dumps(source or {})), "rule": json.loads(json.dumps(rule or {})),
                "transitions": total, "episodes": rows,
                "created_by": f"taco-repro {__version__}"}
    atomic_write_text(folder / MANIFEST, json.dumps(manifest, indent=2) + "\n")
    return manifest


def check_dataset(folder: str | Path) -> list[str]:
    try:
        manifest = load_manifest(folder)
    except DatasetError as exc:
        return [str(exc)]
    problems = []
    for ep in manifest["episodes"]:
        path = Path(folder) / ep["file"]
        if not path.is_file() or _sha256(path) != ep["sha256"]:
            problems.append(f"{ep['file']}: missing or hash differs")
    return problems
