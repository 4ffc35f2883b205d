"""Append-only CSV logs whose byte offsets are stored in checkpoints, so a resume truncates them exactly."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Sequence


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


class CsvLog:
    """One CSV file with a fixed header; each row is flushed and fsynced as soon as it is written."""

    def __init__(self, path: str | os.PathLike, columns: Sequence[str], offset: int | None = None):
        """Open ``path`` for appending. ``offset`` (from a checkpoint) truncates rows written after it;
        ``None`` starts the file afresh."""
        self.path = Path(path)
        self.columns = list(columns)
        header = ",".join(self.columns) + "\n"
        if offset is None or not self.path.exists():
            self.path.write_text(header)
        else:
            with open(self.path, "r+b") as f:
                existing = f.readline().decode()
                if existing != header:
                    raise ValueError(f"{self.path}: header differs from the run's columns")
                f.truncate(max(offset, len(header.encode())))
        self._f = open(self.path, "ab")

    def write(self, row: dict[str, Any]) -> None:
        unknown = set(row) - set(self.columns)
        if unknown:
            raise KeyError(f"{self.path.name}: unknown columns {sorted(unknown)}")
        line = ",".join(_fmt(row.get(c)) for c in self.columns) + "\n"
        self._f.write(line.encode())
        self._f.flush()
        os.fsync(self._f.fileno())

    def offset(self) -> int:
        return self._f.tell()

    def close(self) -> None:
        self._f.close()


EVAL_COLUMNS = ["frame", "step", "episode", "episode_reward", "episode_reward_std", "episode_length",
                "success", "eval_episodes", "total_time"]
TRAIN_COLUMNS = ["frame", "step", "episode", "episode_reward", "episode_length", "success", "buffer_size",
                 "stddev", "fps", "total_time"]
WALLCLOCK_COLUMNS = ("total_time", "fps")


class RunLogger:
    """The run's ``eval.csv`` and ``train.csv`` plus console output."""

    def __init__(self, run_dir: str | os.PathLike, metric_names: Sequence[str],
                 offsets: dict[str, int] | None = None, echo=print):
        run_dir = Path(run_dir)
        offsets = offsets or {}
        self.eval = CsvLog(run_dir / "eval.csv", EVAL_COLUMNS, offsets.get("eval"))
        self.train = CsvLog(run_dir / "train.csv", TRAIN_COLUMNS + list(metric_names), offsets.get("train"))
        self.echo = echo

    def offsets(self) -> dict[str, int]:
        return {"eval": self.eval.offset(), "train": self.train.offset()}

    def log_eval(self, row: dict[str, Any]) -> None:
        self.eval.write(row)
        success = "" if row.get("success") is None else f"  success {row['success']:.2f}"
        self.echo(f"eval  frame {row['frame']:>9}  return {row['episode_reward']:8.2f}"
                  f" ± {row['episode_reward_std']:.2f}{success}")

    def log_train(self, row: dict[str, Any]) -> None:
        self.train.write(row)

    def close(self) -> None:
        self.eval.close()
        self.train.close()
