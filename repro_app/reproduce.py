"""`repro reproduce`: the main job, a tiny end-to-end reproduction on the defaults.

Three steps, each resumable (a re-run skips what is done):
1. online: the `tiny` sweep (TACO and DrQ-v2, two DMC tasks, two seeds, real rendering and updates),
   recorded (runtime.record=true);
2. offline: a medium and a full-replay dataset made from one recorded run (taco, cheetah_run, seed 1),
   then the `tiny_offline` sweep (every offline learner on both datasets, a few updates);
3. report: every table and figure, the claim verdicts, the audit and REPORT.md/.html from those runs
   (`tiny` read as experiment `main`, `tiny_offline` as `offline`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

import typer

from repro.runs.console import fail
from repro.runs.fsutil import writable_folder

OFFLINE_SWEEP = "tiny_offline"
# The recorded online run the datasets come from: {experiment}/{agent}/{variant}/{task}/seed_{seed}.
SOURCE_RUN = Path("taco/base/cheetah_run/seed_1")
# Dataset kinds and their size in transitions (whole 50-step episodes of the tiny profile; full-replay
# takes every recorded episode up to this many).
DATASETS = {"medium": 100, "full-replay": 200}


def _call(cmd: list[str], what: str) -> None:
    typer.echo(f"  $ repro {' '.join(cmd[3:])}")
    rc = subprocess.call(cmd)
    if rc != 0:
        fail(f"{what} failed (exit {rc})", 1)


def _offline_leg(results_root: Path, sweep: str, max_parallel: int, warm: list[str]) -> bool:
    """Make the two datasets from the recorded source run and train the offline sweep on them. False (with one
    line saying why) when the source run has no recording, e.g. a `tiny` run trained before recording was on."""
    source = results_root / sweep / SOURCE_RUN
    if not (source / "record").is_dir():
        typer.echo(f"  skipped: {source} has no recording (trained without runtime.record=true); remove it and "
                   "re-run `repro reproduce` to include the offline half")
        return False
    repro = [sys.executable, "-m", "repro"]
    for kind, transitions in DATASETS.items():
        folder = results_root / "datasets" / "cheetah_run" / kind
        if (folder / "manifest.json").is_file():
            typer.echo(f"  {kind}: {folder} exists")
            continue
        _call([*repro, "dataset", "make", "--source", str(source), "--kind", kind, "--transitions",
               str(transitions), "--seed", "1", "--device", "cpu"], f"dataset make --kind {kind}")
    cmd = [*repro, "sweep", OFFLINE_SWEEP, "--results", str(results_root), "--max-parallel", str(max_parallel), *warm]
    _call(cmd, f"the {OFFLINE_SWEEP} sweep (see `repro status {OFFLINE_SWEEP}`)")
    return True


def register(app: typer.Typer) -> None:
    @app.command()
    def reproduce(
        results_root: Path = typer.Option(Path("runs/tiny"), "--results", help="Results root."),
        out: Path = typer.Option(Path("results/tiny"), "--out", help="Where tables, figures and the report go."),
        sweep: str = typer.Option("tiny", help="Sweep to train before reporting."),
        max_parallel: Optional[int] = typer.Option(
            None, "--max-parallel", help="Runs at once (default: one per core; each tiny run is one thread)."),
        reps: int = typer.Option(2000, help="Bootstrap repetitions (rliable's default is 50,000)."),
        offline: bool = typer.Option(True, "--offline/--no-offline",
                                     help="Also make two tiny datasets and train every offline learner on them."),
        render_envs: bool = typer.Option(
            False, "--render-envs/--no-render-envs", help="Let F13 render random-action frames for tasks without runs."
        ),
        warm_start: bool = typer.Option(
            True, "--warm-start/--no-warm-start", help="Start the runs with `repro sweep --warm-start` (forked from a "
            "process that has imported torch already: about 4 s of CPU less per tiny run)."),
    ):
        """Train the tiny sweeps locally (online, then offline), then build every table, figure, claim and the
        report from them."""
        t0 = time.time()
        writable_folder(results_root, "--results")
        writable_folder(out, "--out")
        parallel = max_parallel or max(1, os.cpu_count() or 1)
        warm = ["--warm-start"] if warm_start else []
        cmd = [sys.executable, "-m", "repro", "sweep", sweep, "--results", str(results_root), "--max-parallel",
               str(parallel), *warm]
        typer.echo(f"[1/3] online training: {' '.join(cmd[2:])}")
        rc = subprocess.call(cmd)
        if rc != 0:
            fail(f"the sweep failed (exit {rc}); see `repro status {sweep}`", 1)
        for csv in sorted(results_root.glob(f"{sweep}/*/*/*/*/eval.csv")):
            typer.echo(f"\n{csv}:\n{csv.read_text().rstrip()}")

        typer.echo(f"\n[2/3] offline: datasets from {sweep}/{SOURCE_RUN}, then the {OFFLINE_SWEEP} sweep")
        experiment_map = {"main": [sweep]}
        if not offline:
            typer.echo("  skipped (--no-offline)")
        elif _offline_leg(results_root, sweep, parallel, warm):
            experiment_map["offline"] = [OFFLINE_SWEEP]

        from analysis.context import Context
        from analysis.load import load_results
        from repro_app.report import build_report

        typer.echo(f"\n[3/3] report from {results_root} (budget: the online runs' own frame budget)")
        results = load_results(results_root)
        online = results.runs[results.runs["offline_updates"].isna()] if not results.empty else results.runs
        frames = int(online["train_frames"].max()) if len(online) else 400
        ctx = Context(results=results, out_dir=out, budget=frames, reps=reps, tsne_n=200, min_seeds=1,
                      experiment_map=experiment_map, render_envs=render_envs)
        md, html = build_report(ctx, progress=lambda s: typer.echo(f"  {s}"))
        typer.echo(f"\nreport: {md} and {html} ({time.time() - t0:.0f} s in all)")
