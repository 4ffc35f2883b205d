"""`repro reproduce`: the main job, a tiny end-to-end reproduction on the defaults.

It trains the `tiny` sweep locally (TACO and DrQ-v2, two DMC tasks, two seeds, real rendering and
updates), then renders every table and figure, the claim verdicts, the audit and REPORT.md/.html
from those runs. Re-running it resumes or skips what is already done.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path
from typing import Optional

import typer


def register(app: typer.Typer) -> None:
    @app.command()
    def reproduce(
        results_root: Path = typer.Option(Path("runs/tiny"), "--results", help="Results root."),
        out: Path = typer.Option(Path("results/tiny"), "--out", help="Where tables, figures and the report go."),
        sweep: str = typer.Option("tiny", help="Sweep to train before reporting."),
        max_parallel: Optional[int] = typer.Option(None, "--max-parallel", help="Runs at once (default: cores / 2)."),
        reps: int = typer.Option(2000, help="Bootstrap repetitions (rliable's default is 50,000)."),
        render_envs: bool = typer.Option(
            False, "--render-envs/--no-render-envs", help="Let F13 render random-action frames for tasks without runs."
        ),
    ):
        """Train the tiny sweep locally, then build every table, figure, claim and the report from it."""
        t0 = time.time()
        cmd = [sys.executable, "-m", "repro", "sweep", sweep, "--results", str(results_root)]
        if max_parallel:
            cmd += ["--max-parallel", str(max_parallel)]
        typer.echo(f"[1/2] training: {' '.join(cmd[2:])}")
        rc = subprocess.call(cmd)
        if rc != 0:
            typer.echo(f"error: the sweep failed (exit {rc}); see `repro status {sweep}`", err=True)
            raise typer.Exit(1)
        for csv in sorted(results_root.glob(f"{sweep}/*/*/*/*/eval.csv")):
            typer.echo(f"\n{csv}:\n{csv.read_text().rstrip()}")

        from analysis.context import Context
        from analysis.load import load_results
        from repro_app.report import build_report

        typer.echo(f"\n[2/2] report from {results_root} (budget: the runs' own frame budget)")
        results = load_results(results_root)
        frames = int(results.runs["train_frames"].max()) if not results.empty else 400
        ctx = Context(results=results, out_dir=out, budget=frames, reps=reps, tsne_n=200, min_seeds=1,
                      experiment_map={"main": [sweep]}, render_envs=render_envs)
        md, html = build_report(ctx, progress=lambda s: typer.echo(f"  {s}"))
        typer.echo(f"\nreport: {md} and {html} ({time.time() - t0:.0f} s in all)")
