"""What every external layout shares: a scan result, the dm_env row alignment, and input-file listing.

External layouts store an episode as T+1 rows in dm_env order: row t holds the observation at t, the
action that *led to* it and the reward and discount received on arriving there; row 0 has a dummy action
(exported here as zeros, reward 0, discount 1). A dataset episode stores the action *taken at* frame t, so
``actions = action[1:]``, ``rewards = reward[1:]``, ``discounts = discount[1:]``.
"""

from __future__ import annotations

import zipfile
import zlib
from collections.abc import Callable, Iterator, Mapping
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


def checked_episode(frames: np.ndarray, action: np.ndarray, reward: np.ndarray, discount: np.ndarray, n: int,
                    where: str) -> Episode:
    """A dataset episode from ``n`` read dm_env rows: frames (n, 3, H, W), actions finite, reward and discount
    per-row columns (see :func:`column`)."""
    return from_rows(frames, action, column(reward, n, "reward", where), column(discount, n, "discount", where), where)


def finite_action(action: np.ndarray, where: str) -> np.ndarray:
    """The action rows as float64; a :class:`DatasetError` when one is not finite."""
    action = np.asarray(action, dtype=np.float64)
    if not np.all(np.isfinite(action)):
        raise DatasetError(f"{where}: non-finite values in 'action'")
    return action


def read_npz_units(scan_: Scan, keys: tuple[str, ...], image_key: str,
                   frames: Callable[[np.ndarray, str], np.ndarray]) -> Iterator[Episode]:
    """The episodes of a one-episode-per-npz layout: each file's arrays ``keys`` (with ``action``, ``reward`` and
    ``discount``) checked against its scan; ``frames(images, where)`` makes the (n, 3, H, W) frames."""
    for u in scan_.units:
        z = load_npz(u.file, keys)
        where, n = str(u.file), u.stop
        if len(z[image_key]) != n:
            raise DatasetError(f"{where}: changed since it was checked")
        action = finite_action(z["action"], where)
        yield checked_episode(frames(z[image_key], where), action, z["reward"], z["discount"], n, where)


class ScanTotals:
    """What a scan gathers over its input files: the episodes, their transitions, and the action dimension and
    frame size every file must share."""

    def __init__(self) -> None:
        self.units: list[Unit] = []
        self.transitions = 0
        self.action_dim: int | None = None
        self.size: tuple[int, int] | None = None

    def same_shapes(self, file: Path, action_dim: int, size: tuple[int, int]) -> None:
        """Refuse ``file`` when its action dimension or frame size differs from the earlier files'."""
        if self.action_dim is not None and action_dim != self.action_dim:
            raise DatasetError(f"{file}: action dim {action_dim}, earlier files have {self.action_dim}")
        if self.size is not None and size != self.size:
            raise DatasetError(f"{file}: frames {size}, earlier files have {self.size}")
        self.action_dim, self.size = int(action_dim), (int(size[0]), int(size[1]))

    def add(self, unit: Unit) -> None:
        """One more episode (refused below 2 rows)."""
        n = unit.stop - unit.start
        if n < 2:
            raise DatasetError(f"{unit.file}: an episode needs at least 2 rows, found {n}")
        self.units.append(unit)
        self.transitions += n - 1

    def scan(self, details: dict[str, Any] | None = None) -> Scan:
        assert self.action_dim is not None and self.size is not None
        return Scan(self.units, self.transitions, self.action_dim, self.size, details=details or {})


def check_rows(file: Path, shapes: Mapping[str, tuple[int, ...]], n: int, expected: str) -> None:
    """Refuse ``file`` unless its action is (n, A) and each per-row column in ``shapes`` is (n,) or (n, 1)."""
    ashape = shapes["action"]
    if len(ashape) != 2 or ashape[0] != n:
        raise DatasetError(f"wrong format: {file}: action is {ashape}, expected ({n}, A)")
    for k, shape in shapes.items():
        if k != "action" and shape not in ((n,), (n, 1)):
            raise DatasetError(f"wrong format: {file}: {k} is {shape}, expected {expected}")


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


def resize_frames(frames: np.ndarray, size: int | None) -> np.ndarray:
    """(N, 3, H, W) uint8 -> (N, 3, size, size) uint8, bicubic (Pillow); a no-op at that size or without one."""
    if size is None or frames.shape[2:] == (size, size):
        return frames
    from PIL import Image

    return np.stack([np.asarray(Image.fromarray(np.ascontiguousarray(f.transpose(1, 2, 0))).resize(
        (size, size), Image.Resampling.BICUBIC)).transpose(2, 0, 1) for f in frames])
