"""Commands ``repro sweeps``, ``repro sweep`` and ``repro status`` (added to the main app by ``register``)."""

from __future__ import annotations

import os
import shlex
import time
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.markup import escape
from rich.table import Table

from repro.launch import spec as specs
from repro.launch.spec import PlannedRun, Selection, SweepError, SweepSpec
from repro.launch.spec.sharing import SweepFrames, shared_frames
from repro.runs.console import Commands, console, fail
from repro.runs.fsutil import writable_folder

if TYPE_CHECKING:
    from repro.launch.local import GpuPacking, LaunchReport
    from repro.launch.status import RunStatus

# The same flags as `repro status`, `figures` and `report`.
RESULTS_FLAGS = ("--results-root", "--results", "-r")
STATE_STYLE = {"done": "green", "partial": "yellow", "extend": "yellow", "absent": "dim", "mismatch": "red",
               "running": "cyan", "queued": "blue", "failed": "red", "cancelled": "yellow", "pending": "dim",
               "waiting": "magenta"}
WATCH_SECONDS = 10.0  # `repro status --watch` without N
# `repro status --watch` stops once every run is in one of these (a waiting run needs its dataset made and the
# sweep launched again, a cancelled one the sweep launched again: watching cannot change it)
FINISHED = ("done", "failed", "cancelled", "waiting")


class Launcher(str, Enum):
    local = "local"
    slurm = "slurm"


def _shown_overrides(p: PlannedRun) -> str:
    return " ".join(o for o in p.overrides if not o.startswith(("runtime.results_root=", "runtime.sweep=")))


def _rel(path: Path, root: Path) -> str:
    return os.path.relpath(path, root)


def print_plan(planned: list[PlannedRun], spec: SweepSpec, root: Path, force: bool,
               excluded: Sequence[tuple[str, str, str, str]] = ()) -> None:
    con = console()
    for agent, variant, task, reason in excluded:
        con.print(f"[dim]{'n/a':<9}[/] {escape(f'{spec.experiment}/{agent}/{variant}/{task}')}  "
                  f"not run: {escape(reason)}", highlight=False)
    for p in planned:
        state = p.state + (" (--force: move aside)" if p.state == "mismatch" and force else "")
        if p.waiting:
            state = "waiting"
        style = STATE_STYLE.get(state, "")
        why = f"  ({escape(p.waiting)})" if p.waiting else ""
        con.print(f"[{style}]{state:<9}[/] {escape(_rel(p.run_dir, root))}  {escape(_shown_overrides(p))}{why}",
                  highlight=False)
    by_state = {s: sum(1 for p in planned if p.state == s and not p.waiting)
                for s in ("done", "partial", "extend", "absent", "mismatch")}
    by_state["waiting"] = sum(1 for p in planned if p.waiting)
    datasets = len({p.run.dataset for p in planned if p.run.dataset})
    dims = (f"{len({p.run.task for p in planned})} task(s) x {len({p.run.agent for p in planned})} agent(s) x "
            f"{len({p.run.variant for p in planned})} variant(s) x "
            + (f"{datasets} dataset(s) x " if datasets else "") + f"{len({p.run.seed for p in planned})} seed(s)")
    summary = ", ".join(f"{n} {s}" for s, n in by_state.items() if n)
    skipped = f" {len(excluded)} cell(s) n/a (not run)." if excluded else ""
    con.print(f"{len(planned)} runs of sweep '{spec.name}' ({dims}): {summary}.{skipped} Results root: {root}",
              highlight=False)


def _mismatch_error(planned: list[PlannedRun], root: Path) -> str:
    bad = [p for p in planned if p.state == "mismatch"]
    first = bad[0]
    return (f"{len(bad)} run dir(s) hold a run with another config (e.g. {_rel(first.run_dir, root)}: "
            f"{first.diff[0]}); rerun with --force to move them aside to {root / '.replaced'}.")


def register(app: typer.Typer) -> None:
    """Add ``sweeps``, ``sweep`` and ``status`` to ``app``."""
    for name, command in (("sweeps", sweeps_cmd), ("sweep", sweep_cmd), ("status", status_cmd)):
        app.command(name)(command)


def sweeps_cmd() -> None:
    """List the paper's experiment sweeps with their run counts."""
    con = console()
    table = Table(title="Sweeps (sweeps/*.yaml)")
    for col in ("name", "artifacts", "runs", "tasks", "agents", "variants", "seeds", "frames", "to train",
                "status"):
        table.add_column(col, overflow="fold")
    all_specs = specs.load_all()
    shared = shared_frames(all_specs)
    for s in all_specs:
        table.add_row(*_sweep_row(s, shared.get(s.name)))
    con.print(table)
    con.print("to train: the frames a sweep trains, summed over its runs, after sharing: a run directory that two "
              "sweeps expand to is one run, trained to the smaller budget and extended to the larger, so a sweep "
              "pays only the frames beyond another's (docs/sweeps.md). Offline sweeps count updates, not frames.",
              highlight=False)


def _sweep_row(s: SweepSpec, frames_of: SweepFrames | None = None) -> tuple[str, ...]:
    """One row of ``repro sweeps``: a refused sweep's runs are counted without expanding it."""
    reason = specs.unavailable_reason(s)
    agents = {a for v in s.variants.values() for a in
              [specs.override_value(o) for o in v if specs.override_key(o) == "agent"] or s.agents}
    if reason:
        runs = len(s.tasks) * len(s.seeds) * sum(
            1 if any(specs.override_key(o) == "agent" for o in v) else len(s.agents)
            for v in s.variants.values())
        status = "[red]refused:[/] " + escape(reason.split(": ", 1)[1])
    else:
        runs = len(specs.expand(s))
        status = "[green]ok[/]"
    frames = f"{s.frames:,}" if s.frames else "default"
    if frames_of is None:
        train = "-"
    else:
        train = f"{frames_of.to_train:,}"
        if frames_of.to_train != frames_of.total:
            train += f" (of {frames_of.total:,}; shares runs with {', '.join(frames_of.shared_with)})"
    return (s.name, ",".join(s.artifacts), str(runs), str(len(s.tasks)), ",".join(sorted(agents)),
            str(len(s.variants)), str(len(s.seeds)), frames, train, status)


def sweep_cmd(
    name: str = typer.Argument(..., help="Sweep name (see `repro sweeps`) or path to a sweep YAML."),
    tasks: Optional[str] = typer.Option(None, "--tasks", help="Comma-separated tasks instead of the sweep's."),
    seeds: Optional[int] = typer.Option(None, "--seeds", min=1, help="Use seeds 1..N."),
    frames: Optional[int] = typer.Option(None, "--frames", min=1, help="Frame budget of every run."),
    sets: Optional[list[str]] = typer.Option(None, "--set", help="Extra config override key=value (repeatable)."),
    results_root: Optional[Path] = typer.Option(
        None,
        *RESULTS_FLAGS,
        help="Results root to write the runs under (the same as --set "
        "runtime.results_root=ROOT; default: the config's runtime.results_root).",
    ),
    dry_run: bool = typer.Option(
        False, "--dry-run", help="Print the grid (run dir, overrides, state); launch nothing."
    ),
    launcher: Launcher = typer.Option(Launcher.local, "--launcher", help="Where to run."),
    max_parallel: Optional[int] = typer.Option(
        None, "--max-parallel", min=1, help="Local: runs at once (default: cores / 2)."
    ),
    force: bool = typer.Option(
        False, "--force", help="Move aside run dirs whose saved config differs, then rerun."
    ),
    cluster_config: Optional[Path] = typer.Option(
        None,
        "--cluster-config",
        help="SLURM launcher YAML (default: $REPRO_SLURM_CONFIG or ~/.config/taco-repro/slurm.yaml).",
    ),
    warm_start: bool = typer.Option(
        False, "--warm-start", help="Local: fork each run from a process that has imported torch and the trainer "
        "already (about 4 s of CPU less per run; the same files and logs) instead of a fresh interpreter."
    ),
    gpus: Optional[str] = typer.Option(
        None, "--gpus", help="Local: GPU ids, e.g. 0,1; each run gets one (CUDA_VISIBLE_DEVICES and "
        "MUJOCO_EGL_DEVICE_ID), at most --runs-per-gpu at once on each."
    ),
    runs_per_gpu: Optional[int] = typer.Option(
        None, "--runs-per-gpu", help="Local, with --gpus: runs sharing one GPU at once (default 1)."
    ),
    preflight: bool = typer.Option(
        True, "--preflight/--no-preflight", help="SLURM: first run `repro doctor` as one short job with the cluster "
        "config (rendering, GPU ids, results root, datasets, versions on the node the runs get) and submit the "
        "grid only if it passes."
    ),
    preflight_wait: float = typer.Option(
        600, "--preflight-wait", metavar="SECONDS", min=1,
        help="SLURM: how long the preflight job may stay pending before the sweep gives up (nothing submitted)."
    ),
) -> None:
    """Run (or resume) every run of a sweep; DONE runs are skipped, partial ones resume."""
    options = LaunchOptions(launcher, max_parallel, force, cluster_config, warm_start, gpus, runs_per_gpu,
                            preflight, preflight_wait)
    sel = specs.selection(tasks, seeds, frames, sets, results_root)
    report = launch_sweep(name, sel, options, dry_run)
    if report is None:
        return
    if report.interrupted:
        raise typer.Exit(130)
    if report.failed or report.mismatch:
        raise typer.Exit(1)


@dataclass(frozen=True)
class LaunchOptions:
    """How a sweep's runs are launched (`repro sweep`'s launcher options; `repro verify` takes the same)."""

    launcher: Launcher = Launcher.local
    max_parallel: Optional[int] = None
    force: bool = False
    cluster_config: Optional[Path] = None
    warm_start: bool = False
    gpus: Optional[str] = None
    runs_per_gpu: Optional[int] = None
    preflight: bool = True  # SLURM: `repro doctor` as one job first; the grid only if it passes
    preflight_wait: float = 600.0  # SLURM: seconds the preflight job may stay pending


def launch_sweep(name: str, sel: Selection, options: LaunchOptions, dry_run: bool = False,
                 agents: Sequence[str] | None = None, variants: Sequence[str] | None = None) -> LaunchReport | None:
    """Expand sweep ``name`` with ``sel`` (only the runs of ``agents`` and ``variants``, when given), then print the
    plan (``dry_run``: returns None) or launch it and print the launch's report. Bad input (a UserError: the sweep, a
    task, a --set, a results root it cannot write, a W&B mirror that cannot start): one line, exit 2, before anything is
    written."""
    if options.warm_start and options.launcher == Launcher.slurm:
        fail("--warm-start is for the local launcher (a SLURM job starts its run on its node)")
    packing = _gpu_packing(options.gpus, options.runs_per_gpu, options.launcher, options.max_parallel,
                           options.warm_start)
    cluster_path = _slurm_ready(options) if options.launcher == Launcher.slurm and not dry_run else None
    spec = specs.load(name)
    planned = specs.plan(specs.expand(spec, sel))
    if agents is not None:
        planned = [p for p in planned if p.run.agent in agents]
    if variants is not None:
        planned = [p for p in planned if p.run.variant in variants]
    root = specs.results_root_of(planned)
    if dry_run:
        print_plan(planned, spec, root, options.force, specs.excluded(spec, sel))
        return None
    writable_folder(root, "results root")
    if any(p.state == "mismatch" for p in planned) and not options.force:
        raise SweepError(_mismatch_error(planned, root))
    _check_wandb(planned)
    from repro.launch.slurm import PreflightFailed

    try:
        report = _launch(spec, planned, root, options, cluster_path, packing)
    except PreflightFailed as exc:  # a failed check exits 1 (a cancelled wait 130), not 2
        fail(str(exc), code=exc.code)
    _print_report(report, options.launcher, spec.name, root)
    return report


def _slurm_ready(options: LaunchOptions) -> Path:
    """The cluster config of a SLURM launch (refused in one line without one) once sbatch is there: checked before
    the sweep is expanded, so a refusal leaves nothing behind."""
    from repro.launch.slurm import require_cluster_config, require_sbatch

    path = require_cluster_config(options.cluster_config)
    require_sbatch()
    return path


def _gpu_packing(gpus: Optional[str], runs_per_gpu: Optional[int], launcher: Launcher, max_parallel: Optional[int],
                 warm_start: bool) -> GpuPacking | None:
    """``--gpus`` / ``--runs-per-gpu`` as a GpuPacking (None without --gpus); bad input: one line, exit 2."""
    from repro.launch.local import check_gpus, parse_gpus

    if gpus is None:
        if runs_per_gpu is not None:
            fail("--runs-per-gpu needs --gpus (the GPUs the runs share)")
        return None
    if launcher == Launcher.slurm:
        fail("--gpus is for the local launcher (SLURM places runs on GPUs: gpus_per_node and the gres in "
                    "the launcher config, sweeps/launchers/example.yaml)")
    if max_parallel is not None:
        fail("--gpus sets the runs at once (GPUs x --runs-per-gpu): drop --max-parallel")
    if warm_start:
        fail("--gpus with --warm-start: the warm server sets up one EGL display for every run; drop one")
    packing = parse_gpus(gpus, 1 if runs_per_gpu is None else runs_per_gpu)
    check_gpus(packing)
    return packing


def _check_wandb(planned: list[PlannedRun]) -> None:
    """runtime.wandb=true without the wandb package: one line (WandbError) before any run starts."""
    if any(p.cfg.runtime.wandb and p.state != "done" for p in planned):
        from repro.runs.wblog import check_wandb

        check_wandb()


def _launch(spec: SweepSpec, planned: list[PlannedRun], root: Path, options: LaunchOptions,
            cluster_path: Optional[Path], gpus: GpuPacking | None = None) -> LaunchReport:
    """Record the launch in the sweep's state folder and submit (SLURM: after the preflight job, when on) or run
    (local) the planned runs."""
    from repro.launch.local import default_parallel, run_local
    from repro.launch.state import record_launch, state_dir

    sdir = state_dir(root, spec.name)
    grid = {p.key: {"run_dir": str(p.run_dir), "overrides": list(p.overrides),
                    **({"dataset": p.need.to_json()} if p.need else {})} for p in planned}
    say = console().print
    if options.launcher == Launcher.slurm:
        from repro.launch.doctor import inputs_for
        from repro.launch.slurm import load_cluster_config, preflight, submit

        cluster = load_cluster_config(cluster_path)

        def check(claimed: list[PlannedRun]) -> None:
            preflight(inputs_for(claimed, root), spec.name, sdir, cluster, say, options.preflight_wait)

        report = submit(planned, spec.name, sdir, cluster, options.force, say, check if options.preflight else None)
        record_launch(sdir, spec.name, spec.path, "slurm", grid, report.job_ids,
                      {"cluster_config": str(cluster_path) if cluster_path else None,
                       "preflight": options.preflight})
        return report
    parallel = gpus.max_parallel if gpus is not None else (options.max_parallel or default_parallel())
    extra = {"max_parallel": parallel, "warm_start": options.warm_start,
             **({"gpus": list(gpus.gpus), "runs_per_gpu": gpus.per_gpu} if gpus is not None else {})}
    record_launch(sdir, spec.name, spec.path, "local", grid, extra=extra)
    return run_local(planned, spec.name, sdir, parallel, options.force, say, options.warm_start, gpus)


def status_cmd(
    name: Optional[str] = typer.Argument(None, help="Sweep name; all launched sweeps when omitted."),
    results_root: Optional[Path] = typer.Option(
        None, *RESULTS_FLAGS,
        help="Results root the sweeps ran under (default: the config's runtime.results_root)."),
    watch_: bool = typer.Option(False, "--watch", "-w",
                                help="Refresh until every run is done or failed (Ctrl-C stops)."),
    every: float = typer.Option(WATCH_SECONDS, "--every", metavar="N", help="Seconds between --watch refreshes."),
) -> None:
    """Per sweep: done / running / queued / failed / pending per run, last frame and eval return."""
    from repro.launch.state import state_dir

    if every <= 0:
        fail(f"--every takes a positive number of seconds (got {every:g})")
    watch = every if watch_ else None

    try:
        root = (results_root or default_results_root()).expanduser().absolute()
        if results_root is not None and not root.is_dir():
            raise SweepError(f"results root {root} does not exist or is not a directory")
        names = _launched_names(name, root)
        while names:
            if watch is not None:
                console().print(f"[dim]{time.strftime('%H:%M:%S')}  refreshing every {watch:g}s "
                                 "(Ctrl-C to stop)[/]", highlight=False)
            statuses = [s for n in names for s in _print_status(n, root, state_dir(root, n))]
            if watch is None or all(s.status in FINISHED for s in statuses):
                return
            time.sleep(watch)
    except KeyboardInterrupt:
        raise typer.Exit(130) from None


def _launched_names(name: Optional[str], root: Path) -> list[str]:
    """The launched sweeps ``repro status`` shows: ``name``, or all without one; none (said in a line) when
    nothing is launched or ``name`` is a known sweep not launched here (SweepError: an unknown one)."""
    base = root / ".sweeps"
    launched = sorted(d.name for d in base.iterdir() if (d / "state.json").exists()) if base.is_dir() else []
    if name is None:
        if not launched:
            console().print(f"no sweep launched under {root}", highlight=False)
        return launched
    if name in launched:
        return [name]
    known = set(specs.sweep_names()) | set(launched)
    if name not in known:
        raise SweepError(f"unknown sweep '{name}'." + specs.close_matches(name, sorted(known)))
    console().print(f"sweep '{name}' has not been launched under {root}", highlight=False)
    return []


def default_results_root() -> Path:
    """The packaged config's ``runtime.results_root`` (ConfigError, one line, when it does not compose)."""
    from repro.config.compose import compose_base

    return Path(str(compose_base().runtime.results_root))


def status_hint(sweep: str, root: Path) -> str:
    """The `repro status` command that follows a launch: the sweep's name and the results root it ran under (the
    user's -r / --set runtime.results_root kept, so the command works as printed)."""
    return f"repro status {shlex.quote(sweep)} -r {shlex.quote(str(root))}"


def _print_report(report, launcher: Launcher, sweep: str, root: Path) -> None:
    con = console()
    parts = [f"{len(report.started)} {'submitted' if launcher == Launcher.slurm else 'started'}"]
    if launcher == Launcher.local:
        parts.append(f"{len(report.finished)} finished")
    parts += [f"{len(report.done)} already done", f"{len(report.locked)} held elsewhere",
              f"{len(report.failed)} failed"]
    if report.mismatch:
        parts.append(f"{len(report.mismatch)} refused (config mismatch; --force)")
    if report.waiting:
        parts.append(f"{len(report.waiting)} waiting for their dataset (not started)")
    con.print(f"sweep '{sweep}': " + ", ".join(parts), highlight=False)
    if report.job_ids:
        con.print(f"SLURM job ids: {', '.join(report.job_ids)}; follow with `{status_hint(sweep, root)}`",
                  highlight=False)
    for key, log in report.failed:
        con.print(f"[red]failed[/] {escape(key)}: log {escape(log)}", highlight=False)


def _print_status(name: str, root: Path, sdir: Path) -> list[RunStatus]:
    """Print the status table of sweep ``name``; returns its RunStatus list."""
    from repro.launch.status import collect, counts, sweep_runs

    statuses = collect(sweep_runs(sdir), root, sdir)
    n = counts(statuses)
    table = Table(title=f"{name}: " + ", ".join(f"{v} {k}" for k, v in n.items()), title_justify="left")
    for col in ("run", "status", "frame", "eval return", "job", "detail"):
        table.add_column(col, overflow="fold")
    for s in statuses:
        style = STATE_STYLE.get(s.status, "")
        table.add_row(escape(_rel(s.run_dir, root)), f"[{style}]{s.status}[/]",
                      "" if s.frame is None else f"{s.frame:,}",
                      "" if s.eval_return is None else f"{s.eval_return:.1f}", s.job_id or "",
                      escape(s.detail) + (f"{'; ' if s.detail else ''}[{'red' if s.saturated else 'yellow'}]"
                                          f"{escape(s.health)}[/]" if s.health else ""))
    con = console()
    con.print(table)
    sick = [s for s in statuses if s.saturated]
    if sick:
        con.print(f"[red]{len(sick)} run(s) with a saturated actor[/] (its tanh exactly +-1 on nearly every state "
                  "of its batches: the policy gradient is zero; docs/watching.md)", highlight=False)
    for s in statuses:
        if s.status == "failed" and s.log:
            con.print(f"[red]failed[/] {escape(_rel(s.run_dir, root))}: {escape(s.log)}", highlight=False)
    return statuses


def main() -> None:
    """Stand-alone entry point (``python -m repro.launch.cli``) until the main CLI registers these."""
    app = typer.Typer(cls=Commands, add_completion=False, no_args_is_help=True)
    register(app)
    app()


if __name__ == "__main__":
    main()
