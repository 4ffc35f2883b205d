"""The `repro dataset make` command, added to the `dataset` sub-app by ``register(dataset_app)``. The maker (and
with it torch) is imported when the command runs, so that `repro` starts without it."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from repro.config.schema import DatasetKind
from repro.runs.console import fail
from repro.runs.fsutil import write_error_message


def register(dataset_app: typer.Typer) -> None:
    @dataset_app.command("make")
    def make_cmd(
        source: Path = typer.Option(
            ..., "--source", help="Run directory of an online run trained with runtime.record=true."),
        kind: str = typer.Option(..., "--kind", help=f"Dataset kind: {' | '.join(DatasetKind.values())}."),
        transitions: Optional[int] = typer.Option(
            None, "--transitions", help="Transitions, whole episodes (default: 100000, quadruped_run 500000)."),
        medium_fraction: Optional[float] = typer.Option(
            None, "--medium-fraction", help="medium: snapshot nearest this fraction of the best return (default 0.5)."),
        seed: int = typer.Option(0, "--seed", help="Seed of the episode draw (replay kinds) or rollouts (medium)."),
        out: Optional[Path] = typer.Option(
            None, "--out", help="Dataset folder (default: {results}/datasets/{task}/{kind})."),
        results: Optional[Path] = typer.Option(
            None, "--results", "-r", help="Results root of the default folder (default: the source run's)."),
        task: Optional[str] = typer.Option(None, "--task", help="Refuse a source run of another task."),
        device: str = typer.Option("auto", "--device", help="Torch device of the medium rollouts: auto | cpu | cuda."),
    ) -> None:
        """Make a medium, medium-replay or full-replay dataset from a recorded online run (docs/offline.md)."""
        from repro.train.make_dataset import make

        try:
            make(source, kind, transitions, medium_fraction, seed, out, results, task, device, echo=typer.echo)
        except OSError as exc:  # a full disk: the staging folder is kept and a re-run resumes from it
            fail(write_error_message(exc), 1)
