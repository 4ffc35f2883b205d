"""`repro bench`: time one agent update per agent and batch size, and the replay memory overhead.

Only ratios between measurements made in this one run are printed (speed-up path vs plain, one batch
size vs another, one agent vs another at the same batch, an offline learner vs DrQ-v2): a ratio
against a figure measured on another machine or in another process says nothing. To compare with the
upstream code, time both side by side on one machine (docs/performance.md). Results are saved as JSON
under ``{results_root}/bench/`` for `repro plan` and the speed tables (T4, T5).

Subcommands: ``update`` (one update of each online agent), ``e2e`` (a short real training run phase by phase,
repro/bench/e2e.py, into the same JSON's ``e2e``), ``offline`` (each offline learner against the online DrQ-v2 update,
repro/bench/offline_update.py), ``data`` (a dataset's load time, memory and sampling speed against the online buffer,
repro/bench/data.py), ``roofline``. Each names its agent files ``--agent``. Each prints a line per setting as it is
done (and a progress bar on a terminal, repro/bench/progress.py), records the machine's load average beside each
entry, and merges its entries into the file of this host and device (an entry of the same setting replaced, the
others kept). Every file is written through repro/bench/results.py.
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
from repro.bench.progress import Steps
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
    """Ratios of update times measured in one run, keyed ``{agent}_b{batch}_over_{agent}_b{batch}``: each
    agent's batch sizes against its smallest one, TACO against DrQ-v2 at each shared batch size, and
    TACO B1024 over DrQ-v2 B256 (the paper's own batch sizes)."""
    ratios: dict[str, float] = {}

    def put(a: tuple[str, int], b: tuple[str, int]) -> None:
        ratios[f"{a[0]}_b{a[1]}_over_{b[0]}_b{b[1]}"] = round(plain_seconds[a] / plain_seconds[b], 3)

    agents = sorted({a for a, _ in plain_seconds}, reverse=True)  # taco before drqv2: ratios above 1
    sizes = {a: sorted(b for x, b in plain_seconds if x == a) for a in agents}
    for a in agents:
        for b in sizes[a][1:]:
            put((a, b), (a, sizes[a][0]))
    for i, a in enumerate(agents):
        for other in agents[i + 1:]:
            for b in sorted(set(sizes[a]) & set(sizes[other])):
                put((a, b), (other, b))
    if ("taco", 1024) in plain_seconds and ("drqv2", 256) in plain_seconds:
        put(("taco", 1024), ("drqv2", 256))
    return ratios


def _ratio_text(name: str, value: float) -> str:
    num, den = (part.replace("_b", " B") for part in name.split("_over_"))
    return f"{num} / {den} update time: {value:.2f}x (measured in this run)"


def _load_text(row: dict[str, Any]) -> str:
    """The load recorded beside an entry, in words (and a warning when it was above the cores)."""
    if "load" not in row:
        return ""
    text = f"; load {row['load']:.1f} on {row['cores']} cores"
    return text + (", TIMED UNDER LOAD: rerun on an idle machine" if results_file.loaded(row["load"], row["cores"])
                   else "")


def _settings_text(configs: list[tuple[str, Any]], paths: tuple[str, ...]) -> str:
    what = ", ".join(f"{a} B{b}" if b is not None else f"{a} (tiny profile)" for a, b in configs)
    return f"{len(configs)} setting(s): {what}; paths {', '.join(('plain', *paths))}"


def run_bench(configs: list[tuple[str, int]], repeats: int, device: str, out_dir: Path,
              echo: Callable[[str], None] = print, paths: tuple[str, ...] = (), warmup: int = 1,
              progress: Optional[bool] = None) -> dict:
    """Time every (agent, batch) plain and on each of ``paths``, a line each as it is done (and a progress bar on a
    terminal: ``progress``), each entry with the machine's load then; print the same-run ratios; merge the entries
    into the bench file of this host and device (an entry of the same agent, batch and path replaced, the others
    kept)."""
    results = []
    plain_seconds: dict[tuple[str, int], float] = {}
    echo(f"timing {_settings_text(configs, paths)} ({warmup} warm-up + {repeats} timed updates each, median)")
    with Steps(len(configs), progress) as steps:
        for agent, bs in configs:
            with steps.item(f"{agent} B{bs} ({', '.join(('plain', *paths))})"):
                rows = time_update(agent, bs, repeats=repeats, device=device, paths=paths, warmup=warmup)
            load = results_file.machine_load()
            for row in rows:
                row.update(load)
                path = row["path"]
                if path == "plain":
                    plain_seconds[(agent, bs)] = row["update_seconds"]
                    echo(f"{agent:>6} batch {bs:>5}: {row['update_seconds']:.3f} s/update, ~{row['fps_estimate']:.1f} "
                         f"fps (update-bound; {warmup} warm-up + {repeats} timed updates, median{_load_text(row)})")
                else:
                    row["speedup_vs_plain"] = round(plain_seconds[(agent, bs)] / row["update_seconds"], 3)
                    echo(f"{agent:>6} batch {bs:>5} {path}: {row['update_seconds']:.3f} s/update, "
                         f"{row['speedup_vs_plain']:.2f}x the plain path (measured in this run, updates alternated)")
                results.append(row)
    ratios = same_run_ratios(plain_seconds)
    for name, value in ratios.items():
        echo(_ratio_text(name, value))
    memory = replay_memory_ratio()
    echo(f"replay memory / raw frame bytes: {memory['ratio']:.4f} (target <= 1.10)")
    bench = results_file.read_or_new(bench_path(out_dir, device), results_file.ONLINE, device)
    before = len(bench.updates) + len(bench.e2e)
    bench.hardware = hardware(device)
    bench.merge(updates=[results_file.UpdateEntry.read(r) for r in results])
    bench.rest.update({**run_meta(device), "ratios": ratios, "replay_memory": memory})
    _write(out_dir, bench, echo, _merge_text(len(results), before, len(bench.updates) + len(bench.e2e)))
    return bench.to_json()


def _merge_text(new: int, before: int, after: int) -> str:
    """What a merge did, in words: the entries this bench timed, and those of earlier benches (of every kind the file
    holds: ``before`` and ``after`` the merge) kept beside them."""
    kept = after - new
    replaced = before - kept
    return (f"{new} {'entry' if new == 1 else 'entries'} timed now ({replaced} replacing an entry of the same "
            f"setting), {kept} kept from earlier benches")


def run_meta(device: str) -> dict[str, Any]:
    """What every bench file records of the run that wrote it (besides its hardware)."""
    import torch

    return {"host": socket.gethostname(), "torch": torch.__version__, "python": platform.python_version(),
            "time": time.strftime("%Y-%m-%dT%H:%M:%S%z")}


def bench_path(out_dir: Path, device: str) -> Path:
    """The bench file of this host and device, read by the speed tables and `repro plan`."""
    return out_dir / results_file.file_name(results_file.ONLINE, device)


def run_e2e_bench(configs: list[tuple[str, Optional[int]]], device: str, out_dir: Path, frames: int,
                  paths: tuple[str, ...] = (), warmup: int = 1, task: str = "cheetah_run",
                  seed_frames: Optional[int] = None, echo: Callable[[str], None] = print,
                  overlap: bool = False, progress: Optional[bool] = None) -> list[dict]:
    """Time each (agent, batch; None: the tiny profile) on every path with :func:`repro.bench.e2e.run_e2e`, a line
    each as it is done (a progress bar on a terminal), each with the machine's load then, and merge the entries into
    ``e2e`` of the bench file (an entry of the same agent, batch, profile, path and phase timing replaced, the
    others and the update entries kept). ``overlap``: each timed as it trains instead (``phase_sync`` false)."""
    from repro.bench.e2e import PHASES, run_e2e

    entries = []
    echo(f"timing the training loop of {_settings_text(configs, paths)} ({frames} frames each)")
    with Steps(len(configs) * (1 + len(paths)), progress) as steps:
        for path in ("plain", *paths):
            for agent, bs in configs:
                with steps.item(f"{agent} {'tiny profile' if bs is None else f'B{bs}'} {path}"):
                    e = run_e2e(agent, bs, device, path, frames=frames, task=task, warmup=warmup,
                                seed_frames=seed_frames, phase_sync=not overlap)
                e.update(results_file.machine_load())
                entries.append(e)
                what = f"profile {e['profile']} B{e['batch_size']}" if e["profile"] else f"B{e['batch_size']}"
                shares = ", ".join(f"{k} {e['phases'][k]:.2f}s" for k in PHASES)
                timing = ", as it trains (phases not synchronized)" if overlap else ""
                echo(f"{agent:>6} {what} {path}{timing}: {e['frames']} frames in {e['seconds']:.2f} s, "
                     f"{e['fps']:.1f} fps ({shares}; {e['updates']} updates, evaluation excluded{_load_text(e)})")
    bench = results_file.read_or_new(bench_path(out_dir, device), results_file.ONLINE, device)
    before = len(bench.updates) + len(bench.e2e)
    bench.hardware = hardware(device)
    bench.rest.update(run_meta(device))
    bench.merge(e2e=[results_file.E2EEntry.read(e) for e in entries])
    _write(out_dir, bench, echo, _merge_text(len(entries), before, len(bench.updates) + len(bench.e2e)))
    return entries


def _write(out_dir: Path, bench: results_file.BenchFile, echo: Callable[[str], None] = print,
           merged: str = "") -> Path:
    """Write ``bench`` (its kind's file of this host and device) in today's format; ``merged``: what the merge
    did, said after the path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / results_file.file_name(bench.kind, bench.device)
    atomic_write_text(path, json.dumps(bench.to_json(), indent=2) + "\n")
    echo(f"wrote {path}" + (f": {merged}" if merged else ""))
    return path


# ---------------------------------------------------------------- the command line
def _writable(root: Path) -> Path:
    """``--results`` checked before any timing (fsutil's one rule for an output folder): one line, exit 2."""
    writable_folder(root, "--results")
    return root


# The options every subcommand that times an agent shares
RESULTS = typer.Option(Path("runs"), "--results", help="Results root (writes bench/).", callback=_writable)
DEVICE = typer.Option("cpu", "--device", help="cpu or cuda.")
REPEATS = typer.Option(2, "--repeats", help="Timed updates per setting (median reported).")
WARMUP = typer.Option(1, "--warmup", help="Untimed warm-up updates before the timed ones.")
AMP = typer.Option(False, "--amp", help="Also time agent.amp=true (ratio to plain).")
COMPILE = typer.Option(False, "--compile", help="Also time agent.compile=true (ratio to plain).")
FAST = typer.Option(False, "--fast", help="Also time agent.fast=true (ratio to plain).")
AGENT_HELP = "Online agent files (default taco and drqv2; any agent whose learner trains online, a plugin's too)."
HELP = """Time what training costs on this machine: `repro bench update` (one update of each online agent), `e2e` (a
short training run per phase), `offline` (each offline learner), `data` (a dataset's load and sampling), `roofline`
(the update's FLOP rate). Each merges its entries into its file under RESULTS/bench/ (an entry of the same agent, batch
and path replaced, the others kept), read by `repro plan` and the speed tables (docs/performance.md)."""


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


def _check_agents(agent: Optional[list[str]]) -> None:
    from repro.config.compose import close_matches, online_agents

    online = online_agents() if agent else ()
    for a in agent or []:
        if a not in online:
            fail(f"unknown online agent '{a}'.{close_matches(a, online)}")


def _new_file(kind: str, device: str, rest: dict[str, Any]) -> results_file.BenchFile:
    return results_file.BenchFile(kind, device.split(":")[0], hardware(device), rest={**run_meta(device), **rest})


def update_cmd(agent: Optional[list[str]] = typer.Option(None, "--agent", help=AGENT_HELP),
               batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256 1024)."),
               repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE, amp: bool = AMP,
               compile_: bool = COMPILE, fast: bool = FAST, results_root: Path = RESULTS) -> None:
    """Time one update of each online agent at each batch size (default TACO and DrQ-v2 at batch 256 and 1024) on
    the plain path and each speed-up path asked for, alternated; print same-run ratios and the replay memory."""
    _check_common(device, batch, repeats, warmup)
    _check_agents(agent)
    configs = [(a, b) for a in (agent or ["taco", "drqv2"]) for b in (batch or [256, 1024])]
    run_bench(configs, repeats, device, results_root / "bench", echo=typer.echo, paths=_paths(amp, compile_, fast),
              warmup=warmup)


def e2e_cmd(agent: Optional[list[str]] = typer.Option(None, "--agent", help=AGENT_HELP),
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
    _check_agents(agent)
    if frames < 1 or (seed_frames is not None and seed_frames < 0):
        fail("--frames must be >= 1 and --seed-frames >= 0")
    if task not in TASKS:
        fail(f"unknown task '{task}'")
    sizes: list[Optional[int]] = list(batch) if batch else [None]
    run_e2e_bench([(a, b) for a in (agent or ["taco", "drqv2"]) for b in sizes], device, results_root / "bench",
                  frames, _paths(amp, compile_, fast), warmup, task, seed_frames, echo=typer.echo, overlap=overlap)


def offline_cmd(agent: Optional[list[str]] = typer.Option(
                    None, "--agent", help="These agent files only (default: every agent file whose learner trains "
                    "offline, plugins' included)."),
                batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256)."),
                dt_batch: Optional[int] = typer.Option(None, "--dt-batch", help="Batch of learners with their own "
                                                       "(default: DT's 64)."),
                repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE,
                results_root: Path = RESULTS) -> None:
    """One update of each offline learner at each batch size as a ratio to the DrQ-v2 update, measured side by
    side."""
    from repro.bench.offline_update import run_offline_bench
    from repro.config.compose import offline_agents

    _check_common(device, batch, repeats, warmup)
    agents = offline_agents() if agent else ()
    for name in agent or []:
        if name not in agents:
            fail(f"unknown offline agent '{name}' ({', '.join(agents)})")
    if dt_batch is not None and dt_batch < 1:
        fail("--dt-batch must be >= 1")
    sizes = list(dict.fromkeys(batch or [256]))
    entries: list[results_file.OfflineEntry] = []
    rest: dict[str, Any] = {}
    with Steps(len(sizes) * (1 + len(agent or offline_agents()))) as steps:
        for size in sizes:
            report = run_offline_bench(size, repeats, warmup, device, agent or None, echo=typer.echo,
                                       own_batch=dt_batch, steps=steps)
            entries += [results_file.OfflineEntry.read(r) for r in report["results"]]
            ratios = {**rest.get("ratios", {}), **report["ratios"]}
            rest = {**{k: v for k, v in report.items() if k not in ("results", "device")}, "ratios": ratios}
    bench = results_file.read_or_new(results_root / "bench" / results_file.file_name(results_file.OFFLINE, device),
                                     results_file.OFFLINE, device)
    before = len(bench.offline)
    bench.hardware = hardware(device)
    bench.rest.update({**run_meta(device), **rest})
    bench.merge(offline=entries)
    _write(results_root / "bench", bench, typer.echo, _merge_text(len(entries), before, len(bench.offline)))


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


def roofline_cmd(agent: Optional[list[str]] = typer.Option(None, "--agent", help="Online agent files (default "
                                                           "taco)."),
                 batch: Optional[list[int]] = typer.Option(None, "--batch", help="Batch sizes (default 256)."),
                 repeats: int = REPEATS, warmup: int = WARMUP, device: str = DEVICE, amp: bool = AMP,
                 compile_: bool = COMPILE, fast: bool = FAST, results_root: Path = RESULTS) -> None:
    """The update's FLOPs (torch's FLOP counter) over its time against this process's measured fp32 and bf16
    convolution peak, and the kernels that keep it from the peak."""
    from repro.bench.roofline import run_roofline

    _check_common(device, batch, repeats, warmup)
    _check_agents(agent)
    configs = [(a, b) for a in (agent or ["taco"]) for b in (batch or [256])]
    entries = []
    with Steps(len(configs)) as steps:
        for a, b in configs:
            with steps.item(f"{a} B{b}"):
                entries.append({**run_roofline(a, b, _paths(amp, compile_, fast), device, repeats, warmup,
                                               echo=typer.echo), **results_file.machine_load()})
    path = results_root / "bench" / results_file.file_name(results_file.ROOFLINE, device)
    bench = results_file.read_or_new(path, results_file.ROOFLINE, device)
    old = bench.rest.get("roofline") or []
    fresh = {(e["agent"], e["batch_size"]) for e in entries}
    kept = [e for e in old if (e.get("agent", e.get("algo")), e.get("batch_size")) not in fresh]
    bench.hardware = hardware(device)
    bench.rest.update({**run_meta(device), "roofline": kept + entries})
    _write(results_root / "bench", bench, typer.echo, _merge_text(len(entries), len(old), len(kept) + len(entries)))


SUBCOMMANDS: dict[str, Callable[..., None]] = {"update": update_cmd, "e2e": e2e_cmd, "offline": offline_cmd,
                                               "data": data_cmd, "roofline": roofline_cmd}


def register(app: typer.Typer) -> None:
    """Add ``bench`` and its subcommands to ``app``."""
    bench = typer.Typer(no_args_is_help=True, help=HELP)
    for name, command in SUBCOMMANDS.items():
        bench.command(name)(command)
    app.add_typer(bench, name="bench")
