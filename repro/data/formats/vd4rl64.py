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
from repro.data.formats.common import Scan, Unit, column, from_rows, input_files, load_npz, npz_header, to_rows

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
    units: list[Unit] = []
    action_dim = None
    size = None
    transitions = 0
    for f in input_files(path, ".npz", "V-D4RL 64px npz episode files"):
        head = npz_header(f, KEYS + FLAGS)
        (shape, dtype), (ashape, _) = head["image"], head["action"]
        if len(shape) != 4 or shape[3] != 3 or dtype != np.uint8:
            raise DatasetError(f"wrong format: {f}: image is {shape} {dtype}, expected (T+1, H, W, 3) uint8")
        n = shape[0]
        if len(ashape) != 2 or ashape[0] != n:
            raise DatasetError(f"wrong format: {f}: action is {ashape}, expected ({n}, A)")
        for k in ("reward", "discount"):
            if head[k][0] not in ((n,), (n, 1)):
                raise DatasetError(f"wrong format: {f}: {k} is {head[k][0]}, expected ({n},)")
        m = _ROWS.search(f.name)
        if m and int(m.group(1)) != n:
            raise DatasetError(f"truncated: {f}: its name says {m.group(1)} rows, it holds {n}")
        if action_dim is not None and ashape[1] != action_dim:
            raise DatasetError(f"{f}: action dim {ashape[1]}, earlier files have {action_dim}")
        if size is not None and tuple(shape[1:3]) != size:
            raise DatasetError(f"{f}: frames {tuple(shape[1:3])}, earlier files have {size}")
        action_dim, size = int(ashape[1]), (int(shape[1]), int(shape[2]))
        _check_flags(load_npz(f, FLAGS), n, str(f))
        if n < 2:
            raise DatasetError(f"{f}: an episode needs at least 2 rows, found {n}")
        units.append(Unit(f, 0, n))
        transitions += n - 1
    assert action_dim is not None and size is not None
    return Scan(units, transitions, action_dim, size,
                details={"resized_to": IMPORT_SIZE, "interpolation": "bicubic (Pillow)"})


def read(scan_: Scan, image_size: int | None = None) -> Iterator[Episode]:
    """The episodes, frames resized to ``image_size`` (default IMPORT_SIZE), bicubic."""
    size = IMPORT_SIZE if image_size is None else image_size
    for u in scan_.units:
        z = load_npz(u.file, KEYS)
        where, n = str(u.file), u.stop
        if len(z["image"]) != n:
            raise DatasetError(f"{where}: changed since it was checked")
        action = np.asarray(z["action"], dtype=np.float64)
        if not np.all(np.isfinite(action)):
            raise DatasetError(f"{where}: non-finite values in 'action'")
        frames = resize(z["image"], size).transpose(0, 3, 1, 2)
        yield from_rows(frames, action, column(z["reward"], n, "reward", where),
                        column(z["discount"], n, "discount", where), where)


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
