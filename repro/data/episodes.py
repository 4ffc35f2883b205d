"""Episode files under ``run_dir/replay``: written once per episode, so checkpoints never rewrite the buffer."""

from __future__ import annotations

import io
import re
from pathlib import Path

import numpy as np

from repro.runs.fsutil import atomic_write

_NAME = re.compile(r"^ep_(\d{7})\.npz$")


class EpisodeStore:
    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)

    def path(self, ep_id: int) -> Path:
        return self.folder / f"ep_{ep_id:07d}.npz"

    def save(self, data: dict[str, np.ndarray]) -> None:
        def write(f) -> None:
            buf = io.BytesIO()
            np.savez_compressed(buf, **data)  # type: ignore[arg-type]  # numpy stub matches **kwds against allow_pickle
            f.write(buf.getvalue())

        atomic_write(self.path(int(data["ep_id"])), write)

    def load(self, ep_id: int) -> dict[str, np.ndarray]:
        with np.load(self.path(ep_id)) as z:
            return {k: z[k] for k in z.files}

    def ids(self) -> list[int]:
        return sorted(int(m.group(1)) for p in self.folder.iterdir() if (m := _NAME.match(p.name)))

    def prune(self, keep: set[int]) -> None:
        """Delete episode files not in ``keep`` (fully overwritten in the ring, or newer than a checkpoint)."""
        for ep_id in self.ids():
            if ep_id not in keep:
                self.path(ep_id).unlink(missing_ok=True)
        for tmp in self.folder.glob(".*.tmp"):
            tmp.unlink(missing_ok=True)
