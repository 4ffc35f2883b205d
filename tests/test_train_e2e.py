"""End-to-end runs with real rendering and real updates: run directory, determinism, SIGKILL, Ctrl-C and resume.

The tiny run is trained once per test session (conftest: ``tiny_taco`` plain, ``tiny_taco_watched`` recorded
with TensorBoard and videos); the kill-and-resume run here checks the CSVs, the recording, the event files and
the videos of a resumed run at once."""

import json
import platform
import re
import signal
import socket
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
import yaml

from helpers import (
    REL,
    TINY,
    TINY_TACO,
    assert_mirrors_csv,
    assert_same_recording,
    assert_wandb_mirrors_csv,
    deterministic,
    kill_when,
    rows,
    train_cmd,
)
from repro.runs import rundir
from repro.runs.logger import WALLCLOCK_COLUMNS
from repro.runs.runformat import CHECKPOINT, DONE, EVAL, TRAIN
from repro.runs.tblog import TB_DIR, read_scalars
from repro.runs.wblog import RUN_ID, WANDB_DIR, offline_folders
from repro.train import api, devices

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group(TINY_TACO)]


def test_run_directory_contract(tiny_taco: Path):
    reference = tiny_taco
    for name in ("config.yaml", "meta.json", "eval.csv", "train.csv", "checkpoint.pt", "DONE"):
        assert (reference / name).is_file(), name
    cfg = yaml.safe_load((reference / "config.yaml").read_text())
    assert cfg["agent"]["name"] == "taco" and cfg["task"]["name"] == "cheetah_run" and cfg["seed"] == 3
    meta = json.loads((reference / "meta.json").read_text())
    for key in ("git_sha", "git_dirty", "versions", "host", "device", "command"):
        assert key in meta
    assert meta["versions"]["torch"] == metadata.version("torch") == torch.__version__
    assert meta["versions"]["python"] == platform.python_version()
    assert meta["host"] == socket.gethostname() and meta["resumes"] == []
    assert meta["device"] == rundir.device_name(devices.resolve_device("auto"))
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=Path(api.__file__).parent, capture_output=True,
                          text=True, check=False)
    if head.returncode == 0:  # a git checkout: the run names the commit it was trained from
        assert meta["git_sha"] == head.stdout.strip() and isinstance(meta["git_dirty"], bool)
    ev = pd.read_csv(reference / "eval.csv")
    assert list(ev["frame"]) == [0, 200, 400]
    assert list(ev["step"]) == [0, 100, 200]
    assert ev["success"].isna().all()  # DMC has no success signal
    tr = pd.read_csv(reference / "train.csv")
    assert list(tr["episode"]) == [1, 2, 3, 4] and list(tr["frame"]) == [100, 200, 300, 400]
    assert tr["taco_loss"].iloc[1:].notna().all() and tr["critic_loss"].iloc[1:].notna().all()
    ckpt = torch.load(reference / "checkpoint.pt", weights_only=True)
    assert "action_encoder" in ckpt["agent"] and "step.0.weight" in ckpt["agent"]["action_encoder"]
    frames = np.load(reference / "frames.npz")["frames"]
    assert frames.shape == (51, 84, 84, 3) and frames.dtype == np.uint8 and frames.std() > 0
    done = json.loads((reference / "DONE").read_text())
    assert done["frame"] == 400
    assert not (reference / rundir.WRITER_LOCK).exists()  # released and removed when the run ended


def test_same_seed_gives_identical_logs_and_recording_or_watching_changes_no_number(tiny_taco: Path,
                                                                                    tiny_taco_watched: Path):
    """The watched twin is a second run of the same seed and config, with recording, TensorBoard, W&B and videos
    on."""
    for name in (EVAL, TRAIN):
        pd.testing.assert_frame_equal(deterministic(tiny_taco_watched / name), deterministic(tiny_taco / name))
    assert set(WALLCLOCK_COLUMNS) <= set(pd.read_csv(tiny_taco_watched / TRAIN).columns)
    for extra in ("record", TB_DIR, WANDB_DIR, "videos"):
        assert (tiny_taco_watched / extra).is_dir() and not (tiny_taco / extra).exists(), extra


def _count(folder: Path, pattern: str) -> int:
    return len(list(folder.glob(pattern))) if folder.is_dir() else 0


def test_sigkill_and_resume_matches_uninterrupted_run(tiny_taco: Path, tiny_taco_watched: Path, tmp_path: Path):
    """Killed twice, stopped by Ctrl-C once, then resumed: the logs, the recording, the event files and the W&B
    history are those of the uninterrupted runs (the W&B run keeps its id), and `train.video_every=last` leaves the
    final evaluation's video only."""
    run = tmp_path / REL
    snaps, eps = run / "record" / "snapshots", run / "record" / "episodes"
    cmd = train_cmd(tmp_path, "runtime.record=true", "runtime.tensorboard=true", "runtime.wandb=true",
                    "train.save_video=true", "train.video_size=32", "train.video_every=last")
    # 1st kill: after the first evaluation row and its snapshot, before any checkpoint (everything recorded goes)
    kill_when(cmd, lambda: rows(run / EVAL) >= 1 and _count(snaps, "step_*.pt") >= 1
              and not (run / CHECKPOINT).exists())
    assert not (run / DONE).exists()
    early_checkpoint = (run / CHECKPOINT).exists()  # the kill is meant to come first; if not, one more resume
    # 2nd kill: after the evaluation at frame 200, which comes after the checkpoint of episode 2, in the middle of
    # episode 3: the resume truncates that row and writes it (its snapshot and event) again, so a mirror that only
    # appended would hold frame 200 twice. 1 s after the row appears, so that its event is written too.
    seen: list[float] = []

    def ready() -> bool:
        if not seen and rows(run / EVAL) >= 2 and rows(run / TRAIN) >= 2 and (run / CHECKPOINT).exists() \
                and _count(eps, "ep_*.npz") >= 2 and _count(snaps, "step_*.pt") >= 2:
            seen.append(time.time())
        return bool(seen) and time.time() - seen[0] > 1.0

    kill_when(cmd, ready)
    assert not (run / DONE).exists() and rows(run / TRAIN) == 2
    assert [s for s, _ in read_scalars(run)["eval/episode_reward"]] == [0, 200]  # the point the resume rewrites
    run_id = (run / WANDB_DIR / RUN_ID).read_text()
    # Ctrl-C (SIGINT) in the resumed run once it has written episode 3's row: one line naming the frame, exit 130,
    # the files closed and no writer lock left; the next start resumes from the checkpoint (issue 50.4). SIGINT is
    # set to its default in the child: a child of a non-interactive shell may inherit it ignored.
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    t0 = time.time()
    while rows(run / TRAIN) < 3 and proc.poll() is None and time.time() - t0 < 300:
        time.sleep(0.05)
    assert proc.poll() is None, "the run ended before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    said = re.fullmatch(r"interrupted at frame (\d+); run the same command to resume", err.strip())
    assert proc.returncode == 130 and said and 300 <= int(said[1]) < 400, (proc.returncode, err[-2000:])
    assert not (run / DONE).exists() and not (run / rundir.WRITER_LOCK).exists()
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    assert "resumed" in out.stdout and not (run / rundir.WRITER_LOCK).exists()
    for name in (EVAL, TRAIN):  # no row twice, none missing
        pd.testing.assert_frame_equal(deterministic(run / name), deterministic(tiny_taco / name))
    meta = json.loads((run / "meta.json").read_text())
    assert len(meta["resumes"]) == 2 + early_checkpoint  # a start without a checkpoint is no resume
    assert_same_recording(run, tiny_taco_watched)
    assert_mirrors_csv(run)
    assert [s for s, _ in read_scalars(run)["eval/episode_reward"]] == [0, 200, 400]
    record, history = assert_wandb_mirrors_csv(run)  # each frame once, though frame 200 was mirrored twice
    assert [row["_step"] for row in history] == [0, 100, 200, 300, 400]
    assert (run / WANDB_DIR / RUN_ID).read_text() == run_id and record["id"] == run_id.strip()
    assert len(offline_folders(run)) == 1
    assert [v.name for v in (run / "videos").iterdir()] == ["frame_000000400.mp4"]


def test_rerun_of_done_run_is_skipped_and_other_config_refused(tiny_taco: Path):
    reference = tiny_taco
    root = reference.parents[4]
    before = (reference / "eval.csv").read_bytes()
    out = subprocess.run([sys.executable, "-m", "repro", "train", *TINY, f"runtime.results_root={root}"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "already done" in out.stdout
    out = subprocess.run([sys.executable, "-m", "repro", "train", *TINY, "agent.K=1",
                          f"runtime.results_root={root}"], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and "another config" in lines[0] and "agent.K" in lines[0]
    assert (reference / "eval.csv").read_bytes() == before
