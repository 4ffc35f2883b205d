"""Sweeps: declaration and expansion, dry-run, error lines, locking, status, and the local launcher
(tiny real training runs: kill and relaunch, two concurrent launchers, a failing run)."""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from helpers import deterministic, launch_app, write_sweep
from repro.launch import lock
from repro.launch import spec as specs
from repro.launch.runner import claim
from repro.launch.state import RunRecord, state_dir, write_record
from repro.launch.status import collect
from repro.runs.rundir import writer_lock_holder
from repro.runs.runformat import EVAL, TRAIN

APP = launch_app()


def run_cli(*args: str) -> tuple[int, str]:
    """In-process CLI call: (exit code, stdout+stderr)."""
    res = CliRunner().invoke(APP, list(args))
    if res.exception and not isinstance(res.exception, SystemExit):
        raise res.exception
    return res.exit_code, res.output  # stdout and stderr interleaved


def cli_proc(*args: str, **kw) -> subprocess.Popen:
    """The CLI in its own process (for launches that train or that must run concurrently)."""
    env = dict(os.environ, OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"))
    return subprocess.Popen([sys.executable, "-m", "repro.launch.cli", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=env, **kw)


def rows(path: Path) -> list[list[str]]:
    return [ln.split(",") for ln in path.read_text().splitlines()[1:] if ln.strip()]


def assert_complete(run_dir: Path, frames: int, eval_every: int = 100, episode_frames: int = 50) -> None:
    """A finished tiny run: every file of the run-format contract, no duplicated or missing CSV rows."""
    for name in ("config.yaml", "meta.json", "eval.csv", "train.csv", "checkpoint.pt", "DONE"):
        assert (run_dir / name).exists(), f"{run_dir}/{name} missing"
    assert [int(r[0]) for r in rows(run_dir / "eval.csv")] == list(range(0, frames + 1, eval_every))
    assert [int(r[0]) for r in rows(run_dir / "train.csv")] == list(range(episode_frames, frames + 1, episode_frames))


# ------------------------------------------------------------------------------------ declarations

def test_horizon_dry_run_lists_k1_k3_times_six_seeds(tmp_path):
    code, out = run_cli("sweep", "horizon", "--tasks", "hopper_hop", "--dry-run",
                        "--set", f"runtime.results_root={tmp_path}")
    assert code == 0, out
    lines = [ln for ln in out.splitlines() if ln.startswith("absent")]
    assert len(lines) == 12
    cells = {re.search(r"horizon/taco/(K\d)/hopper_hop/seed_(\d)", ln).groups() for ln in lines}
    assert cells == {(k, str(s)) for k in ("K1", "K3") for s in range(1, 7)}
    for ln in lines:
        k = re.search(r"/(K\d)/", ln).group(1)
        assert f"agent.K={k[1]}" in ln and "task=hopper_hop" in ln and "train.frames=1000000" in ln
    assert "12 runs of sweep 'horizon'" in out and "drqv2" not in out
    assert not any(tmp_path.iterdir()), "a dry run must not create anything"


def test_action_repeat_dry_run_is_ar_times_k_times_seeds(tmp_path):
    code, out = run_cli("sweep", "action_repeat", "--dry-run", "--set", f"runtime.results_root={tmp_path}")
    assert code == 0, out
    lines = [ln for ln in out.splitlines() if ln.startswith("absent")]
    found = set()
    for ln in lines:
        ar, k, seed = re.search(r"action_repeat/taco/ar(\d)_K(\d)/hopper_hop/seed_(\d)", ln).groups()
        assert f"env.action_repeat={ar}" in ln and f"agent.K={k}" in ln
        found.add((ar, k, seed))
    assert found == {(a, k, str(s)) for a in "124" for k in "135" for s in range(1, 7)}
    assert len(lines) == 54


def test_every_paper_sweep_is_declared_and_expands_or_is_refused():
    expected = {"main", "metaworld", "horizon", "action_repeat", "batch_size", "objective_removal",
                "action_repr", "action_dim", "repr_objectives", "tsne", "speed", "manipulator", "offline"}
    assert expected <= set(specs.sweep_names())
    for s in specs.load_all():
        raw = yaml.safe_load(s.path.read_text())
        # verify (`repro verify`) checks the installation against published curves: no artifact of the paper
        assert (raw["artifacts"] or s.name == "verify") and raw["description"] and "eval" in raw and "frames" in raw
        reason = specs.unavailable_reason(s)
        if s.name == "offline" and "dt" not in specs.config_groups()["agent"]:  # until the DT agent file lands
            assert reason and "\n" not in reason and "agent dt" in reason
            with pytest.raises(specs.SweepError):
                specs.expand(s)
        else:
            assert reason is None, reason
            runs = specs.expand(s)
            assert len({(r.agent, r.variant, r.task, r.dataset, r.seed) for r in runs}) == len(runs)
    assert specs.load("action_dim").seeds == tuple(range(1, 9))
    batch = specs.expand(specs.load("batch_size"))
    assert {(r.agent, r.variant) for r in batch} == {(a, f"bs{b}") for a in ("taco", "drqv2") for b in (256, 512, 1024)}
    speed = specs.expand(specs.load("speed"))
    assert {(r.agent, r.variant) for r in speed} == {("taco", "bs1024"), ("taco", "bs512"), ("taco", "bs256"),
                                                      ("drqv2", "bs256")}


def test_sweeps_command_lists_run_counts_and_refusals(tmp_path, monkeypatch):
    code, out = run_cli("sweeps")
    assert code == 0, out
    assert re.search(r"horizon\s*│\s*F8\s*│\s*108", out)
    assert re.search(r"action_repeat\s*│\s*F9\s*│\s*54", out)
    assert re.search(r"offline\s*│\s*T3,T6\s*│\s*504", out)
    # a sweep selecting an option the packaged config lacks is listed as refused, with what is missing
    folder = tmp_path / "sweeps"
    folder.mkdir()
    write_sweep(folder, "future", ["hopper_hop"], {"x": ["agent=dreamerv3"]}, 1)
    monkeypatch.setenv(specs.ENV_SWEEPS_DIR, str(folder))
    code, out = run_cli("sweeps")
    assert code == 0 and "refused" in out and "dreamerv3" in out, out


def test_refused_sweep_is_one_line_exit_2(tmp_path):
    # the check is generic: any config group option the sweep selects that the packaged config lacks
    path = write_sweep(tmp_path, "future", ["hopper_hop"], {"x": ["agent=dreamerv3"]}, 1)
    code, out = run_cli("sweep", str(path), "--dry-run")
    assert code == 2
    assert out.strip().count("\n") == 0 and "dreamerv3" in out and "cannot run yet" in out
    with pytest.raises(specs.SweepError, match="agent dreamerv3 not in the packaged config"):
        specs.expand(specs.load(str(path)))


@pytest.mark.parametrize("args, needle", [
    (["sweep", "horizn", "--dry-run"], "Did you mean: horizon"),
    (["sweep", "horizon", "--tasks", "hoper_hop", "--dry-run"], "Did you mean: hopper_hop"),
    (["sweep", "horizon", "--tasks", "hopper_hop", "--set", "agent.KK=2", "--dry-run"], "agent.KK"),
    (["sweep", "horizon", "--tasks", "hopper_hop", "--set", "agent=tacoo", "--dry-run"], "Did you mean: taco"),
    (["status", "horizn"], "Did you mean: horizon"),
    (["sweep", "horizon", "--launcher", "slurm", "--warm-start", "--dry-run"], "--warm-start is for the local"),
])
def test_unknown_names_are_one_line_with_close_matches(args, needle, tmp_path):
    code, out = run_cli(*args, *(["--results-root", str(tmp_path)] if args[0] == "status" else []))
    assert code == 2, out
    assert needle in out and out.strip().count("\n") == 0 and "Traceback" not in out


def test_a_wandb_sweep_that_cannot_mirror_is_one_line_before_anything_is_written(tmp_path, monkeypatch):
    sweep = write_sweep(tmp_path, "wb", ["reacher_hard"], {"a": []}, 1)
    root = tmp_path / "results"
    monkeypatch.setenv("WANDB_MODE", "bogus")  # check_wandb's refusal: the WandbError reaches the app as it is
    code, out = run_cli("sweep", str(sweep), "--set", f"runtime.results_root={root}", "--set", "runtime.wandb=true")
    assert code == 2 and out.startswith("error: WANDB_MODE='bogus'") and out.strip().count("\n") == 0, out
    assert not (root / ".sweeps").exists() and not (root / "wb").exists()


def test_spec_validation(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(yaml.safe_dump({"name": "bad", "description": "x", "artifacts": [], "tasks": ["hopper_hop"],
                                   "agents": ["taco"], "seeds": 2, "frames": 100, "eval": {}, "variants": {"a": []},
                                   "varaints": {}}))
    with pytest.raises(specs.SweepError, match="Did you mean: variants"):
        specs.load(str(bad))
    dup = write_sweep(tmp_path, "dup", ["hopper_hop"], {"a": ["variant=x"], "b": ["variant=x"]}, 1)
    with pytest.raises(specs.SweepError, match="same run directory"):
        specs.expand(specs.load(str(dup)))
    # --set of a profile hands the budget to the profile; --frames still wins
    s = specs.load("horizon")
    run = specs.expand(s, specs.Selection(tasks=("hopper_hop",), sets=("profile=tiny",)))[0]
    assert not any(o.startswith("train.frames") for o in run.overrides)
    run = specs.expand(s, specs.Selection(tasks=("hopper_hop",), seeds=2, frames=300))[0]
    assert "train.frames=300" in run.overrides and run.overrides.count("train.frames=300") == 1
    assert len(specs.expand(s, specs.Selection(tasks=("hopper_hop",), seeds=2))) == 4


# ------------------------------------------------------------------------------------------ locking

def _race(path: str, start, hold, results) -> None:
    start.wait()
    ok, _ = lock.acquire(Path(path), lock.LockInfo.mine("local"))
    results.put(ok)
    hold.wait()  # keep the winner alive until everybody tried (a dead winner's lock is stale)


def test_lock_has_one_winner_among_racing_processes(tmp_path):
    ctx = mp.get_context("fork")
    n = 8
    start, hold, results = ctx.Barrier(n), ctx.Barrier(n), ctx.Queue()
    procs = [ctx.Process(target=_race, args=(str(tmp_path / "x.lock"), start, hold, results)) for _ in range(n)]
    for p in procs:
        p.start()
    outcomes = [results.get(timeout=30) for _ in range(n)]
    for p in procs:
        p.join(timeout=30)
    assert sum(outcomes) == 1


def test_stale_and_live_locks(tmp_path):
    path = tmp_path / "run.lock"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = lock.LockInfo.mine("local")
    stale.pid, stale.pid_start = dead.pid, None
    assert lock.try_create(path, stale)
    mine = lock.LockInfo.mine("local")
    ok, _ = lock.acquire(path, mine)
    assert ok, "a lock of a dead local pid is stale"
    ok, owner = lock.acquire(path, lock.LockInfo.mine("local"))
    assert not ok and owner.token == mine.token, "a live owner keeps its lock"
    assert not lock.release(path, "not-the-token") and lock.release(path, mine.token) and not path.exists()

    remote = lock.LockInfo.mine("local")
    remote.host = "another-host-" + socket.gethostname()
    assert not lock.is_stale(remote, None), "a pid on another host cannot be checked: live"
    job = lock.LockInfo.mine("slurm")
    job.job_id = "12_3"
    assert not lock.is_stale(job, {"12_3": "PENDING"}) and not lock.is_stale(job, {"12_3": "COMPLETING"})
    assert lock.is_stale(job, {"12_3": "CANCELLED"}) and lock.is_stale(job, {})
    assert not lock.is_stale(job, None), "SLURM unreachable: assume live"


def test_update_rewrites_only_our_own_lock(tmp_path):
    path = tmp_path / "run.lock"
    mine = lock.LockInfo.mine("local")
    assert not lock.update(path, mine.token, job_id="1"), "no lock: nothing to update"
    assert lock.try_create(path, mine)
    assert lock.update(path, mine.token, child_pid=4321, job_id="77_1")
    got = lock.read(path)
    assert got is not None and (got.child_pid, got.job_id) == (4321, "77_1")
    assert (got.token, got.pid, got.host) == (mine.token, mine.pid, mine.host)  # the rest is kept
    before = path.read_bytes()
    assert not lock.update(path, "not-the-token", job_id="99"), "another owner's lock is left alone"
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["run.lock"]  # no temporary file left behind


# ------------------------------------------------------------------------------------------ status

def test_status_reports_each_state(tmp_path):
    sweep = write_sweep(tmp_path, "st", ["reacher_hard"], {"a": [], "b": [], "c": [], "d": []}, 1)
    planned = specs.plan(
        specs.expand(specs.load(str(sweep)), specs.Selection(sets=(f"runtime.results_root={tmp_path}",)))
    )
    root = specs.results_root_of(planned)
    sdir = state_dir(root, "st")
    a, b, c, d = planned
    for p in planned:
        p.run_dir.mkdir(parents=True)
        (p.run_dir / "eval.csv").write_text("frame,step,episode,episode_reward\n0,0,0,1.5\n100,50,2,7.25\n")
    (a.run_dir / "DONE").write_text("{}")
    write_record(sdir, RunRecord(key=b.key, run_dir=str(b.run_dir), overrides=[], launcher="local",
                                 status="failed", returncode=1, log="/x/b.log", stderr="/x/b.log"))
    info = lock.LockInfo.mine("local")
    assert lock.try_create(lock.lock_path(root, c.run_dir), info)
    (d.run_dir / "checkpoint.pt").write_bytes(b"x")
    from repro.launch.state import record_launch

    record_launch(sdir, "st", sweep, "local", {p.key: {"run_dir": str(p.run_dir), "overrides": []} for p in planned})
    got = {s.key: s for s in collect({p.key: p.run_dir for p in planned}, root, sdir)}
    assert [got[p.key].status for p in planned] == ["done", "failed", "running", "pending"]
    assert got[a.key].frame == 100 and got[a.key].eval_return == 7.25
    assert got[b.key].log == "/x/b.log" and "partial" in got[d.key].detail
    code, out = run_cli("status", "st", "--results-root", str(tmp_path))
    assert code == 0 and "1 done, 1 running, 0 queued, 1 failed, 1 pending" in out
    assert f"failed {os.path.relpath(b.run_dir, root)}: /x/b.log" in out


def test_mismatched_run_dir_is_refused_unless_force(tmp_path):
    from repro.runs.rundir import write_config

    sweep = write_sweep(tmp_path, "mm", ["reacher_hard"], {"a": []}, 1)
    sel = specs.Selection(sets=(f"runtime.results_root={tmp_path}",))
    planned = specs.plan(specs.expand(specs.load(str(sweep)), sel))[0]
    planned.run_dir.mkdir(parents=True)
    # another value of a key the run reads (a larger budget would extend the run, not mismatch it)
    other = specs.plan(specs.expand(specs.load(str(sweep)), specs.Selection(sets=(*sel.sets, "agent.lr=0.0002"))))[0]
    write_config(planned.run_dir, other.cfg)
    code, out = run_cli("sweep", str(sweep), "--set", f"runtime.results_root={tmp_path}", "--dry-run")
    assert code == 0 and out.startswith("mismatch")
    code, out = run_cli("sweep", str(sweep), "--set", f"runtime.results_root={tmp_path}")
    assert code == 2 and "--force" in out and "agent.lr" in out and out.strip().count("\n") == 0
    planned = specs.plan(specs.expand(specs.load(str(sweep)), sel))[0]
    assert claim(planned, "local", "mm", force=False).status == "mismatch"
    c = claim(planned, "local", "mm", force=True)
    assert c.status == "claimed" and c.moved_to is not None
    assert not planned.run_dir.exists() and (c.moved_to / "config.yaml").exists()
    assert ".replaced" in str(c.moved_to)
    lock.release(c.lock_path, c.info.token)


# ------------------------------------------------------------------------------ local launcher (slow)

def _started(out: str) -> set[str]:
    return set(re.findall(r"^start (\S+)", out, flags=re.M))


def _wait(pred, timeout: float, what: str) -> None:
    end = time.time() + timeout
    while not pred():
        if time.time() > end:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.5)


@pytest.mark.slow
def test_local_grid_killed_and_relaunched_twice_concurrently_runs_each_once(tmp_path):
    """2 tasks x 2 variants: kill the launcher halfway (SIGKILL), then two launchers at once finish the grid;
    every run ends DONE exactly once with complete, duplicate-free CSVs."""
    sweep = write_sweep(
        tmp_path, "grid", ["reacher_hard", "cheetah_run"], {"K1": ["agent.K=1"], "K3": ["agent.K=3"]}, 1
    )
    root = tmp_path / "results"
    common = [str(sweep), "--set", f"runtime.results_root={root}"]
    planned = specs.plan(specs.expand(specs.load(str(sweep)), specs.Selection(sets=(f"runtime.results_root={root}",))))
    assert len(planned) == 4
    dirs = [p.run_dir for p in planned]

    first = cli_proc("sweep", *common, "--max-parallel", "2", "--warm-start")  # its children die with it too
    _wait(lambda: sum((d / "DONE").exists() for d in dirs) >= 2
          and any((d / "checkpoint.pt").exists() and not (d / "DONE").exists() for d in dirs), 300, "a partial run")
    first.send_signal(signal.SIGKILL)
    first.wait()
    # the children die with the launcher (PDEATHSIG), so their locks become stale; a child still shutting down
    # holds its run's writer lock until it has exited, and a launcher started before then skips that run as held
    def children_gone() -> bool:
        for p in planned:
            try:
                info = lock.read(lock.lock_path(root, p.run_dir))
            except ValueError:
                return False
            if info is not None and not lock.is_stale(info, None):
                return False
            if writer_lock_holder(p.run_dir) is not None:
                return False
        return True
    _wait(children_gone, 60, "the killed launcher's children to exit")
    # what the two launchers find: a child of the killed launcher can still finish its run (write DONE) before it exits
    done_before = {p.key for p in planned if (p.run_dir / "DONE").exists()}
    partial = {p.key for p in planned if (p.run_dir / "checkpoint.pt").exists() and p.key not in done_before}
    assert partial

    b = cli_proc("sweep", *common, "--max-parallel", "1")
    c = cli_proc("sweep", *common, "--max-parallel", "1")
    out_b, out_c = b.communicate(timeout=600)[0], c.communicate(timeout=600)[0]
    assert b.returncode == 0, out_b
    assert c.returncode == 0, out_c
    ran_b, ran_c = _started(out_b), _started(out_c)
    assert not ran_b & ran_c, "a run was executed by both launchers"
    assert ran_b | ran_c == {p.key for p in planned} - done_before
    for p in planned:
        assert_complete(p.run_dir, 100)
        resumes = json.loads((p.run_dir / "meta.json").read_text())["resumes"]
        assert len(resumes) == (1 if p.key in partial else 0), p.key

    again = cli_proc("sweep", *common)
    out = again.communicate(timeout=120)[0]
    assert again.returncode == 0 and "0 started" in out and "4 already done" in out, out
    code, out = run_cli("status", "grid", "--results-root", str(root))
    assert code == 0 and "grid: 4 done" in out


@pytest.mark.slow
def test_local_launcher_keeps_going_after_a_failure_and_a_warm_start_gives_the_same_runs(tmp_path):
    """The same two-run sweep, one run of it broken (a corrupt checkpoint), launched plain and with --warm-start
    (runs forked from a server that has imported torch: repro/launch/warm.py): each launch keeps going past the
    failure, exits 1 and names the failed run's log, and `status` says so; the good runs' logs, config and
    resolved values are the same either way, and so is the broken run's error line."""
    from repro.runs.rundir import write_config

    sweep = write_sweep(tmp_path, "fail", ["reacher_hard"], {"a": [], "b": []}, 1)
    got = {}
    for how, extra in (("plain", []), ("warm", ["--warm-start"])):
        root = tmp_path / how
        sel = specs.Selection(sets=(f"runtime.results_root={root}",))
        bad, good = specs.plan(specs.expand(specs.load(str(sweep)), sel))
        bad.run_dir.mkdir(parents=True)
        write_config(bad.run_dir, bad.cfg)
        (bad.run_dir / "checkpoint.pt").write_bytes(b"not a checkpoint")  # resuming it fails
        proc = cli_proc("sweep", str(sweep), "--set", f"runtime.results_root={root}", "--max-parallel", "1", *extra)
        out = proc.communicate(timeout=300)[0]
        assert proc.returncode == 1, out
        assert (good.run_dir / "DONE").exists() and not (bad.run_dir / "DONE").exists()
        log = state_dir(root, "fail") / "logs" / f"{bad.key}.log"
        assert f"failed {bad.key}: log {log}" in out and log.exists() and log.read_text().strip()
        code, out = run_cli("status", "fail", "--results-root", str(root))
        assert "1 done" in out and "1 failed" in out and f"failed {os.path.relpath(bad.run_dir, root)}: {log}" in out
        header, *lines = log.read_text().strip().splitlines()
        assert header.endswith("(warm start)") == (how == "warm")
        got[how] = (good.run_dir, [ln.replace(str(root), "ROOT") for ln in lines])
    (plain, plain_log), (warm, warm_log) = got["plain"], got["warm"]
    # the error: one line (a file that is not a checkpoint is no traceback), the same from both
    assert warm_log == plain_log and len(plain_log) == 1, (warm_log, plain_log)
    assert plain_log[0].startswith("error: ") and "checkpoint.pt cannot be read" in plain_log[0], plain_log
    for name in (EVAL, TRAIN):
        pd.testing.assert_frame_equal(deterministic(warm / name), deterministic(plain / name))
    for name in ("resolved.json", "config.yaml"):
        assert (warm / name).read_text().replace(str(tmp_path / "warm"), "ROOT") == \
            (plain / name).read_text().replace(str(tmp_path / "plain"), "ROOT"), name


def test_repr_objectives_marks_driml_na_on_k1_tasks():
    spec = specs.load("repr_objectives")
    runs = specs.expand(spec)
    assert len(runs) == (5 * 5 - 2) * 6
    assert not any(r.agent == "driml" and r.task in ("quadruped_run", "walker_run") for r in runs)
    assert any(r.agent == "driml" and r.task == "hopper_hop" for r in runs)
    assert {(a, t) for a, _, t, _ in specs.excluded(spec)} == {("driml", "quadruped_run"), ("driml", "walker_run")}


def test_exclude_must_have_a_reason(tmp_path):
    data = yaml.safe_load((specs.sweeps_dir() / "tiny.yaml").read_text())
    data["exclude"] = [{"agents": ["taco"]}]
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(specs.SweepError, match="reason"):
        specs.load_file(path)


def test_an_exclusion_naming_seeds_leaves_out_those_runs_only(tmp_path):
    spec = specs.load("tiny_offline")
    runs = specs.expand(spec)
    by = {(r.agent, r.dataset, r.seed) for r in runs}
    assert ("iql", "medium", 1) in by and ("iql", "medium", 2) not in by and ("cql", "medium", 2) in by
    assert len(runs) == 2 * (4 * 2 + 3 * 1)
    assert specs.excluded(spec) == []  # no cell is n/a: its other seeds run
    bad = yaml.safe_load(spec.path.read_text())
    bad["exclude"][0]["seeds"] = ["two"]
    path = tmp_path / "tiny_offline.yaml"
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(specs.SweepError, match="seeds must be a list"):
        specs.load(str(path))
