"""The offline sweep: its grid, runs that wait for their dataset (dry run, local launcher, SLURM submission,
status), and a tiny offline sweep end to end (every learner on every dataset kind, then T3)."""

from __future__ import annotations

import csv
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
import typer
import yaml
from typer.testing import CliRunner

from helpers import launch_app
from offline_fixtures import make_episode
from repro.config.compose import config_groups
from repro.data.dataset import write_dataset
from repro.launch import local, slurm
from repro.launch import spec as specs
from repro.launch.state import RunRecord, state_dir, write_record
from repro.launch.status import collect
from repro.launch.waiting import waiting_lines
from repro.runs.runformat import run_path

KINDS = ("medium", "medium-replay", "full-replay")
LEARNERS = ("td3bc", "td3bc_taco", "cql", "cql_taco", "iql", "bc", "dt")
TASK = "cheetah_run"  # the cheapest DMC task to render and step (also the offline loop's own tests' task)
ACTION_DIM = 6  # cheetah_run


def available_learners() -> list[str]:
    """The paper's offline learners that have an agent file (dt may land after this test)."""
    return [a for a in LEARNERS if a in config_groups()["agent"]]


def run_cli(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(launch_app(), list(args))
    if res.exception and not isinstance(res.exception, SystemExit):
        raise res.exception
    return res.exit_code, res.output


def make_dataset(root: Path, kind: str, lengths: tuple[int, ...] = (12, 9, 15), seed: int = 0) -> Path:
    """A complete synthetic dataset of ``kind`` for TASK, written by the real writer where the sweep looks."""
    rng = np.random.default_rng(seed)
    episodes = [make_episode(i, n, (3, 84, 84), ACTION_DIM, rng) for i, n in enumerate(lengths)]
    return _write(root, kind, episodes)


def _write(root: Path, kind: str, episodes) -> Path:
    d = root / "datasets" / TASK / kind
    write_dataset(d, episodes, task=TASK, kind=kind, source={"run_dir": "synthetic", "best_return": 300.0},
                  rule={"synthetic": True})
    return d


def make_partial_dataset(root: Path, kind: str) -> Path:
    """A dataset whose write was interrupted after its first episode (no manifest.json)."""
    rng = np.random.default_rng(1)

    def episodes():
        yield make_episode(0, 12, (3, 84, 84), ACTION_DIM, rng)
        raise RuntimeError("killed")

    with pytest.raises(RuntimeError, match="killed"):
        _write(root, kind, episodes())
    d = root / "datasets" / TASK / kind
    assert (d / "episodes" / "ep_0000000.npz").exists() and not (d / "manifest.json").exists()
    return d


def sweep_file(tmp: Path, name: str, agents, kinds=KINDS, common=(), experiment: str | None = None) -> Path:
    data = {"name": name, "description": "test offline sweep", "artifacts": ["T3"], "experiment": experiment or name,
            "tasks": [TASK], "agents": list(agents), "seeds": 1, "frames": None,
            "eval": {"every_frames": None, "episodes": None}, "common": list(common),
            "variants": {k: ["variant=base", f"offline.dataset={k}"] for k in kinds}}
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def planned_runs(sweep: Path, root: Path) -> list[specs.PlannedRun]:
    return specs.plan(specs.expand(specs.load(str(sweep)), specs.Selection(sets=(f"runtime.results_root={root}",))))


# ------------------------------------------------------------------------------------------- the grid

def test_offline_sweep_is_four_tasks_three_datasets_seven_learners_six_seeds():
    spec = specs.load("offline")
    assert spec.tasks == ("hopper_hop", "cheetah_run", "walker_run", "quadruped_run")
    assert set(spec.agents) == set(LEARNERS) and spec.seeds == tuple(range(1, 7))
    if "dt" in config_groups()["agent"]:
        runs = specs.expand(spec)
        assert len(runs) == 504
    else:  # until the DT agent file lands the sweep is refused, naming only what is missing
        reason = specs.unavailable_reason(spec)
        assert reason and "agent dt not in the packaged config" in reason and "td3bc" not in reason
        runs = specs.expand(dataclasses.replace(spec, agents=tuple(a for a in spec.agents if a != "dt")))
        assert len(runs) == 432
    agents = {r.agent for r in runs}
    assert {(r.agent, r.task, r.dataset, r.seed) for r in runs} == {
        (a, t, k, s) for a in agents for t in spec.tasks for k in KINDS for s in range(1, 7)}
    assert {r.variant for r in runs} == {"base"}
    for r in runs:
        assert f"offline.dataset={r.dataset}" in r.overrides and f"agent={r.agent}" in r.overrides


def test_each_offline_run_has_its_own_run_directory_with_the_dataset(tmp_path):
    sweep = sweep_file(tmp_path, "offgrid", ["td3bc", "td3bc_taco", "cql"])
    planned = planned_runs(sweep, tmp_path)
    assert len(planned) == 9
    for p in planned:
        assert p.run_dir == run_path(tmp_path, "offgrid", p.run.agent, "base", TASK, 1, p.run.dataset)
    assert len({p.run_dir for p in planned}) == 9


# ------------------------------------------------------------------------------ waiting for a dataset

def test_dry_run_lists_runs_whose_dataset_is_missing_or_partial_as_waiting(tmp_path):
    make_dataset(tmp_path, "medium")
    make_partial_dataset(tmp_path, "medium-replay")  # full-replay: never made
    sweep = sweep_file(tmp_path, "offdry", ["bc", "td3bc"])
    code, out = run_cli("sweep", str(sweep), "--dry-run", "--results", str(tmp_path))
    assert code == 0, out
    lines = {re.search(r"offdry/(\w+)/base/cheetah_run/([\w-]+)/seed_1", ln).groups(): ln
             for ln in out.splitlines() if "/seed_1" in ln}
    assert len(lines) == 6
    for agent in ("bc", "td3bc"):
        assert lines[(agent, "medium")].startswith("absent") and "waiting" not in lines[(agent, "medium")]
        partial, missing = lines[(agent, "medium-replay")], lines[(agent, "full-replay")]
        assert partial.startswith("waiting") and "dataset medium-replay for cheetah_run not complete" in partial
        assert "incomplete dataset" in partial
        assert missing.startswith("waiting") and "dataset full-replay for cheetah_run not made yet" in missing
        assert "repro dataset make --source RUN_DIR --kind full-replay" in missing
        assert str(tmp_path / "datasets" / TASK / "full-replay") in missing
    assert "6 runs of sweep 'offdry'" in out and "2 absent, 4 waiting" in out and "3 dataset(s)" in out


def test_local_launcher_starts_no_run_that_waits_and_says_so_once_per_dataset(tmp_path, monkeypatch):
    make_dataset(tmp_path, "medium")
    sweep = sweep_file(tmp_path, "offloc", ["bc", "td3bc"])
    planned = planned_runs(sweep, tmp_path)
    waiting = [p for p in planned if p.waiting]
    assert {p.run.dataset for p in waiting} == {"medium-replay", "full-replay"} and len(waiting) == 4
    ready = [p for p in planned if not p.waiting]
    def never(c, sdir, env):
        raise AssertionError(f"{c.planned.key} was started")

    monkeypatch.setattr(local, "_start", never)
    said: list[str] = []
    report = local.run_local(waiting, "offloc", state_dir(tmp_path, "offloc"), 2, False, said.append)
    assert report.started == [] and report.failed == []
    assert sorted(k for k, _ in report.waiting) == sorted(p.key for p in waiting)
    assert len(said) == 2 and all(s.startswith("[yellow]skip[/] 2 run(s) waiting: dataset ") for s in said)
    assert not any(p.run_dir.exists() for p in planned)
    # the filter both launchers use: done runs and waiting runs out, the rest in
    report = local.LaunchReport()
    assert report.to_launch(planned, lambda s: None) == ready and len(report.waiting) == 4


class _FakeJob:
    def __init__(self, job_id: str):
        self.job_id = job_id
        self.paths = type("Paths", (), {"stdout": Path(f"/x/{job_id}.out"), "stderr": Path(f"/x/{job_id}.err")})()


class _FakeExecutor:
    """Stands in for submitit.AutoExecutor: records what would be submitted."""

    submitted: list = []

    def __init__(self, folder, cluster, slurm_max_num_timeout):
        pass

    def update_parameters(self, **params) -> None:
        pass

    def map_array(self, fn, tasks):
        _FakeExecutor.submitted.extend(tasks)
        return [_FakeJob(f"77_{i}") for i in range(len(tasks))]


def test_slurm_submission_leaves_out_runs_waiting_for_their_dataset(tmp_path, monkeypatch):
    make_dataset(tmp_path, "full-replay")
    sweep = sweep_file(tmp_path, "offslurm", ["bc", "cql"])
    planned = planned_runs(sweep, tmp_path)
    monkeypatch.setattr(slurm.shutil, "which", lambda name: "/usr/bin/" + name)
    monkeypatch.setattr(slurm.submitit, "AutoExecutor", _FakeExecutor)
    _FakeExecutor.submitted = []
    said: list[str] = []
    report = slurm.submit(planned, "offslurm", state_dir(tmp_path, "offslurm"), slurm.ClusterConfig(), False,
                          said.append)
    ready = {p.key for p in planned if p.run.dataset == "full-replay"}
    assert {t.key for t in _FakeExecutor.submitted} == ready == set(report.started)
    assert {k for k, _ in report.waiting} == {p.key for p in planned} - ready
    assert sum("run(s) waiting: dataset medium" in s for s in said) == 2  # medium and medium-replay


def test_status_shows_waiting_runs_until_their_dataset_is_made(tmp_path):
    sweep = sweep_file(tmp_path, "offst", ["bc", "iql"], kinds=("medium", "full-replay"))
    code, out = run_cli("sweep", str(sweep), "--results", str(tmp_path))
    assert code == 0, out  # nothing to run is not a failure
    assert "0 started" in out and "4 waiting for their dataset (not started)" in out
    assert "[yellow]" not in out and out.count("2 run(s) waiting: dataset ") == 2
    planned = planned_runs(sweep, tmp_path)
    assert not any(p.run_dir.exists() for p in planned)
    code, out = run_cli("status", "offst", "--results-root", str(tmp_path))
    assert code == 0 and "0 pending, 4 waiting" in out, out
    assert "dataset full-replay for cheetah_run not made yet" in out

    make_dataset(tmp_path, "full-replay")
    sdir = state_dir(tmp_path, "offst")
    medium = next(p for p in planned if p.run.dataset == "medium")
    write_record(sdir, RunRecord(key=medium.key, run_dir=str(medium.run_dir), overrides=[], launcher="local",
                                 status="failed", returncode=1, log="/x/a.log", stderr="/x/a.log"))
    got = {s.key: s for s in collect({p.key: p.run_dir for p in planned}, tmp_path, sdir)}
    for p in planned:
        want = "pending" if p.run.dataset == "full-replay" else "waiting"
        assert got[p.key].status == want, (p.key, got[p.key])
    assert "dataset medium for cheetah_run not made yet" in got[medium.key].detail


def test_waiting_lines_count_runs_per_reason():
    assert waiting_lines([("a", "x"), ("b", "y"), ("c", "x")]) == ["2 run(s) waiting: x", "1 run(s) waiting: y"]


# --------------------------------------------------------------------------------- tiny sweep, end to end

TINY = ["profile=tiny", "runtime.threads=1", "env.max_episode_frames=10", "offline.updates=2",
        "offline.eval_every_updates=2", "offline.eval_episodes=1", "offline.checkpoint_every_updates=2",
        "offline.log_every_updates=1"]


def _t3_rows(results: Path, out: Path) -> list[dict[str, str]]:
    from repro_app.analysis_cli import register as register_analysis

    app = typer.Typer(add_completion=False, pretty_exceptions_enable=False)
    register_analysis(app)

    @app.callback()
    def _root() -> None:
        pass

    res = CliRunner().invoke(app, ["figures", "T3", "--results", str(results), "--out", str(out), "--reps", "200"])
    assert res.exit_code == 0, res.output
    with open(next(out.rglob("T3.csv"))) as fh:
        return list(csv.DictReader(fh))


@pytest.mark.slow
def test_tiny_offline_sweep_runs_every_learner_on_every_dataset_kind_then_t3(tmp_path):
    """One learner x the three kinds on tiny synthetic datasets of cheetah_run, 2 updates each (real
    evaluation rollouts). First the full-replay dataset is missing: its runs wait, the others run; once it
    is made, a relaunch runs just those; then T3 shows a reproduced cell for every learner and kind. (Every
    learner on real datasets made from a recorded run: the main job, tests/test_reproduce.py.)"""
    learners = ["td3bc"]
    assert set(learners) <= set(available_learners())
    root = tmp_path / "results"
    for i, kind in enumerate(KINDS[:2]):
        make_dataset(root, kind, seed=i)
    sweep = sweep_file(tmp_path, "offline_tiny", learners, common=TINY, experiment="offline")  # T3 reads `offline`
    args = ("sweep", str(sweep), "--results", str(root), "--max-parallel", "2")
    code, out = run_cli(*args)
    assert code == 0, out
    n = len(learners)
    assert f"{2 * n} started, {2 * n} finished" in out and f"{n} waiting for their dataset" in out, out
    planned = planned_runs(sweep, root)
    for p in planned:
        assert (p.run_dir / "DONE").exists() == (p.run.dataset != "full-replay"), p.key
    code, status = run_cli("status", "offline_tiny", "--results-root", str(root))
    assert f"{2 * n} done" in status and f"{n} waiting" in status, status

    make_dataset(root, "full-replay", seed=2)
    code, out = run_cli(*args)
    assert code == 0, out
    assert f"{n} started, {n} finished, {2 * n} already done" in out, out
    for p in planned:
        assert (p.run_dir / "DONE").exists(), p.key
        rows = list(csv.DictReader(open(p.run_dir / "eval.csv")))
        assert [int(r["update"]) for r in rows] == [0, 2] and rows[-1]["normalized_score"] != ""
    code, status = run_cli("status", "offline_tiny", "--results-root", str(root))
    assert f"offline_tiny: {3 * n} done" in status, status

    rows = _t3_rows(root, tmp_path / "report")
    labels = {"td3bc": "TD3+BC", "td3bc_taco": "TD3+BC+TACO", "cql": "CQL", "cql_taco": "CQL+TACO", "iql": "IQL",
              "bc": "BC", "dt": "DT"}
    cells = {(r["task"], r["dataset"], r["method"]): r for r in rows}
    for learner in learners:
        for kind in KINDS:
            cell = cells.get((TASK, kind, labels[learner]))
            assert cell is not None, (kind, learner, sorted(cells))
            assert int(cell["n"]) == 1, (kind, learner, cell)
            assert cell["repro_mean"] not in ("", "nan"), (kind, learner, cell)
