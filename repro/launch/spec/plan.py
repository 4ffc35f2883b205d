"""Planning: compose each run's config, pin one absolute results root, find each run directory and its state."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig

from repro.config.compose import ConfigError, compose, identity
from repro.launch.spec.errors import SweepError
from repro.launch.spec.grid import Run
from repro.launch.spec.overrides import hydra_quote, merge_overrides
from repro.launch.waiting import DatasetNeed, dataset_need, missing_reason
from repro.runs.migrate import Diff
from repro.runs.rundir import config_diff, run_budget, run_dir, run_state


@dataclass
class PlannedRun:
    """A run with its composed config, run directory and current state."""

    run: Run
    cfg: DictConfig
    run_dir: Path
    results_root: Path
    state: str  # done | partial | extend (done at a smaller budget) | absent | mismatch
    diff: list[Diff] = field(default_factory=list)
    need: DatasetNeed | None = None  # the dataset an offline run reads
    waiting: str | None = None  # why a not-done run cannot start yet (its dataset is not complete), or None

    @property
    def key(self) -> str:
        """Stable file-name-safe id of the run within its results root."""
        return run_key(self.run_dir, self.results_root)

    @property
    def overrides(self) -> tuple[str, ...]:
        return self.run.overrides

    @property
    def budget(self) -> int:
        """The run's budget in this sweep (frames online, updates offline): it is done when it has reached it."""
        return run_budget(self.cfg)


def run_key(run_dir: Path, results_root: Path) -> str:
    return "__".join(Path(os.path.relpath(run_dir, results_root)).parts)


def _composer(composer: Composer | None) -> Composer:
    """``composer`` (default :func:`compose`) with ConfigError as one-line SweepError."""
    def run(overrides: Sequence[str]) -> DictConfig:
        try:
            return (composer or compose)(list(overrides))
        except ConfigError as exc:
            raise SweepError(str(exc).strip().splitlines()[0]) from None

    return run


def _with_seed(cfg: DictConfig, seed: int) -> DictConfig:
    out = cfg.copy()
    out.seed = seed
    return out


Composer = Callable[[Sequence[str]], DictConfig]


def compose_runs(runs: Sequence[Run], composer: Composer | None = None) -> list[DictConfig]:
    """Composed configs of ``runs`` (by ``composer``, default :func:`repro.config.compose.compose`: e.g. one that
    keeps its results, given a fresh config for each call).

    Composing is slow (~0.3 s), so runs that differ only by seed share one composition when a check
    on the first cell shows the seed feeds nothing else in the config."""
    _compose = _composer(composer)
    configs: list[DictConfig] = []
    by_cell: dict[tuple[str, str, str, str | None], tuple[Run, DictConfig]] = {}
    seed_is_plain: bool | None = None
    for run in runs:
        cached = by_cell.get(run.cell)
        same_rest = cached is not None and cached[0].overrides == tuple(
            f"seed={cached[0].seed}" if o == f"seed={run.seed}" else o for o in run.overrides)
        if cached is not None and same_rest and seed_is_plain is None:
            full = _compose(run.overrides)
            seed_is_plain = identity(full) == identity(_with_seed(cached[1], run.seed))
            configs.append(full)
            continue
        if cached is not None and same_rest and seed_is_plain:
            configs.append(_with_seed(cached[1], run.seed))
            continue
        cfg = _compose(run.overrides)
        by_cell.setdefault(run.cell, (run, cfg))
        configs.append(cfg)
    return configs


def plan(runs: Sequence[Run], composer: Composer | None = None) -> list[PlannedRun]:
    """Compose every run (see :func:`compose_runs`), pin an absolute results root, and read each run directory's
    state and whether an offline run's dataset is complete (``waiting`` says why not)."""
    planned: list[PlannedRun] = []
    reasons: dict[DatasetNeed, str | None] = {}
    for run, cfg in zip(runs, compose_runs(runs, composer)):
        root = Path(str(cfg.runtime.results_root)).expanduser().absolute()
        if str(root) != str(cfg.runtime.results_root):
            cfg.runtime.results_root = str(root)
        overrides = merge_overrides(run.overrides, [f"runtime.results_root={hydra_quote(str(root))}"])
        run = Run(run.agent, run.variant, run.task, run.seed, overrides, run.dataset)
        path = run_dir(cfg)
        state = run_state(path, run_budget(cfg))
        if state == "partial" and run_state(path) == "done":
            state = "extend"  # done at a smaller budget: a start continues it from its checkpoint
        diff = config_diff(path, cfg) if state != "absent" else []
        need = dataset_need(cfg)
        if need is not None and need not in reasons:
            reasons[need] = missing_reason(need)
        waiting = reasons[need] if need is not None and state != "done" else None
        planned.append(PlannedRun(run, cfg, path, root, "mismatch" if diff else state, diff, need, waiting))
    return planned


def results_root_of(planned: Sequence[PlannedRun]) -> Path:
    roots = {p.results_root for p in planned}
    if len(roots) != 1:
        raise SweepError(f"the runs of one sweep must share one results root (got {len(roots)}).")
    return roots.pop()
