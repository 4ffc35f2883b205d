"""What sweeps cost on the user's hardware (``repro plan SWEEP...``): runs, frames to train, each run's peak host
and device memory, device-hours from the user's own ``repro bench`` JSON, and the wall-clock time on N devices
or on a SLURM array. Documented in docs/plan.md.

The bench JSON read here (written by ``repro bench``, repro/bench/cli.py; see docs/plan.md):

* ``{results}/bench/bench-<host>-<device>.json``: ``device`` ("cuda", "cpu", ...), ``hardware``, ``results``:
  one object per timed update with ``algo`` (the agent file, e.g. ``taco``), ``batch_size``, ``speedup``
  (``plain``, ``amp``, ``compile``), ``update_seconds``; optional per result ``peak_device_bytes`` (the device's
  peak allocation during the timed updates); optional top level ``device_memory_bytes`` (the device's memory).
  Optional ``e2e`` (``repro bench --e2e``, repro/bench/e2e.py): one object per end-to-end training measurement
  with ``algo``, ``batch_size``, ``frames`` (environment frames trained), ``seconds`` (wall-clock of those frames,
  every phase), optional ``speedup`` (the path, as in ``results``; default ``plain``) and optional ``phases``
  (phase name -> seconds of the same run, e.g. ``env_step``, ``render``, ``update``), ``peak_device_bytes``,
  ``peak_host_bytes``. A run's FPS is ``frames / seconds`` of its e2e entry where there is one, else the
  update-bound ``frames per update / update_seconds`` (frames per update = the run's
  ``train.update_every_steps x env.action_repeat``).
* ``{results}/bench/bench-offline-<host>-<device>.json`` (``repro bench --offline``): ``results`` with
  ``agent``, ``batch_size``, ``update_seconds``; an offline run costs ``offline.updates x update_seconds``.
"""

from __future__ import annotations

import heapq
import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from analysis.tables import TableOutput, write_table

GB = 1024**3
ADAM_BYTES_PER_PARAM = 16  # fp32 weights, gradients and Adam's two moments
TIMED_ALGOS = ("taco", "drqv2", "alix")  # the online agents of the paper's sweeps that `repro bench --algo` times


class PlanError(Exception):
    """Bad input to ``repro plan`` (one line, exit 2)."""


# ---------------------------------------------------------------- frames to train
@dataclass(frozen=True)
class RunBudget:
    """One expanded run: its directory, its frame budget and the frames it has trained already."""

    run_dir: Path
    frames: int
    trained: int = 0


def frames_to_train(runs: Iterable[RunBudget]) -> dict[Path, int]:
    """Frames each run directory still has to train: a directory that several sweeps expand to is one run, trained
    to the smaller budget and extended to the largest (docs/run-format.md, "Budgets that extend"), so it counts once,
    at the largest budget, less what it has trained (repro/launch/spec/sharing.py counts the same per sweep)."""
    best: dict[Path, RunBudget] = {}
    for r in runs:
        if r.run_dir not in best or r.frames > best[r.run_dir].frames:
            best[r.run_dir] = r
    return {d: max(0, r.frames - r.trained) for d, r in best.items()}


# ---------------------------------------------------------------- the bench JSON
@dataclass
class Bench:
    """The parsed bench files of one device (see the module docstring for their shape)."""

    device: str
    path: Path | None = None
    hardware: str = ""
    updates: dict[tuple[str, int, str], dict[str, Any]] = field(default_factory=dict)
    e2e: dict[tuple[str, int, str], dict[str, Any]] = field(default_factory=dict)
    offline: dict[tuple[str, int], float] = field(default_factory=dict)
    offline_path: Path | None = None
    device_memory_bytes: int | None = None


def _read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise PlanError(f"cannot read bench file {path}: {str(exc).splitlines()[0]}") from None
    if not isinstance(data, dict) or not isinstance(data.get("results", []), list):
        raise PlanError(f"bench file {path} is not a `repro bench` JSON (an object with a 'results' list)")
    return data


def parse_bench(data: dict[str, Any], path: Path | None, device: str) -> Bench:
    """A :class:`Bench` from one online bench JSON object."""
    bench = Bench(device, path, str(data.get("hardware", "")))
    try:
        for r in data.get("results", []):
            key = (str(r["algo"]), int(r["batch_size"]), str(r.get("speedup", "plain")))
            if float(r["update_seconds"]) <= 0:
                raise ValueError("update_seconds must be positive")
            bench.updates[key] = r
        # an entry timed as the loop trains (phase_sync false: host and device overlapping) wins over the one timed
        # phase by phase (each phase waits for the device) of the same run
        for r in sorted(data.get("e2e", []) or [], key=lambda r: not r.get("phase_sync", True)):
            if float(r["frames"]) <= 0 or float(r["seconds"]) <= 0:
                raise ValueError("e2e frames and seconds must be positive")
            bench.e2e[(str(r["algo"]), int(r["batch_size"]), str(r.get("speedup", "plain")))] = r
        mem = data.get("device_memory_bytes")
        bench.device_memory_bytes = int(mem) if mem else None
    except (KeyError, TypeError, ValueError) as exc:
        raise PlanError(f"bench file {path}: bad entry ({exc})") from None
    return bench


def _newest(paths: Sequence[Path]) -> Path | None:
    return max(paths, key=lambda p: p.stat().st_mtime) if paths else None


def bench_command(device: str, results: Path) -> str:
    """The command that writes the bench file ``repro plan`` needs."""
    return f"repro bench --device {device} --batch 256 --batch 1024 --results {results}"


def find_bench(results: Path, device: str, explicit: Path | None = None) -> Bench:
    """The bench of ``device``: ``explicit``, else the newest ``{results}/bench/bench-*-<device>.json`` (and the
    newest offline one beside it). PlanError naming the command to run when there is none."""
    folder = results / "bench"
    if explicit is not None:
        if not explicit.is_file():
            raise PlanError(f"bench file {explicit} does not exist")
        path = explicit
    else:
        newest = _newest([p for p in folder.glob(f"bench-*-{device}.json") if not p.name.startswith("bench-offline")])
        if newest is None:
            raise PlanError(f"no `repro bench` file for device {device} under {folder}: run "
                            f"`{bench_command(device, results)}` first (or pass --bench FILE)")
        path = newest
    bench = parse_bench(_read_json(path), path, device)
    off = _newest([p for p in folder.glob(f"bench-offline-*-{device}.json")
                   if not p.name.startswith("bench-offline-data")])
    if off is not None:
        try:
            bench.offline = {(str(r["agent"]), int(r["batch_size"])): float(r["update_seconds"])
                             for r in _read_json(off).get("results", [])}
        except (KeyError, TypeError, ValueError) as exc:
            raise PlanError(f"bench file {off}: bad entry ({exc})") from None
        bench.offline_path = off
    return bench


# ---------------------------------------------------------------- one run's cost
@dataclass
class RunCost:
    """One planned run: what it trains, its peak memory, and its device-hours on the bench's device."""

    sweep: str
    run_dir: Path
    task: str
    algo: str
    batch_size: int
    speedup: str
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

    def hours(self, work: int) -> float | None:
        """Device-hours of ``work`` frames (online) or updates (offline)."""
        return None if self.fps is None else work / self.fps / 3600


def _speedup(agent: Any) -> str:
    return "compile" if agent.compile else "amp" if agent.amp else "plain"


class _Params:
    """Trainable parameters per agent config, each agent built once (on the CPU)."""

    def __init__(self) -> None:
        self.cache: dict[str, int] = {}

    def count(self, cfg: Any, rc: Any) -> int:
        from omegaconf import OmegaConf

        from repro.train.build import build_agent, run_action_dim

        action_dim = run_action_dim(rc)
        obs = (3 * rc.env.frame_stack, rc.env.image_size, rc.env.image_size)
        key = f"{OmegaConf.to_yaml(cfg.agent)}|{action_dim}|{obs}"
        if key not in self.cache:
            self.cache[key] = sum(n for _, n in build_agent(rc, obs, action_dim, "cpu").parameter_counts())
        return self.cache[key]


def run_cost(sweep: str, planned: Any, bench: Bench | None, params: _Params | None) -> RunCost:
    """The :class:`RunCost` of one ``repro.launch.spec.PlannedRun`` (its composed config)."""
    from repro.config.compose import typed
    from repro.data.replay import ReplayBuffer
    from repro.launch.status import progress
    from repro.train.build import run_action_dim

    rc = typed(planned.cfg)
    offline = planned.run.dataset is not None
    per_update = rc.train.update_every_steps * rc.env.action_repeat
    nets = params.count(planned.cfg, rc) * ADAM_BYTES_PER_PARAM if params is not None else 0
    frame_shape = (3, rc.env.image_size, rc.env.image_size)
    replay = 0 if offline else ReplayBuffer.bytes_for(rc.replay.capacity, frame_shape, run_action_dim(rc))
    replay_on_device = replay if str(getattr(rc.replay.device, "value", rc.replay.device)) == "cuda" else 0
    note = "" if not offline else "offline: the dataset's replay (its size) not counted"
    done = planned.state == "done"
    last = 0
    if planned.state == "partial":
        frame, _ = progress(planned.run_dir)
        last = int(frame or 0)
    budget = rc.offline.updates if offline else rc.train.frames
    cost = RunCost(sweep, planned.run_dir, rc.task.name, rc.agent.name, rc.agent.batch_size, _speedup(rc.agent),
                   offline, 0 if offline else rc.train.frames, rc.offline.updates if offline else 0,
                   budget if done else min(last, budget), per_update, replay - replay_on_device,
                   nets + replay_on_device, replay_on_device, note, planned.state)
    if bench is not None:
        _rate(cost, bench)
    return cost


def _rate(cost: RunCost, bench: Bench) -> None:
    """Set the run's FPS (or updates per second) from the bench, or say which bench command would time it."""
    if cost.offline:
        secs = bench.offline.get((cost.algo, cost.batch_size))
        if secs:
            cost.fps, cost.fps_source = 1.0 / secs, "offline update"
        else:
            cost.missing = (f"repro bench --offline --device {bench.device} --learner {cost.algo} "
                            f"--batch {cost.batch_size}")
        return
    e2e = bench.e2e.get((cost.algo, cost.batch_size, cost.speedup))
    upd = bench.updates.get((cost.algo, cost.batch_size, cost.speedup))
    if e2e is not None:
        cost.fps, cost.fps_source = float(e2e["frames"]) / float(e2e["seconds"]), "e2e"
        peak = e2e.get("peak_device_bytes")
    elif upd is not None:
        cost.fps, cost.fps_source = cost.frames_per_update / float(upd["update_seconds"]), "update-bound"
        peak = upd.get("peak_device_bytes")
    else:
        flag = {"plain": "", "amp": " --amp", "compile": " --compile"}[cost.speedup]
        cost.missing = (f"repro bench --device {bench.device} --algo {cost.algo} --batch {cost.batch_size}{flag}"
                        if cost.algo in TIMED_ALGOS else f"{cost.algo} (not an agent `repro bench` times)")
        return
    if peak:
        cost.device_bytes = int(peak) + cost.replay_on_device  # measured: networks, activations, batch
        cost.memory_note = "device: the bench's measured peak"


# ---------------------------------------------------------------- sweeps
def plan_sweeps(names: Sequence[str], bench: Bench | None, seeds: int | None = None,
                results_root: Path | None = None, memory: bool = True) -> list[RunCost]:
    """Every run of the sweeps ``names`` (each expanded and composed as ``repro sweep`` does) with its cost;
    ``memory`` False: without the network parameters (no agent is built; device memory 0)."""
    from repro.launch import spec as specs

    params = _Params() if memory else None
    out: list[RunCost] = []
    for name in names:
        spec = specs.load(name)
        sets = (f"runtime.results_root={specs.hydra_quote(str(results_root))}",) if results_root else ()
        planned = specs.plan(specs.expand(spec, specs.Selection(seeds=seeds, sets=sets)))
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


def totals(name: str, costs: Sequence[RunCost], devices: int, slurm_slots: int,
           slurm_minutes: int | None = None) -> Totals:
    """Sum ``costs`` (a run directory once, at its largest budget: :func:`frames_to_train`)."""
    online = [c for c in costs if not c.offline]
    left = frames_to_train(RunBudget(c.run_dir, c.frames, c.trained) for c in online)
    updates = frames_to_train(RunBudget(c.run_dir, c.updates, c.trained) for c in costs if c.offline)
    by_dir = {c.run_dir: c for c in costs}
    work = {**left, **updates}
    todo = {d: w for d, w in work.items() if w > 0}
    hours = {d: by_dir[d].hours(w) for d, w in todo.items()}
    priced = [h for h in hours.values() if h is not None]
    requeues = 0
    if slurm_minutes:
        requeues = sum(max(0, math.ceil(h * 60 / slurm_minutes) - 1) for h in priced)
    return Totals(name, len(by_dir), len(todo), sum(left.values()), sum(updates.values()),
                  max((c.host_bytes for c in costs), default=0), max((c.device_bytes for c in costs), default=0),
                  sum(priced) if priced else (None if todo else 0.0), len(todo) - len(priced),
                  bool(costs) and all(c.memory_note.startswith("device: the bench") for c in costs),
                  makespan(priced, devices) if priced else None, makespan(priced, slurm_slots) if priced else None,
                  requeues)


def _gb(b: int) -> str:
    return f"{b / GB:.1f} GiB" if b else "—"


def _frames(n: int) -> str:
    return "—" if not n else f"{n / 1e6:,.1f}M" if n >= 100_000 else f"{n:,}"


def _hours(h: float | None) -> str:
    return "—" if h is None else f"{h:,.1f} h" if h < 48 else f"{h:,.0f} h ({h / 24:,.1f} d)"


def runs_per_device(device_bytes: int, memory: int | None, measured: bool = True) -> str:
    """How many such runs fit in the device's memory at once (by the per-run estimate), or '—'; an estimate of
    the networks alone is an upper bound."""
    if not memory or not device_bytes:
        return "—"
    n = str(max(0, memory // device_bytes))
    return n if measured else f"<= {n} (networks only)"


def plan_frames(rows: Sequence[Totals], device_memory: int | None, devices: int,
                slots: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of the plan table."""
    raw = pd.DataFrame([{**r.__dict__, "runs_per_device": runs_per_device(r.device_bytes, device_memory, r.measured)}
                        for r in rows])
    display = pd.DataFrame({
        "Sweep": [r.name for r in rows],
        "Runs": [str(r.runs) for r in rows],
        "To train": [str(r.to_train) for r in rows],
        "Frames to train": [_frames(r.frames) for r in rows],
        "Updates to train": [_frames(r.updates) for r in rows],
        "Host memory / run": [_gb(r.host_bytes) for r in rows],
        "Device memory / run": [_gb(r.device_bytes) for r in rows],
        "Runs / device": [runs_per_device(r.device_bytes, device_memory, r.measured) for r in rows],
        "Device-hours": [_hours(r.hours) + (f" (+{r.unpriced} runs not timed)" if r.unpriced else "")
                         for r in rows],
        f"Wall-clock on {devices} device(s)": [_hours(r.local_hours) for r in rows],
        f"Wall-clock on SLURM (%{slots})": [_hours(r.slurm_hours) + (f", {r.requeues} requeues" if r.requeues else "")
                                           for r in rows],
    })
    return raw, display


def plan_notes(bench: Bench | None, costs: Sequence[RunCost], devices: int, slots: int, cluster: str,
               device_memory: int | None) -> list[str]:
    """The assumptions stated under the plan table."""
    sources = sorted({c.fps_source for c in costs if c.fps_source})
    notes = [
        "Frames to train: each run's train.frames less what a partial run has trained (a done run: none); a run "
        "directory that several sweeps expand to counts once, at its largest budget (the Total row).",
        "Host memory: the replay buffer, allocated in full at its capacity (uint8 frames, float32 actions, rewards, "
        "discounts; repro/data/replay.py), plus nothing for the Python process and the environments. Device "
        f"memory: trainable parameters x {ADAM_BYTES_PER_PARAM} bytes (fp32 weights, gradients, two Adam moments), "
        "without activations or the CUDA context, unless the bench JSON gives a measured peak_device_bytes.",
    ]
    if bench is not None:
        notes.append(f"Device-hours: frames to train / FPS on {bench.hardware or bench.device} (bench file "
                     f"{bench.path}; FPS from {', '.join(sources) or 'no entry'}): 'e2e' is the bench's "
                     "end-to-end FPS (every phase), 'update-bound' is frames per update (the run's "
                     "update_every_steps x action_repeat) / the bench's seconds per update, which leaves out "
                     "environment steps, rendering and evaluation, so it is a lower bound on the time.")
        missing = sorted({c.missing for c in costs if c.missing})
        if missing:
            notes.append("Not timed by the bench (left out of the device-hours): " + "; ".join(
                f"`{m}`" if m.startswith("repro") else m for m in missing) + ".")
    notes.append(f"Wall-clock: the runs' device-hours placed longest first onto {devices} device(s) (one run at a "
                 "time per device: runs that share a device share its throughput), and onto the SLURM array's "
                 f"{slots} parallel tasks ({cluster}), each with its own device, queue time not counted; a run "
                 "longer than the job's --time is requeued from its checkpoint (requeues counted).")
    notes.append("Runs / device: the device's memory" + (f" ({device_memory / GB:.0f} GB)" if device_memory else
                 " (unknown: pass --device-memory-gb or add device_memory_bytes to the bench JSON)")
                 + " over the run's device memory estimate.")
    return notes


def write_plan(out_dir: Path, rows: Sequence[Totals], notes: Sequence[str], device_memory: int | None,
               devices: int, slots: int) -> TableOutput:
    """Write ``plan.csv/.md/.tex``."""
    raw, display = plan_frames(rows, device_memory, devices, slots)
    total = rows[-1]
    caption = (f"Cost of {', '.join(r.name for r in rows[:-1]) if len(rows) > 1 else total.name}: {total.runs} runs, "
               f"{total.to_train} to train, {_hours(total.hours)} of device time.")
    return write_table(out_dir, "plan", raw, caption, display, notes)


def seeds_cost(costs: Sequence[RunCost], tasks: Sequence[str] | None, sweep_seeds: dict[str, int],
               seeds: int) -> str:
    """What ``seeds`` seeds of the runs in ``costs`` (on ``tasks``, if given) cost: device-hours where the bench
    times every run, and frames (or updates); the runs' cost per seed scaled by ``seeds``."""
    chosen = [c for c in costs if tasks is None or c.task in tasks]
    if not chosen:
        return ""
    per = list({c.run_dir: c for c in chosen}.values())
    scale = {c.run_dir: seeds / sweep_seeds[c.sweep] for c in chosen}
    frames = sum((c.updates if c.offline else c.frames) * scale[c.run_dir] for c in per)
    hours = [c.hours(c.updates if c.offline else c.frames) for c in per]
    unit = "updates" if all(c.offline for c in per) else "frames"
    text = f"{frames / 1e6:,.0f}M {unit}"
    if hours and all(h is not None for h in hours):
        text = _hours(sum(h * scale[c.run_dir] for h, c in zip(hours, per) if h is not None)) + " device, " + text
    return text
