"""The SLURM launcher against a real one-node SLURM cluster on localhost (scripts/slurm_local.sh):
munge, slurmctld, slurmd, slurmdbd and MariaDB, no mocks. Each test trains tiny runs through submitit. The node
declares two stand-in GPUs as GRES (REPRO_SLURM_GPUS=2: character devices named by gres.conf's File=), so jobs
asking for GPUs are scheduled there and get CUDA_VISIBLE_DEVICES."""

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
import yaml

from helpers import assert_wandb_mirrors_csv, write_sweep  # the same tiny-run sweep files as the local launcher tests

# one worker runs every test: they share the session's cluster (brought up once, and not taken down by one
# worker while the other still uses it)
pytestmark = [pytest.mark.slurm, pytest.mark.slow, pytest.mark.xdist_group("slurm")]

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "slurm_local.sh"
CLUSTER = REPO / "sweeps" / "launchers" / "localhost.yaml"
# A private cluster for the tests (own folder and ports), so a developer's cluster is left alone
# ($REPRO_SLURM_TEST_DIR / $REPRO_SLURM_TEST_PORT_BASE: another one, e.g. beside a test run already using these).
SLURM_ENV = {"REPRO_SLURM_DIR": os.environ.get("REPRO_SLURM_TEST_DIR", "/tmp/taco-slurm-test"),
             "REPRO_SLURM_PORT_BASE": os.environ.get("REPRO_SLURM_TEST_PORT_BASE", "17817"), "REPRO_SLURM_GPUS": "2"}


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


def run_cli(*args: str, timeout: float = 120, **env: str) -> subprocess.CompletedProcess:
    """``repro ARGS`` (the whole app, as a user runs it) with ``env`` added to this environment."""
    env = dict(os.environ, OMP_NUM_THREADS="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"), **env)
    return subprocess.run([sys.executable, "-m", "repro", *args], capture_output=True, text=True, env=env,
                          timeout=timeout)


def cli(*args: str, timeout: float = 120) -> tuple[int, str]:
    res = run_cli(*args, timeout=timeout)
    return res.returncode, res.stdout + res.stderr


def cluster_config(tmp: Path, name: str, **changes: object) -> Path:
    """sweeps/launchers/localhost.yaml with ``changes``, written to ``tmp/cluster-NAME.yaml``."""
    data = yaml.safe_load(CLUSTER.read_text())
    data.update(changes)
    path = tmp / f"cluster-{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def error_line(res: subprocess.CompletedProcess) -> str:
    """The one line a refused command writes on stderr."""
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.stdout + res.stderr
    return lines[0]


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
    """2 tasks x 2 variants as one job array of 4: submission returns once the preflight job has passed and the
    array is queued, a second submission queues nothing, the array is cancelled halfway (the node runs two at once:
    two done, two running), and a relaunch finishes every run exactly once; meta.json records each run's command."""
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
    assert re.search(r"preflight ok on \S+ \(job \d+\): \d+ checks passed", out), out
    ids = re.search(r"SLURM job ids: (\S+(?:, \S+)*);", out).group(1).split(", ")
    assert len(ids) == N and len({i.split("_")[0] for i in ids}) == 1, "one array, one task per run"
    out = status_line("sgrid", root)
    assert re.search(r"sgrid: 0 done, \d running, \d queued", out) and "queued" in out.split("\n", 1)[1]

    args += ["--no-preflight"]  # the preflight passed above; the relaunches skip it
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
        command = json.loads((d / "meta.json").read_text())["command"]  # the run's own, not submitit's _submit.py
        assert command[1:3] == ["train", "experiment=sgrid"] and f"runtime.results_root={root}" in command, command
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
                    "--launcher", "slurm", "--cluster-config", str(CLUSTER), "--no-preflight")
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


def test_without_a_cluster_config_the_sweep_is_refused_and_nothing_is_submitted(slurm, tmp_path):
    """No --cluster-config, $REPRO_SLURM_CONFIG or ~/.config/taco-repro/slurm.yaml: one line naming the option and the
    example config, exit 2, no job, nothing under the results root (the defaults asked for no GPU, 8 CPUs, a day)."""
    sweep = write_sweep(tmp_path, "nocfg", ["reacher_hard"], {"base": []}, 1)
    root = tmp_path / "results"
    env = {k: v for k, v in os.environ.items() if k != "REPRO_SLURM_CONFIG"}
    res = subprocess.run([sys.executable, "-m", "repro", "sweep", str(sweep), "-r", str(root), "--launcher", "slurm"],
                         capture_output=True, text=True, env={**env, "HOME": str(tmp_path)}, timeout=120)
    line = error_line(res)
    assert res.returncode == 2 and "--cluster-config" in line and "sweeps/launchers/example.yaml" in line, line
    assert not root.exists() and not squeue()


def test_a_broken_renderer_in_the_jobs_stops_the_sweep_at_the_preflight(slurm, tmp_path):
    """The preflight job (`repro doctor` with the sweep's cluster config) finds that MuJoCo cannot render in the jobs'
    environment (MUJOCO_GL set to a backend that does not exist): one line naming the check, exit 1, nothing of the
    grid submitted, its log kept."""
    sweep = write_sweep(tmp_path, "badgl", ["reacher_hard"], {"base": []}, 1)
    root = tmp_path / "results"
    broken = cluster_config(tmp_path, "broken", env={"MUJOCO_GL": "nogl"})
    res = run_cli("sweep", str(sweep), "-r", str(root), "--launcher", "slurm", "--cluster-config", str(broken))
    line = error_line(res)
    assert res.returncode == 1, res.stdout + res.stderr
    assert re.match(r"error: preflight on \S+ \(job \d+\) failed: render: MuJoCo cannot render with MUJOCO_GL=nogl",
                    line), line
    assert "--no-preflight" in line
    wait(lambda: not squeue(), 30, "the preflight job to leave the queue")
    names = subprocess.run(["sacct", "-n", "-X", "-P", "-o", "JobName"], capture_output=True, text=True).stdout.split()
    assert {n for n in names if n.startswith("repro-badgl")} == {"repro-badgl-preflight"}, names
    assert not run_dirs(root, "badgl") and not (root / ".sweeps" / "badgl" / "state.json").exists()
    assert not list((root / ".sweeps" / "badgl").glob("slurm")), "no job of the grid"
    assert list((root / ".sweeps" / "badgl" / "preflight").glob("*/*_log.out")), "the preflight's log is kept"


def test_gpu_jobs_on_the_gres_node_and_jobs_that_cannot_start(slurm, tmp_path):
    """A run asking for a GPU is scheduled on the stand-in GRES node and sees CUDA_VISIBLE_DEVICES (its preflight
    too); a sweep asking for more GPUs than the node has is refused at submission in one line (SLURM rejects it);
    one asking for more than are free waits, and `repro status` says why (squeue's reason), then that it was
    cancelled before it started. The submit hint keeps -r."""
    root = tmp_path / "results"
    sweep = write_sweep(tmp_path, "gpu", ["reacher_hard"], {"base": []}, 1)
    gpu1 = cluster_config(tmp_path, "gpu1", gpus_per_node=1)
    res = run_cli("sweep", str(sweep), "-r", str(root), "--set", "runtime.device=cpu", "--launcher", "slurm",
                  "--cluster-config", str(gpu1))
    out = res.stdout + res.stderr
    assert res.returncode == 0, out
    assert re.search(r"preflight ok on \S+ \(job \d+\).*CUDA_VISIBLE_DEVICES=\d", out), out
    assert f"follow with `repro status gpu -r {root}`" in out, out
    job = re.search(r"SLURM job ids: (\S+);", out).group(1)
    shown = subprocess.run(["scontrol", "show", "job", job], capture_output=True, text=True).stdout
    assert "gres:gpu:1" in shown, shown

    # the node's two GPUs: one for the run above (while it runs), one for this job; two more are not free
    holder = subprocess.run(["sbatch", "--parsable", "--gpus-per-node=1", "-c1", "-o", "/dev/null", "--wrap",
                             "sleep 300"], capture_output=True, text=True, cwd=tmp_path, check=True).stdout.strip()
    big = write_sweep(tmp_path, "gpu2", ["reacher_hard"], {"base": []}, 1)
    gpu2 = cluster_config(tmp_path, "gpu2", gpus_per_node=2)
    code, out = cli("sweep", str(big), "-r", str(root), "--launcher", "slurm", "--cluster-config", str(gpu2),
                    "--no-preflight")
    assert code == 0, out
    waiting = re.search(r"SLURM job ids: (\S+);", out).group(1)

    def reason() -> str:
        got = subprocess.run(["squeue", "-h", "-j", waiting, "-o", "%r"], capture_output=True, text=True)
        return got.stdout.strip()

    wait(lambda: reason() in ("Resources", "Priority"), 30, "the scheduler to give the pending reason")
    out = status_line("gpu2", root)
    assert "queued" in out and re.search(r"(Resources|Priority): ", out), out
    subprocess.run(["scancel", waiting], check=True)
    wait(lambda: not any(j.split("_")[0] == waiting.split("_")[0] for j, _ in squeue()), 30, "the cancelled job")
    out = status_line("gpu2", root)
    assert "1 cancelled" in out and "cancelled before it started" in out, out

    three = cluster_config(tmp_path, "gpu3", gpus_per_node=3)
    res = run_cli("sweep", str(big), "-r", str(tmp_path / "more"), "--launcher", "slurm", "--cluster-config",
                  str(three), "--no-preflight")
    line = error_line(res)
    assert res.returncode == 2 and "Requested node configuration is not available" in line and "3 GPU(s)" in line
    assert not (tmp_path / "more" / ".sweeps" / "gpu2" / "state.json").exists()

    def started() -> str:
        logs = list((root / ".sweeps" / "gpu" / "slurm").glob("*/*_log.out"))
        return logs[0].read_text() if logs else ""

    wait(lambda: " CUDA_VISIBLE_DEVICES=" in started(), 120, "the GPU run to start")
    assert re.search(r"run gpu__\S+ on \S+ \(job \S+\): CUDA_VISIBLE_DEVICES=\d", started()), started()
    subprocess.run(["scancel", holder, job], check=True)
    wait(lambda: not squeue(), 60, "the jobs to leave the queue")
