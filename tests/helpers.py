"""Helpers shared by several test modules (imported as ``from helpers import ...``; tests/ is on the path
through pyproject's ``[tool.pytest.ini_options] pythonpath``). Run builders for the analysis and offline tests
live beside it in analysis_fixtures.py, offline_fixtures.py and seam_reference.py, imported the same way."""

from __future__ import annotations

import contextlib
import csv
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import torch
import typer
import yaml
from torch.utils._python_dispatch import TorchDispatchMode

import repro
from repro.data.record import load_snapshot
from repro.launch.cli import register as register_launch
from repro.runs.console import Commands
from repro.runs.logger import WALLCLOCK_COLUMNS
from repro.runs.runformat import EVAL, TRAIN
from repro.runs.tblog import read_scalars
from repro.runs.wblog import read_offline_run

# The tiny online run several modules share (conftest's session fixtures train it once).
TINY = ["profile=tiny", "task=cheetah_run", "seed=3", "runtime.threads=1"]
REL = Path("default/taco/base/cheetah_run/seed_3")  # its run directory under a results root
# Its recorded, watched twin: recording, TensorBoard, W&B and videos are runtime keys (not identity, not logs).
WATCH = ["runtime.tensorboard=true", "runtime.wandb=true", "train.save_video=true", "train.video_size=64"]
RECORD = ["runtime.record=true"]
# pytest-xdist groups: the tests that use one session run (conftest) run on one worker, so it is made once.
TINY_TACO = "tiny_taco"
MAIN_JOB = "main_job"
TINY_ALIX = "tiny_alix"  # the tiny A-LIX run through a sweep (conftest), read by test_alix_train and test_alix_dataset
# Its overrides: the tiny profile's 4 episodes of 100 frames (evaluations at 0, 200, 400); updates from frame 40 on,
# so the first checkpoint (after episode 1) holds updated networks, a moved strength and the encoder optimizer's two
# groups; recorded (snapshots and episodes, no frames) so that a dataset can be made from it.
TINY_ALIX_SETS = ["profile=tiny", "runtime.threads=1", "train.seed_frames=40", "train.explore_steps=10",
                  "train.save_frames=false", "runtime.record=true"]
TINY_ALIX_REL = Path("alix_tiny/alix/base/cheetah_run/seed_1")  # its run directory under a results root


def deterministic(csv: Path) -> pd.DataFrame:
    """A run's CSV without its wall-clock columns (the part two runs of one seed must share)."""
    df = pd.read_csv(csv)
    return df.drop(columns=[c for c in WALLCLOCK_COLUMNS if c in df.columns])


def rows(csv: Path) -> int:
    """Data rows of a CSV file (0 when it does not exist yet)."""
    return max(len(csv.read_text().splitlines()) - 1, 0) if csv.exists() else 0


def train_cmd(root: Path, *extra: str) -> list[str]:
    """`repro train` of the tiny run in its own process, under results root ``root``."""
    return [sys.executable, "-m", "repro", "train", *TINY, *extra, f"runtime.results_root={root}", "--no-progress"]


def kill_when(cmd: list[str], ready: Callable[[], bool], timeout: float = 300, poll: float = 0.05) -> None:
    """Start ``cmd`` and SIGKILL it as soon as ``ready()`` holds (checked every ``poll`` s); fails if it finished
    first."""
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ.copy())
    t0 = time.time()
    while not ready() and proc.poll() is None and time.time() - t0 < timeout:
        time.sleep(poll)
    assert proc.poll() is None, "the run finished before it could be killed"
    proc.send_signal(signal.SIGKILL)
    proc.wait()


def assert_same_recording(a: Path, b: Path) -> None:
    names = lambda p, sub: sorted(f.name for f in (p / "record" / sub).iterdir())  # noqa: E731
    assert names(a, "episodes") == names(b, "episodes") and names(a, "snapshots") == names(b, "snapshots")
    for name in names(a, "episodes"):
        with np.load(a / "record" / "episodes" / name) as x, np.load(b / "record" / "episodes" / name) as y:
            assert sorted(x.files) == sorted(y.files)
            for key in x.files:
                np.testing.assert_array_equal(x[key], y[key], err_msg=f"{name}:{key}")
    for name in names(a, "snapshots"):
        x, y = load_snapshot(a / "record" / "snapshots" / name), load_snapshot(b / "record" / "snapshots" / name)
        assert {k: v for k, v in x.items() if k not in ("encoder", "actor")} == \
               {k: v for k, v in y.items() if k not in ("encoder", "actor")}
        for part in ("encoder", "actor"):
            assert x[part].keys() == y[part].keys()
            for k in x[part]:
                assert torch.equal(x[part][k], y[part][k]), f"{name}:{part}.{k}"


def csv_series(run: Path) -> dict[str, list[tuple[int, float]]]:
    """What the event files must hold: every non-empty numeric CSV cell as ``{file}/{column}`` at its frame."""
    out: dict[str, list[tuple[int, float]]] = {}
    for prefix, name in (("eval", EVAL), ("train", TRAIN)):
        with open(run / name, newline="") as f:
            for row in csv.DictReader(f):
                for key, value in row.items():
                    if key != "frame" and value != "":
                        out.setdefault(f"{prefix}/{key}", []).append((int(row["frame"]), float(value)))
    return out


def _assert_same_series(got: dict[str, list[tuple[int, float]]], expected: dict[str, list[tuple[int, float]]]) -> None:
    assert set(got) == set(expected)
    for tag, points in expected.items():
        steps = [s for s, _ in got[tag]]
        assert len(steps) == len(set(steps)), f"{tag}: a step twice {steps}"
        assert steps == [s for s, _ in points], tag
        np.testing.assert_allclose([v for _, v in got[tag]], [v for _, v in points], rtol=1e-6, err_msg=tag)


def assert_mirrors_csv(run: Path) -> None:
    """The run's TensorBoard event files (read by TensorBoard) hold every CSV point once."""
    _assert_same_series(read_scalars(run), csv_series(run))


def assert_wandb_mirrors_csv(run: Path) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The run's offline W&B history (read by wandb's own reader) holds every CSV point once: one history row per
    frame of either CSV, at W&B step = frame; returns the W&B run record and the history."""
    record, history = read_offline_run(run)
    steps = [row["_step"] for row in history]
    assert steps == sorted(set(steps)), f"a W&B step twice or out of order: {steps}"
    assert all(row["frame"] == row["_step"] for row in history)
    expected = csv_series(run)
    assert set(steps) == {s for points in expected.values() for s, _ in points}
    got: dict[str, list[tuple[int, float]]] = {}
    for row in history:
        for key, value in row.items():
            if key.startswith(("eval/", "train/")):  # W&B's own _step, _runtime, _timestamp and the frame aside
                got.setdefault(key, []).append((int(row["frame"]), float(value)))
    _assert_same_series(got, expected)
    return record, history


# Sweeps of tiny runs (the local and SLURM launcher tests).
SWEEP_TINY = ["profile=tiny", "env.max_episode_frames=50", "train.seed_frames=50", "train.update_every_steps=4",
              "train.eval_every_frames=100"]  # 50-frame episodes, updates from frame 50, evals every 100 frames


def write_sweep(tmp: Path, name: str, tasks: list[str], variants: dict[str, list[str]], seeds: int,
                frames: int = 100) -> Path:
    """A sweep file of tiny TACO runs (SWEEP_TINY) in ``tmp``."""
    data = {"name": name, "description": "test sweep", "artifacts": [], "experiment": name, "tasks": tasks,
            "agents": ["taco"], "seeds": seeds, "frames": None, "eval": {"every_frames": None, "episodes": None},
            "common": [*SWEEP_TINY, f"train.frames={frames}"], "variants": variants}
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


# Update-level batches (the objective and speed-up tests).
OBS = (9, 84, 84)


def offline_learner(agent: str, **over: object) -> Any:
    """An offline learner of agent file ``agent`` for cheetah_run (|A| = 6) under profile=tiny, seeded; ``over``:
    dotted config overrides."""
    from repro.config.compose import compose, typed
    from repro.learners import build_learner

    overrides = [f"agent={agent}", "task=cheetah_run", "profile=tiny", "offline.dataset=medium"]
    overrides += [f"{k}={v}" for k, v in over.items()]
    torch.manual_seed(0)
    return build_learner(typed(compose(overrides)).agent, OBS, 6, "cpu")


def offline_batch(B: int = 8, K: int = 3, A: int = 6) -> dict[str, torch.Tensor]:
    """A fixed-seed replay batch for the offline learners (random frames, actions in [-1, 1], K-step sequences)."""
    g = torch.Generator().manual_seed(1)

    def obs() -> torch.Tensor:
        return torch.randint(0, 256, (B, *OBS), generator=g, dtype=torch.uint8)

    return {"obs": obs(), "next_obs": obs(), "future_obs": obs(),
            "action": torch.rand(B, A, generator=g) * 2 - 1, "action_seq": torch.rand(B, K, A, generator=g) * 2 - 1,
            "reward": torch.rand(B, 1, generator=g), "discount": torch.full((B, 1), 0.99 ** 3),
            "reward_ksum": torch.rand(B, 1, generator=g)}


def make_batch(B: int = 6, K: int = 3, A: int = 4, seed: int = 0) -> dict[str, torch.Tensor]:
    """A replay batch of random frames and actions, as ReplayBuffer.sample returns it."""
    g = torch.Generator().manual_seed(seed)
    u8 = lambda: torch.randint(0, 256, (B, *OBS), dtype=torch.uint8, generator=g)  # noqa: E731
    return {"obs": u8(), "next_obs": u8(), "future_obs": u8(), "action": torch.rand(B, A, generator=g) * 2 - 1,
            "action_seq": torch.rand(B, K, A, generator=g) * 2 - 1, "reward": torch.rand(B, 1, generator=g),
            "discount": torch.full((B, 1), 0.99 ** 3), "reward_ksum": torch.rand(B, 1, generator=g) * 3}


def launch_app() -> typer.Typer:
    """A Typer app with the launch commands only (``sweep``, ``sweeps``, ``status``), as ``repro`` registers them."""
    app = typer.Typer(cls=Commands, add_completion=False, pretty_exceptions_enable=False)
    register_launch(app)

    @app.callback()
    def _root() -> None:  # keep sub-commands even when only one is registered
        pass

    return app


def bench_app() -> typer.Typer:
    """A Typer app with ``repro bench`` only, as ``repro`` registers it."""
    from repro.bench.cli import register

    app = typer.Typer(cls=Commands)
    register(app)

    @app.callback()
    def main() -> None:  # keep `bench` a named sub-command
        pass

    return app


# ------------------------------------------------------------------ host syncs of an update (issue 25)
REPRO = str(Path(repro.__file__).parent)
SYNCS = ("item", "tolist", "cpu", "numpy", "__float__", "__int__", "__bool__")  # each waits for the device
TORCH = Path(torch.__file__).parent
# torch's dispatch plumbing between a caller and the operator (not a caller itself)
PLUMBING = tuple(str(TORCH / p) for p in ("_dynamo", "_compile.py", "_ops.py", "_tensor.py", "overrides.py",
                                         "utils/_python_dispatch.py"))
# operators that read a value on the host, or size their result by the data (the host waits for the count)
DATA_SIZED = {"_local_scalar_dense", "nonzero", "masked_select", "unique", "_unique", "_unique2", "unique_dim",
              "unique_consecutive", "is_nonzero", "equal"}


class DataSizedOps(TorchDispatchMode):
    """Records the host-syncing operators (``DATA_SIZED``, indexing with a boolean mask, ``repeat_interleave``
    by a tensor of counts) that code under ``roots`` calls: an operator that torch's own code calls (an optimizer's
    CPU step count, autograd's backward) is torch's."""

    def __init__(self, roots: tuple[str, ...], calls: list[str]) -> None:
        super().__init__()
        self.roots, self.calls = roots, calls

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        name = func._schema.name.split("::")[-1]
        bool_index = (name in ("index", "index_put", "index_put_") and len(args) > 1
                      and any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in args[1]))
        by_counts = name == "repeat_interleave" and func._overloadname == "Tensor"
        if name in DATA_SIZED or bool_index or by_counts:
            frame = sys._getframe(1)
            while frame is not None and (frame.f_code.co_filename == __file__
                                         or frame.f_code.co_filename.startswith(PLUMBING)):
                frame = frame.f_back
            if frame is not None and frame.f_code.co_filename.startswith(self.roots):
                self.calls.append(f"{func} at {frame.f_code.co_filename}:{frame.f_lineno}")
        return func(*args, **(kwargs or {}))


def watch_syncs(mp: pytest.MonkeyPatch, events: list[str], roots: tuple[str, ...] = (REPRO,)) -> None:
    """Through ``mp``: append ``"sync NAME at FILE:LINE"`` to ``events`` at every call from code under ``roots``
    (not torch's own internals: an optimizer's CPU step count) of a Tensor method of ``SYNCS``, and at every
    ``torch.cuda.synchronize``; the calls still run (the CPU never waits)."""
    for name in SYNCS:
        real = getattr(torch.Tensor, name)

        def watched(self: torch.Tensor, *args: Any, _real: Any = real, _name: str = name, **kwargs: Any) -> Any:
            caller = sys._getframe(1)
            if caller.f_code.co_filename.startswith(roots):
                events.append(f"sync {_name} at {caller.f_code.co_filename}:{caller.f_lineno}")
            return _real(self, *args, **kwargs)

        mp.setattr(torch.Tensor, name, watched)
    mp.setattr(torch.cuda, "synchronize", lambda *a, **k: events.append("sync torch.cuda.synchronize"))


@contextlib.contextmanager
def host_syncs(monkeypatch: Any, roots: tuple[str, ...] = (REPRO,)) -> Iterator[list[str]]:
    """The host syncs that code under ``roots`` makes inside the block: the Tensor methods of ``SYNCS``
    (:func:`watch_syncs`) and the operators of :class:`DataSizedOps`, each as 'what at file:line'
    (tests/test_learner_contract.py, and tests/test_plugins.py for its plugin's code too)."""
    calls: list[str] = []
    watch_syncs(monkeypatch, calls, roots)
    try:
        with DataSizedOps(roots, calls):
            yield calls
    finally:
        monkeypatch.undo()


def watch_loop(mp: pytest.MonkeyPatch, events: list[str]) -> None:
    """Through ``mp``: every online loop appends ``"update returned"`` to ``events`` when its ``agent.update``
    returns and ``"env.step"`` when it calls ``env.step`` (beside :func:`watch_syncs`' events)."""
    from repro.train.online_loop import OnlineLoop

    init = OnlineLoop.__init__

    def watched_init(loop: OnlineLoop, *args: Any, **kwargs: Any) -> None:
        init(loop, *args, **kwargs)
        update, env_step = loop.agent.update, loop.env.step

        def update_then_mark(*a: Any, **k: Any) -> Any:
            out = update(*a, **k)
            events.append("update returned")
            return out

        def mark_then_step(*a: Any, **k: Any) -> Any:
            events.append("env.step")
            return env_step(*a, **k)

        loop.agent.update, loop.env.step = update_then_mark, mark_then_step  # type: ignore[method-assign]

    mp.setattr(OnlineLoop, "__init__", watched_init)
