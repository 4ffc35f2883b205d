"""One sweep file (``sweeps/NAME.yaml``, documented in docs/sweeps.md): its fields, validated into a SweepSpec."""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from repro.config.compose import NAME_RE, close_matches
from repro.launch.spec.errors import SweepError
from repro.launch.spec.overrides import merge_overrides

FIELDS = {"name", "description", "artifacts", "experiment", "tasks", "agents", "seeds", "frames", "eval",
          "common", "variants", "product", "exclude"}
EXCLUDE_FIELDS = {"agents", "variants", "tasks", "seeds", "reason"}
REQUIRED = {"name", "description", "artifacts", "tasks", "agents", "seeds", "frames", "eval", "variants"}


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
    exclude: tuple[Exclusion, ...] = ()

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

    An empty ``agents``/``variants``/``tasks``/``seeds`` matches every value of that axis. An exclusion that
    names seeds leaves out those seeds' runs only: its cells still run with the other seeds.
    """

    agents: tuple[str, ...]
    variants: tuple[str, ...]
    tasks: tuple[str, ...]
    reason: str
    seeds: tuple[int, ...] = ()

    def matches(self, agent: str, variant: str, task: str, seed: int | None = None) -> bool:
        """Whether the cell (``seed`` None) or the run (a seed) is left out."""
        if self.seeds and (seed is None or seed not in self.seeds):
            return False
        return ((not self.agents or agent in self.agents) and (not self.variants or variant in self.variants)
                and (not self.tasks or task in self.tasks))


def _exclusions(data: dict, path: Path) -> tuple[Exclusion, ...]:
    raw = data.get("exclude") or []
    if not isinstance(raw, list):
        raise SweepError(f"{path}: 'exclude' must be a list of mappings.")
    out = []
    for i, item in enumerate(raw):
        if not isinstance(item, dict) or set(item) - EXCLUDE_FIELDS or "reason" not in item:
            raise SweepError(f"{path}: exclude[{i}] must be a mapping of agents/variants/tasks/seeds lists and a "
                             "reason.")
        lists = {k: _str_list(item, k, path) if k in item else () for k in ("agents", "variants", "tasks")}
        seeds = item.get("seeds") or []
        if not isinstance(seeds, list) or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 1
                                                  for s in seeds):
            raise SweepError(f"{path}: exclude[{i}].seeds must be a list of seeds (integers >= 1).")
        out.append(Exclusion(reason=str(item["reason"]), seeds=tuple(seeds), **lists))
    return tuple(out)



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
        raise SweepError(f"{path}: unknown field '{first}'." + close_matches(first, sorted(FIELDS)))
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
