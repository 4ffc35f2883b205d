"""What sweeps cost on the user's hardware (``repro plan SWEEP...``): runs, frames to train, each run's peak host and
device memory and how many runs share a device (:func:`packing`), device-hours from the user's own ``repro bench``
files (the runs they do not time counted apart, with the `repro bench` commands that time them: :func:`bench_commands`),
and the wall-clock on N devices or on a SLURM array. The tables and their wording are the app's (repro_app/plan.py);
docs/plan.md.

A run is expanded and composed as ``repro sweep`` does (the same :class:`repro.launch.spec.Selection`: ``--set``,
``--tasks``, ``--seeds``, ``--frames``), so what is planned is what is launched. Its speed is the one FPS of
repro/bench/results.py (``rate``) on the path its config trains with (``path_of``: ``agent.fast``, ``compile``,
``amp``), the same FPS the speed tables T4/T5 show. A run directory that several sweeps expand to is one run: the
shared-run rule of repro/launch/spec/sharing.py (``split_budget``).
"""

from __future__ import annotations

import heapq
import math
import os
from collections import defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from repro.bench import results as bench_results
from repro.bench.results import BenchFile, BenchFormatError, offline_entry, path_of, rate
from repro.config.errors import UserError
from repro.launch.spec.sharing import split_budget

if TYPE_CHECKING:
    from repro.launch.spec.plan import Composer

GB = 1024**3
ADAM_BYTES_PER_PARAM = 16  # fp32 weights, gradients and Adam's two moments


class PlanError(UserError):
    """Bad input to ``repro plan`` (one line, exit 2)."""


# ---------------------------------------------------------------- frames to train
@dataclass(frozen=True)
class RunBudget:
    """One expanded run: its directory, its frame budget, the frames it has trained already and its sweep."""

    run_dir: Path
    frames: int
    trained: int = 0
    sweep: str = ""


def frames_to_train(runs: Iterable[RunBudget]) -> dict[Path, int]:
    """Frames each run directory still has to train: a directory that several sweeps expand to is one run, trained
    to the smaller budget and extended to the largest (docs/run-format.md, "Budgets that extend"), so it counts once,
    at what the sweeps pay together (repro/launch/spec/sharing.py ``split_budget``: its largest budget), less what
    it has trained."""
    budgets: dict[Path, list[tuple[int, str]]] = defaultdict(list)
    trained: dict[Path, int] = defaultdict(int)
    for i, r in enumerate(runs):
        budgets[r.run_dir].append((r.frames, r.sweep or f"#{i}"))
        trained[r.run_dir] = max(trained[r.run_dir], r.trained)
    return {d: max(0, sum(split_budget(b).values()) - trained[d]) for d, b in budgets.items()}


# ---------------------------------------------------------------- the bench files
@dataclass
class DeviceBench:
    """The bench files `repro plan` prices with: the online one of a device and the newest offline one beside it."""

    online: BenchFile
    offline: BenchFile | None = None
    chosen: str = ""  # how the device was chosen, when not by the user

    @property
    def device(self) -> str:
        return self.online.device

    @property
    def hardware(self) -> str:
        return self.online.hardware or self.online.device

    @property
    def path(self) -> Path | None:
        return self.online.path

    @property
    def device_memory_bytes(self) -> int | None:
        return self.online.device_memory_bytes


def bench_command(device: str, results: Path) -> str:
    """The command that writes a bench file, where the runs to price are not known (`repro plan SWEEP` names the
    one that prices its runs: :func:`bench_commands`)."""
    return f"repro bench update --device {device} --batch 256 --batch 1024 --results {results}"


class NoBench(PlanError):
    """No bench file to price with (its message names a command that writes one)."""

    def __init__(self, message: str, folder: Path, device: str | None) -> None:
        super().__init__(message)
        self.folder, self.device = folder, device


def _read(path: Path) -> BenchFile:
    try:
        return bench_results.read(path)
    except BenchFormatError as exc:
        raise PlanError(str(exc)) from None


def find_bench(results: Path, device: str | None = None, explicit: Path | None = None) -> DeviceBench:
    """The bench to price with: ``explicit``, else the newest ``{results}/bench/bench-*-<device>.json``, or, with no
    ``device``, the newest online bench file of any device (:attr:`DeviceBench.chosen` says so); the newest offline
    file of the same device beside it. PlanError naming the command to run when there is none."""
    folder = results / "bench"
    chosen = ""
    if explicit is not None:
        if not explicit.is_file():
            raise PlanError(f"bench file {explicit} does not exist")
        online = _read(explicit)
        if online.kind != bench_results.ONLINE:
            raise PlanError(f"bench file {explicit} is a `repro bench {online.kind}` file, not the online one "
                            "(bench-<host>-<device>.json)")
    else:
        if device is None:
            device = bench_results.newest_device(folder)
            if device is None:
                raise NoBench(f"no `repro bench` file under {folder}: run `{bench_command('cuda', results)}` "
                              "(or --device cpu) first, or pass --bench FILE", folder, None)
            chosen = f"the device of the newest bench file under {folder}; --device picks another"
        found = bench_results.files(folder, bench_results.ONLINE, device)
        if not found:
            raise NoBench(f"no `repro bench` file for device {device} under {folder}: run "
                          f"`{bench_command(device, results)}` first (or pass --bench FILE)", folder, device)
        online = _read(found[0])
    off = bench_results.files(folder, bench_results.OFFLINE, online.device)
    return DeviceBench(online, _read(off[0]) if off else None, chosen)


# ---------------------------------------------------------------- one run's cost
@dataclass
class RunCost:
    """One planned run: what it trains, its peak memory, and its device-hours on the bench's device."""

    sweep: str
    run_dir: Path
    task: str
    agent: str  # agent.name
    batch_size: int
    path: str  # the speed-up path it trains with (repro/bench/results.py path_of)
    offline: bool
    frames: int  # train.frames (online)
    updates: int  # offline.updates (offline)
    trained: int  # frames (online) or updates (offline) already done
    frames_per_update: int
    host_bytes: int
    device_bytes: int
    replay_on_device: int = 0  # replay bytes held on the device (replay.device cuda), in device_bytes
    memory_note: str = ""
    state: str = "absent"
    fps: float | None = None  # frames (online) or updates (offline) per second on the bench's device
    fps_source: str = ""
    missing: str = ""  # the bench command that would time this run, when the bench lacks it
    load: float | None = None  # the load average and cores when the bench timed the entry that prices it
    cores: int | None = None

    @property
    def budget(self) -> int:
        """Its frames (online) or updates (offline) to train in all."""
        return self.updates if self.offline else self.frames

    @property
    def setting(self) -> str:
        """What the bench times for this run, in words: agent, batch size and (when not plain) path."""
        return f"{self.agent} B{self.batch_size}" + ("" if self.path == "plain" else f" {self.path}")

    @property
    def under_load(self) -> bool:
        """Priced from an entry timed with the machine's load average above its cores (its time too long)."""
        return bench_results.loaded(self.load, self.cores)

    def hours(self, work: int | float) -> float | None:
        """Device-hours of ``work`` frames (online) or updates (offline)."""
        return None if self.fps is None else work / self.fps / 3600


class ParamCounts:
    """Trainable parameters per agent config, each agent built once (on the CPU)."""

    def __init__(self) -> None:
        self.cache: dict[str, int] = {}

    def count(self, cfg: Any, rc: Any) -> int:
        from omegaconf import OmegaConf

        from repro.train.build import build_run_learner, run_action_dim

        action_dim = run_action_dim(rc)
        obs = (3 * rc.env.frame_stack, rc.env.image_size, rc.env.image_size)
        key = f"{OmegaConf.to_yaml(cfg.agent)}|{action_dim}|{obs}"
        if key not in self.cache:
            self.cache[key] = sum(n for _, n in build_run_learner(rc, obs, action_dim, "cpu").parameter_counts())
        return self.cache[key]


def run_cost(sweep: str, planned: Any, bench: DeviceBench | None, params: ParamCounts | None) -> RunCost:
    """The :class:`RunCost` of one ``repro.launch.spec.PlannedRun`` (its composed config)."""
    from repro.config.compose import typed
    from repro.data.sizes import replay_bytes
    from repro.envs import run_action_dim
    from repro.launch.status import progress

    rc = typed(planned.cfg)
    offline = planned.run.dataset is not None
    per_update = rc.train.update_every_steps * rc.env.action_repeat
    nets = params.count(planned.cfg, rc) * ADAM_BYTES_PER_PARAM if params is not None else 0
    frame_shape = (3, rc.env.image_size, rc.env.image_size)
    replay = 0 if offline else replay_bytes(rc.replay.capacity, frame_shape, run_action_dim(rc))
    replay_on_device = replay if str(getattr(rc.replay.device, "value", rc.replay.device)) == "cuda" else 0
    note = "" if not offline else "offline: the dataset's replay (its size) not counted"
    done = planned.state == "done"
    last = 0
    if planned.state == "partial":
        frame, _ = progress(planned.run_dir)
        last = int(frame or 0)
    budget = rc.offline.updates if offline else rc.train.frames
    cost = RunCost(sweep, planned.run_dir, rc.task.name, rc.agent.name, rc.agent.batch_size, path_of(rc.agent),
                   offline, 0 if offline else rc.train.frames, rc.offline.updates if offline else 0,
                   budget if done else min(last, budget), per_update, replay - replay_on_device,
                   nets + replay_on_device, replay_on_device, note, planned.state)
    if bench is not None:
        price(cost, bench)
    return cost


def bench_for(cost: RunCost, device: str) -> str:
    """The ``repro bench`` command that would time ``cost``'s run on ``device``."""
    return bench_commands([cost], device)[0]


def bench_commands(costs: Iterable[RunCost], device: str, results: Path | None = None) -> list[str]:
    """The `repro bench` commands that price every run of ``costs`` on ``device``: one `repro bench update` for the
    online runs (each of their agents at each of their batch sizes, on the plain path and each other path they
    train with) and one `repro bench offline` for the offline ones; ``results``: the results root it writes under."""
    online: dict[str, None] = {}
    offline: dict[str, None] = {}
    batches: dict[bool, set[int]] = {False: set(), True: set()}
    paths: set[str] = set()
    for c in costs:
        (offline if c.offline else online)[c.agent] = None
        batches[c.offline].add(c.batch_size)
        if not c.offline:
            paths.add(c.path)
    where = f" --results {results}" if results is not None else ""
    out = []
    for kind, agents, is_offline in (("update", online, False), ("offline", offline, True)):
        if not agents:
            continue
        flags = "".join(f" --{p}" for p in bench_results.PATHS if p in paths and p != "plain" and not is_offline)
        out.append(f"repro bench {kind} --device {device}" + "".join(f" --agent {a}" for a in agents)
                   + "".join(f" --batch {b}" for b in sorted(batches[is_offline])) + flags + where)
    return out


def unpriced_runs(costs: Iterable[RunCost]) -> list[RunCost]:
    """The runs of ``costs`` with frames (or updates) left to train that the bench does not price."""
    return [c for c in costs if c.fps is None and c.trained < c.budget]


def machine_memory() -> int | None:
    """This machine's memory in bytes (None where the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (AttributeError, ValueError, OSError):
        return None


@dataclass(frozen=True)
class Packing:
    """How many runs fit on one device at once: the smaller of the device's memory over a run's device memory and
    the host memory per device over a run's host memory (its replay), and which of the two bounds it."""

    runs: int | None  # None: neither memory known
    bound: str = ""  # "device memory" or "host memory"
    upper: bool = False  # bound by a device estimate of the networks alone (no activations): at most this many


def packing(device_bytes: int, host_bytes: int, device_memory: int | None, host_memory: int | None,
            devices: int = 1, measured: bool = True) -> Packing:
    """Runs per device = min(device memory / a run's device bytes, host memory / (a run's host bytes x the
    ``devices`` that share the host)); ``measured`` False: the device bytes are the networks' alone."""
    bounds = []
    if device_memory and device_bytes:
        bounds.append((device_memory // device_bytes, "device memory"))
    if host_memory and host_bytes:
        bounds.append((host_memory // (host_bytes * max(1, devices)), "host memory"))
    if not bounds:
        return Packing(None)
    runs, bound = min(bounds)
    return Packing(int(runs), bound, bound == "device memory" and not measured)


def price(cost: RunCost, bench: DeviceBench) -> None:
    """Set the run's FPS (or updates per second) from the bench, or say which bench command would time it."""
    if cost.offline:
        entry = offline_entry(bench.offline, cost.agent, cost.batch_size)
        if entry is not None:
            cost.fps, cost.fps_source = 1.0 / entry.update_seconds, "offline update"
            cost.load, cost.cores = entry.load, entry.cores
        else:
            cost.missing = bench_for(cost, bench.device)
        return
    found = rate(bench.online, cost.agent, cost.batch_size, cost.path, cost.frames_per_update)
    if found is None:
        cost.missing = bench_for(cost, bench.device)
        return
    cost.fps, cost.fps_source = found.fps, found.source
    cost.load, cost.cores = found.load, found.cores
    if found.peak_device_bytes:
        cost.device_bytes = found.peak_device_bytes + cost.replay_on_device  # measured: networks, activations, batch
        cost.memory_note = "device: the bench's measured peak"


# ---------------------------------------------------------------- sweeps
def plan_sweeps(names: Sequence[str], bench: DeviceBench | None, selection: Any = None,
                results_root: Path | None = None, memory: bool = True,
                composer: Composer | None = None) -> list[RunCost]:
    """Every run of the sweeps ``names``, each expanded with ``selection`` (a :class:`repro.launch.spec.Selection`:
    the grid options of ``repro sweep``) and composed as ``repro sweep`` does (by ``composer``, see
    :func:`repro.launch.spec.plan.compose_runs`), with its cost; ``memory`` False: without the network parameters
    (no agent is built; device memory 0)."""
    from dataclasses import replace

    from repro.launch import spec as specs

    params = ParamCounts() if memory else None
    sel = selection if selection is not None else specs.Selection()
    if results_root is not None:
        sel = replace(sel, sets=(*sel.sets, f"runtime.results_root={specs.hydra_quote(str(results_root))}"))
    out: list[RunCost] = []
    for name in names:
        spec = specs.load(name)
        planned = specs.plan(specs.expand(spec, sel), composer)
        out += [run_cost(spec.name, p, bench, params) for p in planned]
    return out


def makespan(hours: Sequence[float], slots: int) -> float:
    """Wall-clock hours of runs of ``hours`` on ``slots`` parallel slots, longest first onto the freest slot."""
    if not hours:
        return 0.0
    heap = [0.0] * max(1, slots)
    for h in sorted(hours, reverse=True):
        heapq.heappush(heap, heapq.heappop(heap) + h)
    return max(heap)


@dataclass
class Totals:
    """One row of the plan table: a sweep, or every sweep together (run directories counted once)."""

    name: str
    runs: int
    to_train: int
    frames: int
    updates: int
    host_bytes: int
    device_bytes: int
    hours: float | None
    unpriced: int  # runs to train that the bench does not time
    measured: bool  # every run's device memory is the bench's measured peak
    local_hours: float | None
    slurm_hours: float | None
    requeues: int
    unpriced_settings: dict[str, int] = field(default_factory=dict)  # setting (RunCost.setting) -> runs unpriced

    @property
    def priced(self) -> int:
        """Runs to train that the bench prices."""
        return self.to_train - self.unpriced


def totals(name: str, costs: Sequence[RunCost], devices: int, slurm_slots: int,
           slurm_minutes: int | None = None) -> Totals:
    """Sum ``costs`` (a run directory once: :func:`frames_to_train`)."""
    online = [c for c in costs if not c.offline]
    left = frames_to_train(RunBudget(c.run_dir, c.frames, c.trained, c.sweep) for c in online)
    updates = frames_to_train(RunBudget(c.run_dir, c.updates, c.trained, c.sweep) for c in costs if c.offline)
    by_dir = {c.run_dir: c for c in costs}
    work = {**left, **updates}
    todo = {d: w for d, w in work.items() if w > 0}
    hours = {d: by_dir[d].hours(w) for d, w in todo.items()}
    priced = [h for h in hours.values() if h is not None]
    unpriced: dict[str, int] = defaultdict(int)
    for d, h in hours.items():
        if h is None:
            unpriced[by_dir[d].setting] += 1
    requeues = 0
    if slurm_minutes:
        requeues = sum(max(0, math.ceil(h * 60 / slurm_minutes) - 1) for h in priced)
    return Totals(name, len(by_dir), len(todo), sum(left.values()), sum(updates.values()),
                  max((c.host_bytes for c in costs), default=0), max((c.device_bytes for c in costs), default=0),
                  sum(priced) if priced else (None if todo else 0.0), len(todo) - len(priced),
                  bool(costs) and all(c.memory_note.startswith("device: the bench") for c in costs),
                  makespan(priced, devices) if priced else None, makespan(priced, slurm_slots) if priced else None,
                  requeues, dict(unpriced))


@dataclass(frozen=True)
class SeedsCost:
    """What some seeds of some runs cost: frames (or updates) and, where the bench times every run, device-hours."""

    work: float
    unit: str  # "frames" or "updates"
    hours: float | None


def seeds_cost(costs: Sequence[RunCost], tasks: Sequence[str] | None, sweep_seeds: dict[str, int],
               seeds: int) -> SeedsCost | None:
    """What ``seeds`` seeds of the runs in ``costs`` (on ``tasks``, if given) cost: the runs' cost per seed of their
    sweep scaled to ``seeds``; None when no run is chosen."""
    chosen = [c for c in costs if tasks is None or c.task in tasks]
    if not chosen:
        return None
    per = list({c.run_dir: c for c in chosen}.values())
    scale = {c.run_dir: seeds / sweep_seeds[c.sweep] for c in chosen}
    work = sum((c.updates if c.offline else c.frames) * scale[c.run_dir] for c in per)
    hours = [c.hours(c.updates if c.offline else c.frames) for c in per]
    unit = "updates" if all(c.offline for c in per) else "frames"
    total = None
    if hours and all(h is not None for h in hours):
        total = sum(h * scale[c.run_dir] for h, c in zip(hours, per) if h is not None)
    return SeedsCost(work, unit, total)
