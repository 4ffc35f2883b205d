"""Helpers shared by objectives: parameter defaults, negative cosine, momentum (EMA) targets."""

from __future__ import annotations

import copy
from typing import TypeVar

import torch
from torch import nn

from repro.agent.objectives.base import ObjectiveContext

P = TypeVar("P")


def typed_params(ctx: ObjectiveContext, kind: type[P]) -> P:
    """The objective's parameters, an instance of ``kind`` (its registered ``ObjectiveSpec.params``): the context's,
    checked and typed by the config (repro.config.compose.objective_params), or ``kind``'s defaults when the context
    carries none (one built by hand)."""
    if ctx.params is None:
        return kind()
    if not isinstance(ctx.params, kind):
        raise TypeError(f"the objective's parameters are a {type(ctx.params).__name__}, not a {kind.__name__} (is "
                        f"the objective registered with params={kind.__name__}?)")
    return ctx.params


def negative_cosine(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean over rows of -cos(pred_i, target_i) (SPR's loss; equal to BYOL's 2 - 2cos up to an affine map)."""
    pred = nn.functional.normalize(pred, dim=-1)
    target = nn.functional.normalize(target, dim=-1)
    return -(pred * target).sum(dim=-1).mean()


class MomentumTarget(nn.Module):
    """Frozen copies of online modules, moved towards them by ``update()``.

    ``update`` computes target <- momentum * target + (1 - momentum) * online for every parameter and
    copies buffers. The online modules are kept as plain references (not registered), so their
    parameters are neither counted nor saved twice under the owning objective.
    """

    def __init__(self, online: dict[str, nn.Module], momentum: float):
        super().__init__()
        if not 0.0 <= momentum < 1.0:
            raise ValueError(f"momentum must be in [0, 1) (got {momentum}).")
        self.momentum = float(momentum)
        self.copies = nn.ModuleDict({name: copy.deepcopy(mod) for name, mod in online.items()})
        self.copies.requires_grad_(False)
        self._online: tuple[tuple[str, nn.Module], ...] = tuple(online.items())

    def __getitem__(self, name: str) -> nn.Module:
        return self.copies[name]

    @torch.no_grad()
    def update(self) -> None:
        for name, online in self._online:
            target = self.copies[name]
            for tp, p in zip(target.parameters(), online.parameters()):
                tp.lerp_(p, 1.0 - self.momentum)
            for tb, b in zip(target.buffers(), online.buffers()):
                tb.copy_(b)
