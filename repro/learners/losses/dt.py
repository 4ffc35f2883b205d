"""Decision Transformer's loss (Chen et al. 2021): mean squared error of the predicted actions of the unpadded
steps of a window (the model, sampler and optimizer are ``repro/learners/dt_model.py``)."""

from __future__ import annotations

import torch


def action_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean squared error over the action dimensions of the unpadded steps only."""
    if pred.shape != target.shape or pred.shape[:2] != mask.shape:
        raise ValueError(f"pred {tuple(pred.shape)}, target {tuple(target.shape)} and mask "
                         f"{tuple(mask.shape)} do not match")
    keep = mask.bool()
    return (pred[keep] - target[keep].detach()).pow(2).mean()
