"""Opt-in Weights & Biases mirror of the run's CSV logs (``runtime.wandb=true``; docs/watching.md).

The CSV files stay the source of truth. Every row written to ``eval.csv`` / ``train.csv`` is also logged to a
W&B run as ``eval/<column>`` / ``train/<column>`` (numeric cells only) at W&B step = the row's ``frame``
(offline runs: ``update``), which is also logged and set as every metric's x axis. An evaluation and a training
row of one frame share one W&B history row.

One W&B run per run directory: its id is kept in ``{run}/wandb/run_id``, so a resume, a requeued SLURM job
and a budget extension continue the same W&B run. Every start opens the CSVs at the checkpoint's offsets
(repro/runs/logger.py) and then calls :meth:`WandbMirror.rebuild` before the first new row:

* offline (the default): the W&B run folder cannot be rewritten in place, so every start deletes it and writes
  a new one, with the same id, from the truncated CSVs (as the TensorBoard mirror rebuilds its event files);
  the history read back holds each step once, whatever was written after the checkpoint.
* online: the server keeps what the killed process sent. The run is resumed (same id) at the server's next
  step: the truncated CSVs' rows from that step on are logged, and live rows before it are not logged again
  (the server has them; a resumed run recomputes the same values, the wall-clock columns aside).

Nothing here imports wandb at module level: runs without ``runtime.wandb`` never load it.
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from repro.config.errors import UserError
from repro.runs.fsutil import atomic_write_text
from repro.runs.runformat import WANDB as WANDB_DIR
from repro.runs.tblog import cell_number, csv_rows

__all__ = ["RUN_ID", "WANDB_DIR", "WandbError", "WandbMirror", "WandbRun", "check_wandb", "offline_folders",
           "read_history", "read_offline_run"]

RUN_ID = "run_id"  # {run}/wandb/run_id: the W&B run id of this run directory
OFFLINE_GLOB = "offline-run-*"  # wandb's name for an offline run folder inside {run}/wandb
PACKAGE_HINT = "pip install '.[wandb]'"


class WandbError(UserError, ValueError):
    """runtime.wandb=true cannot be honoured: no wandb package, or the W&B run cannot start (one line)."""


# wandb.Settings.mode's values: wandb reads WANDB_MODE from the environment at every run it starts, even when
# the run's mode is passed, and an invalid value is a pydantic traceback at the first write.
WANDB_MODES = ("online", "offline", "shared", "disabled", "dryrun", "run")


def check_wandb() -> None:
    """Raise :class:`WandbError` (one line) unless the wandb package imports and the environment's WANDB_MODE, if
    set, is one wandb accepts; call before anything is written."""
    mode = os.environ.get("WANDB_MODE")
    if mode is not None and mode not in WANDB_MODES:
        raise WandbError(f"WANDB_MODE={mode!r} in the environment is not a W&B mode ({', '.join(WANDB_MODES)}); "
                         "unset it (runtime.wandb_mode decides) or train with runtime.wandb=false")
    try:
        import wandb  # noqa: F401
    except ImportError as exc:
        raise WandbError(f"runtime.wandb=true needs the wandb package ({exc.msg}): {PACKAGE_HINT}, "
                         "or train with runtime.wandb=false") from None


@dataclass(frozen=True)
class WandbRun:
    """Where and how a run is mirrored: runtime.wandb_* and the run's identity (repro/train/build.py builds it)."""

    mode: str  # runtime.wandb_mode: offline | online
    project: str  # runtime.wandb_project
    entity: str | None  # runtime.wandb_entity
    group: str  # experiment/agent/variant/task (offline learners: /dataset)
    name: str  # the run's identity: its directory under the results root
    tags: tuple[str, ...]  # the sweep (runtime.sweep) and the seed
    config: Mapping[str, Any] = field(default_factory=dict)  # the run's resolved config


def read_run_id(folder: Path) -> str:
    """The W&B run id kept in ``folder/run_id``; a new one is made (and kept) the first time."""
    file = folder / RUN_ID
    if file.exists():
        run_id = file.read_text().strip()
        if re.fullmatch(r"[a-z0-9]{8,64}", run_id):
            return run_id
    folder.mkdir(parents=True, exist_ok=True)
    run_id = "".join(secrets.choice("abcdefghijklmnopqrstuvwxyz0123456789") for _ in range(16))
    atomic_write_text(file, run_id + "\n")
    return run_id


def _clear_local(folder: Path) -> None:
    """Everything wandb wrote under ``folder`` ({run}/wandb), the run id aside."""
    for entry in folder.iterdir():
        if entry.name == RUN_ID:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry)
        else:
            entry.unlink()


SERVICE_ENV = "WANDB_SERVICE"  # where wandb keeps the address of its wandb-core process; children inherit it
_service: str | None = None  # its value once this process started its own wandb-core


def _own_service() -> None:
    """Forget a wandb-core process inherited from a parent (one that mirrored a run in-process, then started
    this one): each run gets its own, which ends with it, so a killed run's W&B run is free for its resume."""
    if os.environ.get(SERVICE_ENV) != _service:
        os.environ.pop(SERVICE_ENV, None)


DEFERRED_SIGNALS = (signal.SIGUSR2, signal.SIGTERM, signal.SIGINT)  # submitit's requeue signals, and Ctrl-C


@contextmanager
def signals_deferred(signums: tuple[int, ...] = DEFERRED_SIGNALS) -> Iterator[None]:
    """Run the block with the Python-level handlers of ``signums`` held back, then call them for what arrived.

    A Python signal handler runs between two bytecodes of the main thread. submitit's USR2 handler requeues the
    job and raises SystemExit there; inside wandb's call to its service that leaves the W&B run half-written and
    its client in a state that the exit then trips over. Deferred, a W&B call completes (or fails) first and the
    handler runs right after it. Signals without a Python handler (default or ignored) are not touched; outside
    the main thread (where handlers cannot be set) the block runs as it is.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: dict[int, Callable[..., Any]] = {}
    arrived: list[tuple[int, Any]] = []
    for signum in signums:
        handler = signal.getsignal(signum)
        if callable(handler):
            held[signum] = handler
            signal.signal(signum, lambda n, frame: arrived.append((n, frame)))
    try:
        yield
    finally:
        for signum, handler in held.items():
            signal.signal(signum, handler)
        for signum, frame in arrived:
            held[signum](signum, frame)


class WandbMirror:
    """One W&B run mirroring a run directory's CSVs (see the module docstring for resume and extension)."""

    def __init__(self, run_dir: str | os.PathLike, run: WandbRun, step_column: str = "frame",
                 echo: Callable[[str], None] = print):
        run_dir = Path(run_dir)
        self.folder = run_dir / WANDB_DIR
        self.step_column = step_column
        self.offline = run.mode != "online"
        if self.offline:
            os.environ["WANDB_ERROR_REPORTING"] = "false"  # no crash reports either: nothing leaves the machine
        _own_service()
        import wandb

        self.run_id = read_run_id(self.folder)
        if self.offline:
            _clear_local(self.folder)  # rebuilt from the truncated CSVs (see rebuild)
        settings = wandb.Settings(silent=True, console="off", x_disable_stats=True, x_disable_machine_info=True,
                                  save_code=False, allow_val_change=True)
        try:
            with signals_deferred():
                self._run = wandb.init(mode="offline" if self.offline else "online", dir=str(run_dir), id=self.run_id,
                                       resume=None if self.offline else "allow", project=run.project,
                                       entity=run.entity, group=run.group, name=run.name, tags=list(run.tags),
                                       config=dict(run.config), reinit="create_new", settings=settings)
        except (wandb.errors.Error, OSError, TimeoutError) as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise WandbError(f"the W&B run {self.run_id} could not start ({first}); train with "
                             "runtime.wandb_mode=offline or runtime.wandb=false") from None
        global _service
        _service = os.environ.get(SERVICE_ENV)  # the wandb-core process that init started for this process
        self._run.define_metric(step_column)
        self._run.define_metric("*", step_metric=step_column)
        self.first_step = int(self._run.starting_step)  # steps below it are in the W&B run already (online)
        where = self._run.url if not self.offline else f"{self.folder} (send with `repro wandb sync`)"
        echo(f"W&B {'offline ' if self.offline else ''}run {self.run_id}: {where}")

    def add_row(self, prefix: str, row: Mapping[str, Any]) -> None:
        """Log every numeric column of ``row`` as ``{prefix}/{column}`` at the row's step (and the step itself)."""
        step = cell_number(row.get(self.step_column))
        if step is None or step < self.first_step:
            return
        data: dict[str, Any] = {self.step_column: int(step)}
        for key, value in row.items():
            x = cell_number(value) if key != self.step_column else None
            if x is not None:
                data[f"{prefix}/{key}"] = x
        with signals_deferred():
            self._run.log(data, step=int(step))

    def rebuild(self, csv_files: Mapping[str, str | os.PathLike]) -> int:
        """Log the rows of the given (truncated) CSV files (prefix -> path) that the W&B run lacks, in step order;
        returns their number."""
        rows = [(cell_number(row.get(self.step_column)), prefix, row) for prefix, row in csv_rows(csv_files)]
        due = sorted(((s, p, r) for s, p, r in rows if s is not None and s >= self.first_step),
                     key=lambda t: t[0])  # stable: one step's rows keep their file order
        for _, prefix, row in due:
            self.add_row(prefix, row)
        return len(due)

    def close(self, failing: bool = False) -> None:
        """Finish the W&B run. ``failing``: the run's loop is ending with an exception (a kill, a requeue's
        SystemExit, an error): a W&B error then is one line on stderr instead of replacing the loop's exception
        (SLURM's requeue stops wandb's service process at once, so its finish fails). Nothing is lost: every
        start rebuilds the W&B run from the CSVs."""
        try:
            with signals_deferred():
                self._run.finish(exit_code=1 if failing else None)
        except Exception as exc:  # wandb raises its own, asyncio and socket errors here; all mean the same
            if not failing:
                raise
            print(f"W&B run {self.run_id} not finished ({type(exc).__name__}: {exc}); the next start of the run "
                  "rebuilds it from the CSVs", file=sys.stderr)


def offline_folders(run_dir: str | os.PathLike) -> list[Path]:
    """The offline W&B run folders of a run directory (one after a start; none without runtime.wandb)."""
    folder = Path(run_dir) / WANDB_DIR
    return sorted(p for p in folder.glob(OFFLINE_GLOB) if p.is_dir()) if folder.is_dir() else []


def _records(run_dir: str | os.PathLike) -> list[Any]:
    """Every record of the run's offline W&B transaction log (``run-<id>.wandb``), read by wandb's own reader
    (``wandb leet inspect``, wandb-core) and parsed into wandb's ``Record`` protobuf messages."""
    from google.protobuf import text_format
    from wandb.proto import wandb_internal_pb2 as pb

    folders = offline_folders(run_dir)
    if len(folders) != 1:
        raise FileNotFoundError(f"{Path(run_dir) / WANDB_DIR}: {len(folders)} offline W&B run folders, not one")
    files = list(folders[0].glob("run-*.wandb"))
    if len(files) != 1:
        raise FileNotFoundError(f"{folders[0]}: {len(files)} .wandb files, not one")
    out = subprocess.run([sys.executable, "-m", "wandb", "leet", "inspect", str(files[0])], capture_output=True,
                         text=True, stdin=subprocess.DEVNULL, timeout=120, check=False)
    if out.returncode != 0:
        raise RuntimeError(f"wandb leet inspect {files[0]}: {out.stderr.strip()[-500:]}")
    records = []
    for block in re.split(r"^# record \d+: \w+\n", out.stdout, flags=re.M):
        if block.strip():
            records.append(text_format.Parse(block, pb.Record()))  # type: ignore[attr-defined]  # a star import
    return records


def read_offline_run(run_dir: str | os.PathLike) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The run's offline W&B run: its run record (id, project, entity, group, name, tags, config: key -> value)
    and its history rows in order (key -> value, ``_step`` included)."""
    run: dict[str, Any] | None = None
    history = []
    for record in _records(run_dir):
        kind = record.WhichOneof("record_type")
        if kind == "history":
            history.append({"/".join(item.nested_key) or item.key: json.loads(item.value_json)
                            for item in record.history.item})
        elif kind == "run" and run is None:
            r = record.run
            run = {"id": r.run_id, "project": r.project, "entity": r.entity, "group": r.run_group,
                   "name": r.display_name, "tags": list(r.tags),
                   "config": {u.key: json.loads(u.value_json) for u in r.config.update}}
    if run is None:
        raise FileNotFoundError(f"{run_dir}: the offline W&B run has no run record")
    return run, history


def read_history(run_dir: str | os.PathLike) -> list[dict[str, Any]]:
    """The history rows of the run's offline W&B run, in order: key -> value (``_step`` included)."""
    return read_offline_run(run_dir)[1]
