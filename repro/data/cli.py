"""``repro dataset info | check | import | export``: the Typer sub-app for offline datasets.

Bad input (a missing, partial or damaged dataset, a wrong layout, another task's data, an existing
``--out``) prints one ``error: ...`` line and exits 2; nothing already on disk is changed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from repro.config.compose import compose_base, is_folder_value
from repro.data.convert import default_import_name, export_dataset, import_dataset
from repro.data.dataset import MANIFEST, check_dataset, dataset_path, load_manifest
from repro.data.formats import FORMATS
from repro.data.summary import plot_returns, summarize
from repro.runs.console import Commands, fail
from repro.runs.fsutil import FULL, writable_folder, write_error_message

dataset_app = typer.Typer(cls=Commands, add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False,
                          help="Offline datasets: inspect, check, import and export.")

FORMAT_HELP = " | ".join(FORMATS)
RESULTS_OPT = typer.Option(None, "--results", "-r",
                           help="Results root (default: the config's runtime.results_root).")


def _os_message(exc: OSError) -> str:
    return f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")


def _results_root(value: Optional[Path]) -> Path:
    if value is not None:
        return value
    return Path(str(compose_base().runtime.results_root))


@dataset_app.command("info")
def info_cmd(directory: Path = typer.Argument(..., help="Dataset folder."),
             out: Optional[Path] = typer.Option(None, "--out", "-o",
                                                help="Histogram PNG path (default: DIR/returns.png)."),
             bins: int = typer.Option(20, "--bins", help="Histogram bins.")) -> None:
    """Size, episodes, transitions and per-episode returns of a dataset, plus a return histogram PNG."""
    try:
        m = load_manifest(directory)
        s = summarize(m, directory)
    except OSError as exc:
        fail(_os_message(exc))
    png = out or directory / "returns.png"
    try:
        plot_returns(m.returns, png, f"{m.task} / {m.kind}: {s['episodes']} episodes", bins=max(1, bins))
        plotted = str(png)
    except OSError as exc:  # a read-only dataset (a shared datasets folder): the statistics still print
        plotted = f"not written ({_os_message(exc)}); pass --out FILE.png to write it elsewhere"
    echo = typer.echo
    echo(f"dataset      {directory}")
    echo(f"task         {s['task']} (action dim {s['action_dim']}, frames {'x'.join(map(str, s['frame_shape']))})")
    echo(f"kind         {s['kind']}")
    echo(f"size         {s['bytes'] / 1e6:.1f} MB on disk")
    echo(f"episodes     {s['episodes']} (length {s['length_min']}-{s['length_max']} transitions)")
    echo(f"transitions  {s['transitions']:,}")
    echo(f"return       mean {s['return_mean']:.2f}  std {s['return_std']:.2f}  min {s['return_min']:.2f}  "
         f"median {s['return_median']:.2f}  max {s['return_max']:.2f}")
    if m.source:
        echo("source       " + ", ".join(f"{k}={v}" for k, v in m.source.items()))
    if m.rule:
        echo("rule         " + ", ".join(f"{k}={v}" for k, v in m.rule.items()))
    echo("per-episode returns:")
    r = s["returns"]
    for i in range(0, len(r), 10):
        echo(f"  {i:>6}: " + " ".join(f"{x:.2f}" for x in r[i:i + 10]))
    echo(f"histogram    {plotted}")


@dataset_app.command("check")
def check_cmd(directory: Path = typer.Argument(..., help="Dataset folder.")) -> None:
    """Verify hashes, shapes, dtypes and episode structure: exit 0 when valid, 2 with one line per problem."""
    try:
        problems = check_dataset(directory)
    except OSError as exc:
        problems = [_os_message(exc)]
    if problems:
        for p in problems:
            typer.echo(f"error: {p}", err=True)
        raise typer.Exit(2)
    m = load_manifest(directory)
    typer.echo(f"ok: {directory}: {len(m.episodes)} episodes, {m.transitions:,} transitions "
               "(hashes, shapes, dtypes and episode structure verified)")


@dataset_app.command("import")
def import_cmd(path: Path = typer.Argument(..., help="An input file or a folder of them."),
               fmt: str = typer.Option(..., "--format", "-f", help=FORMAT_HELP),
               task: str = typer.Option(..., "--task", help="Task the data comes from (checks the action dim)."),
               out: Optional[str] = typer.Option(
                   None, "--out", "-o",
                   help="A name (-> RESULTS/datasets/TASK/NAME) or a folder (with a '/'); "
                        "default: imported-FORMAT."),
               resize: Optional[int] = typer.Option(
                   None, "--resize", help="Accept frames of any size and resize them to NxN (bicubic; recorded in "
                                          "the manifest). Without it each format takes its documented size only."),
               results_root: Optional[Path] = RESULTS_OPT) -> None:
    """Import V-D4RL (hdf5 84px, npz 64px) or DrQ-v2/TACO replay episodes as a dataset (resumable)."""
    if fmt not in FORMATS:
        fail(f"unknown format '{fmt}' (known: {', '.join(FORMATS)})")
    name = out or default_import_name(fmt)
    root = Path(".") if is_folder_value(name) else _results_root(results_root)
    try:
        target = dataset_path(name, root, task)
        existed = (target / MANIFEST).exists()
        if not existed:
            writable_folder(target, "--out")
        m = import_dataset(path, fmt, task, target, resize=resize)
    except OSError as exc:  # a full disk: the partial import is kept and a re-run resumes it
        fail(write_error_message(exc), 1 if exc.errno in FULL else 2)
    if existed:
        typer.echo(f"already imported: {target} holds this import ({len(m.episodes)} episodes); nothing written")
        return
    typer.echo(f"imported {len(m.episodes)} episodes ({m.transitions:,} transitions, return mean "
               f"{m.returns.mean():.2f}) from {path} into {target}")


@dataset_app.command("export")
def export_cmd(directory: Path = typer.Argument(..., help="Dataset folder."),
               fmt: str = typer.Option(..., "--format", "-f", help=FORMAT_HELP),
               out: Path = typer.Option(..., "--out", "-o", help="New folder to write (must not exist).")) -> None:
    """Export a dataset as V-D4RL hdf5 (84px), V-D4RL npz (64px) or DrQ-v2 replay episodes."""
    if fmt not in FORMATS:
        fail(f"unknown format '{fmt}' (known: {', '.join(FORMATS)})")
    writable_folder(out, "--out")
    try:
        files = export_dataset(directory, fmt, out)
    except OSError as exc:
        fail(_os_message(exc))
    typer.echo(f"exported {directory} as {fmt}: {len(files)} file(s) in {out}")
