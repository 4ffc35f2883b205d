"""Recording of an online run for offline datasets (``runtime.record=true``).

``{run_dir}/record/episodes/ep_XXXXXXX.npz`` holds every training episode (the arrays of
``ReplayBuffer.end_episode()``, written once, never pruned) and ``{run_dir}/record/snapshots/step_XXXXXXXXX.pt``
one policy snapshot per evaluation: what acting needs (encoder and actor weights, the values that rebuild
them, the exploration stddev at that step) and the evaluation's mean return.

Resume: a run resumes from its last checkpoint and replays what came after it deterministically, so on
(re)start :meth:`Recorder.rewind` deletes every episode and snapshot the checkpoint does not cover; the
replay writes them again with the same content. Recording draws no random numbers and changes the order
of nothing in the training loop.
"""

from __future__ import annotations

import io
import os
import re
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import numpy as np
import torch

from repro.agent.protocol import OnlineLearner
from repro.config.schema import AgentConfig
from repro.data.episodes import EpisodeStore
from repro.runs.fsutil import atomic_output, atomic_write

RECORD, EPISODES, SNAPSHOTS = "record", "episodes", "snapshots"
SNAPSHOT_FORMAT = 1
_SNAPSHOT = re.compile(r"^step_(\d{9})\.pt$")


@dataclass(frozen=True)
class PolicySpec:
    """The values that rebuild the acting networks (Encoder(obs_shape), Actor(repr_dim, action_dim, ...))."""

    obs_shape: tuple[int, int, int]
    action_dim: int
    feature_dim: int
    hidden_dim: int

    def as_dict(self) -> dict[str, Any]:
        return {"obs_shape": list(self.obs_shape), "action_dim": self.action_dim,
                "feature_dim": self.feature_dim, "hidden_dim": self.hidden_dim}


def record_dir(run_dir: str | Path) -> Path:
    return Path(run_dir) / RECORD


def snapshot_path(folder: str | Path, step: int) -> Path:
    return Path(folder) / f"step_{step:09d}.pt"


def snapshot_steps(folder: str | Path) -> list[int]:
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(int(m.group(1)) for p in folder.iterdir() if (m := _SNAPSHOT.match(p.name)))


def load_snapshot(path: str | Path) -> dict[str, Any]:
    """A snapshot as saved (plain tensors and containers: loaded with ``weights_only=True``)."""
    state = torch.load(path, map_location="cpu", weights_only=True)
    if not isinstance(state, dict) or state.get("format") != SNAPSHOT_FORMAT:
        raise ValueError(f"{path}: not a policy snapshot of format {SNAPSHOT_FORMAT}")
    return state


def _cpu_state(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().to("cpu", copy=True) for k, v in module.state_dict().items()}


class Recorder:
    """Writes the recording of one run; the trainer calls :meth:`episode` and :meth:`snapshot`."""

    def __init__(self, run_dir: str | Path, policy: PolicySpec):
        self.root = record_dir(run_dir)
        self.episodes = EpisodeStore(self.root / EPISODES)  # never pruned
        self.snapshots = self.root / SNAPSHOTS
        self.snapshots.mkdir(parents=True, exist_ok=True)
        self.policy = policy

    @classmethod
    def open(cls, run_dir: str | Path, agent_cfg: AgentConfig, obs_shape: tuple[int, int, int], action_dim: int,
             checkpoint: dict | None) -> Recorder:
        """The recorder of a (re)starting run, rewound to ``checkpoint`` (None: a start from scratch)."""
        shape = cast("tuple[int, int, int]", tuple(obs_shape))
        rec = cls(run_dir, PolicySpec(shape, int(action_dim), int(agent_cfg.feature_dim),
                                      int(agent_cfg.hidden_dim)))
        counters = checkpoint["counters"] if checkpoint else {"episode": 0, "step": 0}
        rec.rewind(int(counters["episode"]), int(counters["step"]))
        return rec

    # ----------------------------------------------------------------- resume
    def rewind(self, episodes_done: int, step: int) -> None:
        """Delete what a checkpoint at ``step`` after ``episodes_done`` training episodes does not cover
        (episodes with id >= episodes_done, snapshots at steps >= step: the evaluation at the checkpoint's
        step runs after it) and torn temporary files. ``rewind(0, 0)`` on a start without checkpoint."""
        for ep_id in self.episodes.ids():
            if ep_id >= episodes_done:
                self.episodes.path(ep_id).unlink(missing_ok=True)
        for s in snapshot_steps(self.snapshots):
            if s >= step:
                snapshot_path(self.snapshots, s).unlink(missing_ok=True)
        for folder in (self.episodes.folder, self.snapshots):
            for tmp in folder.glob(".*.tmp"):
                tmp.unlink(missing_ok=True)

    # ----------------------------------------------------------------- hooks
    def episode(self, data: dict[str, np.ndarray], written: str | Path | None = None) -> None:
        """Keep a finished training episode. ``written``: a file that already holds exactly ``data`` (the
        run's replay/ episode file, saved just before); it is hard-linked (no second copy on disk),
        falling back to a copy, or to writing ``data`` when no such file is given."""
        target = self.episodes.path(int(data["ep_id"]))
        if written is None or not Path(written).is_file():
            self.episodes.save(data)
            return
        with atomic_output(target) as tmp:
            tmp.unlink()
            try:
                os.link(written, tmp)
            except OSError:  # no hard links on this filesystem
                shutil.copyfile(written, tmp)

    def snapshot(self, agent: OnlineLearner, step: int, frame: int, eval_return: float) -> None:
        """Keep the acting part of ``agent`` (its ``acting_modules()``, ``.stddev(step)``) after the evaluation at
        ``step``, with that evaluation's mean return."""
        state: dict[str, Any] = {"format": SNAPSHOT_FORMAT, "step": int(step), "frame": int(frame),
                                 "eval_return": float(eval_return), "stddev": float(agent.stddev(step)),
                                 "policy": self.policy.as_dict()}
        state.update({name: _cpu_state(module) for name, module in agent.acting_modules().items()})

        def write(f) -> None:
            buf = io.BytesIO()
            torch.save(state, buf)
            f.write(buf.getvalue())

        atomic_write(snapshot_path(self.snapshots, step), write)
