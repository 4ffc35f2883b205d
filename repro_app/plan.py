"""The tables and wording of ``repro plan SWEEP...``: the plan table (``plan.csv/.md/.tex``), its notes, and the
cost of the seeds the power table asks for, in words. The cost model (frames to train, memory, device-hours from the
user's ``repro bench`` files, wall-clock) is repro/launch/cost.py's; docs/plan.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from analysis.tables import TableOutput, write_table
from repro.launch.cost import ADAM_BYTES_PER_PARAM, GB, DeviceBench, RunCost, Totals
from repro.launch.cost import seeds_cost as _seeds_cost


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


def plan_notes(bench: DeviceBench | None, costs: Sequence[RunCost], devices: int, slots: int, cluster: str,
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
        chosen = f", device {bench.device}: {bench.chosen}" if bench.chosen else ""
        paths = sorted({c.path for c in costs if not c.offline})
        notes.append(f"Device-hours: frames to train / FPS on {bench.hardware} (bench file {bench.path}{chosen}; "
                     f"FPS from {', '.join(sources) or 'no entry'}; each run on the path its config trains with: "
                     f"{', '.join(paths) or 'none'}): 'e2e' is the bench's end-to-end FPS (every phase), "
                     "'update-bound' is frames per update (the run's update_every_steps x action_repeat) / the "
                     "bench's seconds per update, which leaves out environment steps, rendering and evaluation, so "
                     "it is a lower bound on the time. The speed tables T4/T5 show the same FPS.")
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
    """What ``seeds`` seeds of the runs in ``costs`` (on ``tasks``, if given) cost, in words: device-hours where
    the bench times every run, and frames (or updates); '' when no run is chosen."""
    cost = _seeds_cost(costs, tasks, sweep_seeds, seeds)
    if cost is None:
        return ""
    text = f"{cost.work / 1e6:,.0f}M {cost.unit}"
    return text if cost.hours is None else f"{_hours(cost.hours)} device, {text}"
