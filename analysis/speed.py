"""Measured training speed (frames per second) from runs (train.csv ``fps``) and benchmark JSONs."""

from __future__ import annotations

import math
from typing import Any

import pandas as pd

from analysis.identity import algo_label
from analysis.load import Results


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
    """One row per measurement: method, batch_size, fps, hardware, source, speedup.

    Runs of the ``speed`` experiment are used if there are any, otherwise (if ``fallback``) every run
    with an FPS (each run's FPS is the median over training episodes once updates started). Benchmark rows are added as
    they are; ``speedup`` is the benchmark's code path ("plain", or e.g. "amp", "compile", shown in the
    source) and "plain" for runs.
    """
    rows: list[dict[str, Any]] = []
    runs = results.runs
    if not runs.empty and "fps" in runs.columns:
        runs = runs[runs["fps"].notna()]
        chosen = runs[runs["experiment"].isin(experiments)]
        if chosen.empty and fallback:
            chosen = runs
        for r in chosen.itertuples(index=False):
            rows.append(
                {
                    "method": r.method,
                    "batch_size": r.batch_size,
                    "fps": float(r.fps),
                    "hardware": hardware_label(r.device, r.cpu, r.host),
                    "source": f"runs ({r.experiment})",
                    "task": r.task,
                    "speedup": "plain",
                }
            )
    for bench in results.benches:
        hw = bench.get("hardware")
        hw_text = (
            hw
            if isinstance(hw, str)
            else (hardware_label(hw.get("device"), hw.get("cpu")) if isinstance(hw, dict) else "unknown hardware")
        )
        for res in bench.get("results", []):
            if not isinstance(res, dict) or "algo" not in res:
                continue
            fps = res.get("fps_estimate", res.get("fps"))
            if fps is None:
                continue
            speedup = str(res.get("speedup") or "plain")
            source = "bench " + str(bench.get("path", "")).rsplit("/", 1)[-1]
            rows.append(
                {
                    "method": algo_label(res["algo"]),
                    "batch_size": res.get("batch_size"),
                    "fps": float(fps),
                    "hardware": hw_text,
                    "source": source if speedup == "plain" else f"{source} [{speedup}]",
                    "task": res.get("task"),
                    "speedup": speedup,
                }
            )
    return pd.DataFrame(rows, columns=["method", "batch_size", "fps", "hardware", "source", "task", "speedup"])
