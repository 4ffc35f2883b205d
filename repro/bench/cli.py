"""`repro bench`: time one agent update per algorithm and batch size, and the replay memory overhead.

Only ratios between measurements made in this one run are printed (speed-up path vs plain, one batch
size vs another, one algorithm vs another at the same batch, an offline learner vs DrQ-v2): a ratio
against a figure measured on another machine or in another process says nothing. To compare with the
upstream code, time both side by side on one machine (docs/performance.md). Results are saved as JSON
under ``{results_root}/bench/`` for the speed tables (T4, T5).

``--e2e`` times a short real training loop phase by phase (repro/bench/e2e.py) into the same JSON's ``e2e``;
``--offline`` times each offline learner against the online DrQ-v2 update (repro/bench/offline_update.py);
``--offline-data`` a dataset's load time, memory and sampling speed against the online buffer
(repro/bench/data.py).
"""

from __future__ import annotations

import json
import platform
import socket
import time
from pathlib import Path
from typing import Optional

import typer

from repro.bench.online_update import time_update
from repro.runs.console import fail
from repro.runs.fsutil import atomic_write_text


def replay_memory_ratio(capacity: int = 100_000, action_dim: int = 12) -> dict:
    """Bytes held by the replay buffer over the raw bytes of its frames."""
    from repro.data.replay import ReplayBuffer

    buf = ReplayBuffer(capacity, (3, 84, 84), action_dim, frame_stack=3, nstep=3, K=3, discount=0.99, seed=0)
    return {"capacity": capacity, "buffer_bytes": buf.nbytes(), "frame_bytes": buf.frame_bytes(),
            "ratio": round(buf.nbytes() / buf.frame_bytes(), 5)}


def hardware(device: str) -> str:
    import torch

    if device.startswith("cuda") and torch.cuda.is_available():
        return torch.cuda.get_device_name(0)
    from repro.runs.rundir import _cpu_model

    return f"{_cpu_model()} ({torch.get_num_threads()} threads)"


def same_run_ratios(plain_seconds: dict[tuple[str, int], float]) -> dict[str, float]:
    """Ratios of update times measured in one run, keyed ``{algo}_b{batch}_over_{algo}_b{batch}``: each
    algorithm's batch sizes against its smallest one, TACO against DrQ-v2 at each shared batch size, and
    TACO B1024 over DrQ-v2 B256 (the paper's own batch sizes)."""
    ratios: dict[str, float] = {}

    def put(a: tuple[str, int], b: tuple[str, int]) -> None:
        ratios[f"{a[0]}_b{a[1]}_over_{b[0]}_b{b[1]}"] = round(plain_seconds[a] / plain_seconds[b], 3)

    algos = sorted({a for a, _ in plain_seconds}, reverse=True)  # taco before drqv2: ratios above 1
    sizes = {a: sorted(b for x, b in plain_seconds if x == a) for a in algos}
    for a in algos:
        for b in sizes[a][1:]:
            put((a, b), (a, sizes[a][0]))
    for i, a in enumerate(algos):
        for other in algos[i + 1:]:
            for b in sorted(set(sizes[a]) & set(sizes[other])):
                put((a, b), (other, b))
    if ("taco", 1024) in plain_seconds and ("drqv2", 256) in plain_seconds:
        put(("taco", 1024), ("drqv2", 256))
    return ratios


def _ratio_text(name: str, value: float) -> str:
    num, den = (part.replace("_b", " B") for part in name.split("_over_"))
    return f"{num} / {den} update time: {value:.2f}x (measured in this run)"


def run_bench(configs: list[tuple[str, int]], repeats: int, device: str, out_dir: Path,
              echo=print, speedups: tuple[str, ...] = (), warmup: int = 1) -> dict:
    """Time every (algo, batch) plain and with each speed-up, print the same-run ratios, write the JSON."""
    import torch

    results = []
    plain_seconds: dict[tuple[str, int], float] = {}
    rows = [row for algo, bs in configs
            for row in time_update(algo, bs, repeats=repeats, device=device, speedups=speedups, warmup=warmup)]
    for row in rows:
        algo, bs, speedup = row["algo"], row["batch_size"], row["speedup"]
        if speedup == "plain":
            plain_seconds[(algo, bs)] = row["update_seconds"]
            echo(f"{algo:>6} batch {bs:>5}: {row['update_seconds']:.3f} s/update, ~{row['fps_estimate']:.1f} fps "
                 f"(update-bound; {warmup} warm-up + {repeats} timed updates, median)")
        else:
            row["speedup_vs_plain"] = round(plain_seconds[(algo, bs)] / row["update_seconds"], 3)
            echo(f"{algo:>6} batch {bs:>5} {speedup}: {row['update_seconds']:.3f} s/update, "
                 f"{row['speedup_vs_plain']:.2f}x the plain path (measured in this run, updates alternated)")
        results.append(row)
    ratios = same_run_ratios(plain_seconds)
    for name, value in ratios.items():
        echo(_ratio_text(name, value))
    memory = replay_memory_ratio()
    echo(f"replay memory / raw frame bytes: {memory['ratio']:.4f} (target <= 1.10)")
    report = {"hardware": hardware(device), "device": device, "host": socket.gethostname(),
              "torch": torch.__version__, "python": platform.python_version(), "results": results,
              "ratios": ratios, "replay_memory": memory, "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    path = bench_path(out_dir, device)
    e2e = _read_existing(path).get("e2e")
    if e2e:
        report["e2e"] = e2e  # the --e2e entries of an earlier run stay (each has its own time)
    _write_report(out_dir, path.name, report, echo)
    return report


def bench_path(out_dir: Path, device: str) -> Path:
    """The bench file of this host and device, read by the speed tables and `repro plan`."""
    return out_dir / f"bench-{socket.gethostname()}-{device.split(':')[0]}.json"


def _read_existing(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return {}
    return data if isinstance(data, dict) else {}


def e2e_key(entry: dict) -> tuple:
    return (entry["algo"], entry["batch_size"], entry.get("profile"), entry.get("speedup", "plain"),
            entry.get("phase_sync", True))


def run_e2e_bench(configs: list[tuple[str, Optional[int]]], device: str, out_dir: Path, frames: int,
                  speedups: tuple[str, ...] = (), warmup: int = 1, task: str = "cheetah_run",
                  seed_frames: Optional[int] = None, echo=print, meta: Optional[dict] = None,
                  overlap: bool = False) -> list[dict]:
    """Time each (algo, batch; None: the tiny profile) on every path with :func:`repro.bench.e2e.run_e2e` and
    put the entries under ``e2e`` of the bench file (an entry of the same algo, batch, profile, path and phase
    timing replaced, the update results kept). ``overlap``: each timed as it trains instead (``phase_sync`` false)."""
    from repro.bench.e2e import PHASES, run_e2e

    entries = []
    for speedup in ("plain", *speedups):
        for algo, bs in configs:
            e = run_e2e(algo, bs, device, speedup, frames=frames, task=task, warmup=warmup, seed_frames=seed_frames,
                        phase_sync=not overlap)
            entries.append(e)
            what = f"profile {e['profile']} B{e['batch_size']}" if e["profile"] else f"B{e['batch_size']}"
            shares = ", ".join(f"{k} {e['phases'][k]:.2f}s" for k in PHASES)
            timing = ", as it trains (phases not synchronized)" if overlap else ""
            echo(f"{algo:>6} {what} {speedup}{timing}: {e['frames']} frames in {e['seconds']:.2f} s, "
                 f"{e['fps']:.1f} fps ({shares}; {e['updates']} updates, evaluation excluded)")
    path = bench_path(out_dir, device)
    report = _read_existing(path) or {"results": []}
    report.update(meta or {})
    new = {e2e_key(e) for e in entries}
    report["e2e"] = [e for e in report.get("e2e", []) if e2e_key(e) not in new] + entries
    _write_report(out_dir, path.name, report, echo)
    return entries


def _write_report(out_dir: Path, name: str, report: dict, echo=print) -> Path:
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / name
    atomic_write_text(path, json.dumps(report, indent=2) + "\n")
    echo(f"wrote {path}")
    return path


def register(app: typer.Typer) -> None:
    @app.command()
    def bench(batch: Optional[list[int]] = typer.Option(
                  None, "--batch", help="Batch sizes (default 256 1024; --offline and --offline-data: 256)."),
              algo: Optional[list[str]] = typer.Option(
                  None, "--algo", help="Online agent files (default taco and drqv2; any agent whose learner trains "
                  "online, a plugin's too)."),
              repeats: int = typer.Option(2, "--repeats", "--iters", min=1,
                                          help="Timed updates per setting (median reported)."),
              warmup: int = typer.Option(1, min=0, help="Untimed warm-up updates before the timed ones."),
              device: str = typer.Option("cpu", help="cpu or cuda."),
              amp: bool = typer.Option(False, "--amp", help="Also time agent.amp=true (ratio to plain)."),
              compile_: bool = typer.Option(False, "--compile", help="Also time agent.compile=true (ratio to plain)."),
              fast: bool = typer.Option(False, "--fast", help="Also time agent.fast=true (ratio to plain)."),
              offline: bool = typer.Option(False, "--offline", help="Instead: one update of each offline learner "
                                           "as a ratio to the DrQ-v2 update, measured side by side."),
              learner: Optional[list[str]] = typer.Option(
                  None, "--learner", help="With --offline: these agent files only (default: every agent file whose "
                                       "learner trains offline, plugins' included)."),
              dt_batch: Optional[int] = typer.Option(
                  None, "--dt-batch", help="With --offline: batch of learners with their own (default: DT's 64)."),
              offline_data: bool = typer.Option(False, "--offline-data", help="Instead: load time, memory and "
                                                "batches/s of a synthetic dataset against the online buffer."),
              transitions: int = typer.Option(100_000, "--transitions", help="With --offline-data: dataset size."),
              episode_length: int = typer.Option(500, "--episode-length",
                                                 help="With --offline-data: transitions per episode."),
              sample_batches: int = typer.Option(50, "--sample-batches",
                                                 help="With --offline-data: batches sampled from each buffer."),
              e2e: bool = typer.Option(False, "--e2e", help="Instead: a short real training loop (env step, "
                                       "render, replay sample, update, act; no evaluation) timed per phase; without "
                                       "--batch the main job's tiny profile."),
              frames: int = typer.Option(100, "--frames", help="With --e2e: timed frames after the seed frames."),
              seed_frames: Optional[int] = typer.Option(
                  None, "--seed-frames", help="With --e2e: untimed frames first (default: the config's)."),
              task: str = typer.Option("cheetah_run", "--task", help="With --e2e: the task."),
              overlap: bool = typer.Option(False, "--overlap", help="With --e2e: time each path as it trains instead, "
                                           "the phases not synchronized with the device (against the synchronized "
                                           "entry: what the env step's overlap with the queued update gains)."),
              roofline: bool = typer.Option(False, "--roofline", help="Instead: the update's FLOPs (torch's FLOP "
                                            "counter) over its time against this process's measured fp32 and bf16 "
                                            "convolution peak, and the kernels that keep it from the peak (default "
                                            "TACO B256; --amp/--compile add paths)."),
              results_root: Path = typer.Option(Path("runs"), "--results", help="Results root (writes bench/).")):
        """Time one update of TACO and DrQ-v2 at batch 256 and 1024; print same-run ratios and replay memory.
        With --offline: each offline learner against DrQ-v2; with --offline-data: dataset load and sampling;
        with --e2e: a short training loop timed per phase (env step, render, replay sample, update, act) and FPS."""
        import torch

        from repro.bench.data import run_data_bench
        from repro.bench.offline_update import run_offline_bench
        from repro.config.compose import close_matches, offline_agents, online_agents

        if device.startswith("cuda") and not torch.cuda.is_available():
            fail("--device cuda but no CUDA device is available")
        online = online_agents() if algo else ()
        for a in algo or []:
            if a not in online:
                fail(f"unknown online agent '{a}'.{close_matches(a, online)}")
        if any(b < 1 for b in batch or []):
            fail("--batch must be >= 1")
        agents = offline_agents() if offline and learner else ()
        for name in learner or []:
            if name not in agents:
                fail(f"unknown offline learner '{name}' ({', '.join(agents)})")
        if dt_batch is not None and dt_batch < 1:
            fail("--dt-batch must be >= 1")
        if transitions < 1 or sample_batches < 1 or episode_length < 3:
            fail("--transitions and --sample-batches must be >= 1, --episode-length >= 3")
        if frames < 1 or (seed_frames is not None and seed_frames < 0):
            fail("--frames must be >= 1 and --seed-frames >= 0")
        if overlap and not e2e:
            fail("--overlap times the --e2e loop: add --e2e")
        if e2e and (offline or offline_data):
            fail("--e2e times the online loop: drop --offline / --offline-data")
        if roofline and (offline or offline_data or e2e):
            fail("--roofline times the online update: drop --offline / --offline-data / --e2e")
        if e2e:
            from repro.envs import TASKS

            if task not in TASKS:
                fail(f"unknown task '{task}'")
        out_dir, host, dev = results_root / "bench", socket.gethostname(), device.split(":")[0]
        meta = {"hardware": hardware(device), "device": device, "host": host, "torch": torch.__version__,
                "python": platform.python_version(), "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
        if offline:
            report = run_offline_bench((batch or [256])[0], repeats, warmup, device, learner or None,
                                       echo=typer.echo, own_batch=dt_batch)
            _write_report(out_dir, f"bench-offline-{host}-{dev}.json", {**meta, **report}, typer.echo)
        if offline_data:
            data = run_data_bench(transitions, (batch or [256])[0], sample_batches, episode_length, echo=typer.echo)
            _write_report(out_dir, f"bench-offline-data-{host}.json", {**meta, **data}, typer.echo)
        if offline or offline_data:
            return
        speedups = tuple(name for name, on in (("amp", amp), ("compile", compile_), ("fast", fast)) if on)
        if roofline:
            from repro.bench.roofline import run_roofline

            entries = [run_roofline(a, b, speedups, device, repeats, warmup, echo=typer.echo)
                       for a in (algo or ["taco"]) for b in (batch or [256])]
            _write_report(out_dir, f"bench-roofline-{host}-{dev}.json", {**meta, "roofline": entries}, typer.echo)
            return
        if e2e:
            sizes: list[Optional[int]] = list(batch) if batch else [None]
            run_e2e_bench([(a, b) for a in (algo or ["taco", "drqv2"]) for b in sizes], device, out_dir, frames,
                          speedups, warmup, task, seed_frames, echo=typer.echo, meta=meta, overlap=overlap)
            return
        configs = [(a, b) for a in (algo or ["taco", "drqv2"]) for b in (batch or [256, 1024])]
        run_bench(configs, repeats, device, out_dir, echo=typer.echo, speedups=speedups, warmup=warmup)
