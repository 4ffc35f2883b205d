"""A sweep's grid: the command line's narrowing (Selection) and one Run per (agent, variant, task, seed)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from repro.launch.spec.errors import SweepError
from repro.launch.spec.groups import check_sets, check_tasks, unavailable_reason
from repro.launch.spec.overrides import hydra_quote, merge_overrides, override_key, override_value
from repro.launch.spec.sweepfile import SweepSpec


@dataclass(frozen=True)
class Selection:
    """Command-line choices that narrow or change a sweep's grid."""

    tasks: tuple[str, ...] | None = None
    seeds: int | None = None
    frames: int | None = None
    sets: tuple[str, ...] = ()


def selection(tasks: str | None = None, seeds: int | None = None, frames: int | None = None,
              sets: Sequence[str] | None = None, results_root: Path | None = None) -> Selection:
    """The Selection of the grid options ``repro sweep`` and ``repro plan`` share: ``--tasks`` (comma-separated),
    ``--seeds``, ``--frames``, ``--set`` (repeatable) and the results root (``runtime.results_root``, given once:
    SweepError when ``--set`` gives it too)."""
    task_list = tuple(t.strip() for t in tasks.split(",") if t.strip()) if tasks else None
    out = tuple(sets or ())
    if results_root is not None:
        if any(override_key(s) == "runtime.results_root" for s in out):
            raise SweepError("give the results root once: --results ROOT or --set runtime.results_root=ROOT, not "
                             "both.")
        out = (*out, f"runtime.results_root={hydra_quote(str(results_root.expanduser()))}")
    return Selection(tasks=task_list, seeds=seeds, frames=frames, sets=out)


@dataclass(frozen=True)
class Run:
    """One cell of a sweep's grid, before its config is composed."""

    agent: str
    variant: str
    task: str
    seed: int
    overrides: tuple[str, ...]
    dataset: str | None = None  # offline.dataset of an offline run (a run directory component)

    @property
    def cell(self) -> tuple[str, str, str, str | None]:
        return (self.agent, self.variant, self.task, self.dataset)


def _dataset_of(overrides: tuple[str, ...]) -> str | None:
    """The ``offline.dataset`` a run's overrides set (part of an offline run's directory), or None."""
    values = [override_value(o).strip("'\"") for o in overrides if override_key(o) == "offline.dataset"]
    return (values[-1] or None) if values else None


def excluded(spec: SweepSpec, sel: Selection | None = None) -> list[tuple[str, str, str, str]]:
    """(agent, variant, task, reason) of every cell the sweep leaves out."""
    tasks = tuple(sel.tasks) if sel and sel.tasks else spec.tasks
    cells = []
    for vname, vovers in spec.variants.items():
        named = {override_key(o): override_value(o) for o in vovers}
        variant = named.get("variant", vname)
        for agent in ((named["agent"],) if "agent" in named else spec.agents):
            for task in tasks:
                for ex in spec.exclude:
                    if ex.matches(agent, variant, task):  # cell-level exclusions only (no seeds named)
                        cells.append((agent, variant, task, ex.reason))
                        break
    return cells


def expand(spec: SweepSpec, sel: Selection = Selection()) -> list[Run]:
    """The sweep's grid: one Run per (agent, variant, task, seed), in a stable order.

    Override order (a later one wins for the same key): identity (experiment, agent, task, seed,
    variant; and ``runtime.sweep``, the sweep's name, which is not part of the run's identity), the sweep's
    budget and eval schedule, ``common``, the variant's overrides, ``--set``, ``--frames``. ``agent=`` or
    ``variant=`` inside a variant replace the defaults. When ``--set`` or ``common`` selects a ``profile``,
    the sweep's budget is left to the profile (``--frames`` still applies).
    """
    reason = unavailable_reason(spec)
    if reason:
        raise SweepError(reason)
    tasks = tuple(sel.tasks) if sel.tasks else spec.tasks
    check_tasks(tasks)
    check_sets(sel.sets)
    seeds = tuple(range(1, sel.seeds + 1)) if sel.seeds else spec.seeds
    uses_profile = any(override_key(o) == "profile" for o in itertools.chain(spec.common, sel.sets))
    budget = () if uses_profile else spec.budget_overrides()
    extra = (f"train.frames={sel.frames}",) if sel.frames else ()
    runs: list[Run] = []
    seen: dict[tuple[str, str, str, str | None, int], str] = {}
    for vname, vovers in spec.variants.items():
        named = {override_key(o): override_value(o) for o in vovers}
        agents = (named["agent"],) if "agent" in named else spec.agents
        variant = named.get("variant", vname)
        for agent in agents:
            for task in tasks:
                if any(ex.matches(agent, variant, task) for ex in spec.exclude):
                    continue
                for seed in seeds:
                    if any(ex.matches(agent, variant, task, seed) for ex in spec.exclude):
                        continue
                    identity = (f"experiment={spec.experiment}", f"agent={agent}", f"task={task}",
                                f"seed={seed}", f"variant={variant}", f"runtime.sweep={hydra_quote(spec.name)}")
                    overrides = merge_overrides(identity, budget, spec.common, vovers, sel.sets, extra)
                    dataset = _dataset_of(overrides)
                    where = (agent, variant, task, dataset, seed)
                    if where in seen:
                        raise SweepError(f"{spec.path}: variants '{seen[where]}' and '{vname}' give the same "
                                         f"run directory ({agent}/{variant}).")
                    seen[where] = vname
                    runs.append(Run(agent, variant, task, seed, overrides, dataset))
    return runs
