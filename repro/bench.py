"""`repro bench`: time one agent update per algorithm and batch size, and the replay memory overhead.

Results are reported as ratios measured in one run (no timed unit tests) and saved as JSON under
``{results_root}/bench/`` for the speed tables (T4, T5).
"""

from __future__ import annotations

import json
import platform
import socket
import statistics
import time
from pathlib import Path
from typing import Optional

import torch
import typer

from repro.fsutil import atomic_write_text

# Seconds per update measured for the upstream code on a 2-core CPU (../shared/docs/upstream.md).
UPSTREAM_CPU_SECONDS = {("taco", 1024): 30.0, ("drqv2", 1024): 11.5, ("taco", 256): 6.7}


def _batch(B: int, K: int, A: int, device: str) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    u8 = lambda: torch.randint(0, 256, (B, 9, 84, 84), dtype=torch.uint8, generator=g).to(device)  # noqa: E731
    return {"obs": u8(), "next_obs": u8(), "future_obs": u8(),
            "action": (torch.rand(B, A, generator=g) * 2 - 1).to(device),
            "action_seq": (torch.rand(B, K, A, generator=g) * 2 - 1).to(device),
            "reward": torch.rand(B, 1, generator=g).to(device), "discount": torch.full((B, 1), 0.97, device=device),
            "reward_ksum": torch.rand(B, 1, generator=g).to(device)}


def time_update(algo: str, batch_size: int, task: str = "cheetah_run", repeats: int = 2,
                device: str = "cpu", speedup: str = "plain") -> dict:
    """Median wall-clock seconds of one full agent update (after one warm-up update)."""
    from repro.agent.agent import Agent
    from repro.config import compose, typed
    from repro.envs import get_task

    flags = {"plain": [], "amp": ["agent.amp=true"], "compile": ["agent.compile=true"]}[speedup]
    rc = typed(compose([f"agent={algo}", f"task={task}", f"agent.batch_size={batch_size}", *flags]))
    A = get_task(task).action_dim
    torch.manual_seed(0)
    agent = Agent(rc.agent, (9, 84, 84), A, device=device)
    batch = _batch(batch_size, rc.agent.K, A, device)
    agent.update(batch, step=10**6)
    times = []
    for _ in range(repeats):
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        agent.update(batch, step=10**6)
        if device.startswith("cuda"):
            torch.cuda.synchronize()
        times.append(time.perf_counter() - t0)
    seconds = statistics.median(times)
    # one update every 2 agent steps at action repeat 2 = 4 frames per update (update-bound estimate)
    fps = rc.train.update_every_steps * rc.env.action_repeat / seconds
    return {"algo": algo, "batch_size": batch_size, "speedup": speedup, "update_seconds": round(seconds, 4),
            "fps_estimate": round(fps, 3), "repeats": repeats}


def replay_memory_ratio(capacity: int = 100_000, action_dim: int = 12) -> dict:
    """Bytes held by the replay buffer over the raw bytes of its frames."""
    from repro.replay import ReplayBuffer

    buf = ReplayBuffer(capacity, (3, 84, 84), action_dim, frame_stack=3, nstep=3, K=3, discount=0.99, seed=0)
    return {"capacity": capacity, "buffer_bytes": buf.nbytes(), "frame_bytes": buf.frame_bytes(),
            "ratio": round(buf.nbytes() / buf.frame_bytes(), 5)}


def hardware(device: str) -> str:
    if device.startswith("cuda") and torch.cuda.is_available():
        return torch.cuda.get_device_name(0)
    from repro.rundir import _cpu_model

    return f"{_cpu_model()} ({torch.get_num_threads()} threads)"


def run_bench(configs: list[tuple[str, int]], repeats: int, device: str, out_dir: Path,
              echo=print, speedups: tuple[str, ...] = ()) -> dict:
    results = []
    plain_seconds: dict[tuple[str, int], float] = {}
    for algo, bs, speedup in [(a, b, "plain") for a, b in configs] + [(a, b, s) for s in speedups
                                                                      for a, b in configs]:
        row = time_update(algo, bs, repeats=repeats, device=device, speedup=speedup)
        if speedup == "plain":
            plain_seconds[(algo, bs)] = row["update_seconds"]
        else:
            row["speedup_vs_plain"] = round(plain_seconds[(algo, bs)] / row["update_seconds"], 3)
            results.append(row)
            echo(f"{algo:>6} batch {bs:>5} {speedup}: {row['update_seconds']:.3f} s/update, "
                 f"{row['speedup_vs_plain']:.2f}x the plain path")
            continue
        upstream = UPSTREAM_CPU_SECONDS.get((algo, bs))
        if upstream is not None and device == "cpu":
            row["upstream_cpu_seconds"] = upstream
            row["speedup_vs_upstream"] = round(upstream / row["update_seconds"], 3)
        results.append(row)
        echo(f"{algo:>6} batch {bs:>5}: {row['update_seconds']:.3f} s/update, ~{row['fps_estimate']:.1f} fps"
             + (f", {row['speedup_vs_upstream']:.2f}x upstream's CPU time" if "speedup_vs_upstream" in row else ""))
    by = plain_seconds
    ratios = {}
    if ("taco", 1024) in by and ("drqv2", 256) in by:
        ratios["taco1024_over_drqv2_256"] = round(by[("taco", 1024)] / by[("drqv2", 256)], 3)
        echo(f"TACO B1024 / DrQ-v2 B256 update time: {ratios['taco1024_over_drqv2_256']:.2f}x (paper: 130/35 = 3.7x in fps)")
    memory = replay_memory_ratio()
    echo(f"replay memory / raw frame bytes: {memory['ratio']:.4f} (target <= 1.10)")
    report = {"hardware": hardware(device), "device": device, "host": socket.gethostname(),
              "torch": torch.__version__, "python": platform.python_version(), "results": results,
              "ratios": ratios, "replay_memory": memory, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"bench-{socket.gethostname()}-{device.split(':')[0]}.json"
    atomic_write_text(path, json.dumps(report, indent=2) + "\n")
    echo(f"wrote {path}")
    return report


def register(app: typer.Typer) -> None:
    @app.command()
    def bench(batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256 1024)."),
              algo: Optional[list[str]] = typer.Option(None, "--algo", help="taco and/or drqv2 (default both)."),
              repeats: int = typer.Option(2, help="Timed updates per setting (median reported)."),
              device: str = typer.Option("cpu", help="cpu or cuda."),
              amp: bool = typer.Option(False, "--amp", help="Also time agent.amp=true (ratio to plain)."),
              compile_: bool = typer.Option(False, "--compile", help="Also time agent.compile=true (ratio to plain)."),
              results_root: Path = typer.Option(Path("runs"), "--results", help="Results root (writes bench/).")):
        """Time one update of TACO and DrQ-v2 at batch 256 and 1024; report ratios and replay memory."""
        if device.startswith("cuda") and not torch.cuda.is_available():
            typer.echo("error: --device cuda but no CUDA device is available", err=True)
            raise typer.Exit(2)
        for a in algo or []:
            if a not in ("taco", "drqv2"):
                typer.echo(f"error: unknown algo '{a}' (taco, drqv2)", err=True)
                raise typer.Exit(2)
        configs = [(a, b) for a in (algo or ["taco", "drqv2"]) for b in (batch or [256, 1024])]
        speedups = tuple(name for name, on in (("amp", amp), ("compile", compile_)) if on)
        run_bench(configs, repeats, device, results_root / "bench", echo=typer.echo, speedups=speedups)
