"""Pure losses of the toy plugin (no modules, no state)."""

from __future__ import annotations

import torch


def return_weights(returns: torch.Tensor, temperature: float, max_weight: float) -> torch.Tensor:
    """Per-transition weights exp((r - max r) / temperature), normalised to mean 1 over the batch and capped at
    ``max_weight``; no gradient (they weight the loss, they are not trained)."""
    r = returns.detach().reshape(-1).float()
    w = torch.exp((r - r.max()) / temperature)
    return (w / w.mean()).clamp(max=max_weight)


def weighted_bc_loss(predicted: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    """Mean over the batch of weight_i x the mean squared error of row i (plain BC when every weight is 1)."""
    if predicted.shape != target.shape or weights.shape != predicted.shape[:1]:
        raise ValueError(f"weighted_bc_loss: predicted {tuple(predicted.shape)}, target {tuple(target.shape)}, "
                         f"weights {tuple(weights.shape)}")
    return (weights * (predicted - target).pow(2).mean(dim=1)).mean()


def inverse_dynamics_loss(predicted: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """Mean squared error between the predicted and the taken action sequence, (B, K x |A|) against (B, K, |A|)."""
    return (predicted - actions.reshape(actions.shape[0], -1)).pow(2).mean()
