"""Offline data benchmark: load time and memory of a dataset, and sampling speed against the online buffer.

In one run: synthesize a dataset of N transitions with the real writer (repro.data.dataset.write_dataset),
load it with the offline loop's loader (repro.data.offline_replay.load_offline_data), and fill an online
ReplayBuffer with the same episodes the way the online loop does (start_episode/add/end_episode). Reported:
load seconds (and the online fill's), the replay's bytes over the raw frame bytes, the process's peak
memory growth during the load over the raw frame bytes, and batches/s of both buffers at the same batch
size, as ratios measured side by side.

Frames are synthetic but compressible like rendered ones (a square moving over a per-episode gradient,
plus mild noise), so the files' compression, and with it the load time, is of the order of real datasets'.
"""

from __future__ import annotations

import resource
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from repro.bench.clock import timed
from repro.data.dataset import iter_episodes, write_dataset
from repro.data.offline_replay import load_offline_data
from repro.data.replay import ReplayBuffer

FRAME_SHAPE = (3, 84, 84)
FRAME_STACK, NSTEP, K, DISCOUNT = 3, 3, 3, 0.99  # the online defaults (DrQ-v2 / TACO)
TASK, ACTION_DIM = "cheetah_run", 6


def synthetic_episode(index: int, transitions: int, seed: int = 0) -> dict[str, np.ndarray]:
    """One episode in the dataset contract's arrays with compressible frames."""
    rng = np.random.default_rng([seed, index])
    h, w = FRAME_SHAPE[1:]
    ramp = np.linspace(0, 1, w, dtype=np.float32)
    base = (np.stack([ramp * 200, ramp[::-1] * 150, np.full(w, 60.0 + index % 100)])[:, None, :]
            * np.ones((1, h, 1), dtype=np.float32))
    frames = np.empty((transitions + 1, *FRAME_SHAPE), dtype=np.uint8)
    for t in range(transitions + 1):
        img = base.copy()
        y, x = (t * 3 + index) % (h - 12), (t * 5 + 2 * index) % (w - 12)
        img[:, y:y + 12, x:x + 12] = 255.0
        noise = rng.integers(0, 4, FRAME_SHAPE)
        frames[t] = np.clip(img + noise, 0, 255).astype(np.uint8)
    return {"frames": frames, "actions": rng.uniform(-1, 1, (transitions, ACTION_DIM)).astype(np.float32),
            "rewards": rng.uniform(0, 1, transitions).astype(np.float32),
            "discounts": np.ones(transitions, dtype=np.float32), "ep_id": np.array(index)}


def episode_lengths(transitions: int, episode_length: int) -> list[int]:
    """Episodes of ``episode_length`` transitions (the last one shorter) summing to ``transitions``."""
    full, rest = divmod(transitions, episode_length)
    return [episode_length] * full + ([rest] if rest else [])


def peak_rss_bytes() -> int:
    """The process's peak resident memory so far (Linux reports KiB)."""
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024


def batches_per_second(buffer: ReplayBuffer, batch_size: int, iters: int) -> float:
    buffer.sample(batch_size)  # warm-up

    def sample() -> None:
        for _ in range(iters):
            buffer.sample(batch_size)

    return iters / timed(sample)[1]


def fill_online(directory: Path, capacity: int, seed: int) -> ReplayBuffer:
    """An online ReplayBuffer holding the dataset's episodes, filled step by step as the online loop does."""
    buf = ReplayBuffer(capacity, FRAME_SHAPE, ACTION_DIM, FRAME_STACK, NSTEP, K, DISCOUNT, seed=seed)
    for ep in iter_episodes(directory, verify=False):
        buf.add_episode(ep)
    return buf


def run_data_bench(transitions: int = 100_000, batch_size: int = 256, iters: int = 50, episode_length: int = 500,
                   work_dir: Path | None = None, echo: Callable[[str], None] = print, seed: int = 0) -> dict[str, Any]:
    """Write, load and sample a dataset of ``transitions``; print ratios measured in this run."""
    if transitions < 1 or batch_size < 1 or iters < 1 or episode_length < K:
        raise ValueError("--transitions, --batch and --sample-batches must be >= 1 and the episode length >= K")
    tmp = Path(tempfile.mkdtemp(prefix="repro-bench-data-", dir=work_dir))
    try:
        lengths = episode_lengths(transitions, episode_length)
        directory = tmp / "dataset"

        def episodes() -> Iterator[dict[str, np.ndarray]]:
            for i, n in enumerate(lengths):
                yield synthetic_episode(i, n, seed)

        manifest, write_s = timed(lambda: write_dataset(directory, episodes(), task=TASK, kind="synthetic",
                                                        source={"benchmark": "repro.bench.data"},
                                                        rule={"transitions": transitions}))
        disk = sum(p.stat().st_size for p in directory.rglob("*") if p.is_file())
        echo(f"wrote {manifest.transitions:,} transitions in {len(lengths)} episodes ({disk / 2**20:.1f} MiB on disk) "
             f"in {write_s:.1f} s")

        rss_before = peak_rss_bytes()
        data, load_s = timed(lambda: load_offline_data(directory, task=TASK, action_dim=ACTION_DIM,
                                                       frame_shape=FRAME_SHAPE, frame_stack=FRAME_STACK, nstep=NSTEP,
                                                       K=K, discount=DISCOUNT, seed=seed))
        rss_growth = max(0, peak_rss_bytes() - rss_before)
        raw = data.raw_frame_bytes
        assert data.buffer is not None  # load_offline_data always builds the replay (only DT's loader does not)
        offline_bytes = data.buffer.nbytes()
        echo(f"load_offline_data: {load_s:.2f} s; replay bytes / raw frame bytes: {offline_bytes / raw:.4f} "
             f"(target <= 1.10); peak memory growth during the load / raw frame bytes: {rss_growth / raw:.3f}")

        capacity = data.buffer.capacity
        online, fill_s = timed(lambda: fill_online(directory, capacity, seed))
        echo(f"online ReplayBuffer filled with the same episodes: {fill_s:.2f} s (read + add step by step); "
             f"load / online fill time: {load_s / fill_s:.2f}x (measured in this run)")

        off_bps = batches_per_second(data.buffer, batch_size, iters)
        on_bps = batches_per_second(online, batch_size, iters)
        echo(f"sampling at batch {batch_size}: offline {off_bps:.1f} batches/s, online {on_bps:.1f} batches/s; "
             f"offline / online: {off_bps / on_bps:.2f}x (measured in this run, {iters} batches each)")
        return {"transitions": manifest.transitions, "episodes": len(lengths), "episode_length": episode_length,
                "disk_bytes": disk, "write_seconds": write_s, "load_seconds": load_s,
                "online_fill_seconds": fill_s, "raw_frame_bytes": raw, "replay_bytes": offline_bytes,
                "online_replay_bytes": online.nbytes(), "peak_rss_growth_bytes": rss_growth,
                "batch_size": batch_size, "iters": iters, "offline_batches_per_s": off_bps,
                "online_batches_per_s": on_bps,
                "ratios": {"replay_bytes_over_raw_frames": offline_bytes / raw,
                           "peak_rss_growth_over_raw_frames": rss_growth / raw,
                           "load_over_online_fill_time": load_s / fill_s,
                           "offline_over_online_batches_per_s": off_bps / on_bps}}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
