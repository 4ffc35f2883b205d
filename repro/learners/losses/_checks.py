"""Shape checks shared by the loss functions: a silent broadcast ((B, 1) against (B,)) is the usual bug."""

from __future__ import annotations

import torch


def same_shape(**tensors: torch.Tensor) -> None:
    """Raise a one-line ValueError unless every tensor has the same shape."""
    shapes = {name: tuple(t.shape) for name, t in tensors.items()}
    if len(set(shapes.values())) > 1:
        raise ValueError("shape mismatch: " + ", ".join(f"{k}={v}" for k, v in shapes.items()))
