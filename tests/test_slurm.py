"""The SLURM launcher against a real one-node SLURM cluster on localhost (scripts/slurm_local.sh):
munge, slurmctld, slurmd, slurmdbd and MariaDB, no mocks. Each test trains tiny runs through submitit."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import assert_wandb_mirrors_csv, write_sweep  # the same tiny-run sweep files as the local launcher tests

# one worker runs both tests: they share the session's cluster (brought up once, and not taken down by one
# worker while the other still uses it)
pytestmark = [pytest.mark.slurm, pytest.mark.slow, pytest.mark.xdist_group("slurm")]

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "slurm_local.sh"
CLUSTER = REPO / "sweeps" / "launchers" / "localhost.yaml"
# A private cluster for the tests (own folder and ports), so a developer's cluster is left alone.
SLURM_ENV = {"REPRO_SLURM_DIR": "/tmp/taco-slurm-test", "REPRO_SLURM_PORT_BASE": "17817"}


@pytest.fixture(scope="session")
def slurm():
    """Bring the local cluster up for the session and tear it down (by recorded PIDs) afterwards."""
    if os.geteuid() != 0 and not shutil.which("slurmctld"):
        pytest.skip("the local SLURM cluster needs root (to install slurm packages) or slurm installed")
    env = dict(os.environ, **SLURM_ENV)
    up = subprocess.run(["bash", str(SCRIPT), "up"], env=env, capture_output=True, text=True, timeout=600)
    assert up.returncode == 0, up.stderr
    conf = re.search(r"export SLURM_CONF=(\S+)", up.stdout).group(1)
    old = os.environ.get("SLURM_CONF")
    os.environ["SLURM_CONF"] = conf
    try:
        yield conf
    finally:
        subprocess.run(["bash", str(SCRIPT), "down"], env=env, capture_output=True, text=True, timeout=120)
        if old is None:
            os.environ.pop("SLURM_CONF", None)
        else:
            os.environ["SLURM_CONF"] = old


def cli(*args: str, timeout: float = 120) -> tuple[int, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    res = subprocess.run([sys.executable, "-m", "repro.launch.cli", *args], capture_output=True, text=True,
                         env=env, timeout=timeout)
    return res.returncode, res.stdout + res.stderr


def run_dirs(root: Path, exp: str) -> list[Path]:
    return sorted(root.glob(f"{exp}/*/*/*/seed_*"))


def squeue() -> list[tuple[str, str]]:
    out = subprocess.run(["squeue", "-h", "-r", "-o", "%i %T"], capture_output=True, text=True).stdout
    return [tuple(ln.split()) for ln in out.splitlines() if ln.strip()]


def wait(pred, timeout: float, what: str) -> None:
    end = time.time() + timeout
    while not pred():
        if time.time() > end:
            raise AssertionError(f"timed out waiting for {what}; squeue: {squeue()}")
        time.sleep(0.5)


def csv_frames(path: Path) -> list[int]:
    return [int(ln.split(",")[0]) for ln in path.read_text().splitlines()[1:] if ln.strip()]


def assert_complete(run_dir: Path, frames: int) -> None:
    for name in ("config.yaml", "meta.json", "eval.csv", "train.csv", "checkpoint.pt", "DONE"):
        assert (run_dir / name).exists(), f"{run_dir}/{name} missing"
    assert csv_frames(run_dir / "eval.csv") == list(range(0, frames + 1, 100))
    assert csv_frames(run_dir / "train.csv") == list(range(50, frames + 1, 50))


def status_line(name: str, root: Path) -> str:
    code, out = cli("status", name, "--results-root", str(root))
    assert code == 0, out
    return out


def test_array_completes_and_survives_cancel_and_relaunch(slurm, tmp_path):
    """2 tasks x 2 variants as one job array of 4: submission returns at once, a second submission queues
    nothing, the array is cancelled halfway (the node runs two at once: two done, two running), and a relaunch
    finishes every run exactly once."""
    sweep = write_sweep(tmp_path, "sgrid", ["reacher_hard", "cheetah_run"], {"K1": ["agent.K=1"], "K3": ["agent.K=3"]},
                        1, frames=100)
    N = 4
    root = tmp_path / "results"
    args = ["sweep", str(sweep), "--set", f"runtime.results_root={root}", "--launcher", "slurm",
            "--cluster-config", str(CLUSTER)]
    t0 = time.time()
    code, out = cli(*args)
    assert code == 0, out
    assert time.time() - t0 < 60, "submission must not wait for the jobs"
    ids = re.search(r"SLURM job ids: (\S+(?:, \S+)*);", out).group(1).split(", ")
    assert len(ids) == N and len({i.split("_")[0] for i in ids}) == 1, "one array, one task per run"
    out = status_line("sgrid", root)
    assert re.search(r"sgrid: 0 done, \d running, \d queued", out) and "queued" in out.split("\n", 1)[1]

    code, out = cli(*args)  # queues nothing: each run is held by the array (or already done: 100 frames are quick)
    counts = re.search(r"0 submitted, (\d+) already done, (\d+) held elsewhere", out)
    assert code == 0 and counts and int(counts.group(1)) + int(counts.group(2)) == N, out

    wait(lambda: sum((d / "DONE").exists() for d in run_dirs(root, "sgrid")) >= 2, 400, "two runs to finish")
    subprocess.run(["scancel", ids[0].split("_")[0]], check=True)
    wait(lambda: not squeue(), 60, "the cancelled array to leave the queue")
    done_first = {d for d in run_dirs(root, "sgrid") if (d / "DONE").exists()}
    assert 2 <= len(done_first) < N

    code, out = cli(*args)
    assert code == 0, out
    assert f"{N - len(done_first)} submitted" in out and f"{len(done_first)} already done" in out, out
    wait(lambda: len([d for d in run_dirs(root, "sgrid") if (d / "DONE").exists()]) == N and not squeue(), 600,
         "the relaunched runs")
    dirs = run_dirs(root, "sgrid")
    assert len(dirs) == N
    for d in dirs:
        assert_complete(d, 100)
    assert f"sgrid: {N} done" in status_line("sgrid", root)


def test_usr2_requeues_and_resumes_without_duplicate_rows(slurm, tmp_path):
    """USR2 mid-training (what SLURM sends before a time limit or on preemption): submitit checkpoints
    and requeues; the requeued job resumes the run from its checkpoint and finishes it. A second task of
    the same array fails for good (corrupt checkpoint) and `repro status` names its stderr file."""
    from repro.launch import spec as specs
    from repro.launch.state import read_record, state_dir
    from repro.runs.rundir import write_config

    sweep = write_sweep(tmp_path, "req", ["reacher_hard"], {"base": [], "broken": []}, 1, frames=400)
    root = tmp_path / "results"
    planned = specs.plan(specs.expand(specs.load(str(sweep)), specs.Selection(sets=(f"runtime.results_root={root}",))))
    good, bad = sorted(planned, key=lambda p: p.run.variant)
    bad.run_dir.mkdir(parents=True)
    write_config(bad.run_dir, bad.cfg)
    (bad.run_dir / "checkpoint.pt").write_bytes(b"not a checkpoint")
    code, out = cli("sweep", str(sweep), "--set", f"runtime.results_root={root}", "--set", "runtime.wandb=true",
                    "--launcher", "slurm", "--cluster-config", str(CLUSTER))
    assert code == 0, out
    sdir = state_dir(root, "req")
    job, bad_job = read_record(sdir, good.key).job_id, read_record(sdir, bad.key).job_id
    run = good.run_dir
    wait(lambda: (run / "train.csv").exists() and len(csv_frames(run / "train.csv")) >= 3, 300, "training")
    assert not (run / "DONE").exists(), "the run finished before the signal; make it longer"
    subprocess.run(["scancel", "--signal=USR2", job], check=True)  # at once: a status call first takes seconds
    time.sleep(1.5)
    wait(lambda: any(j == job and s == "PENDING" for j, s in squeue()), 60, "the requeue")
    wait(lambda: not any(j == bad_job for j, _ in squeue()), 120, "the broken run to fail")
    out = status_line("req", root)
    assert "req: 0 done, 0 running, 1 queued, 1 failed" in out, out
    err = read_record(sdir, bad.key).stderr
    assert err and Path(err).exists() and f"failed {os.path.relpath(bad.run_dir, root)}: {err}" in out
    subprocess.run(["scontrol", "update", f"JobId={job}", "StartTime=now"], check=True)
    wait(lambda: (run / "DONE").exists() and not squeue(), 300, "the resumed run")
    assert_complete(run, 400)
    meta = json.loads((run / "meta.json").read_text())
    assert len(meta["resumes"]) == 1, "the requeued job must resume, not restart"
    # issue 28: the requeued job resumed its W&B run (one id, one offline folder, every CSV point once)
    record, _ = assert_wandb_mirrors_csv(run)
    assert record["id"] == (run / "wandb" / "run_id").read_text().strip()
    assert len(list((run / "wandb").glob("offline-run-*"))) == 1

    def states() -> list[str]:
        return subprocess.run(["sacct", "-n", "-X", "-D", "-P", "-o", "State", "-j", job], capture_output=True,
                              text=True).stdout.split()

    # the accounting daemon records the end a moment after the job leaves the queue
    wait(lambda: states()[-1:] == ["COMPLETED"], 60, f"sacct to record the completion (states {states()})")
    assert "REQUEUED" in states(), states()
    assert "req: 1 done, 0 running, 0 queued, 1 failed" in status_line("req", root)
