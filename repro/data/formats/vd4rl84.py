"""V-D4RL's 84px layout: ``*.hdf5`` files (gzip) of concatenated episodes in dm_env row order.

Datasets per file: ``observation`` (N, 3, 84, 84) uint8 single frames, ``action`` (N, A), ``reward`` (N,),
``discount`` (N,), ``step_type`` (N,) with 0 first, 1 mid, 2 last. Episodes are found from ``step_type``
(never assumed to be 501 rows); an episode cut short (no last step) is an error. Export writes one
``data.hdf5`` (the name V-D4RL's converter uses) with ``step_type`` as float64, as that converter does.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import h5py
import numpy as np

from repro.data.dataset import DatasetError, Episode
from repro.data.formats.common import (
    Scan,
    ScanTotals,
    Unit,
    check_rows,
    checked_episode,
    finite_action,
    input_files,
    resize_frames,
    to_rows,
)

NAME = "vd4rl-84"
KEYS = ("observation", "action", "reward", "discount", "step_type")
OUT_FILE = "data.hdf5"
SIZE = 84  # the only frame size import accepts without --resize


def _open(path: Path) -> h5py.File:
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        raise DatasetError(
            f"corrupt or truncated file {path} (not readable as hdf5: {exc.__class__.__name__})"
        ) from None


def split_episodes(step_type: np.ndarray, where: str) -> list[tuple[int, int]]:
    """(start, stop) rows of each episode from dm_env step types; a cut or malformed episode is an error."""
    st = np.asarray(step_type, dtype=np.float64)
    if not np.all(np.isin(st, (0, 1, 2))):
        raise DatasetError(f"wrong format: {where}: step_type holds values other than 0, 1, 2")
    n = len(st)
    if n == 0:
        raise DatasetError(f"{where}: no rows")
    if st[0] != 0:
        raise DatasetError(f"wrong format: {where}: row 0 has step_type {int(st[0])}, an episode starts with 0")
    starts = np.flatnonzero(st == 0).tolist()
    out = []
    for k, s in enumerate(starts):
        stop = starts[k + 1] if k + 1 < len(starts) else n
        body = st[s + 1:stop]
        if stop - s < 2 or body[-1] != 2:
            if k + 1 == len(starts):
                raise DatasetError(f"truncated: {where}: the last episode (row {s} on, {stop - s} rows) has no "
                                   f"last step (step_type 2); {k} complete episodes before it")
            raise DatasetError(f"wrong format: {where}: episode {k} (rows {s}-{stop - 1}) does not end with "
                               "step_type 2")
        if np.any(body[:-1] != 1):
            bad = s + 1 + int(np.flatnonzero(body[:-1] != 1)[0])
            raise DatasetError(f"wrong format: {where}: row {bad} inside episode {k} has step_type {int(st[bad])}")
        out.append((s, stop))
    return out


def scan(path: Path) -> Scan:
    totals = ScanTotals()
    for f in input_files(path, ".hdf5", "V-D4RL 84px hdf5 files"):
        with _open(f) as h:
            missing = [k for k in KEYS if k not in h]
            if missing:
                raise DatasetError(f"wrong format: {f} has no dataset {', '.join(missing)} "
                                   f"(it holds {', '.join(sorted(h.keys())) or 'nothing'})")
            obs, act = h["observation"], h["action"]
            n = obs.shape[0] if obs.ndim else 0
            if obs.ndim != 4 or obs.shape[1] != 3 or obs.dtype != np.uint8:
                raise DatasetError(f"wrong format: {f}: observation is {obs.shape} {obs.dtype}, "
                                   "expected (N, 3, H, W) uint8")
            check_rows(f, {k: h[k].shape for k in ("action", "reward", "discount", "step_type")}, n, f"({n},)")
            totals.same_shapes(f, act.shape[1], (obs.shape[2], obs.shape[3]))
            try:
                step_type = np.asarray(h["step_type"][:]).reshape(n)
            except OSError as exc:
                raise DatasetError(f"corrupt or truncated file {f}: {exc.__class__.__name__}") from None
        for s, stop in split_episodes(step_type, str(f)):
            totals.add(Unit(f, s, stop))
    return totals.scan()


def read(scan_: Scan, image_size: int | None = None) -> Iterator[Episode]:
    """The episodes; ``image_size``: resize the frames to it (bicubic), as asked by ``--resize``."""
    handle: h5py.File | None = None
    try:
        for u in scan_.units:
            if handle is None or Path(handle.filename) != u.file:
                if handle is not None:
                    handle.close()
                handle = _open(u.file)
            where = f"{u.file} rows {u.start}-{u.stop - 1}"
            try:
                rows = {k: handle[k][u.start:u.stop] for k in KEYS}
            except OSError as exc:
                raise DatasetError(f"corrupt or truncated file {u.file}: {exc.__class__.__name__}") from None
            action = finite_action(rows["action"], where)
            yield checked_episode(resize_frames(rows["observation"], image_size), action, rows["reward"],
                                  rows["discount"], u.stop - u.start, where)
    finally:
        if handle is not None:
            handle.close()


def write(episodes: Iterable[Episode], out: Path) -> list[Path]:
    path = out / OUT_FILE
    with h5py.File(path, "w") as h:
        n = 0
        for ep in episodes:
            frames = np.asarray(ep["frames"])
            action, reward, discount = to_rows(ep)
            step_type = np.ones(len(frames), np.float64)
            step_type[0], step_type[-1] = 0, 2
            rows = {"observation": frames, "action": action, "reward": reward, "discount": discount,
                    "step_type": step_type}
            if n == 0:
                for k, v in rows.items():
                    chunk = (min(64, len(v)),) + v.shape[1:]
                    h.create_dataset(k, shape=(0,) + v.shape[1:], maxshape=(None,) + v.shape[1:], dtype=v.dtype,
                                     chunks=chunk, compression="gzip")
            for k, v in rows.items():
                h[k].resize(n + len(v), axis=0)
                h[k][n:n + len(v)] = v
            n += len(frames)
    return [path]
