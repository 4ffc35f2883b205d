"""``repro plan``: what sweeps cost on your hardware (the cost model repro/launch/cost.py, its tables
repro_app/plan.py) and each claim's statistical power if the paper's numbers are the truth (analysis/power.py). Bad
input: one line, exit 2. Documented in docs/plan.md."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from analysis.defaults import DEFAULT_REPS, DEFAULT_SEED
from repro.runs.console import console, fail
from repro.runs.fsutil import writable_folder

DEFAULT_RESULTS = Path("runs")


def _print(display, title: str, notes: list[str]) -> None:
    """A display frame as a rich table, with its notes under it."""
    from rich.markup import escape
    from rich.table import Table

    con = console(min_width=160)
    table = Table(title=escape(title), title_justify="left")
    for col in display.columns:
        table.add_column(escape(str(col)), overflow="fold")
    for row in display.itertuples(index=False):
        table.add_row(*(escape(str(v)) for v in row))
    con.print(table)
    for note in notes:
        con.print(escape(note), highlight=False)


def plan_cmd(
    sweeps: Optional[list[str]] = typer.Argument(None, help="Sweep names (see `repro sweeps`) or sweep YAML paths."),
    all_: bool = typer.Option(False, "--all", help="Every sweep of sweeps/."),
    claims: bool = typer.Option(False, "--claims", help="Each claim's statistical power (with runs under --results: "
                                "given the runs done) and the seeds for 80% power."),
    results: Path = typer.Option(DEFAULT_RESULTS, "--results", "-r", help="Results root: its runs (what is done) "
                                 "and its bench/ folder."),
    out: Path = typer.Option(Path("results/report"), "--out", "-o", help="Folder for plan.{csv,md,tex} and "
                             "plan_power*.{csv,md,tex}."),
    bench_file: Optional[Path] = typer.Option(None, "--bench", help="A `repro bench` JSON (default: the newest "
                                              "RESULTS/bench/bench-*-DEVICE.json)."),
    device: Optional[str] = typer.Option(None, "--device", help="The device the bench timed: cuda or cpu (default: "
                                         "the device of the newest bench file; the notes say which)."),
    tasks: Optional[str] = typer.Option(None, "--tasks", help="As `repro sweep`: comma-separated tasks instead of "
                                        "the sweep's."),
    seeds_n: Optional[int] = typer.Option(None, "--seeds", help="As `repro sweep`: seeds 1..N."),
    frames: Optional[int] = typer.Option(None, "--frames", help="As `repro sweep`: the frame budget of every run."),
    sets: Optional[list[str]] = typer.Option(None, "--set", help="As `repro sweep`: a config override key=value "
                                             "(repeatable), e.g. --set agent.fast=true."),
    devices: int = typer.Option(1, "--devices", help="Devices the runs share (the local wall-clock)."),
    cluster_config: Optional[Path] = typer.Option(None, "--cluster-config", help="SLURM launcher YAML (default: "
                                                  "$REPRO_SLURM_CONFIG or ~/.config/taco-repro/slurm.yaml)."),
    device_memory_gb: Optional[float] = typer.Option(None, "--device-memory-gb", help="The device's memory (runs "
                                                     "per device; default: the bench JSON's device_memory_bytes)."),
    host_memory_gb: Optional[float] = typer.Option(None, "--host-memory-gb", help="The memory of the host the "
                                                   "devices share (runs per device: each run holds its replay there; "
                                                   "default: this machine's)."),
    sims: int = typer.Option(2000, "--sims", help="Simulated draws per claim and seed count."),
    max_seeds: int = typer.Option(50, "--max-seeds", help="Largest seeds per cell searched for 80% power."),
    seed: int = typer.Option(DEFAULT_SEED, "--seed", help="Random state of the simulation (and of the bootstraps)."),
    reps: int = typer.Option(DEFAULT_REPS, "--reps", help="Bootstrap repetitions of the current verdicts' CIs."),
    min_seeds: int = typer.Option(2, "--min-seeds", help="As `repro claims --min-seeds`."),
    cache: bool = typer.Option(True, "--cache/--no-cache", help="With --claims: reuse and keep what the last "
                               "analysis into --out computed (its runs as loaded, F6's t-SNE, intervals, the sweeps' "
                               "compositions); --no-cache recomputes all and writes no cache."),
) -> None:
    """Plan a reproduction before paying for it: each sweep's runs, frames, memory, device-hours and wall-clock
    on your hardware (from your `repro bench` JSON); with --claims each claim's power and the seeds it needs."""
    if not sweeps and not all_ and not claims:
        fail("name sweeps (e.g. 'repro plan main'), or pass --all or --claims")
    if devices < 1 or sims < 10 or max_seeds < 2 or reps < 1 or min_seeds < 1 or any(
            gb is not None and gb <= 0 for gb in (device_memory_gb, host_memory_gb)):
        fail("--devices must be >= 1, --sims >= 10, --max-seeds >= 2, --reps and --min-seeds >= 1, "
             "--device-memory-gb and --host-memory-gb > 0")
    if device is not None and device not in ("cuda", "cpu"):
        fail(f"--device must be cuda or cpu (got {device!r})")
    if (seeds_n is not None and seeds_n < 1) or (frames is not None and frames < 1):
        fail("--seeds and --frames must be >= 1")
    if (tasks or seeds_n or frames or sets) and not (sweeps or all_):
        fail("--tasks, --seeds, --frames and --set narrow the sweeps named: name sweeps or pass --all")
    writable_folder(out, "--out")
    if sweeps or all_:
        from repro.launch import spec as specs

        selection = specs.selection(tasks, seeds_n, frames, sets, results.expanduser().absolute())
        _plan_sweeps(sweeps or [], all_, results, out, bench_file, device, devices, cluster_config,
                     (device_memory_gb, host_memory_gb), selection)
    if claims:
        from analysis.cache import opened

        with opened(out if cache else None) as kept:
            _plan_claims(results, out, bench_file, device, sims, max_seeds, seed, reps, min_seeds)
        if cache:
            typer.echo(f"Cache ({out / '.cache'}): {kept.summary() or 'nothing computed'}")


def _cluster(cluster_config: Optional[Path]):
    from repro.launch.slurm import cluster_config_path, load_cluster_config

    path = cluster_config_path(cluster_config)
    return load_cluster_config(path), (f"launcher config {path}" if path else "no launcher config: SLURM defaults")


def _plan_sweeps(names: list[str], all_: bool, results: Path, out: Path, bench_file: Optional[Path],
                 device: Optional[str], devices: int, cluster_config: Optional[Path],
                 memory_gb: tuple[Optional[float], Optional[float]], selection) -> None:
    from repro.launch import spec as specs
    from repro.launch.cost import (
        GB,
        NoBench,
        PlanError,
        bench_commands,
        find_bench,
        machine_memory,
        plan_sweeps,
        totals,
        unpriced_runs,
    )
    from repro_app.plan import Memory, plan_frames, plan_notes, write_plan

    chosen = specs.sweep_names() if all_ else names
    try:
        bench = find_bench(results, device, bench_file)
    except NoBench as exc:  # one line naming the command that prices every run of these sweeps
        every = plan_sweeps(chosen, None, selection, memory=False)
        where = f" for device {exc.device}" if exc.device else ""
        commands = " then ".join(f"`{c}`" for c in bench_commands(unpriced_runs(every), exc.device or "cuda",
                                                                     results))
        raise PlanError(f"no `repro bench` file{where} under {exc.folder}: run {commands} first (every agent, batch "
                        f"and path of {', '.join(chosen)}{'' if exc.device else '; --device cpu for this CPU'}), "
                        "or pass --bench FILE") from None
    cluster, where = _cluster(cluster_config)
    costs = plan_sweeps(chosen, bench, selection)
    slots, limit = cluster.array_parallelism, cluster.time_min
    sweep_names = [specs.load(n).name for n in chosen]  # a sweep given as a YAML path: its name
    rows = [totals(n, [c for c in costs if c.sweep == n], devices, slots, limit) for n in sweep_names]
    rows.append(totals("Total", costs, devices, slots, limit))
    device_gb, host_gb = memory_gb
    memory = Memory(int(device_gb * GB) if device_gb else bench.device_memory_bytes,
                    int(host_gb * GB) if host_gb else machine_memory(), devices,
                    "--host-memory-gb" if host_gb else "this machine's; --host-memory-gb for the nodes'")
    notes = plan_notes(bench, costs, devices, slots, where, memory, rows[-1], sweep_names, results, cluster.mem_gb)
    table = write_plan(out, rows, notes, memory, devices, slots,
                       bench_commands(unpriced_runs(costs), bench.device, results))
    _print(plan_frames(rows, memory, devices, slots)[1], table.caption, notes)
    typer.echo(f"Wrote {', '.join(str(p) for p in table.files)}")


def _plan_claims(results: Path, out: Path, bench_file: Optional[Path], device: Optional[str], sims: int, max_seeds: int,
                 seed: int, reps: int, min_seeds: int) -> None:
    from analysis.claims import claim_specs, evaluate_claims
    from analysis.composed import composed
    from analysis.power import power_rows, write_power
    from repro.launch import spec as specs
    from repro.launch.cost import PlanError, find_bench, plan_sweeps
    from repro_app.analysis_cli import make_context
    from repro_app.plan import seeds_cost

    extra: list[str] = []
    try:
        bench = find_bench(results, device, bench_file)
    except PlanError as exc:
        if bench_file is not None:  # the file asked for is missing or unreadable: one line, before any work
            raise
        bench = None  # none found: the plan prices in frames and says so
        extra.append(f"Cost of those seeds in frames only: {exc}.")
    ctx = make_context(results, out, 1_000_000, reps, seed, min_seeds)
    conditioned = not ctx.no_runs
    listed = claim_specs(ctx.paper)  # the claims, listed once for the verdicts and the power
    verdicts = evaluate_claims(ctx, listed) if conditioned else None
    rows = power_rows(ctx, sims, max_seeds, verdicts, conditioned, specs=listed)
    by_experiment = {s.experiment: s for s in specs.load_all()}
    needed = sorted({by_experiment[e].name for r in rows if r.seeds_80 for e in r.experiments if e in by_experiment})
    costs = plan_sweeps(needed, bench, results_root=results.expanduser().absolute(), memory=False,
                        composer=composed)
    sweep_seeds = {by_experiment[e].name: len(by_experiment[e].seeds) for e in by_experiment}
    row_of = {r.id: r for r in rows}

    def cost(claim: str, n: int) -> str:
        r = row_of[claim]
        names = {by_experiment[e].name for e in r.experiments if e in by_experiment}
        return seeds_cost([c for c in costs if c.sweep in names], r.tasks or None, sweep_seeds, n)

    extra.append("Cost of those seeds: the runs of the claim's sweeps on its tasks, scaled from the sweep's seeds "
                 "to the seeds for 80%, at each run's full budget.")
    table, cells = write_power(out, rows, sims, seed, max_seeds, cost, conditioned, extra)
    _print(table.display, table.caption, table.notes)
    typer.echo(f"Wrote {', '.join(str(p) for p in table.files + cells.files)}")


def register(app: typer.Typer) -> None:
    """Add ``plan`` to ``app``."""
    app.command("plan")(plan_cmd)
