"""``repro tensorboard``, ``repro wandb sync`` and ``repro plot``: look at runs while they train (docs/watching.md).

Bad input (no runs, unknown metric or --by column, a missing folder) prints one line and exits 2.
"""

from __future__ import annotations

import shlex
import shutil
import subprocess
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer

from repro.runs.console import fail
from repro.runs.fsutil import writable_folder
from repro.runs.runformat import DONE
from repro.runs.tblog import TB_DIR
from repro.runs.wblog import RUN_ID, WANDB_DIR, offline_folders

if TYPE_CHECKING:
    import pandas as pd


def _tool(name: str) -> str:
    """The command ``name`` on PATH, else beside this Python (an unactivated venv), else the bare name."""
    exe = shutil.which(name) or str(Path(sys.executable).with_name(name))
    return exe if Path(exe).exists() else name


def tensorboard_command(root: Path, port: Optional[int] = None) -> list[str]:
    """``tensorboard --logdir ROOT`` (TensorBoard finds every run's ``tb`` folder below ROOT)."""
    cmd = [_tool("tensorboard"), "--logdir", str(root)]
    return cmd + (["--port", str(port)] if port is not None else [])


wandb_app = typer.Typer(add_completion=False, no_args_is_help=True,
                        help="The W&B mirror of runs trained with runtime.wandb=true (docs/watching.md).")


def register(app: typer.Typer) -> None:
    """Add ``tensorboard``, ``wandb sync`` and ``plot`` to ``app``."""
    app.command("tensorboard")(tensorboard_cmd)
    wandb_app.command("sync")(wandb_sync_cmd)
    app.add_typer(wandb_app, name="wandb")
    app.command("plot")(plot_cmd)


def tensorboard_cmd(
    root: Path = typer.Argument(..., help="A results root (a whole sweep) or one run directory."),
    run: bool = typer.Option(False, "--run", help="Start TensorBoard instead of printing the command."),
    port: Optional[int] = typer.Option(None, "--port", min=1, max=65535, help="TensorBoard's port."),
) -> None:
    """Print (or --run) the command that opens every run under ROOT in TensorBoard (runtime.tensorboard=true)."""
    if not root.is_dir():
        fail(f"{root} does not exist or is not a directory")
    n = sum(1 for _ in root.rglob(f"{TB_DIR}/events.out.tfevents.*"))
    cmd = tensorboard_command(root, port)
    if not run:
        typer.echo(shlex.join(cmd))
        typer.echo(f"# {n} run(s) with event files under {root}"
                   + ("" if n else " (train with runtime.tensorboard=true)"), err=True)
        return
    if n == 0:
        fail(f"no event files under {root} (train with runtime.tensorboard=true)")
    raise typer.Exit(subprocess.call(cmd))

def wandb_runs(paths: list[Path]) -> list[Path]:
    """The run directories at or under ``paths`` that have a W&B mirror (``wandb/run_id``), sorted, each once."""
    found: set[Path] = set()
    for path in paths:
        if (path / WANDB_DIR / RUN_ID).exists():
            found.add(path)
        found.update(f.parent.parent for f in path.rglob(f"{WANDB_DIR}/{RUN_ID}"))
    return sorted(found)


def wandb_sync_cmd(
    paths: list[Path] = typer.Argument(..., help="Results roots (a whole sweep) and/or run directories."),
    run: bool = typer.Option(False, "--run", help="Run `wandb sync` instead of printing the command."),
    unfinished: bool = typer.Option(False, "--unfinished", help="Also runs that are not done (a resume "
                                    "rebuilds their W&B folder: sync them again once they are done)."),
) -> None:
    """Print (or --run) the `wandb sync` command that sends the offline W&B runs under PATHS (runtime.wandb=true)."""
    for path in paths:
        if not path.is_dir():
            fail(f"{path} does not exist or is not a directory")
    runs = wandb_runs(paths)
    done = [r for r in runs if unfinished or (r / DONE).exists()]
    folders = [f for r in done for f in offline_folders(r)]
    if not folders:
        why = (" (train with runtime.wandb=true)" if not runs else
               f"; {len(runs) - len(done)} not done (--unfinished)" if len(done) < len(runs) else
               " (runtime.wandb_mode=online runs were sent as they trained)")
        fail(f"no offline W&B run to sync under {', '.join(map(str, paths))}{why}")
    cmd = [_tool("wandb"), "sync", *map(str, folders)]
    if not run:
        left = len(runs) - len(done)
        typer.echo(shlex.join(cmd))
        typer.echo(f"# {len(folders)} offline W&B run(s)" + (f", {left} not done left out (--unfinished)" if left
                                                            else ""), err=True)
        return
    if shutil.which(cmd[0]) is None and not Path(cmd[0]).exists():
        fail("wandb not found: pip install '.[wandb]' (or run the printed command where it is installed)")
    raise typer.Exit(subprocess.call(cmd))


def plot_cmd(
    paths: list[Path] = typer.Argument(..., help="Results roots and/or run directories."),
    metric: str = typer.Option("episode_reward", "--metric", "-m",
                               help="An eval.csv column, or else a train.csv column (e.g. critic_loss)."),
    by: str = typer.Option("agent,variant", "--by",
                           help="Identity columns that name a curve (e.g. agent,variant or method,K)."),
    out: Path = typer.Option(Path("plot.png"), "--out", "-o", help="PNG to write; the PDF goes beside it."),
    reps: int = typer.Option(2000, "--reps", min=1, help="Bootstrap repetitions of the CI band."),
    seed: int = typer.Option(0, "--seed", help="Random state of the bootstrap."),
    published: bool = typer.Option(True, "--published/--no-published",
                                   help="Draw the DrQ-v2 authors' published curve (mean and 95% CI band) on "
                                        "each task that has one (episode_reward against frames only)."),
) -> None:
    """Learning curves of any runs: one panel per task, mean over seeds with a 95% bootstrap CI band."""
    from analysis.quick import by_columns, load_runs, repeated_seeds, tidy_curves
    from paper_figures.quick_plot import plot_curves

    writable_folder(out.expanduser().absolute().parent, f"--out {out}: its folder")
    cols = by_columns(by)
    runs, evals, problems = load_runs(paths)
    curves = tidy_curves(runs, evals, metric, cols)
    for problem in problems:
        typer.echo(f"  {problem}", err=True)
    for cell in repeated_seeds(curves):
        typer.echo(f"  warning: {cell}: several runs share a seed (averaged); add experiment to --by", err=True)
    bands = _published_bands(curves, reps, seed) if published and metric == "episode_reward" else {}
    written = plot_curves(curves, metric, out, by=cols, reps=reps, seed=seed, published=bands)
    typer.echo(f"{curves['run_id'].nunique()} run(s), {curves['task'].nunique()} task(s): "
               f"wrote {', '.join(str(p) for p in written)}")


def _published_bands(curves: pd.DataFrame, reps: int, seed: int) -> dict[str, pd.DataFrame]:
    """Per task of ``curves`` with a published DrQ-v2 curve: its mean and 95% CI band up to the task's last frame."""
    from analysis.calibration import packaged_published, published_band

    pub = packaged_published()
    bands = {}
    for task, rows in curves.groupby("task"):
        band = published_band(pub, str(task), float(rows["frame"].max()), reps, seed)
        if not band.empty:
            bands[str(task)] = band
    return bands
