"""The progress bar of a run in a terminal (``runtime.progress``): frames (offline: updates), their rate, the last
evaluation's return and the time left."""

from __future__ import annotations

import sys
import time
from typing import Any

from repro.config.schema import RunConfig


class ProgressBar:
    """A rich progress bar: frames (offline: updates), their rate, last eval return, ETA."""

    def __init__(self, total_frames: int, start_frame: int, label: str, unit: str = "fps"):
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
            TimeRemainingColumn,
        )

        self._p = Progress(TextColumn("[bold]{task.description}"), BarColumn(), MofNCompleteColumn(),
                           TextColumn(f"{{task.fields[fps]}} {unit}"), TextColumn("eval {task.fields[ret]}"),
                           TimeElapsedColumn(), TimeRemainingColumn(), transient=False)
        self._p.start()
        self._task = self._p.add_task(label, total=total_frames, completed=start_frame, fps="-", ret="-")
        self._t, self._f = time.time(), start_frame

    def update(self, frame: int, last_eval: float | None) -> None:
        now = time.time()
        fps = (frame - self._f) / max(now - self._t, 1e-9)
        fields: dict[str, Any] = {"ret": f"{last_eval:.1f}" if last_eval is not None else "-"}
        if now - self._t > 2.0:
            fields["fps"] = f"{fps:.0f}"
            self._t, self._f = now, frame
        self._p.update(self._task, completed=frame, **fields)

    def close(self) -> None:
        self._p.stop()


def progress_bar(rc: RunConfig, forced: bool | None, total: int | None = None,
                 unit: str = "fps") -> ProgressBar | None:
    """The run's bar, or None when off: ``forced`` (the caller's choice) over ``runtime.progress`` (``auto``: when
    stderr is a terminal); ``total`` defaults to ``train.frames``."""
    setting = rc.runtime.progress if forced is None else forced
    enabled = sys.stderr.isatty() if setting == "auto" else bool(setting)
    if not enabled:
        return None
    return ProgressBar(rc.train.frames if total is None else total, 0, f"{rc.agent.name} {rc.task.name} s{rc.seed}",
                       unit=unit)
