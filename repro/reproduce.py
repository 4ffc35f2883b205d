"""`repro reproduce`: the main job, a tiny end-to-end reproduction on the defaults."""

from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    @app.command()
    def reproduce(results_root: Path = typer.Option(Path("runs/tiny"), "--results", help="Results root."),
                  out: Path = typer.Option(Path("results/tiny"), "--out", help="Where figures and report go.")):
        """Train a short TACO run on cheetah_run (real rendering, real updates) and print its eval rows."""
        from repro.api import train

        path = train(["profile=tiny", "task=cheetah_run", "agent=taco", f"runtime.results_root={results_root}",
                      "experiment=tiny"], echo=typer.echo, progress=None)
        typer.echo(f"\n{path / 'eval.csv'}:")
        typer.echo((path / "eval.csv").read_text())
