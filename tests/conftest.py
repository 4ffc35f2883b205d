"""Shared test setup: headless rendering, one torch thread, and the runs several test modules check, each
made once per test session (pytest-xdist: the tests that use one are kept on one worker by their
``xdist_group`` mark, so no run is trained twice).

* ``tiny_taco``: the tiny TACO cheetah_run run (seed 3, 400 frames), plain.
* ``tiny_taco_watched``: the same run recorded, with TensorBoard and videos (runtime keys): its logs must equal
  ``tiny_taco``'s (determinism, and neither recording nor watching changes a logged number).
* ``main_job``: `repro reproduce` (the README's main job: tiny online grid, its offline leg, the report),
  started in the background as the session starts when a selected test needs it.
"""

from __future__ import annotations

import fcntl
import os
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])

import pytest  # noqa: E402
import torch  # noqa: E402

from helpers import RECORD, TINY, WATCH  # noqa: E402

torch.set_num_threads(1)


def _quiet(_: str) -> None:
    pass


@pytest.fixture(scope="session")
def tiny_taco(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro.train import api

    return api.train([*TINY, f"runtime.results_root={tmp_path_factory.mktemp('tiny_taco')}"], echo=_quiet)


@pytest.fixture(scope="session")
def tiny_taco_watched(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro.train import api

    root = tmp_path_factory.mktemp("tiny_taco_watched")
    return api.train([*TINY, *RECORD, *WATCH, f"runtime.results_root={root}"], echo=_quiet)


@dataclass(frozen=True)
class MainJob:
    """What `repro reproduce --results runs --out out` left: its folders and its output."""

    runs: Path
    out: Path
    stdout: str


MAIN_JOB_TIMEOUT = 1800  # seconds


def _shared_root(factory: pytest.TempPathFactory) -> Path:
    """A folder every pytest-xdist worker of this test run sees (the base temp folder without xdist)."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session", autouse=True)
def _main_job_started_early(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """The main job is the longest run of the suite: when a selected test needs it, the first worker to start
    launches it in the background at once, so it trains while both workers run other tests."""
    if not any("main_job" in getattr(item, "fixturenames", ()) for item in request.session.items):
        yield
        return
    folder = _shared_root(tmp_path_factory) / "main_job"
    folder.mkdir(exist_ok=True)
    proc = None
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / "started").exists():
            cmd = [sys.executable, "-m", "repro", "reproduce", "--results", str(folder / "runs"), "--out",
                   str(folder / "out"), "--max-parallel", "2", "--reps", "500"]  # fewer bootstrap reps
            # the exit code goes to a file that every worker can wait for
            script = " ".join(shlex.quote(c) for c in cmd) + f" > {shlex.quote(str(folder / 'stdout'))} 2>&1; " \
                f"echo $? > {shlex.quote(str(folder / 'rc.tmp'))} && mv {shlex.quote(str(folder / 'rc.tmp'))} " \
                f"{shlex.quote(str(folder / 'rc'))}"
            proc = subprocess.Popen(["bash", "-c", script], start_new_session=True)
            (folder / "started").write_text(str(proc.pid))
    yield
    if proc is not None:  # the worker that started it leaves no process behind
        try:
            proc.wait(timeout=MAIN_JOB_TIMEOUT)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.fixture(scope="session")
def main_job(tmp_path_factory: pytest.TempPathFactory, _main_job_started_early: None) -> MainJob:
    folder = _shared_root(tmp_path_factory) / "main_job"
    deadline = time.time() + MAIN_JOB_TIMEOUT
    while not (folder / "rc").exists():
        assert time.time() < deadline, "the main job did not finish in time"
        time.sleep(1)
    stdout = (folder / "stdout").read_text()
    assert (folder / "rc").read_text().strip() == "0", stdout[-6000:]
    return MainJob(folder / "runs", folder / "out", stdout)
