"""A run's actor health, read from its train.csv: the one rule ``repro train``, ``repro status``, ``repro verify`` and
the report share for "this seed's actor has died".

Every actor update logs ``actor_saturated`` (the share of the batch's action-mean entries whose tanh is exactly +-1 in
float32) and ``actor_pretanh`` (the mean |pre-tanh|) in its episode's train.csv row (repro/agent/losses.py). Where the
tanh is exactly +-1 its gradient is exactly zero: the actor cannot move by its own loss, only by a drift of the
encoder's features (DrQ-v2's actor trains on detached features, its trunk does not). The rule:

    a run's actor is *saturated* when its last train.csv rows with updates, over at least ``SATURATED_FRAMES``
    environment frames without a break, all have ``actor_saturated >= SATURATED_SHARE``;

it is reported as "actor saturated since frame N: its policy gradient is zero", N the first frame of the stretch.
A shorter stretch at the end is reported too, as what it is so far ("actor at the bound since frame N: F of the 10,000
frames that make it saturated"), so that no table calls an actor at the bound on every state "not saturated".
A stretch of 10K frames is 10 episodes of cartpole_balance and 20% of the published curves' first 50K frames: at
130 frames/s (the paper's DrQ-v2 on an A100) a GPU user reads it about a minute and a half after it starts. It says
what the gradient is, not that the seed cannot recover: two of the ten published DrQ-v2 seeds on cartpole_balance sit
at 135 at 20K frames and recover by 40K (docs/verification.md).
"""

from __future__ import annotations

import csv
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from repro.runs.runformat import TRAIN

SATURATED_SHARE = 0.99  # "nearly every state": at least this share of action-mean entries exactly at +-1
SATURATED_FRAMES = 10_000  # the stretch of environment frames the share must hold over
COLUMNS = ("frame", "episode_length", "actor_saturated")  # what the rule reads from train.csv


@dataclass(frozen=True)
class Saturation:
    """A stretch of saturated rows at the end of a run's train.csv."""

    since: int  # the first environment frame of the stretch (the start of its first episode)
    until: int  # the last row's frame
    share: float  # the last row's actor_saturated
    min_frames: int = SATURATED_FRAMES  # the length that makes the stretch saturated

    @property
    def frames(self) -> int:
        return self.until - self.since

    @property
    def saturated(self) -> bool:
        """The rule holds: the stretch spans at least ``min_frames``."""
        return self.frames >= self.min_frames

    def message(self) -> str:
        if self.saturated:
            return f"actor saturated since frame {self.since:,}: its policy gradient is zero"
        return (f"actor at the bound since frame {self.since:,}: {self.frames:,} of the {self.min_frames:,} frames "
                "that make it saturated")


@dataclass(frozen=True)
class Row:
    """What the rule reads of one train.csv row: its frame, its episode's length in frames and its share (NaN
    for an episode without updates)."""

    frame: int
    length: int
    share: float


class Watch:
    """The rule over rows in the order a run writes them, one row at a time: :meth:`add` returns the saturation the
    first time a stretch reaches the length (once per stretch; a recovery and a new stretch report again);
    :attr:`stretch` is the stretch ending at the last row with updates, of any length, and :attr:`current` the same
    once long enough. A row without updates (NaN share) neither extends nor breaks a stretch."""

    def __init__(self, min_share: float = SATURATED_SHARE, min_frames: int = SATURATED_FRAMES):
        self.min_share, self.min_frames = min_share, min_frames
        self.stretch: Saturation | None = None
        self._since: int | None = None  # the first frame of the stretch of saturated rows ending at the last one
        self._said: int | None = None  # the ``since`` of the stretch already reported

    def add(self, row: Row) -> Saturation | None:
        if math.isnan(row.share):
            return None
        if row.share < self.min_share:
            self._since, self.stretch = None, None
            return None
        if self._since is None:
            self._since = row.frame - row.length
        self.stretch = Saturation(since=self._since, until=row.frame, share=row.share, min_frames=self.min_frames)
        found = self.current
        if found is None or found.since == self._said:
            return None
        self._said = found.since
        return found

    @property
    def current(self) -> Saturation | None:
        """:attr:`stretch` once the rule holds for it, else None."""
        return self.stretch if self.stretch is not None and self.stretch.saturated else None

    def extend(self, rows: Iterable[Row]) -> None:
        """Rows already written (a resumed run): remembered, a stretch among them not reported again."""
        for row in rows:
            self.add(row)


def saturation(rows: Iterable[Row], min_share: float = SATURATED_SHARE,
               min_frames: int = SATURATED_FRAMES) -> Saturation | None:
    """The saturated stretch ending at the last row with updates, when it spans at least ``min_frames``; None
    otherwise (also for a run that has logged no update yet)."""
    found = at_bound(rows, min_share, min_frames)
    return found if found is not None and found.saturated else None


def at_bound(rows: Iterable[Row], min_share: float = SATURATED_SHARE,
             min_frames: int = SATURATED_FRAMES) -> Saturation | None:
    """The stretch at the bound ending at the last row with updates, of any length (its ``saturated`` says whether
    the rule holds yet); None when the last row with updates is under ``min_share`` or there is none."""
    watch = Watch(min_share, min_frames)
    watch.extend(rows)
    return watch.stretch


def _number(text: str | None) -> float:
    try:
        return float(text) if text not in (None, "") else math.nan
    except ValueError:
        return math.nan


def row_of(values: dict[str, object]) -> Row:
    """A :class:`Row` from a train.csv row (strings from the file, or the numbers a run writes)."""
    def num(key: str) -> float:
        v = values.get(key)
        return math.nan if v is None else _number(str(v))

    frame, length = num("frame"), num("episode_length")
    return Row(int(frame) if not math.isnan(frame) else 0, int(length) if not math.isnan(length) else 0,
               num("actor_saturated"))


def read_rows(run_dir: str | os.PathLike[str]) -> list[Row]:
    """The rule's rows of ``run_dir``'s train.csv; empty when the file is missing, unreadable or has no
    ``actor_saturated`` column (a run logged before issue 49, or a learner without an actor)."""
    try:
        with open(Path(run_dir) / TRAIN, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            if not reader.fieldnames or "actor_saturated" not in reader.fieldnames:
                return []
            return [row_of(r) for r in reader if r.get("frame")]
    except (OSError, UnicodeDecodeError, csv.Error):
        return []


def read_at_bound(run_dir: str | os.PathLike[str]) -> Saturation | None:
    """:func:`at_bound` of ``run_dir``'s train.csv: the stretch at the bound at its end, saturated or not yet."""
    return at_bound(read_rows(run_dir))
