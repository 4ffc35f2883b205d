"""V-D4RL's 64px layout: one npz per episode, ``{time}-{id}-{rows}.npz``, in dm_env row order.

Arrays: ``image`` (T+1, 64, 64, 3) uint8 channels last, ``action`` (T+1, A), ``reward`` (T+1,),
``discount`` (T+1,), ``is_first``, ``is_last``, ``is_terminal`` (older files lack it: discount == 0).
Files are taken in name order (the time stamp first, as V-D4RL's loaders do). Import resizes the frames
to 84x84 with bicubic interpolation (Pillow; V-D4RL's own converter uses OpenCV's bicubic, which differs
by a few grey levels); export resizes back to 64x64, so a 64 -> 84 -> 64 round trip keeps every array but
the images exactly.
"""

from __future__ import annotations

import hashlib
import io
import re
from collections.abc import Iterable, Iterator
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np
from PIL import Image

from repro.data.dataset import DatasetError, Episode
from repro.data.formats.common import (
    Scan,
    ScanTotals,
    Unit,
    check_rows,
    input_files,
    load_npz,
    npz_header,
    read_npz_units,
    to_rows,
)

NAME = "vd4rl-64"
KEYS = ("image", "action", "reward", "discount")
FLAGS = ("is_first", "is_last")
SIZE = 64  # the only frame size import accepts without --resize
IMPORT_SIZE = 84  # the documented conversion: 64x64 in, 84x84 in the dataset (recorded in the manifest)
EXPORT_SIZE = 64
_ROWS = re.compile(r"-(\d+)\.npz$")


def resize(images: np.ndarray, size: int) -> np.ndarray:
    """(N, H, W, 3) uint8 -> (N, size, size, 3) uint8 with bicubic interpolation (a no-op at that size)."""
    if images.shape[1:3] == (size, size):
        return np.ascontiguousarray(images)
    return np.stack([np.asarray(Image.fromarray(im).resize((size, size), Image.Resampling.BICUBIC))
                     for im in images])


def _check_flags(flags: dict[str, np.ndarray], n: int, where: str) -> None:
    first, last = (np.asarray(flags[k]).reshape(-1).astype(bool) for k in FLAGS)
    if len(first) != n or len(last) != n:
        raise DatasetError(f"wrong format: {where}: is_first/is_last have {len(first)}/{len(last)} rows, image {n}")
    if not first[0] or first[1:].any():
        raise DatasetError(f"wrong format: {where}: is_first must be set on row 0 only (one episode a file)")
    if last[:-1].any():
        raise DatasetError(f"wrong format: {where}: is_last set before the final row (one episode a file)")
    if not last[-1]:
        raise DatasetError(f"truncated: {where}: the episode has no last step (is_last unset on the final row)")


def scan(path: Path) -> Scan:
    totals = ScanTotals()
    for f in input_files(path, ".npz", "V-D4RL 64px npz episode files"):
        head = npz_header(f, KEYS + FLAGS)
        shape, dtype = head["image"]
        if len(shape) != 4 or shape[3] != 3 or dtype != np.uint8:
            raise DatasetError(f"wrong format: {f}: image is {shape} {dtype}, expected (T+1, H, W, 3) uint8")
        n = shape[0]
        check_rows(f, {k: head[k][0] for k in ("action", "reward", "discount")}, n, f"({n},)")
        m = _ROWS.search(f.name)
        if m and int(m.group(1)) != n:
            raise DatasetError(f"truncated: {f}: its name says {m.group(1)} rows, it holds {n}")
        totals.same_shapes(f, head["action"][0][1], (shape[1], shape[2]))
        _check_flags(load_npz(f, FLAGS), n, str(f))
        totals.add(Unit(f, 0, n))
    return totals.scan(details={"resized_to": IMPORT_SIZE, "interpolation": "bicubic (Pillow)"})


def read(scan_: Scan, image_size: int | None = None) -> Iterator[Episode]:
    """The episodes, frames resized to ``image_size`` (default IMPORT_SIZE), bicubic."""
    size = IMPORT_SIZE if image_size is None else image_size
    return read_npz_units(scan_, KEYS, "image", lambda images, _: resize(images, size).transpose(0, 3, 1, 2))


def write(episodes: Iterable[Episode], out: Path, image_size: int = EXPORT_SIZE) -> list[Path]:
    paths = []
    start = datetime(2000, 1, 1)  # names sort in episode order; the stamp is an index, not a time
    for i, ep in enumerate(episodes):
        frames = np.asarray(ep["frames"])
        action, reward, discount = to_rows(ep)
        n = len(frames)
        first = np.zeros(n, bool)
        first[0] = True
        last = np.zeros(n, bool)
        last[-1] = True
        terminal = discount == 0
        terminal[0] = False
        arrays = {"image": resize(frames.transpose(0, 2, 3, 1), image_size), "action": action,
                  "reward": reward, "discount": discount, "is_first": first, "is_last": last,
                  "is_terminal": terminal}
        stamp = (start + timedelta(seconds=i)).strftime("%Y%m%dT%H%M%S")
        ident = hashlib.sha256(frames.tobytes()).hexdigest()[:32]
        path = out / f"{stamp}-{ident}-{n}.npz"
        buf = io.BytesIO()
        np.savez_compressed(buf, **arrays)
        path.write_bytes(buf.getvalue())
        paths.append(path)
    return paths
