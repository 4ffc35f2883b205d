"""Measured training speed (frames per second) from runs (train.csv ``fps``) and benchmark JSONs."""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from analysis.identity import agent_label
from analysis.load import Results
from repro.bench.results import ONLINE, rate, settings


def hardware_label(device: Any, cpu: Any = None, host: Any = None) -> str:
    """``cuda:NVIDIA A100`` -> ``NVIDIA A100 (GPU)``; ``cpu`` -> ``CPU: <model>``."""
    dev = "" if device is None or (isinstance(device, float) and math.isnan(device)) else str(device)
    if dev.startswith("cuda"):
        name = dev.split(":", 1)[1] if ":" in dev else dev
        return f"{name.strip()} (GPU)"
    cpu_text = "" if cpu is None or (isinstance(cpu, float) and math.isnan(cpu)) else str(cpu)
    if dev in ("", "cpu") and cpu_text:
        return f"CPU: {cpu_text}"
    return dev or "unknown hardware"


def speed_measurements(results: Results, experiments: tuple[str, ...] = ("speed",),
                       fallback: bool = True) -> pd.DataFrame:
    """One row per measurement: method, batch_size, fps, hardware, source, task, speedup.

    Runs of the ``speed`` experiment are used if there are any, otherwise (if ``fallback``) every run
    with an FPS (each run's FPS is the median over training episodes once updates started), each with the speed-up
    path it trained with (the runs table's ``speedup``). Each online bench file gives one row per agent, batch size and
    path it times, at the one FPS `repro plan` prices a run with (repro/bench/results.py ``rate``: the end-to-end
    entry where there is one, else update-bound); ``source`` names the file, the FPS's kind and a path other than
    plain.
    """
    rows: list[dict[str, Any]] = []
    runs = results.runs
    if not runs.empty and "fps" in runs.columns:
        runs = runs[runs["fps"].notna()]
        chosen = runs[runs["experiment"].isin(experiments)]
        if chosen.empty and fallback:
            chosen = runs
        for r in chosen.to_dict("records"):
            path = str(r.get("speedup") or "plain")
            source = f"runs ({r['experiment']})"
            rows.append({"method": r["method"], "batch_size": r["batch_size"], "fps": float(r["fps"]),
                         "hardware": hardware_label(r.get("device"), r.get("cpu"), r.get("host")),
                         "source": source if path == "plain" else f"{source} [{path}]", "task": r["task"],
                         "speedup": path})
    for bench in results.benches:
        if bench.kind != ONLINE:
            continue
        hw = bench.hardware or hardware_label(bench.device)
        for agent, batch, path in settings(bench):
            found = rate(bench, agent, batch, path)
            if found is None:
                continue
            source = f"bench {bench.name} ({found.source})"
            rows.append({"method": agent_label(agent), "batch_size": batch, "fps": found.fps, "hardware": hw,
                         "source": source if path == "plain" else f"{source} [{path}]", "task": None,
                         "speedup": path})
    return pd.DataFrame(rows, columns=["method", "batch_size", "fps", "hardware", "source", "task", "speedup"])
