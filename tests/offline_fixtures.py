"""Tiny datasets in the dataset contract's format (docs/offline.md): episodes/ep_XXXXXXX.npz + manifest.json (last).

Frames carry their episode and time index in pixel (0, 0) and (0, 1) of every channel, rewards and actions
are known functions of (episode, t), so tests can check what the replay samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from repro.data.dataset import write_dataset as real_write_dataset


def reward_of(ep: int, t: int) -> float:
    return float(ep * 100 + t)


def action_of(ep: int, t: int, action_dim: int) -> np.ndarray:
    return np.array([(ep + 1) / 10.0, t / 100.0] + [0.5] * (action_dim - 2), dtype=np.float32)[:action_dim]


def make_episode(ep: int, transitions: int, frame_shape: tuple[int, int, int], action_dim: int,
                 rng: np.random.Generator) -> dict[str, np.ndarray]:
    frames = rng.integers(0, 256, (transitions + 1, *frame_shape), dtype=np.uint8)
    frames[:, :, 0, 0] = ep
    frames[:, :, 0, 1] = np.arange(transitions + 1)[:, None]
    return {"frames": frames,
            "actions": np.stack([action_of(ep, t, action_dim) for t in range(transitions)]),
            "rewards": np.array([reward_of(ep, t) for t in range(transitions)], dtype=np.float32),
            "discounts": np.ones(transitions, dtype=np.float32), "ep_id": np.array(ep)}


def write_dataset(directory: Path, task: str = "hopper_hop", lengths: tuple[int, ...] = (12, 9, 15),
                  frame_shape: tuple[int, int, int] = (3, 84, 84), action_dim: int = 4, kind: str = "medium",
                  best_return: float | None = None, seed: int = 0) -> Path:
    """A tiny dataset written through the real dataset writer (repro.data.dataset.write_dataset)."""
    directory = Path(directory)
    rng = np.random.default_rng(seed)
    episodes = [make_episode(ep, n, frame_shape, action_dim, rng) for ep, n in enumerate(lengths)]
    source = {"run_dir": "synthetic"} if best_return is None else {"run_dir": "synthetic", "best_return": best_return}
    real_write_dataset(directory, episodes, task=task, kind=kind, source=source, rule={"synthetic": True})
    return directory
