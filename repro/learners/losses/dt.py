"""Decision Transformer's loss (Chen et al. 2021): mean squared error of the predicted actions of the unpadded
steps of a window (the model, sampler and optimizer are ``repro/learners/dt_model.py``)."""

from __future__ import annotations

import torch


def action_loss(pred: torch.Tensor, target: torch.Tensor, keep: torch.Tensor) -> torch.Tensor:
    """Mean squared error over the action dimensions of the unpadded steps only.

    ``keep`` holds the flat indices (into the B*K steps, ascending) of the unpadded steps, as the window
    sampler builds them on the host (``dt_model.kept_steps``). Gathering with an integer index needs no host
    sync, where indexing with the boolean (B, K) mask would (its count of kept steps sizes the result); both
    pick the same steps in the same order, so the mean is the same bits.
    """
    if pred.shape != target.shape or pred.dim() != 3 or keep.dim() != 1 or keep.dtype != torch.int64:
        raise ValueError(f"pred {tuple(pred.shape)} and target {tuple(target.shape)} must be the same (B, K, A) "
                         f"and keep 1-D int64 step indices; got keep {tuple(keep.shape)} {keep.dtype}")
    steps = pred.flatten(0, 1)[keep]
    return (steps - target.flatten(0, 1)[keep].detach()).pow(2).mean()
