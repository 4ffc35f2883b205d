"""Watching runs (issue 12): TensorBoard mirror of the CSVs, evaluation videos, `repro plot`, `repro status --watch`;
the W&B mirror and `repro wandb sync` (issue 28)."""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from analysis_fixtures import FRAMES, write_run
from helpers import REL, TINY_TACO, assert_mirrors_csv, assert_wandb_mirrors_csv, write_sweep
from repro.launch.state import record_launch, state_dir
from repro.runs import rundir
from repro.runs.logger import RunLogger
from repro.runs.runformat import DONE, EVAL, RESOLVED
from repro.runs.tblog import TB_DIR, read_scalars
from repro.runs.video import count_frames, write_mp4
from repro.runs.wblog import RUN_ID, WANDB_DIR, WandbRun, offline_folders, read_history
from repro_app.cli import app

METRICS = ["critic_loss"]


def cli(*args: str) -> tuple[int, str, str]:
    res = CliRunner().invoke(app, list(args))
    if res.exception and not isinstance(res.exception, SystemExit):
        raise res.exception
    return res.exit_code, res.stdout, res.stderr


def _train_row(frame: int, loss: float | None) -> dict:
    return {"frame": frame, "step": frame // 2, "episode": frame // 100, "episode_reward": frame / 7,
            "episode_length": 100, "success": None, "buffer_size": frame, "stddev": 0.5, "fps": 10.0,
            "total_time": 1.0, "critic_loss": loss}


def _eval_row(frame: int) -> dict:
    return {"frame": frame, "step": frame // 2, "episode": frame // 100, "episode_reward": frame / 3,
            "episode_reward_std": 0.0, "episode_length": 100.0, "success": None, "eval_episodes": 1,
            "total_time": 2.0}


# ----------------------------------------------------------------------------- TensorBoard mirror
def test_mirror_equals_csv_and_a_resume_rebuilds_it_without_repeated_steps(tmp_path: Path):
    log = RunLogger(tmp_path, METRICS, echo=lambda s: None, tensorboard=True)
    log.log_eval(_eval_row(0))
    log.log_train(_train_row(100, None))
    checkpoint = log.offsets()  # what a checkpoint stores
    log.log_train(_train_row(200, 0.25))  # written after the checkpoint, then the process dies
    log.log_eval(_eval_row(200))
    log.close()
    assert read_scalars(tmp_path)["train/episode_reward"][-1][0] == 200
    resumed = RunLogger(tmp_path, METRICS, offsets=checkpoint, echo=lambda s: None, tensorboard=True)
    assert_mirrors_csv(tmp_path)  # truncated CSVs -> event files without the rows after the checkpoint
    assert [s for s, _ in read_scalars(tmp_path)["train/episode_reward"]] == [100]
    resumed.log_train(_train_row(200, 0.5))  # the resumed run writes the same frames again
    resumed.log_eval(_eval_row(200))
    resumed.close()
    assert_mirrors_csv(tmp_path)
    assert read_scalars(tmp_path)["train/critic_loss"] == [(200, 0.5)]  # empty cells are no points
    assert len(list((tmp_path / TB_DIR).iterdir())) == 1


def _offline_rows(tmp_path: Path, **mirror: Any) -> None:
    """Two eval rows (updates 0 and 1000) and one train row of an offline run, through its logger's mirrors."""
    from repro.train.offline_loop import OfflineLogger

    log = OfflineLogger(tmp_path, ["actor_loss"], echo=lambda s: None, **mirror)
    for update in (0, 1000):
        log.log_eval({"update": update, "episode_reward": update / 10, "episode_reward_std": 0.0,
                      "episode_length": 100.0, "success": None, "eval_episodes": 1, "normalized_score": None,
                      "reference_return": None, "score_reference": "none", "total_time": 1.0})
    log.log_train({"update": 1000, "updates_per_s": 5.0, "total_time": 1.0, "actor_loss": -0.5})
    log.close()


def test_offline_mirror_steps_are_updates(tmp_path: Path):
    _offline_rows(tmp_path, tensorboard=True)
    tb = read_scalars(tmp_path)
    assert tb["eval/episode_reward"] == [(0, 0.0), (1000, 100.0)] and tb["train/actor_loss"] == [(1000, -0.5)]
    assert "eval/score_reference" not in tb and "eval/normalized_score" not in tb  # text and empty cells


def test_mirror_is_off_by_default(tmp_path: Path):
    log = RunLogger(tmp_path, METRICS, echo=lambda s: None)
    log.log_eval(_eval_row(0))
    log.close()
    assert not (tmp_path / TB_DIR).exists()


# ----------------------------------------------------------------------------- W&B mirror
WB = WandbRun(mode="offline", project="taco-test", entity=None, group="e/taco/base/cheetah_run",
              name="e/taco/base/cheetah_run/seed_1", tags=("sweep=s", "seed=1"), config={"seed": 1, "agent": {"K": 3}})


def test_wandb_mirror_equals_csv_and_a_resume_rebuilds_it_without_repeated_steps(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "online")  # runtime.wandb_mode decides, not the environment
    log = RunLogger(tmp_path, METRICS, echo=lambda s: None, wandb=WB)
    run_id = (tmp_path / WANDB_DIR / RUN_ID).read_text()
    log.log_eval(_eval_row(0))
    log.log_train(_train_row(100, None))
    checkpoint = log.offsets()
    log.log_train(_train_row(200, 0.25))  # written after the checkpoint, then the process dies
    log.log_eval(_eval_row(200))
    log.close()
    resumed = RunLogger(tmp_path, METRICS, offsets=checkpoint, echo=lambda s: None, wandb=WB)
    resumed.log_train(_train_row(200, 0.5))  # the resumed run writes the same frames again
    resumed.log_eval(_eval_row(200))
    resumed.log_train(_train_row(300, 0.75))
    resumed.close()
    record, history = assert_wandb_mirrors_csv(tmp_path)
    assert [row["_step"] for row in history] == [0, 100, 200, 300]
    assert history[2]["train/critic_loss"] == 0.5 and "eval/episode_reward" in history[2]  # one row per frame
    assert "train/critic_loss" not in history[1]  # an empty cell is no point
    assert len(offline_folders(tmp_path)) == 1 and (tmp_path / WANDB_DIR / RUN_ID).read_text() == run_id
    assert record["id"] == run_id.strip() and record["project"] == "taco-test"
    assert (record["group"], record["name"], record["tags"]) == (WB.group, WB.name, list(WB.tags))
    assert record["config"]["agent"] == {"K": 3} and record["config"]["seed"] == 1


def test_wandb_mirror_logs_only_the_steps_the_w_and_b_run_lacks(tmp_path: Path):
    """What an online resume does at the server's next step (``first_step``, from W&B's ``starting_step``): the
    truncated CSVs' rows from it on are logged, and live rows before it are not logged again."""
    from repro.runs.wblog import WandbMirror

    log = RunLogger(tmp_path, METRICS, echo=lambda s: None)
    for frame in (100, 200):
        log.log_train(_train_row(frame, 0.5))
    log.close()
    mirror = WandbMirror(tmp_path, WB, echo=lambda s: None)
    mirror.first_step = 150  # the server has steps 0..149 from the killed process
    assert mirror.rebuild({"train": tmp_path / "train.csv"}) == 1
    mirror.add_row("eval", _eval_row(100))  # already on the server
    mirror.add_row("eval", _eval_row(200))
    mirror.close()
    assert [(row["_step"], "eval/episode_reward" in row) for row in read_history(tmp_path)] == [(200, True)]


def test_offline_wandb_mirror_steps_are_updates(tmp_path: Path):
    _offline_rows(tmp_path, wandb=WB)
    history = read_history(tmp_path)
    assert [(row["_step"], row["update"], row["eval/episode_reward"]) for row in history] == [(0, 0, 0),
                                                                                                (1000, 1000, 100)]
    assert history[1]["train/actor_loss"] == -0.5
    assert not any("eval/score_reference" in row or "eval/normalized_score" in row for row in history)


def test_signals_deferred_holds_a_requeue_handler_until_the_block_ends():
    """submitit's USR2 handler raises SystemExit wherever the main thread is; inside a W&B call it left the run
    half-written (the SLURM requeue test). Deferred, the handler runs once, right after the block."""
    import os
    import signal

    from repro.runs.wblog import signals_deferred

    seen: list[int] = []

    def handler(signum, frame):
        seen.append(signum)

    old = signal.signal(signal.SIGUSR2, handler)
    try:
        with signals_deferred():
            os.kill(os.getpid(), signal.SIGUSR2)
            for _ in range(3):
                time.sleep(0.01)  # a Python handler would have run by now
            assert seen == []
        assert seen == [signal.SIGUSR2] and signal.getsignal(signal.SIGUSR2) is handler
        os.kill(os.getpid(), signal.SIGUSR2)  # outside the block: at once, as before
        time.sleep(0.01)
        assert seen == [signal.SIGUSR2, signal.SIGUSR2]
    finally:
        signal.signal(signal.SIGUSR2, old)


def test_a_failing_wandb_finish_does_not_replace_the_loops_exception(tmp_path: Path, capsys):
    """SLURM's requeue stops wandb's service at once, so the finish of a requeued run fails: while the loop is
    failing (``failing=True``) that is one line on stderr, not an exception in place of submitit's SystemExit;
    a finish that fails after a loop that ended well still raises."""
    log = RunLogger(tmp_path, METRICS, echo=lambda s: None, wandb=WB)
    log.log_eval(_eval_row(0))
    run = log.wb._run
    finish = run.finish

    def lost(*args, **kwargs):
        raise ConnectionResetError("Connection lost")

    run.finish = lost
    try:
        with pytest.raises(ConnectionResetError):
            log.wb.close()
        log.close(failing=True)
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "not finished (ConnectionResetError: Connection lost)" in err[0], err
    finally:
        run.finish = finish
        finish()


def test_wandb_without_the_package_is_one_line_before_anything_is_written(tmp_path: Path, monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)  # `import wandb` fails as it does when it is not installed
    code, _, err = cli("train", "profile=tiny", "runtime.wandb=true", f"runtime.results_root={tmp_path}")
    assert code == 2 and len(err.strip().splitlines()) == 1 and "pip install '.[wandb]'" in err, err
    assert list(tmp_path.iterdir()) == []
    sweep = write_sweep(tmp_path, "wb", ["cheetah_run"], {"a": []}, 1)
    code, out, err = cli("sweep", str(sweep), "--set", "runtime.wandb=true", "--results", str(tmp_path / "r"))
    assert code == 2 and len(err.strip().splitlines()) == 1 and "pip install '.[wandb]'" in err, out + err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("mode", ["", "bogus"])
def test_an_invalid_wandb_mode_in_the_environment_is_one_line_before_anything_is_written(tmp_path: Path, monkeypatch,
                                                                                         mode: str):
    monkeypatch.setenv("WANDB_MODE", mode)  # wandb itself would fail with a traceback at the run's first write
    code, _, err = cli("train", "profile=tiny", "runtime.wandb=true", f"runtime.results_root={tmp_path}")
    assert code == 2 and len(err.strip().splitlines()) == 1 and f"WANDB_MODE={mode!r}" in err, err
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- videos
def test_video_decodes_to_the_frames_written(tmp_path: Path):
    frames = np.random.default_rng(0).integers(0, 255, size=(23, 32, 48, 3), dtype=np.uint8)
    path = write_mp4(tmp_path / "v.mp4", frames)
    assert count_frames(path) == 23
    assert [p.name for p in tmp_path.iterdir()] == ["v.mp4"]  # no temporary file left
    with pytest.raises(ValueError, match="even"):
        write_mp4(tmp_path / "odd.mp4", frames[:, :31])


def test_video_options_are_checked():
    code, _, err = cli("train", "--dry-run", "train.video_every=sometimes")
    assert code == 2 and "train.video_every" in err
    code, _, err = cli("train", "--dry-run", "train.video_size=255")
    assert code == 2 and "train.video_size" in err


@pytest.mark.slow
@pytest.mark.parametrize("task", ["cheetah_run", "hammer"])
def test_render_view_leaves_observations_unchanged(task: str):
    from repro.envs import make_env

    def rollout(view: bool) -> tuple[np.ndarray, list[np.ndarray]]:
        env = make_env(task, seed=1, action_repeat=2, frame_stack=3, image_size=84)
        try:
            obs, views = [env.reset(seed=5).observation], []
            actions = np.random.default_rng(0).uniform(-1, 1, (4, env.spec.action_dim)).astype(np.float32)
            for a in actions:
                if view:
                    views.append(env.render_view(64))
                obs.append(env.step(a).observation)
            return np.stack(obs), views
        finally:
            env.close()

    plain, _ = rollout(False)
    viewed, views = rollout(True)
    np.testing.assert_array_equal(plain, viewed)
    assert views[0].shape == (64, 64, 3) and views[0].dtype == np.uint8 and views[0].std() > 0


# conftest's session run `tiny_taco_watched` (TensorBoard, W&B, videos of every evaluation); that its logs equal the
# plain run's, `video_every=last` and the SIGKILL-and-resume of the event files and of the W&B run are checked by
# tests/test_train_e2e.py.
@pytest.mark.slow
@pytest.mark.xdist_group(TINY_TACO)
def test_tiny_run_writes_videos_and_event_files(tiny_taco_watched: Path):
    import imageio_ffmpeg

    watched = tiny_taco_watched
    assert_mirrors_csv(watched)
    health = read_scalars(watched)  # the actor's health metrics (issue 49) are mirrored like every column
    assert {"train/actor_saturated", "train/actor_pretanh"} <= set(health)
    ev = pd.read_csv(watched / EVAL)
    videos = sorted((watched / "videos").iterdir())
    assert [v.name for v in videos] == [f"frame_{f:09d}.mp4" for f in ev["frame"]]
    steps = (ev["episode_length"] // 2).astype(int)  # frames -> agent steps (action repeat 2)
    for video, n in zip(videos, steps):
        assert count_frames(video) == n + 1  # the reset frame and one per step
        meta = next(imageio_ffmpeg.read_frames(str(video)))
        assert tuple(meta["size"]) == (64, 64)


@pytest.mark.slow
@pytest.mark.xdist_group(TINY_TACO)
def test_tiny_run_w_and_b_history_equals_its_csvs_and_repro_wandb_sync_names_it(tiny_taco_watched: Path):
    import json

    watched = tiny_taco_watched
    record, history = assert_wandb_mirrors_csv(watched)  # every eval.csv and train.csv point once, at its frame
    assert any("train/actor_saturated" in row for row in history)  # the actor's health (issue 49)
    ev = pd.read_csv(watched / EVAL)
    evals = [row for row in history if "eval/episode_reward" in row]
    assert [row["frame"] for row in evals] == list(ev["frame"]) == [0, 200, 400]
    np.testing.assert_allclose([row["eval/episode_reward"] for row in evals], ev["episode_reward"], rtol=1e-6)
    assert record["name"] == REL.as_posix() and record["group"] == REL.parent.as_posix()
    assert record["tags"] == ["seed=3"] and record["project"] == "taco-repro"  # no sweep: `repro train`
    config = record["config"]
    assert config["seed"] == 3 and config["agent"]["name"] == "taco" and config["runtime"]["wandb"] is True
    assert config["resolved"] == {k: v for k, v in json.loads((watched / RESOLVED).read_text()).items()
                                  if k != "format"}
    root = watched.parents[len(REL.parts) - 1]
    code, out, err = cli("wandb", "sync", str(root))
    (folder,) = offline_folders(watched)
    assert code == 0 and out.split()[1:] == ["sync", str(folder)] and "1 offline W&B run(s)" in err, out + err


def test_wandb_sync_bad_input_is_one_line(tmp_path: Path):
    for target, message in ((tmp_path / "missing", "does not exist"), (tmp_path, "runtime.wandb=true")):
        code, _, err = cli("wandb", "sync", str(target))
        assert code == 2 and len(err.strip().splitlines()) == 1 and message in err, err
    run = tmp_path / "e" / "seed_1"
    (run / WANDB_DIR / "offline-run-1-x").mkdir(parents=True)
    (run / WANDB_DIR / RUN_ID).write_text("x" * 16)
    code, _, err = cli("wandb", "sync", str(tmp_path), "--run")  # not done: nothing sent, nothing started
    assert code == 2 and "1 not done (--unfinished)" in err and len(err.strip().splitlines()) == 1, err
    code, out, _ = cli("wandb", "sync", str(tmp_path), "--unfinished")
    assert code == 0 and out.strip().endswith(str(run / WANDB_DIR / "offline-run-1-x"))


# ----------------------------------------------------------------------------- repro tensorboard
def test_tensorboard_command_names_the_root(tmp_path: Path):
    code, out, _ = cli("tensorboard", str(tmp_path))
    assert code == 0 and out.strip().endswith(f"--logdir {tmp_path}") and "tensorboard" in out
    code, _, err = cli("tensorboard", str(tmp_path / "missing"))
    assert code == 2 and len(err.strip().splitlines()) == 1
    code, _, err = cli("tensorboard", str(tmp_path), "--run")
    assert code == 2 and "runtime.tensorboard=true" in err  # nothing to show: refused, TensorBoard not started


# ----------------------------------------------------------------------------- repro plot
@pytest.fixture(scope="module")
def plot_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("plot")
    for task in ("cheetah_run", "hopper_hop"):
        for agent, final in (("taco", 600.0), ("drqv2", 300.0)):
            for seed, offset in enumerate((-30.0, 0.0, 30.0)):
                write_run(root, experiment="main", agent=agent, task=task, seed=seed, final=final + offset)
    return root


def test_plot_writes_non_blank_png_and_pdf(plot_root: Path, tmp_path: Path):
    import matplotlib.image

    code, out, _ = cli("plot", str(plot_root), "--out", str(tmp_path / "curves.png"), "--reps", "200")
    assert code == 0, out
    assert "12 run(s), 2 task(s)" in out
    img = matplotlib.image.imread(tmp_path / "curves.png")
    assert img.ndim == 3 and img.shape[0] > 200 and img[..., :3].std() > 0.05
    pdf = (tmp_path / "curves.pdf").read_bytes()
    assert pdf.startswith(b"%PDF") and len(pdf) > 5000


def test_plot_curves_are_the_seed_means_of_the_runs(plot_root: Path):
    from analysis.quick import by_columns, load_runs, tidy_curves

    runs, evals, _ = load_runs([plot_root, plot_root / "main/taco/base/cheetah_run/seed_0"])  # a run twice
    curves = tidy_curves(runs, evals, "episode_reward", by_columns("agent,variant"))
    last = curves[curves["frame"] == FRAMES].groupby(["task", "label"])["value"].agg(["mean", "count"])
    # labelled by the methods' registered labels, not the agent files' names
    assert last.loc[("cheetah_run", "TACO / base")].tolist() == [600.0, 3]
    assert last.loc[("hopper_hop", "DrQ-v2 / base")].tolist() == [300.0, 3]
    train = tidy_curves(runs, evals, "critic_loss", by_columns("method"))
    assert set(train["value"]) == {0.5} and set(train["frame"]) == {2000, 3000}  # empty first-episode cells


@pytest.mark.parametrize("args, message", [
    (["--metric", "no_such_metric"], "unknown metric"),
    (["--by", "agent,colour"], "unknown --by column 'colour'"),
    (["--metric", "frame"], "x axis"),
])
def test_plot_bad_input_is_one_line(plot_root: Path, tmp_path: Path, args: list[str], message: str):
    code, _, err = cli("plot", str(plot_root), "--out", str(tmp_path / "x.png"), *args)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.png").exists()


def test_plot_without_runs_is_one_line(tmp_path: Path):
    for target in (tmp_path, tmp_path / "missing"):
        code, _, err = cli("plot", str(target), "--out", str(tmp_path / "x.png"))
        assert code == 2 and len(err.strip().splitlines()) == 1, err


# ----------------------------------------------------------------------------- repro status --watch
def _launched(root: Path, done: bool) -> Path:
    run = write_run(root, experiment="w", agent="taco", task="cheetah_run", seed=1, final=1.0, done=done)
    record_launch(state_dir(root, "w"), "w", root / "w.yaml", "local",
                  {"w/taco/base/cheetah_run/s1": {"run_dir": str(run), "overrides": []}})
    return run


def test_status_watch_returns_at_once_when_every_run_is_done(tmp_path: Path):
    _launched(tmp_path, done=True)
    t0 = time.time()
    code, out, _ = cli("status", "w", "--results-root", str(tmp_path), "--watch", "--every", "30")
    assert code == 0 and "1 done" in out and out.count("refreshing") == 1
    assert time.time() - t0 < 20


def test_status_watch_refreshes_until_the_run_finishes(tmp_path: Path):
    run = _launched(tmp_path, done=False)
    (run / DONE).unlink(missing_ok=True)
    timer = threading.Timer(1.5, lambda: rundir.write_done(run, {"frame": FRAMES}))
    timer.start()
    try:
        code, out, _ = cli("status", "w", "--results-root", str(tmp_path), "--watch", "--every", "0.2")
    finally:
        timer.cancel()
    assert code == 0
    assert out.count("refreshing every 0.2s") >= 3  # pending, pending, ..., done
    assert "1 pending" in out and out.rstrip().count("1 done") == 1


def test_status_watch_bad_interval_is_one_line(tmp_path: Path):
    _launched(tmp_path, done=True)
    code, _, err = cli("status", "w", "--results-root", str(tmp_path), "--watch", "--every", "0")
    assert code == 2 and len(err.strip().splitlines()) == 1


def test_video_switches_are_not_run_identity(tmp_path):
    """Resuming a run with videos switched on is the same run; any trained-on change still is not."""
    from repro.config.compose import compose
    from repro.runs import rundir

    base = ["profile=tiny", "task=cheetah_run", f"runtime.results_root={tmp_path}"]
    rundir.write_config(tmp_path, compose(base))
    assert rundir.config_diff(tmp_path, compose([*base, "train.save_video=true", "train.video_every=last",
                                                 "train.video_size=128"])) == []
    assert rundir.config_diff(tmp_path, compose([*base, "train.eval_episodes=2"])) != []
