"""``repro verify``: launch the ``verify`` sweep through the ordinary launchers, then judge its runs against the DrQ-v2
authors' published curves (analysis/verify.py) and write the verdicts and the figure. docs/verification.md."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Optional

import typer

from repro.launch.cli import (
    RESULTS_FLAGS,
    Launcher,
    LaunchOptions,
    default_results_root,
    launch_sweep,
    status_hint,
)
from repro.launch.spec import Selection
from repro.runs.console import console, fail
from repro.runs.fsutil import writable_folder

SWEEP = "verify"
CPU_AGENTS = ("drqv2",)  # the CPU check: DrQ-v2 alone (TACO to 40K frames takes hours more on a CPU)
CPU_SEEDS = 1  # one seed at a time uses the 2 cores of the machine it was measured on (docs/verification.md)
# The CPU check's wall time, measured (docs/verification.md, "What it costs"): 60K frames at 10.3 frames/s and four
# evaluations of about 84 s, one DrQ-v2 seed alone on an idle 2-core Intel Xeon. The README and docs repeat it.
CPU_CHECK_TIME = "about 1 h 45 min on an idle 2-core CPU"
CPU_VARIANTS = ("base",)  # the CPU check: the fast path (the plain path, variant `plain`, is 3-5x its CPU time)


def _has_cuda() -> bool:
    import torch

    return bool(torch.cuda.is_available())


def _chosen(option: str, given: Optional[str], sweep_values: tuple[str, ...], cpu_default: tuple[str, ...],
            cuda: bool) -> tuple[str, ...]:
    """The sweep's values an option picks (``--agents`` / ``--variants``, comma-separated): all of them on a GPU
    machine, ``cpu_default`` on a CPU when the option is not given; an unknown or empty one is one line, exit 2."""
    if given is None:
        return sweep_values if cuda else tuple(v for v in cpu_default if v in sweep_values)
    chosen = tuple(v.strip() for v in given.split(",") if v.strip())
    unknown = [v for v in chosen if v not in sweep_values]
    if unknown or not chosen:
        fail(f"{option}: {', '.join(unknown) or 'none given'}; the verify sweep has {', '.join(sweep_values)}")
    return chosen


def verify_cmd(
    seeds: Optional[int] = typer.Option(None, "--seeds", min=1, help="Use seeds 1..N (default: the sweep's 3 on a "
                                        "GPU machine, 1 on a CPU)."),
    frames: Optional[int] = typer.Option(None, "--frames", min=1, help="Frame budget of every run (default 60K; a "
                                         "larger one extends the runs)."),
    sets: Optional[list[str]] = typer.Option(None, "--set", help="Extra config override key=value (repeatable)."),
    results_root: Optional[Path] = typer.Option(None, *RESULTS_FLAGS, help="Results root of the runs (default: the "
                                                "config's runtime.results_root)."),
    agents: Optional[str] = typer.Option(None, "--agents", help="Comma-separated agents of the sweep to run (default: "
                                         "all of them on a GPU machine, drqv2 on a CPU)."),
    variants: Optional[str] = typer.Option(None, "--variants", help="Comma-separated variants of the sweep to run "
                                           "(base: agent.fast; plain: the default path, DrQ-v2 seed 1; default: "
                                           "both on a GPU machine, base on a CPU)."),
    out: Path = typer.Option(Path("results/verify"), "--out", "-o", help="Folder for verify.{csv,md,tex}, "
                             "verify_frames.{csv,md,tex} and verify.{png,pdf}."),
    judge_only: bool = typer.Option(False, "--judge-only", help="Judge the verify runs already under the results "
                                    "root; launch nothing."),
    keep_runs: bool = typer.Option(False, "--keep-runs", help="Also copy each verify run's small files (config, "
                                   "eval.csv, train.csv, provenance) to OUT/runs/, a results root that "
                                   "`--judge-only -r OUT/runs` judges again."),
    min_seeds: int = typer.Option(1, "--min-seeds", min=1, help="Seeds a cell needs before it gets a verdict."),
    dry_run: bool = typer.Option(False, "--dry-run", help="Print the runs (and what they cost, from a bench file); "
                                 "launch nothing."),
    launcher: Launcher = typer.Option(Launcher.local, "--launcher", help="Where to run."),
    max_parallel: Optional[int] = typer.Option(None, "--max-parallel", min=1, help="Local: runs at once (default: "
                                               "cores / 2)."),
    force: bool = typer.Option(False, "--force", help="Move aside run dirs whose saved config differs, then rerun."),
    cluster_config: Optional[Path] = typer.Option(None, "--cluster-config", help="SLURM launcher YAML."),
    warm_start: bool = typer.Option(True, "--warm-start/--no-warm-start", help="Local: fork each run from a process "
                                    "that has imported torch already (ignored with --launcher slurm)."),
    gpus: Optional[str] = typer.Option(None, "--gpus", help="Local: GPU ids, e.g. 0,1 (as `repro sweep`)."),
    runs_per_gpu: Optional[int] = typer.Option(None, "--runs-per-gpu", help="Local, with --gpus: runs per GPU."),
) -> None:
    """Does this installation learn as the DrQ-v2 authors' code did? Trains the verify sweep (DrQ-v2 and TACO on
    cartpole_balance to 60K frames; resumable, extendable), then prints one verdict per task and agent."""
    from repro.launch import spec as specs

    spec = specs.load(SWEEP)
    root_sets = specs.selection(None, None, None, profile_wins(sets), results_root).sets
    if not dry_run:
        writable_folder(out, "--out")
    say = console().print
    if not judge_only:
        cuda = _has_cuda() or gpus is not None
        chosen = _chosen("--agents", agents, spec.agents, CPU_AGENTS, cuda)
        kinds = _chosen("--variants", variants, tuple(spec.variants), CPU_VARIANTS, cuda)
        if seeds is None and not cuda:
            seeds = CPU_SEEDS
        if agents is None or seeds == CPU_SEEDS:
            say(f"{'GPU' if cuda else 'no GPU'}: agents {', '.join(chosen)}, variants {', '.join(kinds)}, seeds "
                f"1..{seeds or len(spec.seeds)}"
                + ("" if cuda else f" (the CPU check, {CPU_CHECK_TIME}: docs/verification.md; --agents "
                   f"{','.join(spec.agents)} --variants {','.join(spec.variants)} --seeds 3 for the whole sweep)"),
                highlight=False)
        options = LaunchOptions(launcher, max_parallel, force, cluster_config,
                                warm_start and launcher == Launcher.local and gpus is None, gpus, runs_per_gpu)
        report = launch_sweep(SWEEP, Selection(seeds=seeds, frames=frames, sets=root_sets), options, dry_run,
                              agents=chosen, variants=kinds)
        if report is None:  # --dry-run
            _print_cost(Selection(seeds=seeds, frames=frames, sets=root_sets), chosen, kinds,
                        results_root if results_root is not None else _root_from(root_sets), cuda)
            return
        if report.interrupted:
            raise typer.Exit(130)
        if launcher == Launcher.slurm:
            root = results_root if results_root is not None else _root_from(root_sets)
            judge = f"repro verify --judge-only -r {shlex.quote(str(root))} -o {shlex.quote(str(out))}"
            say(f"submitted: follow them with `{status_hint(SWEEP, root)}`, judge them when they are done with "
                f"`{judge}`", highlight=False)
            return
    root = results_root if results_root is not None else _root_from(root_sets)
    raise typer.Exit(judge_and_write(root, out, min_seeds, keep_runs))


def profile_wins(sets: Optional[list[str]]) -> list[str]:
    """``--set profile=NAME`` (e.g. ``tiny``) with the profile's own settings after it, so that they win over the
    sweep's budget, evaluation schedule and batch as they would in `repro train profile=NAME` (a profile is a
    defaults choice, which the sweep's explicit keys would otherwise override); a key also given with --set keeps
    the --set value."""
    from omegaconf import OmegaConf

    from repro.config.compose import check_option, conf_dirs
    from repro.launch import spec as specs

    out = list(sets or ())
    given = {specs.override_key(s) for s in out}
    for s in list(out):
        if specs.override_key(s) != "profile":
            continue
        name = s.split("=", 1)[1]
        check_option("profile", name)
        path = next(p for d in conf_dirs() if (p := d / "profile" / f"{name}.yaml").is_file())
        flat = OmegaConf.to_container(OmegaConf.load(path))
        assert isinstance(flat, dict)
        for key, value in _dotted(flat):
            if key not in given:
                out.append(f"{key}={value}")
    return out


def _dotted(data: dict, prefix: str = "") -> list[tuple[str, object]]:
    out: list[tuple[str, object]] = []
    for key, value in data.items():
        if isinstance(value, dict):
            out += _dotted(value, f"{prefix}{key}.")
        else:
            out.append((f"{prefix}{key}", value))
    return out


def _root_from(sets: tuple[str, ...]) -> Path:
    from repro.launch import spec as specs

    for s in sets:
        if specs.override_key(s) == "runtime.results_root":
            return Path(s.split("=", 1)[1].strip("'\""))
    return default_results_root()


def judge_and_write(root: Path, out: Path, min_seeds: int = 1, keep: bool = False) -> int:
    """Judge the verify runs under ``root``, write the tables and the figure to ``out``, print one line per cell;
    the exit code: 1 when a verdict says the pipeline does not learn as published, else 0."""
    from analysis.load import load_results
    from analysis.verify import (
        ABOVE,
        BELOW,
        NOT_LEARNED,
        advantage_lines,
        judgement,
        keep_runs,
        verdict_lines,
        write_verdicts,
    )
    from paper_figures.verify_plot import plot_verify

    results = load_results(root)
    judged = judgement(results, min_seeds=min_seeds)
    rows = judged.rows
    con = console()
    if not rows:
        con.print(f"no verify runs under {root}: run `repro verify`", highlight=False)
        return 0
    for line in verdict_lines(rows) + advantage_lines(rows):
        con.print(line, highlight=False, soft_wrap=True)
    tables = write_verdicts(out, rows)
    figures = plot_verify(results, judged, out)
    if keep:
        con.print(f"kept {len(keep_runs(results, out, judged.cells))} run files under {out / 'runs'}",
                  highlight=False)
    con.print("wrote " + ", ".join(str(p) for t in tables for p in t.files[:2]) + ", "
              + ", ".join(str(p) for p in figures), highlight=False, soft_wrap=True)
    return 1 if any(r.verdict in (BELOW, ABOVE, NOT_LEARNED) for r in rows) else 0


def _print_cost(sel: Selection, agents: tuple[str, ...], variants: tuple[str, ...], root: Path,
                cuda: bool = True) -> None:
    """What `repro plan` expects the planned runs to take on this machine's kind of device (``cuda``: a GPU, else the
    CPU), from the newest bench file of that device under ``root`` (``repro/launch/cost.py``), or the command that
    writes one for that device (a CPU machine is never told to bench CUDA)."""
    from repro.launch.cost import NoBench, PlanError, bench_commands, find_bench, makespan, plan_sweeps, unpriced_runs

    con = console()
    device = "cuda" if cuda else "cpu"

    def planned(bench):
        return [c for c in plan_sweeps([SWEEP], bench, sel, memory=False)
                if c.agent in agents and c.run_dir.parent.parent.name in variants]  # verify/agent/VARIANT/task/seed_N

    try:
        bench = find_bench(root, device)
    except NoBench:
        command = " then ".join(f"`{c}`" for c in bench_commands(unpriced_runs(planned(None)), device, root))
        con.print(f"expected time: unknown (no `repro bench` file for device {device} under {root / 'bench'}: "
                  f"{command or '`repro bench update --device ' + device + '`'} times these runs here)",
                  highlight=False, soft_wrap=True)
        return
    except PlanError as exc:
        con.print(f"expected time: unknown ({exc})", highlight=False, soft_wrap=True)
        return
    costs = planned(bench)
    hours = [c.hours(c.frames - c.trained) for c in costs if c.frames > c.trained]
    if any(h is None for h in hours):
        command = " then ".join(f"`{c}`" for c in bench_commands(unpriced_runs(costs), device, root))
        con.print(f"expected time: the bench file {bench.path} does not time every run; {command} times them",
                  highlight=False, soft_wrap=True)
        return
    priced = [h for h in hours if h is not None]
    loaded = sorted({f"{c.setting} (load {c.load:.1f} on {c.cores} cores)" for c in costs if c.under_load})
    con.print(f"expected time on {bench.hardware} ({bench.path}): {sum(priced):.2f} device-hours, "
              f"{makespan(priced, 1):.2f} h one run at a time (repro plan verify)"
              + (f"; timed under load, so too long: {', '.join(loaded)}" if loaded else ""),
              highlight=False, soft_wrap=True)


def register(app: typer.Typer) -> None:
    app.command("verify")(verify_cmd)
