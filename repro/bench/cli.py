"""`repro bench`: time one agent update per algorithm and batch size, and the replay memory overhead.

Only ratios between measurements made in this one run are printed (speed-up path vs plain, one batch
size vs another, one algorithm vs another at the same batch, an offline learner vs DrQ-v2): a ratio
against a figure measured on another machine or in another process says nothing. To compare with the
upstream code, time both side by side on one machine (docs/performance.md). Results are saved as JSON
under ``{results_root}/bench/`` for the speed tables (T4, T5).

Subcommands: ``update`` (one update of each online agent, the default), ``e2e`` (a short real training run phase by
phase, repro/bench/e2e.py, into the same JSON's ``e2e``), ``offline`` (each offline learner against the online
DrQ-v2 update, repro/bench/offline_update.py), ``data`` (a dataset's load time, memory and sampling speed against the
online buffer, repro/bench/data.py), ``roofline``. The one-command form of earlier versions (``repro bench --e2e``,
``--offline``, ``--offline-data``, ``--roofline``) still works and prints one line naming the new form. Every file is
written through repro/bench/results.py.
"""

from __future__ import annotations

import json
import platform
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Optional

import typer

from repro.bench import results as results_file
from repro.bench.online_update import time_update
from repro.runs.console import fail
from repro.runs.fsutil import atomic_write_text, writable_folder


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
    from repro.runs.rundir import cpu_model

    return f"{cpu_model()} ({torch.get_num_threads()} threads)"


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
              echo: Callable[[str], None] = print, speedups: tuple[str, ...] = (), warmup: int = 1) -> dict:
    """Time every (algo, batch) plain and with each speed-up, print the same-run ratios, write the JSON."""
    results = []
    plain_seconds: dict[tuple[str, int], float] = {}
    rows = [row for algo, bs in configs
            for row in time_update(algo, bs, repeats=repeats, device=device, speedups=speedups, warmup=warmup)]
    for row in rows:
        algo, bs, speedup = row["agent"], row["batch_size"], row["speedup"]
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
    path = bench_path(out_dir, device)
    bench = results_file.read_or_new(path, results_file.ONLINE, device)  # the e2e entries of an earlier run stay
    bench.hardware = hardware(device)
    bench.updates = [results_file.UpdateEntry.read(r) for r in results]
    bench.rest.update({**run_meta(device), "ratios": ratios, "replay_memory": memory})
    _write(out_dir, bench, echo)
    return bench.to_json()


def run_meta(device: str) -> dict[str, Any]:
    """What every bench file records of the run that wrote it (besides its hardware)."""
    import torch

    return {"host": socket.gethostname(), "torch": torch.__version__, "python": platform.python_version(),
            "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def bench_path(out_dir: Path, device: str) -> Path:
    """The bench file of this host and device, read by the speed tables and `repro plan`."""
    return out_dir / results_file.file_name(results_file.ONLINE, device)


def run_e2e_bench(configs: list[tuple[str, Optional[int]]], device: str, out_dir: Path, frames: int,
                  speedups: tuple[str, ...] = (), warmup: int = 1, task: str = "cheetah_run",
                  seed_frames: Optional[int] = None, echo: Callable[[str], None] = print,
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
    bench = results_file.read_or_new(path, results_file.ONLINE, device)
    bench.hardware = hardware(device)
    bench.rest.update(run_meta(device))
    bench.put_e2e(results_file.E2EEntry.read(e) for e in entries)
    _write(out_dir, bench, echo)
    return entries


def _write(out_dir: Path, bench: results_file.BenchFile, echo: Callable[[str], None] = print) -> Path:
    """Write ``bench`` (its kind's file of this host and device) in today's format."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / results_file.file_name(bench.kind, bench.device)
    atomic_write_text(path, json.dumps(bench.to_json(), indent=2) + "\n")
    echo(f"wrote {path}")
    return path


# ---------------------------------------------------------------- the command line
def _writable(root: Path) -> Path:
    """``--results`` checked before any timing (fsutil's one rule for an output folder): one line, exit 2."""
    writable_folder(root, "--results")
    return root


# The options every subcommand that times an agent shares
RESULTS = typer.Option(Path("runs"), "--results", help="Results root (writes bench/).", callback=_writable)
DEVICE = typer.Option("cpu", "--device", help="cpu or cuda.")
REPEATS = typer.Option(2, "--repeats", "--iters", help="Timed updates per setting (median reported).")
WARMUP = typer.Option(1, "--warmup", help="Untimed warm-up updates before the timed ones.")
AMP = typer.Option(False, "--amp", help="Also time agent.amp=true (ratio to plain).")
COMPILE = typer.Option(False, "--compile", help="Also time agent.compile=true (ratio to plain).")
FAST = typer.Option(False, "--fast", help="Also time agent.fast=true (ratio to plain).")
ALGO_HELP = "Online agent files (default taco and drqv2; any agent whose learner trains online, a plugin's too)."


def _paths(amp: bool, compile_: bool, fast: bool) -> tuple[str, ...]:
    return tuple(name for name, on in (("amp", amp), ("compile", compile_), ("fast", fast)) if on)


def _check_common(device: str, batch: Optional[list[int]], repeats: int, warmup: int) -> None:
    import torch

    if device.split(":")[0] not in ("cpu", "cuda"):
        fail(f"--device must be cpu or cuda (got {device!r})")
    if device.startswith("cuda") and not torch.cuda.is_available():
        fail("--device cuda but no CUDA device is available")
    if any(b < 1 for b in batch or []):
        fail("--batch must be >= 1")
    if repeats < 1 or warmup < 0:
        fail("--repeats must be >= 1 and --warmup >= 0")


def _check_algos(algo: Optional[list[str]]) -> None:
    from repro.config.compose import close_matches, online_agents

    online = online_agents() if algo else ()
    for a in algo or []:
        if a not in online:
            fail(f"unknown online agent '{a}'.{close_matches(a, online)}")


def _new_file(kind: str, device: str, rest: dict[str, Any]) -> results_file.BenchFile:
    return results_file.BenchFile(kind, device.split(":")[0], hardware(device), rest={**run_meta(device), **rest})


def update_cmd(algo: Optional[list[str]] = typer.Option(None, "--algo", help=ALGO_HELP),
               batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256 1024)."),
               repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE, amp: bool = AMP,
               compile_: bool = COMPILE, fast: bool = FAST, results_root: Path = RESULTS) -> None:
    """Time one update of each online agent (default TACO and DrQ-v2 at batch 256 and 1024) on the plain path and
    each speed-up path asked for, alternated; print same-run ratios and the replay memory."""
    _check_common(device, batch, repeats, warmup)
    _check_algos(algo)
    configs = [(a, b) for a in (algo or ["taco", "drqv2"]) for b in (batch or [256, 1024])]
    run_bench(configs, repeats, device, results_root / "bench", echo=typer.echo, speedups=_paths(amp, compile_, fast),
              warmup=warmup)


def e2e_cmd(algo: Optional[list[str]] = typer.Option(None, "--algo", help=ALGO_HELP),
            batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes at the agent's own "
                                                      "settings (default: the main job's tiny profile)."),
            frames: int = typer.Option(100, "--frames", help="Timed frames after the seed frames."),
            seed_frames: Optional[int] = typer.Option(None, "--seed-frames", help="Untimed frames first (default: "
                                                      "the config's)."),
            task: str = typer.Option("cheetah_run", "--task", help="The task."),
            overlap: bool = typer.Option(False, "--overlap", help="Time each path as it trains instead, the phases "
                                         "not synchronized with the device (against the synchronized entry: what the "
                                         "env step's overlap with the queued update gains)."),
            warmup: int = WARMUP, device: str = DEVICE, amp: bool = AMP, compile_: bool = COMPILE, fast: bool = FAST,
            results_root: Path = RESULTS) -> None:
    """A short real training run (the online loop itself, no evaluation) timed per phase: env step, render,
    replay sample, update, act; and its FPS."""
    from repro.envs import TASKS

    _check_common(device, batch, 1, warmup)
    _check_algos(algo)
    if frames < 1 or (seed_frames is not None and seed_frames < 0):
        fail("--frames must be >= 1 and --seed-frames >= 0")
    if task not in TASKS:
        fail(f"unknown task '{task}'")
    sizes: list[Optional[int]] = list(batch) if batch else [None]
    run_e2e_bench([(a, b) for a in (algo or ["taco", "drqv2"]) for b in sizes], device, results_root / "bench",
                  frames, _paths(amp, compile_, fast), warmup, task, seed_frames, echo=typer.echo, overlap=overlap)


def offline_cmd(learner: Optional[list[str]] = typer.Option(
                    None, "--learner", help="These agent files only (default: every agent file whose learner trains "
                    "offline, plugins' included)."),
                batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch size (default 256)."),
                dt_batch: Optional[int] = typer.Option(None, "--dt-batch", help="Batch of learners with their own "
                                                       "(default: DT's 64)."),
                repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE,
                results_root: Path = RESULTS) -> None:
    """One update of each offline learner as a ratio to the DrQ-v2 update, measured side by side."""
    from repro.bench.offline_update import run_offline_bench
    from repro.config.compose import offline_agents

    _check_common(device, batch, repeats, warmup)
    agents = offline_agents() if learner else ()
    for name in learner or []:
        if name not in agents:
            fail(f"unknown offline learner '{name}' ({', '.join(agents)})")
    if dt_batch is not None and dt_batch < 1:
        fail("--dt-batch must be >= 1")
    report = run_offline_bench((batch or [256])[0], repeats, warmup, device, learner or None, echo=typer.echo,
                               own_batch=dt_batch)
    bench = _new_file(results_file.OFFLINE, device, {k: v for k, v in report.items() if k not in ("results", "device")})
    bench.offline = [results_file.OfflineEntry.read(r) for r in report["results"]]
    _write(results_root / "bench", bench, typer.echo)


def data_cmd(transitions: int = typer.Option(100_000, "--transitions", help="Dataset size."),
             episode_length: int = typer.Option(500, "--episode-length", help="Transitions per episode."),
             sample_batches: int = typer.Option(50, "--sample-batches", help="Batches sampled from each buffer."),
             batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch size (default 256)."),
             results_root: Path = RESULTS) -> None:
    """Load time, memory and batches/s of a synthetic dataset against the online buffer."""
    from repro.bench.data import run_data_bench

    _check_common("cpu", batch, 1, 0)
    if transitions < 1 or sample_batches < 1 or episode_length < 3:
        fail("--transitions and --sample-batches must be >= 1, --episode-length >= 3")
    data = run_data_bench(transitions, (batch or [256])[0], sample_batches, episode_length, echo=typer.echo)
    bench = _new_file(results_file.DATA, "cpu", {k: v for k, v in data.items() if k not in results_file.DATA_KEYS})
    bench.data = results_file.DataEntry.read({k: v for k, v in data.items() if k in results_file.DATA_KEYS})
    _write(results_root / "bench", bench, typer.echo)


def roofline_cmd(algo: Optional[list[str]] = typer.Option(None, "--algo", help="Online agent files (default taco)."),
                 batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256)."),
                 repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE, amp: bool = AMP,
                 compile_: bool = COMPILE, fast: bool = FAST, results_root: Path = RESULTS) -> None:
    """The update's FLOPs (torch's FLOP counter) over its time against this process's measured fp32 and bf16
    convolution peak, and the kernels that keep it from the peak."""
    from repro.bench.roofline import run_roofline

    _check_common(device, batch, repeats, warmup)
    _check_algos(algo)
    entries = [run_roofline(a, b, _paths(amp, compile_, fast), device, repeats, warmup, echo=typer.echo)
               for a in (algo or ["taco"]) for b in (batch or [256])]
    _write(results_root / "bench", _new_file(results_file.ROOFLINE, device, {"roofline": entries}), typer.echo)


SUBCOMMANDS: dict[str, Callable[..., None]] = {"update": update_cmd, "e2e": e2e_cmd, "offline": offline_cmd,
                                               "data": data_cmd, "roofline": roofline_cmd}
# The old flags' modes -> their subcommand (`repro bench --e2e ...` is `repro bench e2e ...`)
OLD_MODES = (("offline", "offline"), ("offline_data", "data"), ("e2e", "e2e"), ("roofline", "roofline"))
# The options of the old single command each mode's subcommand takes (the rest belong to other modes)
MODE_OPTIONS = {
    "update": ("algo", "batch", "repeats", "warmup", "device", "amp", "compile_", "fast", "results_root"),
    "e2e": ("algo", "batch", "frames", "seed_frames", "task", "overlap", "warmup", "device", "amp", "compile_", "fast",
            "results_root"),
    "offline": ("learner", "batch", "dt_batch", "repeats", "warmup", "device", "results_root"),
    "data": ("transitions", "episode_length", "sample_batches", "batch", "results_root"),
    "roofline": ("algo", "batch", "repeats", "warmup", "device", "amp", "compile_", "fast", "results_root"),
}


def _flag(name: str) -> str:
    """The command-line flag of parameter ``name``."""
    return "--" + {"results_root": "results"}.get(name, name.rstrip("_").replace("_", "-"))


def _as_args(name: str, value: Any) -> str:
    """Parameter ``name`` at ``value`` as command-line arguments."""
    if isinstance(value, bool):
        return _flag(name) if value else ""
    if isinstance(value, (list, tuple)):
        return " ".join(f"{_flag(name)} {v}" for v in value)
    return f"{_flag(name)} {value}"


def legacy(ctx: typer.Context,
           batch: Optional[list[int]] = typer.Option(None, "--batch", hidden=True),
           algo: Optional[list[str]] = typer.Option(None, "--algo", hidden=True),
           repeats: int = typer.Option(2, "--repeats", "--iters", hidden=True),
           warmup: int = typer.Option(1, "--warmup", hidden=True),
           device: str = typer.Option("cpu", "--device", hidden=True),
           amp: bool = typer.Option(False, "--amp", hidden=True),
           compile_: bool = typer.Option(False, "--compile", hidden=True),
           fast: bool = typer.Option(False, "--fast", hidden=True),
           offline: bool = typer.Option(False, "--offline", hidden=True),
           learner: Optional[list[str]] = typer.Option(None, "--learner", hidden=True),
           dt_batch: Optional[int] = typer.Option(None, "--dt-batch", hidden=True),
           offline_data: bool = typer.Option(False, "--offline-data", hidden=True),
           transitions: int = typer.Option(100_000, "--transitions", hidden=True),
           episode_length: int = typer.Option(500, "--episode-length", hidden=True),
           sample_batches: int = typer.Option(50, "--sample-batches", hidden=True),
           e2e: bool = typer.Option(False, "--e2e", hidden=True),
           frames: int = typer.Option(100, "--frames", hidden=True),
           seed_frames: Optional[int] = typer.Option(None, "--seed-frames", hidden=True),
           task: str = typer.Option("cheetah_run", "--task", hidden=True),
           overlap: bool = typer.Option(False, "--overlap", hidden=True),
           roofline: bool = typer.Option(False, "--roofline", hidden=True),
           results_root: Path = typer.Option(Path("runs"), "--results", hidden=True)) -> None:
    """Time what training costs on this machine: `repro bench update` (one update of each online agent, the
    default), `e2e` (a short training run per phase), `offline` (each offline learner), `data` (a dataset's load and
    sampling), `roofline` (the update's FLOP rate). Files under RESULTS/bench/ read by `repro plan` and the speed
    tables (docs/performance.md). The options of the one-command form (`repro bench --e2e ...`) still work."""
    # by name: typer's context may come with its own copy of click's ParameterSource
    given = {name for name in ctx.params if getattr(ctx.get_parameter_source(name), "name", "") == "COMMANDLINE"}
    if ctx.invoked_subcommand is not None:
        if given:
            first = _flag(sorted(given)[0])
            fail(f"options go after the subcommand: `repro bench {ctx.invoked_subcommand} {first} ...`")
        return
    values = dict(ctx.params)
    modes = [sub for flag, sub in OLD_MODES if values[flag]]
    if overlap and not e2e:
        fail("--overlap times the --e2e loop: add --e2e")
    if e2e and (offline or offline_data):
        fail("--e2e times the online loop: drop --offline / --offline-data")
    if roofline and (offline or offline_data or e2e):
        fail("--roofline times the online update: drop --offline / --offline-data / --e2e")
    # the one command ran --offline and --offline-data together: each its subcommand, in that order
    allowed = {n for sub in modes or ["update"] for n in MODE_OPTIONS[sub]} | {flag for flag, _ in OLD_MODES}
    stray = sorted(given - allowed)
    if stray:
        fail(f"{_flag(stray[0])} is not an option of `repro bench {' / '.join(modes or ['update'])}`")
    for sub in modes or ["update"]:
        kwargs = {n: values[n] for n in MODE_OPTIONS[sub]}
        SUBCOMMANDS[sub](**kwargs)
    if given:
        for sub in modes or ["update"]:
            args = " ".join(a for n in MODE_OPTIONS[sub] if n in given for a in [_as_args(n, values[n])] if a)
            new = f"repro bench {sub} {args}".strip()
            typer.echo(f"note: the new form of this command is `{new}` (`repro bench --help`)")


def register(app: typer.Typer) -> None:
    """Add ``bench`` and its subcommands to ``app``."""
    bench = typer.Typer(no_args_is_help=False)
    bench.callback(invoke_without_command=True)(legacy)
    for name, command in SUBCOMMANDS.items():
        bench.command(name)(command)
    app.add_typer(bench, name="bench")
