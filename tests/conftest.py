"""Shared test setup: headless rendering, one torch thread, and the runs several test modules check, each
made once per test session (pytest-xdist: the tests that use one are kept on one worker by their
``xdist_group`` mark, so no run is trained twice).

* ``tiny_taco``: the tiny TACO cheetah_run run (seed 3, 400 frames), plain. Its loop is watched as it trains
  (``tiny_taco_loop_events``: each update's return, each env step and each wait for the device, in order).
* ``tiny_taco_watched``: the same run recorded, with TensorBoard and videos (runtime keys): its logs must equal
  ``tiny_taco``'s (determinism, and neither recording nor watching changes a logged number).
* ``main_job``: `repro reproduce` (the README's main job: tiny online grid, its offline leg, the report) and its
  second invocation on the same folders, started in the background as the session starts when a selected test
  needs it.

With pytest-xdist (``-n 2 --dist loadgroup``) the longest work units are queued first (``pytest_collection_modifyitems``
below), so that no long test starts last on one worker while the other has nothing left to do.
"""

from __future__ import annotations

import fcntl
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
# The W&B mirror (runtime.wandb) of the tests is offline: no test needs the network, whatever a run's config says.
os.environ.update(WANDB_MODE="offline", WANDB_SILENT="true", WANDB_ERROR_REPORTING="false")

import pytest  # noqa: E402
import torch  # noqa: E402

from helpers import (  # noqa: E402
    MAIN_JOB,
    RECORD,
    TINY,
    TINY_ALIX,
    TINY_ALIX_REL,
    TINY_ALIX_SETS,
    TINY_TACO,
    WATCH,
    watch_loop,
    watch_syncs,
)

torch.set_num_threads(1)


def _quiet(_: str) -> None:
    pass


_TINY_TACO_LOOP: list[str] = []  # tiny_taco's loop events (helpers.watch_loop, helpers.watch_syncs)


@pytest.fixture(scope="session")
def tiny_taco(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro.train import api

    with pytest.MonkeyPatch.context() as mp:
        watch_syncs(mp, _TINY_TACO_LOOP)
        watch_loop(mp, _TINY_TACO_LOOP)
        return api.train([*TINY, f"runtime.results_root={tmp_path_factory.mktemp('tiny_taco')}"], echo=_quiet)


@pytest.fixture(scope="session")
def tiny_taco_loop_events(tiny_taco: Path) -> list[str]:
    """What ``tiny_taco``'s loop did, in order: ``"update returned"``, ``"env.step"`` and ``"sync ..."`` events."""
    return list(_TINY_TACO_LOOP)


@pytest.fixture(scope="session")
def tiny_taco_watched(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from repro.train import api

    root = tmp_path_factory.mktemp("tiny_taco_watched")
    return api.train([*TINY, *RECORD, *WATCH, f"runtime.results_root={root}"], echo=_quiet)


@pytest.fixture(scope="session")
def tiny_alix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A tiny recorded A-LIX run through `repro sweep` (helpers.TINY_ALIX_SETS): its run directory. Made once for
    test_alix_train (a killed and resumed `repro train` gives its logs) and test_alix_dataset (a dataset made from
    it)."""
    import yaml
    from typer.testing import CliRunner

    from helpers import launch_app

    folder = tmp_path_factory.mktemp("tiny_alix")
    sweep = folder / "alix_tiny.yaml"
    sweep.write_text(yaml.safe_dump({
        "name": "alix_tiny", "description": "a tiny A-LIX run", "artifacts": [], "experiment": "alix_tiny",
        "tasks": ["cheetah_run"], "agents": ["alix"], "seeds": 1, "frames": None,
        "eval": {"every_frames": None, "episodes": None}, "common": TINY_ALIX_SETS, "variants": {"base": []}}))
    out = CliRunner().invoke(launch_app(), ["sweep", str(sweep), "--results-root", str(folder / "swept")])
    assert out.exit_code == 0, out.output
    return folder / "swept" / TINY_ALIX_REL


@dataclass(frozen=True)
class MainJob:
    """What `repro reproduce --results runs --out out`, run twice, left: its folders, the output of each
    invocation, and every run's DONE file (path -> mtime in ns) before and after the second invocation."""

    runs: Path
    out: Path
    stdout: str
    again: str
    done_before: dict[str, int]
    done_after: dict[str, int]


MAIN_JOB_TIMEOUT = 1800  # seconds
MAIN_JOB_REPS = "500"  # fewer bootstrap repetitions than the default 2,000 (no test reads a CI's width)

# The background process: the main job, then (if it passed) its second invocation, which must find every run
# done. Each invocation's output and the DONE files go to files every worker can read; ``rc`` (both exit codes)
# is written last, atomically.
_MAIN_JOB_SCRIPT = r"""
import json, os, subprocess, sys
from pathlib import Path

folder, reps = Path(sys.argv[1]), sys.argv[2]
cmd = [sys.executable, "-m", "repro", "reproduce", "--results", str(folder / "runs"), "--out", str(folder / "out"),
       "--max-parallel", "2", "--reps", reps]


def done(name):
    files = sorted((folder / "runs").glob("tiny*/**/DONE"))
    (folder / name).write_text(json.dumps({str(p): p.stat().st_mtime_ns for p in files}))


codes = []
for log in ("stdout", "stdout_again"):
    with open(folder / log, "w") as out:
        codes.append(subprocess.call(cmd, stdout=out, stderr=subprocess.STDOUT))
    done("done_before.json" if log == "stdout" else "done_after.json")
    if codes[-1] != 0:
        break
(folder / "rc.tmp").write_text(" ".join(map(str, codes)))
os.replace(folder / "rc.tmp", folder / "rc")
"""


def _shared_root(factory: pytest.TempPathFactory) -> Path:
    """A folder every pytest-xdist worker of this test run sees (the base temp folder without xdist)."""
    base = factory.getbasetemp()
    return base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base


@pytest.fixture(scope="session", autouse=True)
def _main_job_started_early(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory):
    """The main job is the longest run of the suite: when a selected test needs it, the first worker to start
    launches it (and its second invocation) in the background at once, so it trains while both workers run
    other tests."""
    if not any("main_job" in getattr(item, "fixturenames", ()) for item in request.session.items):
        yield
        return
    folder = _shared_root(tmp_path_factory) / "main_job"
    folder.mkdir(exist_ok=True)
    proc = None
    with open(folder / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (folder / "started").exists():
            proc = subprocess.Popen([sys.executable, "-c", _MAIN_JOB_SCRIPT, str(folder), MAIN_JOB_REPS],
                                    start_new_session=True)
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
    codes = (folder / "rc").read_text().split()
    assert codes[0] == "0", stdout[-6000:]
    again = (folder / "stdout_again").read_text()
    assert codes == ["0", "0"], again[-6000:]
    return MainJob(folder / "runs", folder / "out", stdout, again,
                   json.loads((folder / "done_before.json").read_text()),
                   json.loads((folder / "done_after.json").read_text()))


# ---------------------------------------------------------------- pytest-xdist: longest work first
# Seconds a work unit took in a `make test` run on the 2-core machine (``--durations``, both workers busy), for
# the units over about 20 s: an xdist_group by its name, any other test by its node id (without parameters).
# `--dist loadgroup` hands out whole units in queue order; queued by these, longest first, no long unit is
# left to start last. A unit missing here keeps its place after them; a stale number only costs time.
UNIT_SECONDS = {
    "tiny_taco": 300,
    "figures": 135,
    "slurm": 175,
    "tests/test_sweeps.py::test_local_grid_killed_and_relaunched_twice_concurrently_runs_each_once": 90,
    "offline_train": 70,
    "budgets_online": 45,
    "tests/test_budgets.py::test_a_sweep_extending_another_trains_every_frame_once": 30,
    "contract": 50,
    "tests/test_offline_sweep.py::test_tiny_offline_sweep_runs_every_learner_on_every_dataset_kind_then_t3": 50,
    "tests/test_speedups.py::test_compile_matches_plain_path": 48,
    "offline_analysis": 40,
    "tiny_alix": 150,
    "tests/test_verify.py::test_verify_tiny_end_to_end": 50,
    "tests/test_cli.py::test_metaworld_tiny_run_logs_success": 36,
    "seam": 30,
    "tests/test_one_writer.py::test_a_write_error_is_one_line_naming_the_file_and_a_rerun_resumes": 26,
    "tests/test_sweeps.py::test_local_launcher_keeps_going_after_a_failure_and_a_warm_start_gives_the_same_runs": 25,
    "tests/test_dt.py::test_dt_end_to_end_run_logs_both_targets": 20,
    "tests/test_analysis.py::test_claim_verdicts_supported_refuted_and_not_enough_data": 20,
    "tests/test_analysis.py::test_offline_claims_use_each_runs_own_budget": 20,
}
# Units queued last: the main job's checks wait for the background job, which is done by then.
LAST = {MAIN_JOB}


def _unit(item: pytest.Item) -> str:
    mark = item.get_closest_marker("xdist_group")
    if mark is not None:
        return str(mark.args[0] if mark.args else mark.kwargs.get("name", "default"))
    return item.nodeid.split("[", 1)[0]


def pytest_configure(config: pytest.Config) -> None:
    if hasattr(config.option, "loadscopereorder"):  # pytest-xdist: keep our queue order (below), not by size
        config.option.loadscopereorder = False


@pytest.hookimpl(tryfirst=True)  # before xdist's own, which reports the collection to the controller
def pytest_collection_finish(session: pytest.Session) -> None:
    """On a pytest-xdist worker under --dist loadgroup: fail at once if the xdist_group marks were not honoured
    (xdist tags each grouped test's node id with ``@group``; pytest 9 ignores the attribute xdist 3.8 sets, and
    every test then ran wherever it landed, building a group's shared runs on both workers)."""
    if not getattr(session.config.option, "loadgroup", False):
        return
    untagged = [item.nodeid for item in session.items
                if item.get_closest_marker("xdist_group") is not None and "@" not in item.nodeid]
    if untagged:
        message = (f"--dist loadgroup ignores the xdist_group of {len(untagged)} tests (e.g. {untagged[0]}): "
                   f"pytest {pytest.__version__} with this pytest-xdist; see requirements.txt")
        print(f"error: {message}", file=sys.__stderr__)  # a worker's exception reaches the controller without it
        raise pytest.UsageError(message)


# The session runs and the xdist_group a test that reads one must be in: outside it, another worker would train the
# run again (a test that read tiny_taco without the mark made the suite train it twice, about 30 s).
SESSION_RUN_GROUPS = {"tiny_taco": TINY_TACO, "tiny_taco_watched": TINY_TACO, "tiny_taco_loop_events": TINY_TACO,
                      "tiny_alix": TINY_ALIX, "main_job": MAIN_JOB}


def outside_their_group(items: list[pytest.Item]) -> list[str]:
    """The tests that read a session run (:data:`SESSION_RUN_GROUPS`) without being in that run's xdist_group."""
    return [f"{item.nodeid} ({fixture})" for item in items
            for fixture, group in SESSION_RUN_GROUPS.items()
            if fixture in getattr(item, "fixturenames", ()) and _unit(item) != group]


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest work units first, the main job's last; otherwise collection order (a stable sort). A test that
    reads a session run outside its group is a usage error (it would train the run on a second worker)."""
    stray = outside_their_group(items)
    if stray:
        raise pytest.UsageError(f"mark these @pytest.mark.xdist_group(...) of the session run they read: {stray}")
    items.sort(key=lambda item: (_unit(item) in LAST, -UNIT_SECONDS.get(_unit(item), 0)))
