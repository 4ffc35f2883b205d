"""Frames to train across sweeps that share run directories (issue 24).

A run's directory is named from its identity (experiment, agent, variant, task, dataset, seed), never from its
budget, so two sweeps that expand to the same directory at different ``train.frames`` share one run: the smaller
budget trains its prefix and the larger extends it (``repro train`` continues a done run from its checkpoint). Each
sweep then pays only the frames beyond what another sweep's smaller (or equal, earlier-named) budget trains.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from repro.launch.spec.grid import Run, expand
from repro.launch.spec.groups import unavailable_reason
from repro.launch.spec.overrides import override_key, override_value
from repro.launch.spec.sweepfile import SweepSpec


@dataclass(frozen=True)
class SweepFrames:
    """A sweep's online frames: its runs' budgets summed (``total``), and what it trains after sharing
    (``to_train``); ``shared_with`` names the sweeps whose runs it shares."""

    total: int
    to_train: int
    shared_with: tuple[str, ...]


def _last(run: Run, key: str) -> str | None:
    values = [override_value(o).strip("'\"") for o in run.overrides if override_key(o) == key]
    return values[-1] if values else None


def run_location(spec: SweepSpec, run: Run) -> tuple[str, str, str, str, str | None, int]:
    """The identity part of a run's directory: (experiment, agent, variant, task, dataset, seed)."""
    return (_last(run, "experiment") or spec.experiment, run.agent, run.variant, run.task, run.dataset, run.seed)


def run_frames(run: Run) -> int | None:
    """The frame budget a run's overrides set (None: an offline run, or the task's default budget)."""
    if run.dataset is not None:
        return None
    value = _last(run, "train.frames")
    return int(value) if value is not None and value.isdigit() else None


def split_budget(entries: Iterable[tuple[int, str]]) -> dict[str, int]:
    """The budgets that sweeps (by name) give one shared run directory -> what each sweep trains of it: the run is
    trained once, to the smaller budget and extended to the larger, so ordered by budget (then sweep name) each sweep
    pays its budget minus the largest before it; together they pay the largest budget. Also `repro plan`'s rule
    (repro/launch/cost.py)."""
    before = 0
    paid: dict[str, int] = defaultdict(int)
    for frames, name in sorted(entries):
        paid[name] += max(0, frames - before)
        before = max(before, frames)
    return dict(paid)


def shared_frames(specs: Sequence[SweepSpec]) -> dict[str, SweepFrames]:
    """Each available sweep's online frames, total and to train after sharing run directories with the others.
    A shared run is trained once: ordered by budget (then sweep name), each sweep pays its budget minus the largest
    budget before it."""
    budgets: dict[tuple, list[tuple[int, str]]] = defaultdict(list)
    for spec in specs:
        if unavailable_reason(spec):
            continue
        for run in expand(spec):
            frames = run_frames(run)
            if frames is not None:
                budgets[run_location(spec, run)].append((frames, spec.name))
    total: dict[str, int] = defaultdict(int)
    to_train: dict[str, int] = defaultdict(int)
    shared: dict[str, set[str]] = defaultdict(set)
    for entries in budgets.values():
        names = {name for _, name in entries}
        for frames, name in entries:
            total[name] += frames
            shared[name] |= names - {name}
        for name, paid in split_budget(entries).items():
            to_train[name] += paid
    return {name: SweepFrames(total[name], to_train[name], tuple(sorted(shared[name]))) for name in total}
