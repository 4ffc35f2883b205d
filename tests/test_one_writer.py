"""One writer per run directory (issue 17): a second `repro train` of a running run is refused in one line
naming the holder, a SIGKILLed holder's lock goes with it, a refused resume writes nothing, a write error is
one line naming the file and a re-run resumes, and one dataset folder spelled several ways is one run."""

from __future__ import annotations

import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from offline_fixtures import write_dataset
from repro.config.compose import compose  # noqa: E402
from repro.runs import rundir  # noqa: E402
from repro.train import api  # noqa: E402
from repro_app.cli import app  # noqa: E402

OFFLINE = ["agent=bc", "task=cheetah_run", "profile=tiny", "seed=2", "runtime.threads=1", "offline.dataset=medium",
           "offline.eval_episodes=1", "offline.log_every_updates=5"]
OFFLINE_REL = Path("default/bc/base/cheetah_run/medium/seed_2")
ONLINE = ["task=cheetah_run", "profile=tiny", "train.frames=200", "runtime.threads=1"]
ONLINE_REL = Path("default/taco/base/cheetah_run/seed_1")


def _cmd(overrides: list[str], root: Path) -> list[str]:
    return [sys.executable, "-m", "repro", "train", *overrides, f"runtime.results_root={root}", "--no-progress"]


def _dataset(root: Path, seed: int = 0) -> Path:
    return write_dataset(root / "datasets" / "cheetah_run" / "medium", task="cheetah_run", action_dim=6,
                         best_return=200.0, seed=seed)


def _started(run: Path) -> bool:
    """meta.json exists: the run has begun writing (under its writer lock)."""
    return (run / "meta.json").exists()


def _second_start_is_refused(cmd: list[str], run: Path) -> None:
    """Start ``cmd``; once it holds the run's lock start it again: the second exits 2 in one line naming the
    first; then SIGKILL the first and take its lock (the kernel released it)."""
    first = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    try:
        t0 = time.time()
        while not _started(run) and first.poll() is None and time.time() - t0 < 120:
            time.sleep(0.05)
        assert _started(run), f"the first start never began: {first.poll()}"
        second = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        assert first.poll() is None, "the first run ended before the second started: the race was not tested"
    finally:
        first.send_signal(signal.SIGKILL)
        first.wait()
    lines = second.stderr.strip().splitlines()
    assert second.returncode == 2, second.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error:") and f"pid {first.pid} on" in lines[0], lines
    lock = rundir.acquire_writer_lock(run)  # SIGKILL released the first holder's lock
    lock.release()


def _rows_unique(csv: Path, key: str) -> None:
    if csv.exists():
        df = pd.read_csv(csv)
        assert df[key].is_unique and df[key].is_monotonic_increasing, df[key].tolist()


@pytest.mark.slow
def test_two_online_starts_of_one_run_one_is_refused(tmp_path: Path):
    run = tmp_path / ONLINE_REL
    _second_start_is_refused(_cmd(ONLINE, tmp_path), run)
    _rows_unique(run / "eval.csv", "frame")
    _rows_unique(run / "train.csv", "episode")


@pytest.mark.slow
def test_two_offline_starts_of_one_run_one_is_refused(tmp_path: Path):
    _dataset(tmp_path)
    run = tmp_path / OFFLINE_REL
    _second_start_is_refused(_cmd(OFFLINE + ["offline.updates=400", "offline.eval_every_updates=100",
                                             "offline.checkpoint_every_updates=50"], tmp_path), run)
    _rows_unique(run / "eval.csv", "update")
    _rows_unique(run / "train.csv", "update")


def test_a_held_lock_refuses_in_process_and_a_released_one_does_not(tmp_path: Path):
    run = tmp_path / "run"
    run.mkdir()
    with rundir.acquire_writer_lock(run):
        with pytest.raises(rundir.RunLocked, match=f"pid {os.getpid()} on"):
            rundir.acquire_writer_lock(run)  # flock: another open file description conflicts, same process too
    assert not (run / rundir.WRITER_LOCK).exists()  # released: its file removed (a run that ended leaves none)
    with rundir.acquire_writer_lock(run):  # a new file, locked as the first was
        assert (run / rundir.WRITER_LOCK).exists()
        with pytest.raises(rundir.RunLocked):
            rundir.acquire_writer_lock(run)
    assert not any(run.iterdir())


def test_a_lock_taken_on_a_file_its_holder_removed_is_taken_again_on_the_new_file(tmp_path: Path, monkeypatch):
    """A start that opened .writer.lock just before its holder released it (removing the file) gets the flock of a
    removed file: try_flock must see it and lock the file at the path, or a third start would lock a new file beside
    it and two would write. The holder's removal is made to land between this start's open and its flock."""
    import fcntl

    from repro.runs import fsutil

    real, removed = fcntl.flock, []

    def flock_after_removal(fd: int, op: int) -> None:
        if op & fcntl.LOCK_EX and not removed:
            removed.append((tmp_path / rundir.WRITER_LOCK).unlink())  # the holder released it meanwhile
        real(fd, op)

    monkeypatch.setattr(fsutil.fcntl, "flock", flock_after_removal)
    lock = rundir.acquire_writer_lock(tmp_path)
    monkeypatch.undo()
    held = os.fstat(lock.fd)
    assert removed and (os.stat(tmp_path / rundir.WRITER_LOCK).st_ino, os.stat(tmp_path / rundir.WRITER_LOCK).st_dev) \
        == (held.st_ino, held.st_dev)  # the lock is on the file at the path
    with pytest.raises(rundir.RunLocked):
        rundir.acquire_writer_lock(tmp_path)
    lock.release()


def _snapshot(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_refused_resume_leaves_every_file_byte_identical(tmp_path: Path):
    _dataset(tmp_path, seed=0)
    fast = OFFLINE + ["offline.updates=10", "offline.eval_every_updates=10", "offline.checkpoint_every_updates=5",
                      "offline.eval_episodes=0", f"runtime.results_root={tmp_path}"]
    run = api.train(fast, echo=lambda s: None)
    (run / rundir.DONE).unlink()  # as if killed after its last checkpoint, before it recorded its budget:
    meta = json.loads((run / rundir.META).read_text())
    (run / rundir.META).write_text(json.dumps({**meta, "budgets": []}))
    shutil.rmtree(tmp_path / "datasets")
    _dataset(tmp_path, seed=1)  # another dataset at the same path
    before = _snapshot(run)
    out = CliRunner().invoke(app, ["train", *fast, "--no-progress"])
    assert out.exit_code == 2 and "dataset changed" in out.output, out.output
    assert len(out.output.strip().splitlines()) == 1, out.output
    assert _snapshot(run) == before


def _limit_file_size(limit: int):
    def apply() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.slow
def test_a_write_error_is_one_line_naming_the_file_and_a_rerun_resumes(tmp_path: Path):
    _dataset(tmp_path)
    cmd = _cmd(OFFLINE + ["offline.updates=10", "offline.eval_every_updates=10", "offline.checkpoint_every_updates=5",
                          "offline.eval_episodes=0"], tmp_path)
    run = tmp_path / OFFLINE_REL
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=300,
                         preexec_fn=_limit_file_size(1_000_000))  # config, meta, CSVs fit; the checkpoint does not
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 1, out.stderr[-2000:]
    assert len(lines) == 1 and lines[0].startswith("error: cannot write"), lines
    assert str(run / "checkpoint.pt") in lines[0] and "re-run" in lines[0]
    assert not list(run.glob(".*.tmp")), "the failed write left its temporary file"
    (run / ".checkpoint.pt.torn.tmp").write_bytes(b"x")  # as a SIGKILL in the middle of a write leaves it
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr[-2000:]
    assert (run / rundir.DONE).exists() and not list(run.glob(".*.tmp"))
    _rows_unique(run / "train.csv", "update")


def test_one_dataset_folder_spelled_several_ways_is_one_run(tmp_path: Path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "ds" / "x").mkdir(parents=True)
    (tmp_path / "link").symlink_to(tmp_path / "ds")
    base = ["agent=bc", "task=cheetah_run"]
    dirs = {rundir.run_dir(compose(base + [f"offline.dataset={v}"]))
            for v in ("ds/x", "ds/x/", "./ds/x", str(tmp_path / "ds" / "x"), "link/x")}
    assert len(dirs) == 1, dirs
    # An absolute path without symlinks keeps the run directory it always had (sha256 of the value as written).
    real = os.path.realpath(tmp_path / "ds" / "x")
    tag = f"x-{hashlib.sha256(real.encode()).hexdigest()[:8]}"
    assert dirs.pop().parent.name == tag


def test_a_second_make_into_one_destination_is_refused(tmp_path: Path):
    from repro.train.make_dataset import MakeError, _make_lock

    out = tmp_path / "datasets" / "medium"
    with _make_lock(out):
        with pytest.raises(MakeError, match=f"being made by pid {os.getpid()}"):
            with _make_lock(out):
                pass
    assert not list(tmp_path.joinpath("datasets").iterdir()), "the lock file stays after a make"


def test_the_sweep_launcher_skips_a_run_that_a_hand_started_train_holds(tmp_path: Path):
    from types import SimpleNamespace

    from repro.launch import lock
    from repro.launch.runner import claim

    cfg = compose(["task=cheetah_run", f"runtime.results_root={tmp_path}"])
    planned = SimpleNamespace(results_root=tmp_path, run_dir=rundir.run_dir(cfg), cfg=cfg,
                              budget=rundir.run_budget(cfg))
    planned.run_dir.mkdir(parents=True)
    with rundir.acquire_writer_lock(planned.run_dir):
        c = claim(planned, "local", "s", force=False)  # type: ignore[arg-type]
        assert c.status == "locked" and c.info is not None
        assert c.info.describe() == f"pid {os.getpid()} on {os.uname().nodename}"
    assert not lock.lock_path(tmp_path, planned.run_dir).exists(), "the launcher's own claim was not released"
    c = claim(planned, "local", "s", force=False)  # type: ignore[arg-type]
    assert c.status == "claimed" and c.info is not None
    lock.release(c.lock_path, c.info.token)


def test_one_atomic_writer_and_one_flock_lock():
    """Only repro/runs/fsutil.py makes a temporary file, replaces a file with one or takes an flock: every other
    writer goes through atomic_output/atomic_write and every holder lock through try_flock. The exceptions publish
    a finished folder (a dataset's staging folder renamed to its name). A copy elsewhere fails here by file:line."""
    import ast

    root = Path(__file__).resolve().parents[1]
    folder_publish = {"repro/data/convert.py"}
    found = []
    for pkg in ("repro", "repro_app", "analysis", "paper_figures", "benchmarks"):
        for path in sorted((root / pkg).rglob("*.py")):
            rel = str(path.relative_to(root))
            if rel == "repro/runs/fsutil.py":
                continue
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and (
                        (node.value.id, node.attr) in {("tempfile", "mkstemp"), ("fcntl", "flock")}
                        or ((node.value.id, node.attr) == ("os", "replace") and rel not in folder_publish)):
                    found.append(f"{rel}:{node.lineno} {node.value.id}.{node.attr}")
    assert not found, found
