"""Load a dataset (contract: docs/offline.md) into the online ReplayBuffer, once.

Frames are stored once (uint8, single frames, like the online ring), so the buffer's memory is the raw
frame bytes plus a few bytes per transition; stacks, n-step returns and K-step action sequences are then
sampled exactly as online, never across episodes. A learner trained on episode windows (Decision
Transformer) gets the checked episodes themselves instead (``load_offline_episodes``), never both.
"""

from __future__ import annotations

import hashlib
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from repro.agent.protocol import EpisodeLimit

# The one import of the dataset API (repro/data/dataset.py).
from repro.data.dataset import DatasetError, Manifest, iter_episodes, load_manifest, resolve_dataset
from repro.data.replay import ReplayBuffer

__all__ = ["DatasetError", "OfflineData", "load_offline_data", "load_offline_episodes", "resolve_dataset"]


@dataclass
class OfflineData:
    directory: Path
    manifest: Manifest
    digest: str  # sha256 of manifest.json (a checkpoint refuses to resume on another dataset)
    buffer: ReplayBuffer | None  # None when loaded as episodes
    raw_frame_bytes: int  # bytes of the dataset's frames as stored in the episode files (uncompressed)
    episodes: list[dict[str, np.ndarray]] | None = None  # load_offline_episodes: the checked episodes, in order

    @property
    def best_return(self) -> float:
        """The dataset's best episode return (the manifest's per-episode returns)."""
        return float(self.manifest.returns.max())


def manifest_digest(directory: str | Path) -> str:
    return hashlib.sha256((Path(directory) / "manifest.json").read_bytes()).hexdigest()


def check_compatible(manifest: Manifest, directory: Path, task: str, action_dim: int,
                     frame_shape: tuple[int, int, int]) -> None:
    """One-line DatasetError when the dataset is for another task, action size or frame size."""
    if manifest.task != task:
        raise DatasetError(f"{directory} is a {manifest.task} dataset, the run's task is {task}")
    if int(manifest.action_dim) != action_dim:
        raise DatasetError(f"{directory} has |A|={manifest.action_dim}, the run's environment has |A|={action_dim}")
    if tuple(manifest.frame_shape) != tuple(frame_shape):
        raise DatasetError(f"{directory} has frames {list(manifest.frame_shape)}, the run renders {list(frame_shape)}"
                           " (env.image_size)")
    if not manifest.episodes:
        raise DatasetError(f"{directory} holds no episode")


def _checked(data: dict[str, np.ndarray], index: int, transitions: int, frame_shape: tuple[int, ...],
             action_dim: int, directory: Path) -> dict[str, np.ndarray]:
    where = f"{directory}: episode {index}"
    for key in ("frames", "actions", "rewards", "discounts"):
        if key not in data:
            raise DatasetError(f"{where} lacks '{key}'")
    frames, actions = data["frames"], data["actions"]
    if frames.dtype != np.uint8 or frames.shape != (transitions + 1, *frame_shape):
        raise DatasetError(f"{where}: frames {frames.dtype}{list(frames.shape)}, expected uint8"
                           f"{[transitions + 1, *frame_shape]} (manifest: {transitions} transitions)")
    if actions.shape != (transitions, action_dim):
        raise DatasetError(f"{where}: actions {list(actions.shape)}, expected {[transitions, action_dim]}")
    for key in ("rewards", "discounts"):
        if data[key].shape != (transitions,):
            raise DatasetError(f"{where}: {key} {list(data[key].shape)}, expected {[transitions]}")
    return data


def _checked_manifest(directory: Path, task: str, action_dim: int,
                      frame_shape: tuple[int, int, int]) -> tuple[Manifest, list[int]]:
    """The dataset's manifest, checked against the run, and its episodes' lengths in transitions."""
    manifest = load_manifest(directory)
    check_compatible(manifest, directory, task, action_dim, frame_shape)
    return manifest, [int(e.transitions) for e in manifest.episodes]


@contextmanager
def _unreadable_episodes(directory: Path) -> Iterator[None]:
    """An episode file that cannot be read, inside the block, as a one-line DatasetError naming the dataset."""
    try:
        yield
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        if isinstance(exc, DatasetError):
            raise
        raise DatasetError(f"{directory}: unreadable episode file ({str(exc).splitlines()[0]})") from None


def load_offline_data(directory: str | Path, *, task: str, action_dim: int, frame_shape: tuple[int, int, int],
                      frame_stack: int, nstep: int, K: int, discount: float, seed: int,
                      device: str | torch.device = "cpu",
                      sample_device: str | torch.device | None = None) -> OfflineData:
    """Check the dataset against the run, then fill a ReplayBuffer sized to it, one episode file at a time."""
    directory = Path(directory)
    manifest, lengths = _checked_manifest(directory, task, action_dim, frame_shape)
    capacity = sum(n + 1 for n in lengths)
    buffer = ReplayBuffer(capacity, frame_shape, action_dim, frame_stack, nstep, K, discount, seed=seed,
                          device=device, sample_device=sample_device)
    starts = np.concatenate([[0], np.cumsum([n + 1 for n in lengths])[:-1]]).astype(int)
    episodes = iter(iter_episodes(directory))
    raw = 0

    def next_episode(index: int) -> dict[str, np.ndarray]:
        nonlocal raw
        try:
            data = next(episodes)
        except StopIteration:
            raise DatasetError(f"{directory}: manifest lists {len(lengths)} episodes, fewer files read") from None
        data = _checked(data, index, lengths[index], frame_shape, action_dim, directory)
        raw += data["frames"].nbytes
        return data

    state = {"cursor": 0, "size": capacity, "next_ep_id": len(lengths),
             "episodes": [[i, int(s), n + 1] for i, (s, n) in enumerate(zip(starts, lengths))],
             "rng": buffer.rng.bit_generator.state}
    with _unreadable_episodes(directory):
        buffer.restore(state, next_episode)
    if buffer.num_valid() == 0:
        raise DatasetError(f"{directory}: no episode has {buffer.horizon} steps after a frame (agent.K, agent.nstep)")
    return OfflineData(directory, manifest, manifest_digest(directory), buffer, raw)


def load_offline_episodes(directory: str | Path, *, task: str, action_dim: int, frame_shape: tuple[int, int, int],
                          max_length: EpisodeLimit | None = None) -> OfflineData:
    """Check the dataset against the run as ``load_offline_data`` does and keep its episodes (frames held once,
    no replay); ``max_length``: the most steps an episode may have and the setting that sets it (DT: its
    timestep embedding's size)."""
    directory = Path(directory)
    manifest, lengths = _checked_manifest(directory, task, action_dim, frame_shape)
    if max_length is not None and max(lengths) > max_length.steps:
        raise DatasetError(f"{directory}: an episode has {max(lengths)} steps, more than the learner's maximum "
                           f"episode length, {max_length.setting}={max_length.steps}: raise it to at least "
                           f"{max(lengths)}")
    episodes: list[dict[str, np.ndarray]] = []
    with _unreadable_episodes(directory):
        for index, data in enumerate(iter_episodes(directory)):
            if index >= len(lengths):
                break
            episodes.append(_checked(dict(data), index, lengths[index], frame_shape, action_dim, directory))
    if len(episodes) != len(lengths):
        raise DatasetError(f"{directory}: manifest lists {len(lengths)} episodes, {len(episodes)} files read")
    raw = sum(ep["frames"].nbytes for ep in episodes)
    return OfflineData(directory, manifest, manifest_digest(directory), None, raw, episodes)
