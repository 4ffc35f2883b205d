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
    ScanTotals,
    Unit,
    check_rows,
    input_files,
    npz_header,
    read_npz_units,
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
    totals = ScanTotals()
    for _, length, f in named:
        head = npz_header(f, KEYS)
        shape, dtype = head["observation"]
        if len(shape) != 4 or shape[1] % 3 or dtype != np.uint8:
            raise DatasetError(f"wrong format: {f}: observation is {shape} {dtype}, expected (T+1, 3k, H, W) uint8")
        n = shape[0]
        if n != length + 1:
            raise DatasetError(f"truncated: {f}: its name says {length} transitions, it holds {n - 1}")
        check_rows(f, {k: head[k][0] for k in ("action", "reward", "discount")}, n, f"({n}, 1)")
        totals.same_shapes(f, head["action"][0][1], (shape[2], shape[3]))
        totals.add(Unit(f, 0, n))
    return totals.scan()


def newest_frames(obs: np.ndarray, where: str) -> np.ndarray:
    """The last 3 channels of each row, after checking rows are stacked oldest to newest."""
    if obs.shape[1] > 3 and not np.array_equal(obs[1:, :-3], obs[:-1, 3:]):
        t = 1 + int(np.flatnonzero((obs[1:, :-3] != obs[:-1, 3:]).reshape(len(obs) - 1, -1).any(1))[0])
        raise DatasetError(f"wrong format: {where}: row {t} is not row {t - 1}'s stack shifted by one frame "
                           "(frames must be stacked oldest to newest)")
    return obs[:, -3:]


def read(scan_: Scan, image_size: int | None = None) -> Iterator[Episode]:
    """The episodes; ``image_size``: resize the frames to it (bicubic), as asked by ``--resize``."""
    return read_npz_units(scan_, KEYS, "observation",
                          lambda obs, where: resize_frames(newest_frames(obs, where), image_size))


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
