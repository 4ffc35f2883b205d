"""The replay's size, computed without torch (``repro plan`` prices runs without importing it)."""

from __future__ import annotations

import math


def replay_bytes(capacity: int, frame_shape: tuple[int, int, int], action_dim: int) -> int:
    """What :meth:`repro.data.replay.ReplayBuffer.nbytes` is for a buffer of ``capacity`` (allocated in full at
    construction): uint8 frames, float32 actions, rewards and discounts, int64 episode ids and positions."""
    return capacity * (math.prod(frame_shape) + 4 * action_dim + 4 + 4 + 8 + 8)
