"""The benchmarks' one clock: ``time.perf_counter`` read after the device's queued work is done.

A CUDA kernel returns before it runs, so a reading without a synchronize times the launch, not the work.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def sync(device: str) -> None:
    """Wait for the work queued on ``device`` (CUDA's synchronize; nothing to wait for on the CPU)."""
    if device.startswith("cuda"):
        import torch

        torch.cuda.synchronize()


def now(device: str = "cpu") -> float:
    """Seconds on the monotonic performance counter, read once ``device`` has finished its queued work."""
    sync(device)
    return time.perf_counter()


def timed(fn: Callable[[], T], device: str = "cpu") -> tuple[T, float]:
    """``fn()``'s result and its wall-clock seconds, the device synchronized before and after."""
    start = now(device)
    out = fn()
    return out, now(device) - start
