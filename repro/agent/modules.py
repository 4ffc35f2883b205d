"""What every learner with named modules and optimizers shares: parameter counts, checkpoint state, train mode."""

from __future__ import annotations

import torch
from torch import nn


class ModuleSet:
    """Mixin over ``modules()`` and ``optimizers()`` (both by name). Modules named in ``untrained`` (a target
    network) stay in eval mode and are left out of the parameter counts; they are still checkpointed."""

    untrained: tuple[str, ...] = ()
    training: bool = True

    def modules(self) -> dict[str, nn.Module]:
        raise NotImplementedError

    def optimizers(self) -> dict[str, torch.optim.Optimizer]:
        raise NotImplementedError

    def parameter_counts(self) -> list[tuple[str, int]]:
        """Trainable parameters per module; a parameter shared by two modules counts at the first."""
        rows: list[tuple[str, int]] = []
        seen: set[int] = set()
        for name, mod in self.modules().items():
            if name in self.untrained:
                continue
            params = [p for p in mod.parameters() if p.requires_grad and id(p) not in seen]
            seen.update(id(p) for p in params)
            rows.append((name, sum(p.numel() for p in params)))
        return rows

    def state_dict(self) -> dict:
        """Plain tensors and containers (checkpoints load with ``weights_only=True``)."""
        return {"modules": {k: m.state_dict() for k, m in self.modules().items()},
                "optimizers": {k: o.state_dict() for k, o in self.optimizers().items()}}

    def load_state_dict(self, state: dict) -> None:
        for k, m in self.modules().items():
            m.load_state_dict(state["modules"][k])
        for k, o in self.optimizers().items():
            o.load_state_dict(state["optimizers"][k])

    def train(self, training: bool = True) -> None:
        self.training = training
        for name, mod in self.modules().items():
            if name not in self.untrained:
                mod.train(training)
