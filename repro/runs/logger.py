"""Append-only CSV logs whose byte offsets are stored in checkpoints, so a resume truncates them exactly."""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from repro.runs import health
from repro.runs.fsutil import atomic_write_text, named_os_error
from repro.runs.runformat import EVAL, EVAL_COLUMNS, TRAIN, TRAIN_COLUMNS, WALLCLOCK_COLUMNS, train_columns
from repro.runs.tblog import TensorBoardMirror
from repro.runs.wblog import WandbMirror, WandbRun

__all__ = ["CsvLog", "RunLogger", "format_row", "header_line", "EVAL_COLUMNS", "TRAIN_COLUMNS", "WALLCLOCK_COLUMNS"]


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, float):
        return "" if math.isnan(value) else repr(value)
    return str(value)


def header_line(columns: Sequence[str]) -> str:
    """The header line (with its newline) of a CSV log with these columns."""
    return ",".join(columns) + "\n"


def format_row(columns: Sequence[str], row: dict[str, Any]) -> str:
    """One CSV line (with its newline) of ``row`` under the header ``columns``: None and NaN empty, bools 0/1,
    floats in full precision (repr)."""
    unknown = set(row) - set(columns)
    if unknown:
        raise KeyError(f"unknown columns {sorted(unknown)}")
    return ",".join(_fmt(row.get(c)) for c in columns) + "\n"


def widen_rows(path: Path, text: str, columns: Sequence[str]) -> None:
    """Write ``text`` (a CSV log's header and rows) to ``path`` atomically under the header ``columns``, each row's
    cell moved to its column and the columns it lacks left empty. Raises ValueError when the old header names a
    column ``columns`` lacks (another learner's log: nothing is written)."""
    lines = text.splitlines()
    old = lines[0].split(",") if lines else []
    missing = [c for c in old if c not in columns]
    if missing:
        raise ValueError(f"{path}: header differs from the run's columns (it has {', '.join(missing)})")
    out = [header_line(columns)]
    for line in lines[1:]:
        cells = dict(zip(old, line.split(",")))
        out.append(",".join(cells.get(c, "") for c in columns) + "\n")
    atomic_write_text(path, "".join(out))


class CsvLog:
    """One CSV file with a fixed header; each row is flushed and fsynced as soon as it is written."""

    def __init__(self, path: str | os.PathLike, columns: Sequence[str], offset: int | None = None):
        """Open ``path`` for appending. ``offset`` (from a checkpoint) truncates rows written after it;
        ``None`` starts the file afresh. A file written with fewer columns (a run logged before a metric was added,
        resumed or extended today) is rewritten once with today's header, its rows' new cells empty."""
        self.path = Path(path)
        self.columns = list(columns)
        header = header_line(self.columns)
        if offset is None or not self.path.exists():
            self.path.write_text(header)
        else:
            with open(self.path, "r+b") as f:
                existing = f.readline().decode()
                if existing != header:
                    f.seek(0)
                    kept = f.read(max(offset, len(existing.encode()))).decode()
                    widen_rows(self.path, kept, self.columns)
                else:
                    f.truncate(max(offset, len(header.encode())))
        self._f = open(self.path, "ab")

    def write(self, row: dict[str, Any]) -> None:
        try:
            line = format_row(self.columns, row)
        except KeyError as exc:
            raise KeyError(f"{self.path.name}: {exc.args[0]}") from None
        try:
            self._f.write(line.encode())
            self._f.flush()
            os.fsync(self._f.fileno())
        except OSError as exc:  # a full disk: a torn row is cut again by the resume's truncation
            raise named_os_error(exc, self.path) from None

    def offset(self) -> int:
        return self._f.tell()

    def close(self) -> None:
        self._f.close()


class CsvPairLogger:
    """A run's ``eval.csv`` and ``train.csv`` (opened at the checkpoint's offsets) and their mirrors at
    ``step_column``: with ``tensorboard`` (runtime.tensorboard), TensorBoard scalars (repro/runs/tblog.py); with
    ``wandb`` (runtime.wandb), a W&B run (repro/runs/wblog.py). Both are rebuilt from the CSVs once they are
    truncated to the checkpoint (a resume, a requeued job, a budget extension), so a resumed run never holds a
    point twice. Subclasses say what an evaluation prints."""

    def __init__(self, run_dir: str | os.PathLike, eval_columns: Sequence[str], train_cols: Sequence[str],
                 offsets: dict[str, int] | None, echo: Callable[[str], None], tensorboard: bool, step_column: str,
                 wandb: WandbRun | None = None):
        run_dir = Path(run_dir)
        offsets = offsets or {}
        self.eval = CsvLog(run_dir / EVAL, eval_columns, offsets.get("eval"))
        self.train = CsvLog(run_dir / TRAIN, train_cols, offsets.get("train"))
        self.echo = echo
        files = {"eval": self.eval.path, "train": self.train.path}
        self.tb: TensorBoardMirror | None = None
        if tensorboard:
            self.tb = TensorBoardMirror(run_dir, step_column=step_column)
            self.tb.rebuild(files)
        self.wb: WandbMirror | None = None
        if wandb is not None:
            self.wb = WandbMirror(run_dir, wandb, step_column=step_column, echo=echo)
            self.wb.rebuild(files)

    def offsets(self) -> dict[str, int]:
        return {"eval": self.eval.offset(), "train": self.train.offset()}

    def _write_eval(self, row: dict[str, Any]) -> None:
        self._write("eval", self.eval, row)

    def log_train(self, row: dict[str, Any]) -> None:
        self._write("train", self.train, row)

    def _write(self, prefix: str, log: CsvLog, row: dict[str, Any]) -> None:
        log.write(row)  # the CSV first: the mirrors follow it
        if self.tb is not None:
            self.tb.add_row(prefix, row)
        if self.wb is not None:
            self.wb.add_row(prefix, row)

    def close(self, failing: bool = False) -> None:
        """Close the CSVs and the mirrors; ``failing``: the loop is ending with an exception, which a mirror's
        failure to close must not replace (the CSVs are closed first either way)."""
        self.eval.close()
        self.train.close()
        if self.tb is not None:
            self.tb.close()
        if self.wb is not None:
            self.wb.close(failing)


class RunLogger(CsvPairLogger):
    """The online run's logs: columns from repro.runs.runformat, TensorBoard and W&B step = frame. A train row that
    completes a stretch of a saturated actor (repro/runs/health.py) prints one warning line."""

    def __init__(self, run_dir: str | os.PathLike, metric_names: Sequence[str],
                 offsets: dict[str, int] | None = None, echo: Callable[[str], None] = print,
                 tensorboard: bool = False, wandb: WandbRun | None = None):
        super().__init__(run_dir, EVAL_COLUMNS, train_columns(metric_names), offsets, echo, tensorboard, "frame",
                         wandb)
        self.health = health.Watch()
        self.health.extend(health.read_rows(run_dir))  # the rows kept by a resume: a stretch there is not said again

    def log_train(self, row: dict[str, Any]) -> None:
        super().log_train(row)
        found = self.health.add(health.row_of(row))
        if found is not None:
            self.echo(f"warning: {found.message()} (actor_saturated {found.share:.2f} over the last "
                      f"{found.frames:,} frames; docs/watching.md)")

    def log_eval(self, row: dict[str, Any]) -> None:
        self._write_eval(row)
        success = "" if row.get("success") is None else f"  success {row['success']:.2f}"
        self.echo(f"eval  frame {row['frame']:>9}  return {row['episode_reward']:8.2f}"
                  f" ± {row['episode_reward_std']:.2f}{success}")
