"""Opt-in TensorBoard event files that mirror the run's CSV logs (``runtime.tensorboard=true``).

The CSV files stay the source of truth. Every row written to ``eval.csv`` / ``train.csv`` is also written as
scalars ``eval/<column>`` / ``train/<column>`` at ``step = frame`` (offline runs: the update count). On a
resume the CSVs are truncated to the checkpoint; the event files are then rebuilt from the truncated CSVs,
so a resumed run's curves never hold a point twice, whatever was written after the checkpoint.
"""

from __future__ import annotations

import csv
import math
import os
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from repro.runs.runformat import TB as TB_DIR

__all__ = ["TB_DIR", "TensorBoardMirror", "cell_number", "csv_rows", "read_scalars"]


def cell_number(value: Any) -> float | None:
    """A CSV cell (or a logged value) as a float; None for an empty cell, text or NaN (no point)."""
    if value is None or value == "":
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return None if math.isnan(x) else x


def csv_rows(csv_files: Mapping[str, str | os.PathLike]) -> Iterator[tuple[str, dict[str, str]]]:
    """(prefix, row) for every row of the given CSV files (prefix -> path; a missing file has none), file by file."""
    for prefix, path in csv_files.items():
        path = Path(path)
        if not path.exists():
            continue
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                yield prefix, row


class TensorBoardMirror:
    """Event files under ``run_dir/tb``; one writer for all files of the run."""

    def __init__(self, run_dir: str | os.PathLike, step_column: str = "frame"):
        from torch.utils.tensorboard import SummaryWriter

        self.folder = Path(run_dir) / TB_DIR
        self.step_column = step_column
        if self.folder.exists():
            shutil.rmtree(self.folder)  # rebuilt from the CSVs (see rebuild)
        self._writer = SummaryWriter(log_dir=str(self.folder), flush_secs=10)

    def add_row(self, prefix: str, row: Mapping[str, Any], flush: bool = True) -> None:
        """Write every numeric column of ``row`` as ``{prefix}/{column}`` at the row's step."""
        step = cell_number(row.get(self.step_column))
        if step is None:
            return
        for key, value in row.items():
            if key == self.step_column:
                continue
            x = cell_number(value)
            if x is not None:
                self._writer.add_scalar(f"{prefix}/{key}", x, global_step=int(step))
        if flush:
            self._writer.flush()

    def rebuild(self, csv_files: Mapping[str, str | os.PathLike]) -> int:
        """Write all rows of the given CSV files (prefix -> path) again; returns the number of rows."""
        rows = 0
        for prefix, row in csv_rows(csv_files):
            self.add_row(prefix, row, flush=False)
            rows += 1
        self._writer.flush()
        return rows

    def close(self) -> None:
        self._writer.close()


def read_scalars(run_dir: str | os.PathLike) -> dict[str, list[tuple[int, float]]]:
    """Every scalar series in ``run_dir/tb`` through TensorBoard's own reader: tag -> [(step, value)]."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(Path(run_dir) / TB_DIR), size_guidance={"scalars": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}
