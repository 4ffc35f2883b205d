"""What `repro bench` shows while it times: a rich progress bar over the settings it times (on a terminal), and the
machine's load recorded as each one is done (repro/bench/results.py ``machine_load``).

A bench of the paper's batch sizes takes minutes; each setting's line is printed as it is done (in a log too), and on
a terminal the bar says which setting is being timed, how many are done and for how long it has run.
"""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console


def _bar_console() -> Console:
    from repro.runs.console import console

    return console(stderr=True)


class Steps:
    """A progress bar of ``total`` settings on stderr (``enabled`` None: when stderr is a terminal); :meth:`item`
    times one."""

    def __init__(self, total: int, enabled: bool | None = None, console: Console | None = None) -> None:
        self._progress: Any = None
        if not (sys.stderr.isatty() if enabled is None else enabled) or total < 1:
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        # the lines printed meanwhile go above the bar when stdout is the same terminal, and to stdout (a log file)
        # as they are otherwise
        self._progress = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                                  TimeElapsedColumn(), console=console or _bar_console(), transient=True,
                                  redirect_stdout=sys.stdout.isatty())
        self._task = self._progress.add_task("repro bench", total=total)
        self._progress.start()

    @contextmanager
    def item(self, what: str) -> Iterator[None]:
        """Say that ``what`` is being timed; one step done when the block ends."""
        if self._progress is not None:
            self._progress.update(self._task, description=f"timing {what}", refresh=True)
        yield
        if self._progress is not None:
            self._progress.update(self._task, advance=1, refresh=True)

    def close(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None

    def __enter__(self) -> Steps:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
