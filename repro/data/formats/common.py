"""What every external layout shares: a scan result, the dm_env row alignment, and input-file listing.

External layouts store an episode as T+1 rows in dm_env order: row t holds the observation at t, the
action that *led to* it and the reward and discount received on arriving there; row 0 has a dummy action
(exported here as zeros, reward 0, discount 1). A dataset episode stores the action *taken at* frame t, so
``actions = action[1:]``, ``rewards = reward[1:]``, ``discounts = discount[1:]``.
"""

from __future__ import annotations

import zipfile
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from repro.data.dataset import DatasetError, Episode


@dataclass(frozen=True)
class Unit:
    """One episode of an input: its file and, for files holding several episodes, its rows."""

    file: Path
    start: int = 0
    stop: int = 0


@dataclass(frozen=True)
class Scan:
    """What a layout check found: the episodes (in order), their size and the input's shapes."""

    units: list[Unit]
    transitions: int
    action_dim: int
    image_size: tuple[int, int]
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def episodes(self) -> int:
        return len(self.units)


def input_files(path: Path, suffix: str, what: str) -> list[Path]:
    """``path`` itself when a file, else its ``*suffix`` files sorted by name (never recursive)."""
    if path.is_file():
        return [path]
    if not path.is_dir():
        raise DatasetError(f"no such file or folder: {path}")
    files = sorted(p for p in path.iterdir() if p.is_file() and p.name.endswith(suffix))
    if not files:
        raise DatasetError(f"wrong format: no *{suffix} file in {path} (expected {what})")
    return files


def from_rows(frames: np.ndarray, action: np.ndarray, reward: np.ndarray, discount: np.ndarray,
              where: str) -> Episode:
    """A dataset episode from T+1 dm_env rows (frames already (T+1, 3, H, W) uint8)."""
    n = len(frames)
    if n < 2:
        raise DatasetError(f"{where}: an episode needs at least 2 rows, found {n}")
    return {"frames": np.ascontiguousarray(frames, dtype=np.uint8),
            "actions": np.asarray(action[1:], dtype=np.float32).reshape(n - 1, -1),
            "rewards": np.asarray(reward[1:], dtype=np.float32).reshape(n - 1),
            "discounts": np.asarray(discount[1:], dtype=np.float32).reshape(n - 1),
            "ep_id": np.array(0, dtype=np.int64)}


def to_rows(ep: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(action, reward, discount) as T+1 dm_env rows, with the dummy first row."""
    actions = np.asarray(ep["actions"], dtype=np.float32)
    action = np.concatenate([np.zeros((1, actions.shape[1]), np.float32), actions])
    reward = np.concatenate([np.zeros(1, np.float32), np.asarray(ep["rewards"], np.float32)])
    discount = np.concatenate([np.ones(1, np.float32), np.asarray(ep["discounts"], np.float32)])
    return action, reward, discount


def column(arr: np.ndarray, n: int, name: str, where: str) -> np.ndarray:
    """A per-row scalar array of length ``n``, given as (n,) or (n, 1)."""
    a = np.asarray(arr)
    if a.shape not in ((n,), (n, 1)):
        raise DatasetError(f"wrong format: {where}: '{name}' has shape {a.shape}, expected ({n},) or ({n}, 1)")
    a = a.reshape(n)
    if not np.all(np.isfinite(a.astype(np.float64))):
        raise DatasetError(f"{where}: non-finite values in '{name}'")
    return a


def npz_header(path: Path, keys: tuple[str, ...]) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Shape and dtype of each array in an npz file without decompressing it (a truncated file fails here)."""
    try:
        with zipfile.ZipFile(path) as zf:
            names = set(zf.namelist())
            missing = [k for k in keys if f"{k}.npy" not in names]
            if missing:
                raise DatasetError(f"wrong format: {path} has no array {', '.join(missing)} "
                                   f"(it holds {', '.join(sorted(n[:-4] for n in names)) or 'nothing'})")
            out = {}
            for k in keys:
                with zf.open(f"{k}.npy") as f:
                    version = np.lib.format.read_magic(f)
                    reader = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                              else np.lib.format.read_array_header_2_0)
                    shape, _, dtype = reader(f)
                out[k] = (tuple(shape), np.dtype(dtype))
            return out
    except DatasetError:
        raise
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise DatasetError(f"corrupt or truncated file {path}: {type(exc).__name__}") from None


def load_npz(path: Path, keys: tuple[str, ...]) -> dict[str, np.ndarray]:
    """The named arrays of an npz file; a damaged file is a :class:`DatasetError`."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in keys if k in z.files}
    except (zipfile.BadZipFile, OSError, ValueError, EOFError, zlib.error) as exc:
        raise DatasetError(f"corrupt or truncated file {path}: {type(exc).__name__}") from None


def resize_frames(frames: np.ndarray, size: int) -> np.ndarray:
    """(N, 3, H, W) uint8 -> (N, 3, size, size) uint8, bicubic (Pillow); a no-op at that size."""
    if frames.shape[2:] == (size, size):
        return frames
    from PIL import Image

    return np.stack([np.asarray(Image.fromarray(np.ascontiguousarray(f.transpose(1, 2, 0))).resize(
        (size, size), Image.Resampling.BICUBIC)).transpose(2, 0, 1) for f in frames])
