"""Checkpoints: plain tensors and containers only (loaded with weights_only=True), written atomically."""

from __future__ import annotations

import io
from pathlib import Path

import torch

from repro.runs.fsutil import atomic_write

FORMAT = 1


def save_checkpoint(path: str | Path, state: dict) -> None:
    def write(f) -> None:
        buf = io.BytesIO()
        torch.save({"format": FORMAT, **state}, buf)
        f.write(buf.getvalue())

    atomic_write(path, write)


def load_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    state = torch.load(path, map_location=map_location, weights_only=True)
    if state.get("format") != FORMAT:
        raise ValueError(f"{path}: unsupported checkpoint format {state.get('format')}")
    return state
