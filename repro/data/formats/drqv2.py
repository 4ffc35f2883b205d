"""DrQ-v2 / TACO replay episodes: one npz per episode, ``{timestamp}_{index}_{transitions}.npz``.

Arrays, in dm_env row order: ``observation`` (T+1, 3k, 84, 84) uint8, k frames stacked oldest to newest
(the last 3 channels are the newest frame; the first row repeats the first frame), ``action`` (T+1, A)
with a dummy first row, ``reward`` and ``discount`` (T+1, 1). Files are taken in index order. Import keeps
the newest frame of each row and checks that consecutive rows are shifted stacks of each other (a stack
stored newest-first fails). Export stacks k = 3 frames, as DrQ-v2 and TACO do.
"""

from __future__ import annotations

import io
import re
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from repro.data.dataset import DatasetError, Episode
from repro.data.formats.common import (
    Scan,
    Unit,
    column,
    from_rows,
    input_files,
    load_npz,
    npz_header,
    resize_frames,
    to_rows,
)

NAME = "drqv2"
KEYS = ("observation", "action", "reward", "discount")
FRAME_STACK = 3
SIZE = 84  # the only frame size import accepts without --resize
_NAME = re.compile(r"^([^_]+)_(\d+)_(\d+)\.npz$")


def scan(path: Path) -> Scan:
    named = []
    for f in input_files(path, ".npz", "DrQ-v2 replay episode files"):
        m = _NAME.match(f.name)
        if not m:
            raise DatasetError(f"wrong format: {f.name} is not named {{timestamp}}_{{index}}_{{length}}.npz")
        named.append((int(m.group(2)), int(m.group(3)), f))
    named.sort(key=lambda x: x[0])
    seen = [i for i, _, _ in named]
    if len(set(seen)) != len(seen):
        dup = next(i for i in seen if seen.count(i) > 1)
        raise DatasetError(f"wrong format: two episode files with index {dup} in {path}")
    units: list[Unit] = []
    action_dim = None
    size = None
    transitions = 0
    for _, length, f in named:
        head = npz_header(f, KEYS)
        (shape, dtype), (ashape, _) = head["observation"], head["action"]
        if len(shape) != 4 or shape[1] % 3 or dtype != np.uint8:
            raise DatasetError(f"wrong format: {f}: observation is {shape} {dtype}, expected (T+1, 3k, H, W) uint8")
        n = shape[0]
        if n != length + 1:
            raise DatasetError(f"truncated: {f}: its name says {length} transitions, it holds {n - 1}")
        if len(ashape) != 2 or ashape[0] != n:
            raise DatasetError(f"wrong format: {f}: action is {ashape}, expected ({n}, A)")
        for k in ("reward", "discount"):
            if head[k][0] not in ((n,), (n, 1)):
                raise DatasetError(f"wrong format: {f}: {k} is {head[k][0]}, expected ({n}, 1)")
        if action_dim is not None and ashape[1] != action_dim:
            raise DatasetError(f"{f}: action dim {ashape[1]}, earlier files have {action_dim}")
        if size is not None and tuple(shape[2:]) != size:
            raise DatasetError(f"{f}: frames {tuple(shape[2:])}, earlier files have {size}")
        if n < 2:
            raise DatasetError(f"{f}: an episode needs at least 2 rows, found {n}")
        action_dim, size = int(ashape[1]), (int(shape[2]), int(shape[3]))
        units.append(Unit(f, 0, n))
        transitions += n - 1
    assert action_dim is not None and size is not None
    return Scan(units, transitions, action_dim, size)


def newest_frames(obs: np.ndarray, where: str) -> np.ndarray:
    """The last 3 channels of each row, after checking rows are stacked oldest to newest."""
    if obs.shape[1] > 3 and not np.array_equal(obs[1:, :-3], obs[:-1, 3:]):
        t = 1 + int(np.flatnonzero((obs[1:, :-3] != obs[:-1, 3:]).reshape(len(obs) - 1, -1).any(1))[0])
        raise DatasetError(f"wrong format: {where}: row {t} is not row {t - 1}'s stack shifted by one frame "
                           "(frames must be stacked oldest to newest)")
    return obs[:, -3:]


def read(scan_: Scan, image_size: int | None = None) -> Iterator[Episode]:
    """The episodes; ``image_size``: resize the frames to it (bicubic), as asked by ``--resize``."""
    for u in scan_.units:
        z = load_npz(u.file, KEYS)
        where, n = str(u.file), u.stop
        if len(z["observation"]) != n:
            raise DatasetError(f"{where}: changed since it was checked")
        action = np.asarray(z["action"], dtype=np.float64)
        if not np.all(np.isfinite(action)):
            raise DatasetError(f"{where}: non-finite values in 'action'")
        frames = newest_frames(z["observation"], where)
        yield from_rows(frames if image_size is None else resize_frames(frames, image_size), action,
                        column(z["reward"], n, "reward", where), column(z["discount"], n, "discount", where), where)


def stack(frames: np.ndarray, k: int = FRAME_STACK) -> np.ndarray:
    """(T+1, 3, H, W) -> (T+1, 3k, H, W): each row the k latest frames, the first repeated at the start."""
    idx = np.maximum(np.arange(len(frames))[:, None] + np.arange(-k + 1, 1)[None, :], 0)
    return frames[idx].reshape(len(frames), 3 * k, *frames.shape[2:])


def write(episodes: Iterable[Episode], out: Path) -> list[Path]:
    paths = []
    for i, ep in enumerate(episodes):
        frames = np.asarray(ep["frames"])
        action, reward, discount = to_rows(ep)
        arrays = {"observation": stack(frames), "action": action, "reward": reward[:, None],
                  "discount": discount[:, None]}
        path = out / f"20000101T000000_{i}_{len(frames) - 1}.npz"  # the stamp is fixed; the index orders
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)  # type: ignore[arg-type]  # numpy stub matches **kwds against allow_pickle
        path.write_bytes(buf.getvalue())
        paths.append(path)
    return paths
