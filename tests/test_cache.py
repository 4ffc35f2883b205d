"""The incremental report (analysis/cache.py): an unchanged tree reuses what the last command computed, a changed
run is read again (and only it), changed code or --no-cache recomputes, and what is reused equals what is
computed."""

from __future__ import annotations

import os
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from analysis import cache as cache_mod
from analysis.cache import opened
from analysis.load import load_results
from analysis.stats import mean_cis
from analysis_fixtures import write_run
from repro_app.cli import app


def _tree(root: Path) -> list[Path]:
    return [write_run(root, experiment="main", agent=agent, task="cheetah_run", seed=s, final=100.0 * (s + 1))
            for agent in ("taco", "drqv2") for s in range(2)]


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


OLD_AGENT_COLUMN = "algo"  # the runs table's agent column in a cache of format 1


def _renamed_agent_column(entry: tuple) -> tuple:
    """A ``runs`` entry as format 1 stored it: the agent column under its old name (issue 51)."""
    row, columns, problems = entry
    return ({(OLD_AGENT_COLUMN if k == "agent" else k): v for k, v in row.items()},
            {(OLD_AGENT_COLUMN if k == "agent" else k): v for k, v in columns.items()}, problems)


def test_a_cache_of_the_old_format_is_not_reused(tmp_path: Path):
    """A cache written before the runs table's agent column was renamed (format 1, the column under its old
    name) is read afresh, even with this code's version; the same entries under the current format would be
    reused (so it is the format that keeps the old column out of the table)."""
    _tree(tmp_path / "runs")
    out = tmp_path / "out"
    with opened(out):
        fresh = load_results(tmp_path / "runs")
    path = out / cache_mod.CACHE_DIR / cache_mod.CACHE_FILE
    stored = pickle.loads(path.read_bytes())
    assert stored["format"] == cache_mod.FORMAT != 1
    old = {k: _renamed_agent_column(v) for k, v in stored["sections"]["runs"].items()}
    path.write_bytes(pickle.dumps({"format": 1, "version": stored["version"], "sections": {"runs": old}}))
    with opened(out) as again:
        loaded = load_results(tmp_path / "runs")
    assert again.misses == {"runs": 4} and not again.hits
    pd.testing.assert_frame_equal(loaded.runs, fresh.runs)
    assert sorted(loaded.runs["agent"]) == ["drqv2", "drqv2", "taco", "taco"]
    current_format = {"format": cache_mod.FORMAT, "version": stored["version"], "sections": {"runs": old}}
    path.write_bytes(pickle.dumps(current_format))
    with opened(out) as current:
        rows = [current.peek("runs", key)[0] for key in old]
    assert sorted(row[OLD_AGENT_COLUMN] for row in rows) == ["drqv2", "drqv2", "taco", "taco"]


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


def test_a_partial_command_keeps_the_reports_entries_and_a_report_prunes(tmp_path: Path):
    runs = _tree(tmp_path / "runs")
    out = tmp_path / "out"
    with opened(out, prune=True):  # a report: its runs and F13's frames
        load_results(tmp_path / "runs")
        cache_mod.lookup("frames", "cheetah_run", lambda: "frames")
    eval_csv = runs[0] / "eval.csv"
    last = eval_csv.read_text().splitlines()[-1].split(",")
    eval_csv.write_text(eval_csv.read_text() + ",".join(["1100000", *last[1:]]) + "\n")
    with opened(out) as claims:  # `repro claims` after it: reads the runs only
        load_results(tmp_path / "runs")
    assert claims.misses == {"runs": 1}
    stored = cache_mod.AnalysisCache(out / ".cache" / "analysis.pkl")._old
    assert list(stored["frames"]) == ["cheetah_run"]  # kept for the next report
    assert len(stored["runs"]) == 4  # the changed run's older entry is superseded, not kept beside the new one
    with opened(out, prune=True) as report:  # a report drops what it did not use of the sections it used
        load_results(tmp_path / "runs")
        cache_mod.lookup("frames", "walker_walk", lambda: "frames")
    assert report.hits == {"runs": 4}
    stored = cache_mod.AnalysisCache(out / ".cache" / "analysis.pkl")._old
    assert list(stored["frames"]) == ["walker_walk"] and len(stored["runs"]) == 4


def _figure(scale: float):
    """A figure with a seaborn style, bars, a fill and a tick formatter whose closure holds ``scale``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter

    fig, axes = plt.subplots(1, 2, figsize=(5, 2))
    x = np.arange(20)
    axes[0].plot(x, np.sin(x / 3), label="a")
    axes[0].fill_between(x, 0, np.cos(x / 4), alpha=0.3)
    axes[0].legend()
    axes[1].bar([1, 2], [3, 4], yerr=[0.1, 0.2])
    axes[1].xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v * scale:g}"))
    fig.suptitle("toy")
    return fig


def test_an_unchanged_figure_is_not_drawn_again_and_a_changed_one_is(tmp_path: Path):
    import matplotlib.pyplot as plt

    from analysis.io import figure_key, save_figure_files

    paths = [tmp_path / "f.png", tmp_path / "f.pdf"]

    def save(scale: float) -> tuple[int, ...]:
        fig = _figure(scale)
        save_figure_files(fig, paths, bbox_inches="tight")
        plt.close(fig)
        return tuple(p.stat().st_mtime_ns for p in paths)

    assert figure_key(_figure(1.0)) == figure_key(_figure(1.0)) != figure_key(_figure(2.0))  # the closure counts
    image = np.arange(12.0).reshape(3, 4)

    def shown(a: np.ndarray) -> str | None:
        fig = _figure(1.0)
        fig.axes[0].imshow(a)  # kept as a masked array
        fig.axes[1].errorbar([1, 2, 3], a[:, 0], yerr=a[:, 1])
        return figure_key(fig)

    # the values count, not the memory order (a computed array, unpickled from the cache, is C-ordered)
    assert shown(np.ascontiguousarray(image)) == shown(np.asfortranarray(image)) != shown(image + 1)
    with opened(tmp_path / "out") as first:
        written = save(1.0)
    assert first.misses == {"figures": 1}
    with opened(tmp_path / "out") as second:
        assert save(1.0) == written  # same content, files as written: not drawn
    assert second.hits == {"figures": 1} and not second.misses
    with opened(tmp_path / "out") as third:
        changed = save(2.0)  # another tick formatter: drawn again
    assert third.misses == {"figures": 1} and changed != written
    assert len(cache_mod.AnalysisCache(tmp_path / "out" / ".cache" / "analysis.pkl")._old["figures"]) == 1  # superseded
    paths[1].unlink()
    with opened(tmp_path / "out") as fourth:
        save(2.0)  # a file removed by hand: drawn again
    assert fourth.misses == {"figures": 1} and paths[1].exists()
    os.utime(paths[0], ns=(0, 0))
    with opened(tmp_path / "out") as fifth:
        save(2.0)  # a file touched by hand: drawn again
    assert fifth.misses == {"figures": 1}
    before = save(2.0)  # no command's cache: always drawn
    assert save(2.0) != before


def _default_style_key() -> str | None:
    """The key of ``_figure(1.0)`` under seaborn's colour codes (which set 'k' to another grey: a figure drawn after
    seaborn's theme differs) and matplotlib's default settings (other tests change the process's)."""
    import matplotlib
    import seaborn as sns

    from analysis.io import figure_key

    sns.set_color_codes()
    with matplotlib.rc_context():
        matplotlib.rcdefaults()
        return figure_key(_figure(1.0))


def test_a_figures_key_is_the_same_in_another_process():
    import subprocess
    import sys

    code = "import sys; sys.path[:0] = [sys.argv[1]]; from test_cache import _default_style_key as k; print(k())"
    tests = str(Path(__file__).resolve().parent)
    other = subprocess.run([sys.executable, "-c", code, tests], capture_output=True, text=True, check=True,
                           env={**os.environ, "PYTHONHASHSEED": "123", "MPLBACKEND": "Agg"}).stdout.strip()
    assert other == _default_style_key() is not None


def test_an_unchanged_tsne_checkpoint_is_neither_loaded_nor_embedded_again(tmp_path: Path, monkeypatch):
    from analysis import tsne
    from analysis.context import Context
    from analysis_fixtures import write_encoder_checkpoint

    run = write_run(tmp_path / "runs", experiment="tsne", agent="taco", task="cheetah_run", seed=0,
                    distracting_dims=20, final=500, latent_action_dim=8)
    write_encoder_checkpoint(run)
    loads: list[Path] = []
    real = tsne.load_step_mlp
    monkeypatch.setattr(tsne, "load_step_mlp", lambda p: loads.append(p) or real(p))

    def f6() -> tsne.TsneResult:
        ctx = Context(results=load_results(tmp_path / "runs"), tsne_n=15, tsne_iter=250)
        return tsne.tsne_for_context(ctx)[0]

    with opened(tmp_path / "out"):
        first = f6()
    with opened(tmp_path / "out") as second:
        again = f6()
    assert len(loads) == 1 and second.hits.get("tsne_result") == 1 and "tsne" not in second.misses
    np.testing.assert_array_equal(first.latent_2d, again.latent_2d)
    write_encoder_checkpoint(run, latent=4)  # a new checkpoint: loaded and embedded again
    with opened(tmp_path / "out") as third:
        f6()
    assert len(loads) == 2 and third.misses.get("tsne_result") == 1


def test_the_compositions_key_changes_with_what_composing_reads(tmp_path: Path, monkeypatch):
    from repro.config import compose as compose_mod

    plugin = tmp_path / "conf" / "agent"
    plugin.mkdir(parents=True)
    (plugin / "mine.yaml").write_text("name: mine\n")
    packaged = compose_mod.conf_dirs()[0]
    monkeypatch.setattr(compose_mod, "conf_dirs", lambda: (packaged, tmp_path / "conf"))
    first = compose_mod.config_digest()
    assert compose_mod.config_digest() == first
    (plugin / "mine.yaml").write_text("name: mine\nbatch_size: 512\n")  # a plugin's agent file changes
    assert compose_mod.config_digest() != first


def test_f13_shows_the_frames_a_trained_run_saved_and_renders_nothing(tmp_path: Path, monkeypatch):
    """A trained run writes its final evaluation's frames (train.save_frames, on by default; the fixture writes them
    with the writer training uses): F13 shows them and starts no rendering, as at the paper's scale."""
    from analysis.context import Context
    from paper_figures import f13_frames

    monkeypatch.setattr(f13_frames, "random_action_frames", lambda *a, **k: pytest.fail("rendered"))
    run = write_run(tmp_path / "runs", experiment="main", agent="taco", task="hammer", seed=0, final=0.5,
                    success=True, save_frames=True)
    ctx = Context(results=load_results(tmp_path / "runs"), render_envs=False)
    frames, source = f13_frames.all_frames(ctx)["hammer"]
    assert frames is not None and frames.shape == (251, 84, 84, 3)  # 500 steps at action repeat 2, and the first
    assert source == f"trained TACO agent, run {run.relative_to(tmp_path / 'runs')}"
