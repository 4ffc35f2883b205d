"""The `repro` command line: train one run and list tasks here; sweeps, benchmark, analysis and the main job
add their commands through their ``register(app)``."""

from __future__ import annotations

import os
from typing import Optional

import typer
from omegaconf import OmegaConf

from repro.bench import cli as bench
from repro.data.cli import dataset_app
from repro.launch import cli as launch_cli
from repro.launch import doctor
from repro.runs.console import Commands, console, fail
from repro.train import make_dataset_cli as make_cli
from repro_app import analysis_cli, plan_cli, reproduce, verify_cli, watch_cli

os.environ.setdefault("MUJOCO_GL", "egl")

app = typer.Typer(cls=Commands, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                  help="Reproduce, extend and report TACO (Zheng et al., NeurIPS 2023).")


@app.command(context_settings={"allow_extra_args": True, "ignore_unknown_options": True})
def train(ctx: typer.Context,
          dry_run: bool = typer.Option(False, "--dry-run", help="Print the resolved config and parameter counts."),
          progress: Optional[bool] = typer.Option(None, "--progress/--no-progress", help="Rich progress bar.")):
    """Train one run: `repro train agent=taco task=hopper_hop agent.K=3 seed=2` (Hydra overrides). Ctrl-C stops it
    in one line, exit 130; the same command resumes it."""
    from repro.config.compose import compose
    from repro.runs.fsutil import write_error_message

    try:
        cfg = compose(ctx.args)  # Hydra and the plugins: a second or more, Ctrl-C included
        if dry_run:
            _dry_run(cfg)
            return
        from repro.train.api import train_config  # torch: seconds to import, Ctrl-C included

        path = train_config(cfg, echo=typer.echo, progress=progress)
    except OSError as exc:  # a full disk or a file size limit: every file is written atomically or truncated on resume
        fail(write_error_message(exc), code=1)
    except KeyboardInterrupt as exc:  # RunInterrupted names the frame; before the loop, nothing to name
        typer.echo(str(exc) or "interrupted; run the same command to resume", err=True)
        raise typer.Exit(130) from None
    typer.echo(f"run directory: {path}")


def _dry_run(cfg) -> None:
    from rich.table import Table

    from repro.config.compose import typed
    from repro.train.build import build_run_learner, run_action_dim

    rc = typed(cfg)
    con = console(min_width=120)
    con.print(OmegaConf.to_yaml(cfg, resolve=True), markup=False, highlight=False)
    action_dim = run_action_dim(rc)
    obs_shape = (3 * rc.env.frame_stack, rc.env.image_size, rc.env.image_size)
    agent = build_run_learner(rc, obs_shape, action_dim, "cpu")
    table = Table(title=f"trainable parameters ({rc.agent.name}, |A|={action_dim})")
    table.add_column("module")
    table.add_column("parameters", justify="right")
    rows = agent.parameter_counts()
    for name, count in rows:
        table.add_row(name, f"{count:,}")
    table.add_row("[bold]total", f"[bold]{sum(c for _, c in rows):,}")
    con.print(table)
    from repro.runs.rundir import run_dir
    con.print(f"run directory: {run_dir(cfg)}")


@app.command()
def tasks():
    """List every task with its suite, action dimension and defaults."""
    from rich.table import Table

    from repro.config.compose import compose
    from repro.envs import TASKS

    table = Table(title="tasks")
    for col in ("task", "suite", "|A|", "preset", "K", "nstep", "frames", "camera"):
        table.add_column(col)
    for name, info in TASKS.items():
        cfg = compose([f"task={name}"])
        table.add_row(name, info.suite, str(info.action_dim), cfg.task.preset, str(cfg.agent.K),
                      str(cfg.agent.nstep), f"{cfg.train.frames:,}", str(info.camera))
    console(min_width=120).print(table)


for _commands in (launch_cli, doctor, analysis_cli, plan_cli, bench, reproduce, verify_cli, watch_cli):
    _commands.register(app)
make_cli.register(dataset_app)  # `repro dataset make` (training layer: it rolls out policies)
app.add_typer(dataset_app, name="dataset")


def main() -> None:
    app()


if __name__ == "__main__":
    main()
