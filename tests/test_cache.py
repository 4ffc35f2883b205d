"""The incremental report (analysis/cache.py): an unchanged tree reuses what the last command computed, a changed
run is read again (and only it), changed code or --no-cache recomputes, and what is reused equals what is
computed."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
from typer.testing import CliRunner

from analysis import cache as cache_mod
from analysis.cache import opened
from analysis.load import load_results
from analysis.stats import mean_cis
from analysis_fixtures import write_run
from repro_app.cli import app


def _tree(root: Path) -> list[Path]:
    return [write_run(root, experiment="main", algo=algo, task="cheetah_run", seed=s, final=100.0 * (s + 1))
            for algo in ("taco", "drqv2") for s in range(2)]


def test_unchanged_runs_are_reused_and_a_changed_run_is_read_again(tmp_path: Path):
    runs = _tree(tmp_path / "runs")
    out = tmp_path / "out"
    with opened(out) as first:
        loaded = load_results(tmp_path / "runs")
    assert first.misses == {"runs": 4} and not first.hits
    with opened(out) as second:
        again = load_results(tmp_path / "runs")
    assert second.hits == {"runs": 4} and not second.misses
    pd.testing.assert_frame_equal(loaded.runs, again.runs)
    pd.testing.assert_frame_equal(loaded.eval, again.eval)
    # one run gets a new evaluation (its eval.csv grows): only it is read again, and the new value is seen
    eval_csv = runs[0] / "eval.csv"
    last = eval_csv.read_text().splitlines()[-1].split(",")
    eval_csv.write_text(eval_csv.read_text() + ",".join(["1100000", *last[1:]]) + "\n")
    with opened(out) as third:
        changed = load_results(tmp_path / "runs")
    assert third.hits == {"runs": 3} and third.misses == {"runs": 1}
    assert changed.runs.set_index("run_id").loc[str(runs[0].relative_to(tmp_path / "runs")), "last_frame"] == 1_100_000


def test_same_size_rewrite_is_seen_by_its_modification_time(tmp_path: Path):
    runs = _tree(tmp_path / "runs")
    with opened(tmp_path / "out"):
        load_results(tmp_path / "runs")
    meta = runs[1] / "meta.json"
    st = meta.stat()
    os.utime(meta, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))  # same bytes, later time
    with opened(tmp_path / "out") as again:
        load_results(tmp_path / "runs")
    assert again.misses == {"runs": 1}


def test_intervals_are_reused_and_changed_code_recomputes(tmp_path: Path, monkeypatch):
    cols = [np.array([1.0, 2.0, 4.0]), np.array([3.0, 5.0, 6.0, 9.0])]
    with opened(tmp_path) as first:
        cis = mean_cis(cols, reps=500, seed=1)
        assert mean_cis(cols, reps=500, seed=1) == cis  # the second call in one command is reused
    assert first.misses == {"intervals": 2} and first.hits == {"intervals": 2}
    with opened(tmp_path) as second:
        assert mean_cis(cols, reps=500, seed=1) == cis
        assert mean_cis(cols, reps=500, seed=2) != cis  # the random state is part of the key
    assert second.hits == {"intervals": 2} and second.misses == {"intervals": 2}
    monkeypatch.setattr(cache_mod, "code_version", lambda: "other code")
    with opened(tmp_path) as third:
        assert mean_cis(cols, reps=500, seed=1) == cis
    assert not third.hits


def test_cli_reuses_the_cache_and_no_cache_writes_none(tmp_path: Path):
    _tree(tmp_path / "runs")
    args = ["figures", "T1", "-r", str(tmp_path / "runs"), "--reps", "200"]
    runner = CliRunner()
    res = runner.invoke(app, [*args, "-o", str(tmp_path / "a")])
    assert res.exit_code == 0, res.output
    res = runner.invoke(app, [*args, "-o", str(tmp_path / "a")])
    assert res.exit_code == 0 and "runs 4 reused, 0 computed" in res.output, res.output
    res = runner.invoke(app, [*args, "-o", str(tmp_path / "b"), "--no-cache"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "a" / ".cache").is_dir() and not (tmp_path / "b" / ".cache").exists()


def test_f13_random_action_frames_render_once_then_come_from_the_cache(tmp_path: Path, monkeypatch):
    from analysis.context import Context
    from paper_figures import f13_frames

    calls: list[list[str]] = []

    def fake(tasks, timeout=600.0):
        calls.append(list(tasks))
        return {t: np.full((3, 4, 4, 3), i, dtype=np.uint8) for i, t in enumerate(tasks)}, ""

    monkeypatch.setattr(f13_frames, "random_action_frames", fake)
    (tmp_path / "empty").mkdir()
    ctx = Context(results=load_results(tmp_path / "empty"))  # no run saved frames
    with opened(tmp_path / "out"):
        first = f13_frames.all_frames(ctx)
    with opened(tmp_path / "out"):
        second = f13_frames.all_frames(ctx)
    assert calls == [f13_frames.TASKS]  # rendered once, all tasks in one call
    for task in f13_frames.TASKS:
        np.testing.assert_array_equal(first[task][0], second[task][0])
        assert second[task][1].startswith("random actions")
