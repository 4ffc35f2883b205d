"""The tables and wording of ``repro plan SWEEP...``: the plan table (``plan.csv/.md/.tex``), its notes, and the
cost of the seeds the power table asks for, in words. The cost model (frames to train, memory, device-hours from the
user's ``repro bench`` files, wall-clock) is repro/launch/cost.py's; docs/plan.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from analysis.tables import TableOutput, write_table
from repro.launch.cost import (
    ADAM_BYTES_PER_PARAM,
    GB,
    DeviceBench,
    Packing,
    RunCost,
    Totals,
    bench_commands,
    packing,
    unpriced_runs,
)
from repro.launch.cost import seeds_cost as _seeds_cost


def _gb(b: int | float) -> str:
    """Bytes as GiB with one decimal (MiB below 1 GiB): the one way the plan, its notes and the docs write memory."""
    if not b:
        return "—"
    return f"{b / GB:.1f} GiB" if b >= GB else f"{b / 2**20:.0f} MiB"


def _frames(n: int) -> str:
    return "—" if not n else f"{n / 1e6:,.1f}M" if n >= 100_000 else f"{n:,}"


def _hours(h: float | None) -> str:
    return "—" if h is None else f"{h:,.1f} h" if h < 48 else f"{h:,.0f} h ({h / 24:,.1f} d)"


def runs_per_device(fit: Packing) -> str:
    """How many such runs fit on one device at once (:func:`repro.launch.cost.packing`) and what bounds it, or '—'
    where neither memory is known; a bound from the networks' estimate alone is an upper bound."""
    if fit.runs is None:
        return "—"
    return f"<= {fit.runs} ({fit.bound}: networks only)" if fit.upper else f"{fit.runs} ({fit.bound})"


@dataclass(frozen=True)
class Memory:
    """The memory the runs are packed into: the device's and the host's (None: unknown), and the devices sharing
    the host."""

    device: int | None
    host: int | None
    devices: int = 1
    host_source: str = "--host-memory-gb"  # where the host memory comes from, in words

    def fit(self, row: Totals) -> Packing:
        return packing(row.device_bytes, row.host_bytes, self.device, self.host, self.devices, row.measured)


def plan_frames(rows: Sequence[Totals], memory: Memory, devices: int,
                slots: int) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(raw, display) frames of the plan table."""
    raw = pd.DataFrame([{**{k: v for k, v in r.__dict__.items() if k != "unpriced_settings"},
                         "runs_per_device": runs_per_device(memory.fit(r)), "runs_per_device_n": memory.fit(r).runs,
                         "runs_per_device_bound": memory.fit(r).bound,
                         "unpriced_settings": "; ".join(f"{k}: {v}" for k, v in r.unpriced_settings.items())}
                        for r in rows])
    display = pd.DataFrame({
        "Sweep": [r.name for r in rows],
        "Runs": [str(r.runs) for r in rows],
        "To train": [str(r.to_train) for r in rows],
        "Frames to train": [_frames(r.frames) for r in rows],
        "Updates to train": [_frames(r.updates) for r in rows],
        "Host memory / run": [_gb(r.host_bytes) for r in rows],
        "Device memory / run": [_gb(r.device_bytes) for r in rows],
        "Runs / device": [runs_per_device(memory.fit(r)) for r in rows],
        "Device-hours": [_hours(r.hours) + (f" (+{r.unpriced} runs not priced)" if r.unpriced else "")
                         for r in rows],
        f"Wall-clock on {devices} device(s)": [_hours(r.local_hours) for r in rows],
        f"Wall-clock on SLURM (%{slots})": [_hours(r.slurm_hours) + (f", {r.requeues} requeues" if r.requeues else "")
                                           for r in rows],
    })
    return raw, display


def plan_notes(bench: DeviceBench | None, costs: Sequence[RunCost], devices: int, slots: int, cluster: str,
               memory: Memory, total: Totals, names: Sequence[str] = (), results: Path | None = None,
               slurm_mem_gb: float | None = None) -> list[str]:
    """The assumptions stated under the plan table, the runs not priced and those priced from entries timed under
    load (each with the `repro bench` command that times them), and the packing advice."""
    sources = sorted({c.fps_source for c in costs if c.fps_source})
    notes = [
        "Frames to train: each run's train.frames less what a partial run has trained (a done run: none); a run "
        "directory that several sweeps expand to counts once, at its largest budget (the Total row).",
        "Host memory: the replay buffer, allocated in full at its capacity (capacity x (a frame's uint8 bytes + its "
        "float32 action, reward and discount + int64 episode id and position); repro/data/replay.py), plus nothing "
        "for the Python process and the environments. Device "
        f"memory: trainable parameters x {ADAM_BYTES_PER_PARAM} bytes (fp32 weights, gradients, two Adam moments), "
        "without activations or the CUDA context, unless the bench JSON gives a measured peak_device_bytes.",
    ]
    if bench is not None:
        chosen = f", device {bench.device}: {bench.chosen}" if bench.chosen else ""
        paths = sorted({c.path for c in costs if not c.offline})
        notes.append(f"Device-hours: frames to train / FPS on {bench.hardware} (bench file {bench.path}{chosen}; "
                     f"FPS from {', '.join(sources) or 'no entry'}; each run on the path its config trains with: "
                     f"{', '.join(paths) or 'none'}): 'e2e' is the bench's end-to-end FPS (every phase), "
                     "'update-bound' is frames per update (the run's update_every_steps x action_repeat) / the "
                     "bench's seconds per update, which leaves out environment steps, rendering and evaluation, so "
                     "it is a lower bound on the time. The speed tables T4/T5 show the same FPS.")
        missing = unpriced_runs(costs)
        if missing:
            notes.append(f"Not priced (left out of the device-hours and the wall-clock): {_settings(missing)}. "
                         f"{_run(bench_commands(missing, bench.device, results))} times every one of them.")
        loaded = [c for c in costs if c.under_load and c.trained < c.budget]
        if loaded:
            notes.append("Timed under load (the machine's load average above its cores when the bench timed the "
                         "entry: other work shared the cores, so these runs' device-hours are too high): "
                         + ", ".join(f"{k} (load {v[0]:.1f} on {v[1]} cores)" for k, v in
                                     {c.setting: (c.load or 0.0, c.cores) for c in loaded}.items())
                         + f". {_run(bench_commands(loaded, bench.device, results))} on an idle machine times them "
                         "again.")
    notes.append(f"Wall-clock: the runs' device-hours placed longest first onto {devices} device(s) (one run at a "
                 "time per device: runs that share a device share its throughput), and onto the SLURM array's "
                 f"{slots} parallel tasks ({cluster}), each with its own device, queue time not counted; a run "
                 "longer than the job's --time is requeued from its checkpoint (requeues counted).")
    notes.append(_packing_note(memory, total, names))
    if slurm_mem_gb and total.host_bytes > slurm_mem_gb * GB:
        notes.append(f"SLURM: the launcher config's mem_gb ({slurm_mem_gb:g} GB) is below a run's host memory "
                     f"({_gb(total.host_bytes)}): raise it, or the jobs run out of memory.")
    return notes


def _settings(costs: Sequence[RunCost]) -> str:
    """The settings of ``costs`` with their runs, in the sweeps' order: 'alix B256 (48 runs), ...'."""
    count: dict[str, int] = {}
    for c in {c.run_dir: c for c in costs}.values():
        count[c.setting] = count.get(c.setting, 0) + 1
    return ", ".join(f"{k} ({v} run{'s' if v > 1 else ''})" for k, v in count.items())


def _run(commands: Sequence[str]) -> str:
    return " then ".join(f"`{c}`" for c in commands)


def _packing_note(memory: Memory, total: Totals, names: Sequence[str]) -> str:
    """How many runs share a device (the Total row's: its largest run) and the `repro sweep` option that packs them."""
    fit = memory.fit(total)
    device = _gb(memory.device) if memory.device else (
        "unknown: --device-memory-gb or device_memory_bytes in the bench JSON")
    host = f"{_gb(memory.host)}, {memory.host_source}" if memory.host else "unknown: --host-memory-gb"
    text = (f"Runs / device: min(device memory ({device}) / a run's device memory ({_gb(total.device_bytes)}), host "
            f"memory ({host}) / (a run's host memory ({_gb(total.host_bytes)}) x {memory.devices} device(s) on the "
            "host))")
    if fit.runs is None:
        return text + ": unknown."
    text += f" = {'at most ' if fit.upper else ''}{fit.runs}, bound by the {fit.bound}"
    if fit.upper:
        text += (" estimated from the networks alone (activations and the CUDA context not counted: a CUDA bench "
                 "records the measured peak_device_bytes)")
    sweep = names[0] if len(names) == 1 else "SWEEP"
    each = "" if len(names) == 1 else " for each sweep"
    gpus = ",".join(str(i) for i in range(memory.devices))
    if fit.runs == 0:
        return text + f". One run does not fit: it needs more {fit.bound} than given."
    if fit.runs == 1:
        return text + f": one run per device (`repro sweep {sweep} --gpus {gpus} --runs-per-gpu 1`{each}, the default)."
    return (text + f": `repro sweep {sweep} --gpus {gpus} --runs-per-gpu {fit.runs}`{each} packs them (runs that share "
            "a device share its throughput: benchmarks/gpu_check.sh measures what packing gains).")


def headline(names: str, total: Totals, commands: Sequence[str]) -> str:
    """The plan's caption: every run of the sweeps, those priced and their device-hours, and those not priced by
    setting with the `repro bench` command that prices them all."""
    text = f"Cost of {names}: {total.runs} runs, {total.to_train} to train"
    if not total.unpriced:
        return text + f", {_hours(total.hours)} of device time."
    groups = ", ".join(f"{k}: {v}" for k, v in total.unpriced_settings.items())
    priced = f"; {total.priced} priced, {_hours(total.hours)} of device time" if total.priced else "; none priced"
    return (text + f"{priced}; {total.unpriced} not priced ({groups}): {_run(commands)} prices "
            f"{'them' if total.priced else 'every run'}.")


def write_plan(out_dir: Path, rows: Sequence[Totals], notes: Sequence[str], memory: Memory,
               devices: int, slots: int, commands: Sequence[str] = ()) -> TableOutput:
    """Write ``plan.csv/.md/.tex``; ``commands``: the `repro bench` commands that price the runs not priced."""
    raw, display = plan_frames(rows, memory, devices, slots)
    total = rows[-1]
    caption = headline(", ".join(r.name for r in rows[:-1]) if len(rows) > 1 else total.name, total, commands)
    return write_table(out_dir, "plan", raw, caption, display, notes)


def seeds_cost(costs: Sequence[RunCost], tasks: Sequence[str] | None, sweep_seeds: dict[str, int],
               seeds: int) -> str:
    """What ``seeds`` seeds of the runs in ``costs`` (on ``tasks``, if given) cost, in words: device-hours where
    the bench times every run, and frames (or updates); '' when no run is chosen."""
    cost = _seeds_cost(costs, tasks, sweep_seeds, seeds)
    if cost is None:
        return ""
    text = f"{cost.work / 1e6:,.0f}M {cost.unit}"
    return text if cost.hours is None else f"{_hours(cost.hours)} device, {text}"
