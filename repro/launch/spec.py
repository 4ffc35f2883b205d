"""Sweep definitions: load and validate a sweep YAML, expand its grid into runs, resolve run dirs.

A sweep file (``sweeps/NAME.yaml``, documented in docs/sweeps.md) declares tasks, agents, variants
(name -> config overrides), seeds, frame budget and evaluation schedule. ``expand`` turns it into one
``Run`` per (agent, variant, task, seed); ``plan`` composes each run's config with the packaged Hydra
config and finds its run directory and state.
"""

from __future__ import annotations

import difflib
import itertools
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import yaml
from omegaconf import DictConfig

ENV_SWEEPS_DIR = "REPRO_SWEEPS_DIR"
NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")
FIELDS = {"name", "description", "artifacts", "experiment", "tasks", "agents", "seeds", "frames", "eval",
          "common", "variants", "product", "exclude"}
EXCLUDE_FIELDS = {"agents", "variants", "tasks", "reason"}
REQUIRED = {"name", "description", "artifacts", "tasks", "agents", "seeds", "frames", "eval", "variants"}


class SweepError(ValueError):
    """A user-facing problem with a sweep, explained in one line (the CLI exits 2)."""


def close_matches(name: str, options: Iterable[str]) -> str:
    """`` Did you mean: a, b?`` or `` Known: ...`` for an error line."""
    options = sorted(set(options))
    matches = difflib.get_close_matches(name, options, n=3, cutoff=0.5)
    if matches:
        return f" Did you mean: {', '.join(matches)}?"
    return f" Known: {', '.join(options)}." if options else ""


def sweeps_dir() -> Path:
    """Folder of the packaged sweep files (``$REPRO_SWEEPS_DIR`` overrides it)."""
    if os.environ.get(ENV_SWEEPS_DIR):
        return Path(os.environ[ENV_SWEEPS_DIR])
    return Path(__file__).resolve().parents[2] / "sweeps"


def sweep_names() -> list[str]:
    return sorted(p.stem for p in sweeps_dir().glob("*.yaml"))


def override_key(override: str) -> str:
    """The config key an override sets (``+a.b=1`` -> ``a.b``)."""
    return override.partition("=")[0].lstrip("+~")


def override_value(override: str) -> str:
    return override.partition("=")[2]


def hydra_quote(value: str) -> str:
    """A value as Hydra override syntax: bare when simple, else single-quoted."""
    if re.match(r"^[A-Za-z0-9_./\-]+$", value):
        return value
    return "'" + value.replace("\\", "\\\\").replace("'", "\\'") + "'"


def merge_overrides(*groups: Iterable[str]) -> tuple[str, ...]:
    """Concatenate override lists; a later override of the same key replaces an earlier one."""
    merged: dict[str, str] = {}
    for group in groups:
        for ov in group:
            key = override_key(ov)
            merged.pop(key, None)
            merged[key] = ov
    return tuple(merged.values())


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file."""

    name: str
    description: str
    artifacts: tuple[str, ...]
    experiment: str
    tasks: tuple[str, ...]
    agents: tuple[str, ...]
    seeds: tuple[int, ...]
    frames: int | None
    eval_every_frames: int | None
    eval_episodes: int | None
    common: tuple[str, ...]
    variants: dict[str, tuple[str, ...]]
    path: Path
    exclude: tuple["Exclusion", ...] = ()

    def budget_overrides(self) -> tuple[str, ...]:
        """Frame budget and evaluation schedule as overrides (fields left null are not set)."""
        out = []
        if self.frames is not None:
            out.append(f"train.frames={self.frames}")
        if self.eval_every_frames is not None:
            out.append(f"train.eval_every_frames={self.eval_every_frames}")
        if self.eval_episodes is not None:
            out.append(f"train.eval_episodes={self.eval_episodes}")
        return tuple(out)


@dataclass(frozen=True)
class Exclusion:
    """Grid cells a sweep does not run (shown as n/a), e.g. DRIML where K=1 (there it equals TACO).

    An empty ``agents``/``variants``/``tasks`` matches every value of that axis.
    """

    agents: tuple[str, ...]
    variants: tuple[str, ...]
    tasks: tuple[str, ...]
    reason: str

    def matches(self, agent: str, variant: str, task: str) -> bool:
        return ((not self.agents or agent in self.agents) and (not self.variants or variant in self.variants)
                and (not self.tasks or task in self.tasks))


def _exclusions(data: dict, path: Path) -> tuple[Exclusion, ...]:
    raw = data.get("exclude") or []
    if not isinstance(raw, list):
        raise SweepError(f"{path}: 'exclude' must be a list of mappings.")
    out = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict) or set(item) - EXCLUDE_FIELDS or "reason" not in item:
            raise SweepError(f"{path}: exclude[{i}] must be a mapping of agents/variants/tasks lists and a reason.")
        lists = {k: _str_list(item, k, path) if k in item else () for k in ("agents", "variants", "tasks")}
        out.append(Exclusion(reason=str(item["reason"]), **lists))
    return tuple(out)


def excluded(spec: SweepSpec, sel: "Selection | None" = None) -> list[tuple[str, str, str, str]]:
    """(agent, variant, task, reason) of every cell the sweep leaves out."""
    tasks = tuple(sel.tasks) if sel and sel.tasks else spec.tasks
    cells = []
    for vname, vovers in spec.variants.items():
        named = {override_key(o): override_value(o) for o in vovers}
        variant = named.get("variant", vname)
        for agent in ((named["agent"],) if "agent" in named else spec.agents):
            for task in tasks:
                for ex in spec.exclude:
                    if ex.matches(agent, variant, task):
                        cells.append((agent, variant, task, ex.reason))
                        break
    return cells


@dataclass(frozen=True)
class Run:
    """One cell of a sweep's grid, before its config is composed."""

    agent: str
    variant: str
    task: str
    seed: int
    overrides: tuple[str, ...]

    @property
    def cell(self) -> tuple[str, str, str]:
        return (self.agent, self.variant, self.task)


@dataclass
class PlannedRun:
    """A run with its composed config, run directory and current state."""

    run: Run
    cfg: DictConfig
    run_dir: Path
    results_root: Path
    state: str  # done | partial | absent | mismatch
    diff: list[str] = field(default_factory=list)

    @property
    def key(self) -> str:
        """Stable file-name-safe id of the run within its results root."""
        return run_key(self.run_dir, self.results_root)

    @property
    def overrides(self) -> tuple[str, ...]:
        return self.run.overrides


def run_key(run_dir: Path, results_root: Path) -> str:
    return "__".join(Path(os.path.relpath(run_dir, results_root)).parts)


# --------------------------------------------------------------------------------------------- loading

def _str_list(data: dict, key: str, path: Path) -> tuple[str, ...]:
    value = data.get(key) or []
    if isinstance(value, str) or not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise SweepError(f"{path}: '{key}' must be a list of strings.")
    return tuple(value)


def _overrides(value: Any, where: str, path: Path) -> tuple[str, ...]:
    if value is None:
        return ()
    if not isinstance(value, list) or not all(isinstance(v, str) and "=" in v for v in value):
        raise SweepError(f"{path}: {where} must be a list of key=value overrides.")
    return tuple(value)


def _optional_int(value: Any, where: str, path: Path) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise SweepError(f"{path}: {where} must be a positive integer or null.")
    return value


def _variants(data: dict, path: Path) -> dict[str, tuple[str, ...]]:
    raw = data.get("variants") or {}
    if not isinstance(raw, dict):
        raise SweepError(f"{path}: 'variants' must map a variant name to a list of overrides.")
    variants = {str(k): _overrides(v, f"variant '{k}'", path) for k, v in raw.items()}
    axes = data.get("product") or []
    if not isinstance(axes, list) or not all(isinstance(a, dict) and a for a in axes):
        raise SweepError(f"{path}: 'product' must be a list of axes (each a mapping name -> overrides).")
    if axes:
        for combo in itertools.product(*[list(a.items()) for a in axes]):
            name = "_".join(str(n) for n, _ in combo)
            if name in variants:
                raise SweepError(f"{path}: variant '{name}' is defined twice.")
            variants[name] = merge_overrides(*[_overrides(ov, f"axis value '{n}'", path) for n, ov in combo])
    if not variants:
        raise SweepError(f"{path}: no variants.")
    for name in variants:
        if not NAME_RE.match(name):
            raise SweepError(f"{path}: variant name '{name}' may only use letters, digits, '_', '.', '-'.")
    return variants


def load_file(path: Path) -> SweepSpec:
    """Parse and validate one sweep file."""
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise SweepError(f"cannot read sweep file {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict):
        raise SweepError(f"{path}: a sweep file is a mapping.")
    unknown = set(data) - FIELDS
    if unknown:
        first = sorted(unknown)[0]
        raise SweepError(f"{path}: unknown field '{first}'." + close_matches(first, FIELDS))
    missing = REQUIRED - set(data)
    if missing:
        raise SweepError(f"{path}: missing field(s) {', '.join(sorted(missing))}.")
    name = str(data["name"])
    if not NAME_RE.match(name):
        raise SweepError(f"{path}: name '{name}' may only use letters, digits, '_', '.', '-'.")
    seeds_raw = data["seeds"]
    if isinstance(seeds_raw, int) and not isinstance(seeds_raw, bool) and seeds_raw >= 1:
        seeds = tuple(range(1, seeds_raw + 1))
    elif isinstance(seeds_raw, list) and seeds_raw and all(isinstance(s, int) for s in seeds_raw):
        seeds = tuple(seeds_raw)
    else:
        raise SweepError(f"{path}: 'seeds' must be a count N (seeds 1..N) or a list of integers.")
    ev = data["eval"] or {}
    if not isinstance(ev, dict) or set(ev) - {"every_frames", "episodes"}:
        raise SweepError(f"{path}: 'eval' must have only every_frames and episodes.")
    episodes = ev.get("episodes")
    if episodes is not None and (not isinstance(episodes, int) or episodes < 0):
        raise SweepError(f"{path}: eval.episodes must be a non-negative integer or null.")
    tasks = _str_list(data, "tasks", path)
    agents = _str_list(data, "agents", path)
    if not tasks or not agents:
        raise SweepError(f"{path}: 'tasks' and 'agents' must not be empty.")
    return SweepSpec(
        name=name, description=" ".join(str(data["description"]).split()),
        artifacts=_str_list(data, "artifacts", path), experiment=str(data.get("experiment") or name),
        tasks=tasks, agents=agents, seeds=seeds,
        frames=_optional_int(data["frames"], "'frames'", path),
        eval_every_frames=_optional_int(ev.get("every_frames"), "eval.every_frames", path),
        eval_episodes=episodes, common=_overrides(data.get("common"), "'common'", path),
        variants=_variants(data, path), path=path, exclude=_exclusions(data, path))


def load(name: str) -> SweepSpec:
    """A packaged sweep by name, or a sweep file by path (``*.yaml``)."""
    if name.endswith((".yaml", ".yml")) or os.sep in name:
        path = Path(name)
        if not path.exists():
            raise SweepError(f"sweep file {name} does not exist.")
        return load_file(path)
    path = sweeps_dir() / f"{name}.yaml"
    if not path.exists():
        raise SweepError(f"unknown sweep '{name}'." + close_matches(name, sweep_names()))
    spec = load_file(path)
    if spec.name != name:
        raise SweepError(f"{path}: name '{spec.name}' differs from the file name '{name}'.")
    return spec


def load_all() -> list[SweepSpec]:
    return [load(n) for n in sweep_names()]


# ------------------------------------------------------------------------------------- config groups

def config_groups() -> dict[str, list[str]]:
    """Config group name -> option names of the packaged Hydra config."""
    from repro.config import CONF_DIR

    return {d.name: sorted(p.stem for p in d.glob("*.yaml")) for d in sorted(CONF_DIR.iterdir()) if d.is_dir()}


def missing_options(spec: SweepSpec) -> dict[str, list[str]]:
    """Group -> options the sweep selects that the packaged config does not have (e.g. an agent
    nobody has written yet). Empty when the sweep can run."""
    groups = config_groups()
    wanted: list[tuple[str, str]] = [("agent", a) for a in spec.agents]
    for ov in itertools.chain(spec.common, *spec.variants.values()):
        key = override_key(ov)
        if key in groups and not ov.startswith("~"):
            wanted.append((key, override_value(ov)))
    missing: dict[str, list[str]] = {}
    for group, option in wanted:
        if option not in groups.get(group, []) and option not in missing.get(group, []):
            missing.setdefault(group, []).append(option)
    return missing


def unavailable_reason(spec: SweepSpec) -> str | None:
    """One line saying why the sweep cannot run yet, or None."""
    missing = missing_options(spec)
    if not missing:
        return None
    parts = [f"{group} {', '.join(opts)}" for group, opts in missing.items()]
    return (f"sweep '{spec.name}' cannot run yet: {'; '.join(parts)} not in the packaged config "
            f"(repro/conf/{'|'.join(missing)}/); it is declared for {', '.join(spec.artifacts)}.")


# ------------------------------------------------------------------------------------------ expansion

@dataclass(frozen=True)
class Selection:
    """Command-line choices that narrow or change a sweep's grid."""

    tasks: tuple[str, ...] | None = None
    seeds: int | None = None
    frames: int | None = None
    sets: tuple[str, ...] = ()


def check_tasks(tasks: Sequence[str]) -> None:
    known = config_groups().get("task", [])
    for task in tasks:
        if task not in known:
            raise SweepError(f"unknown task '{task}'." + close_matches(task, known))


def check_sets(sets: Sequence[str]) -> None:
    groups = config_groups()
    for ov in sets:
        if "=" not in ov:
            raise SweepError(f"--set '{ov}' is not key=value.")
        key = override_key(ov)
        if key in groups and override_value(ov) not in groups[key]:
            value = override_value(ov)
            raise SweepError(f"unknown {key} '{value}' in --set {ov}." + close_matches(value, groups[key]))


def expand(spec: SweepSpec, sel: Selection = Selection()) -> list[Run]:
    """The sweep's grid: one Run per (agent, variant, task, seed), in a stable order.

    Override order (a later one wins for the same key): identity (experiment, agent, task, seed,
    variant), the sweep's budget and eval schedule, ``common``, the variant's overrides, ``--set``,
    ``--frames``. ``agent=`` or ``variant=`` inside a variant replace the defaults. When ``--set``
    or ``common`` selects a ``profile``, the sweep's budget is left to the profile (``--frames`` still
    applies).
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
    seen: dict[tuple[str, str, str, int], str] = {}
    for vname, vovers in spec.variants.items():
        named = {override_key(o): override_value(o) for o in vovers}
        agents = (named["agent"],) if "agent" in named else spec.agents
        variant = named.get("variant", vname)
        for agent in agents:
            for task in tasks:
                if any(ex.matches(agent, variant, task) for ex in spec.exclude):
                    continue
                for seed in seeds:
                    identity = (f"experiment={spec.experiment}", f"agent={agent}", f"task={task}",
                                f"seed={seed}", f"variant={variant}")
                    overrides = merge_overrides(identity, budget, spec.common, vovers, sel.sets, extra)
                    where = (agent, variant, task, seed)
                    if where in seen:
                        raise SweepError(f"{spec.path}: variants '{seen[where]}' and '{vname}' give the same "
                                         f"run directory ({agent}/{variant}).")
                    seen[where] = vname
                    runs.append(Run(agent, variant, task, seed, overrides))
    return runs


# ---------------------------------------------------------------------------------------- planning

def _compose(overrides: Sequence[str]) -> DictConfig:
    from repro.config import ConfigError, compose

    try:
        return compose(list(overrides))
    except ConfigError as exc:
        raise SweepError(str(exc).strip().splitlines()[0]) from None


def _with_seed(cfg: DictConfig, seed: int) -> DictConfig:
    out = cfg.copy()
    out.seed = seed
    return out


def compose_runs(runs: Sequence[Run]) -> list[DictConfig]:
    """Composed configs of ``runs``.

    Composing is slow (~0.3 s), so runs that differ only by seed share one composition when a check
    on the first cell shows the seed feeds nothing else in the config."""
    from repro.config import identity

    configs: list[DictConfig] = []
    by_cell: dict[tuple[str, str, str], tuple[Run, DictConfig]] = {}
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


def plan(runs: Sequence[Run]) -> list[PlannedRun]:
    """Compose every run, pin an absolute results root, and read each run directory's state."""
    from repro.rundir import config_diff, run_dir, run_state

    planned: list[PlannedRun] = []
    for run, cfg in zip(runs, compose_runs(runs)):
        root = Path(str(cfg.runtime.results_root)).expanduser().absolute()
        if str(root) != str(cfg.runtime.results_root):
            cfg.runtime.results_root = str(root)
        overrides = merge_overrides(run.overrides, [f"runtime.results_root={hydra_quote(str(root))}"])
        run = Run(run.agent, run.variant, run.task, run.seed, overrides)
        path = run_dir(cfg)
        state = run_state(path)
        diff = config_diff(path, cfg) if state != "absent" else []
        planned.append(PlannedRun(run, cfg, path, root, "mismatch" if diff else state, diff))
    return planned


def results_root_of(planned: Sequence[PlannedRun]) -> Path:
    roots = {p.results_root for p in planned}
    if len(roots) != 1:
        raise SweepError(f"the runs of one sweep must share one results root (got {len(roots)}).")
    return roots.pop()
